"""Validation: every certified number against Monte-Carlo simulation of the true system.

:func:`validate` (:mod:`drip_cert.validate.run`) returns a :class:`ValidationReport` of
:class:`EmpiricalCheck` objects (:mod:`drip_cert.validate.checks`); the scenarios simulated are in
:mod:`drip_cert.validate.scenarios`.
"""

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
