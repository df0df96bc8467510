"""Validation: every certified number against Monte-Carlo simulation of the true system.

:func:`validate` (:mod:`drip_cert.validate.run`) returns a :class:`ValidationReport` of
:class:`EmpiricalCheck` objects (:mod:`drip_cert.validate.checks`); the scenarios simulated are in
:mod:`drip_cert.validate.scenarios`.
"""

import sys
import types
from typing import Any

from drip_cert.validate.checks import (
    HOLDS,
    NOT_CHECKED,
    NOTHING_CHECKED,
    VIOLATED,
    EmpiricalCheck,
    checks_from_result,
    overall_status,
)
from drip_cert.validate.run import ShortHorizonRun, ValidationReport, validate

__all__ = [
    "HOLDS",
    "NOTHING_CHECKED",
    "NOT_CHECKED",
    "VIOLATED",
    "EmpiricalCheck",
    "ShortHorizonRun",
    "ValidationReport",
    "checks_from_result",
    "overall_status",
    "validate",
]


class _CallableModule(types.ModuleType):
    """This package, callable as :func:`validate`.

    ``drip_cert.validate`` names both the public function (lazily re-exported by
    ``drip_cert/__init__.py``) and this package: importing the package binds the name
    ``validate`` of ``drip_cert`` to the module, so without this a second
    ``drip_cert.validate(...)`` (or any after ``import drip_cert.validate``) would raise
    "'module' object is not callable".
    """

    def __call__(self, *args: Any, **kwargs: Any) -> ValidationReport:
        return validate(*args, **kwargs)


sys.modules[__name__].__class__ = _CallableModule
