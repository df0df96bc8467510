"""drip-cert: certificates for DRIP (TaSIL imitation policy + L1-DRAC adaptive control).

The public API is re-exported here explicitly (and imported lazily, so that ``import drip_cert``
and the command line stay fast): every name of :data:`__all__` maps to the module defining it.
The same names are imported under ``TYPE_CHECKING`` (``from module import Name as Name``, the
explicit re-export of PEP 484), so that a type checker sees each one's real type rather than the
``Any`` of the lazy ``__getattr__``; ``tests/test_public_types.py`` keeps the two lists equal and
runs mypy on a misuse of the API.
"""

from __future__ import annotations

import importlib
from typing import TYPE_CHECKING, Any

__version__ = "0.1.0"

_EXPORTS: dict[str, str] = {
    # errors and provenance
    "DripCertError": "drip_cert.errors",
    "SpecError": "drip_cert.errors",
    "AssumptionViolation": "drip_cert.errors",
    "SolverError": "drip_cert.errors",
    "InputTypeError": "drip_cert.errors",
    "Quantity": "drip_cert.provenance",
    "Check": "drip_cert.provenance",
    "How": "drip_cert.provenance",
    # describing a system
    "System": "drip_cert.model.system",
    "Spec": "drip_cert.spec.load",
    "load_spec": "drip_cert.spec.load",
    "Block": "drip_cert.model.blocks",
    "mlp_block": "drip_cert.model.blocks",
    "MLP": "drip_cert.model.mlp",
    "load_mlp": "drip_cert.model.mlp",
    "Fingerprint": "drip_cert.model.fingerprint",
    # analysis
    "input_constants": "drip_cert.analysis.growth.constants",
    "uncertainty_constants": "drip_cert.analysis.growth.constants",
    "contraction_rate": "drip_cert.analysis.contraction.rate",
    "contraction_metric": "drip_cert.analysis.contraction.lmi",
    "delta_iss": "drip_cert.analysis.iss",
    "mu_1": "drip_cert.analysis.contraction.lognorm",
    "mu_2": "drip_cert.analysis.contraction.lognorm",
    "mu_inf": "drip_cert.analysis.contraction.lognorm",
    # bounds
    "certify": "drip_cert.bounds.certificate",
    "Certificate": "drip_cert.bounds.certificate",
    "L1Constants": "drip_cert.bounds.l1drac.constants",
    "DesignRequest": "drip_cert.bounds.l1drac.request",
    "design": "drip_cert.bounds.l1drac.designer",
    "tradeoff_table": "drip_cert.bounds.l1drac.designer",
    "tasil_certificate": "drip_cert.bounds.tasil.certificate",
    # learning, control, simulation, validation
    "train_policy": "drip_cert.learn.tasil",
    "generate_demonstrations": "drip_cert.learn.data",
    "train_on_system": "drip_cert.learn.imitation",
    "learned_system": "drip_cert.learn.imitation",
    "L1Params": "drip_cert.control.l1drac",
    "L1DRACController": "drip_cert.control.controller",
    "l1drac_controller": "drip_cert.deploy",
    "learned_policy": "drip_cert.deploy",
    "SimConfig": "drip_cert.sim.config",
    "simulate": "drip_cert.sim.engine",
    "SimModel": "drip_cert.model.numeric",
    "validate": "drip_cert.validate",
    "ValidationReport": "drip_cert.validate",
    "EmpiricalCheck": "drip_cert.validate",
    "run_pipeline": "drip_cert.workflows",
    "demonstration_set": "drip_cert.learn.imitation",
    "reproduce": "drip_cert.workflows",
}

if TYPE_CHECKING:  # the names with their types, for mypy and IDEs (imported lazily at run time)
    from drip_cert.analysis.contraction.lmi import contraction_metric as contraction_metric
    from drip_cert.analysis.contraction.lognorm import mu_1 as mu_1
    from drip_cert.analysis.contraction.lognorm import mu_2 as mu_2
    from drip_cert.analysis.contraction.lognorm import mu_inf as mu_inf
    from drip_cert.analysis.contraction.rate import contraction_rate as contraction_rate
    from drip_cert.analysis.growth.constants import input_constants as input_constants
    from drip_cert.analysis.growth.constants import uncertainty_constants as uncertainty_constants
    from drip_cert.analysis.iss import delta_iss as delta_iss
    from drip_cert.bounds.certificate import Certificate as Certificate
    from drip_cert.bounds.certificate import certify as certify
    from drip_cert.bounds.l1drac.constants import L1Constants as L1Constants
    from drip_cert.bounds.l1drac.designer import design as design
    from drip_cert.bounds.l1drac.designer import tradeoff_table as tradeoff_table
    from drip_cert.bounds.l1drac.request import DesignRequest as DesignRequest
    from drip_cert.bounds.tasil.certificate import tasil_certificate as tasil_certificate
    from drip_cert.control.controller import L1DRACController as L1DRACController
    from drip_cert.control.l1drac import L1Params as L1Params
    from drip_cert.deploy import l1drac_controller as l1drac_controller
    from drip_cert.deploy import learned_policy as learned_policy
    from drip_cert.errors import AssumptionViolation as AssumptionViolation
    from drip_cert.errors import DripCertError as DripCertError
    from drip_cert.errors import InputTypeError as InputTypeError
    from drip_cert.errors import SolverError as SolverError
    from drip_cert.errors import SpecError as SpecError
    from drip_cert.learn.data import generate_demonstrations as generate_demonstrations
    from drip_cert.learn.imitation import demonstration_set as demonstration_set
    from drip_cert.learn.imitation import learned_system as learned_system
    from drip_cert.learn.imitation import train_on_system as train_on_system
    from drip_cert.learn.tasil import train_policy as train_policy
    from drip_cert.model.blocks import Block as Block
    from drip_cert.model.blocks import mlp_block as mlp_block
    from drip_cert.model.fingerprint import Fingerprint as Fingerprint
    from drip_cert.model.mlp import MLP as MLP
    from drip_cert.model.mlp import load_mlp as load_mlp
    from drip_cert.model.numeric import SimModel as SimModel
    from drip_cert.model.system import System as System
    from drip_cert.provenance import Check as Check
    from drip_cert.provenance import How as How
    from drip_cert.provenance import Quantity as Quantity
    from drip_cert.sim.config import SimConfig as SimConfig
    from drip_cert.sim.engine import simulate as simulate
    from drip_cert.spec.load import Spec as Spec
    from drip_cert.spec.load import load_spec as load_spec
    from drip_cert.validate import EmpiricalCheck as EmpiricalCheck
    from drip_cert.validate import ValidationReport as ValidationReport
    from drip_cert.validate import validate as validate
    from drip_cert.workflows import reproduce as reproduce
    from drip_cert.workflows import run_pipeline as run_pipeline

__all__ = sorted(_EXPORTS) + ["__version__"]


def __getattr__(name: str) -> Any:
    module = _EXPORTS.get(name)
    if module is None:
        raise AttributeError(f"module 'drip_cert' has no attribute {name!r}")
    return getattr(importlib.import_module(module), name)


def __dir__() -> list[str]:
    return __all__
