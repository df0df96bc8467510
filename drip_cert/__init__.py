"""drip-cert: certificates for DRIP (TaSIL imitation policy + L1-DRAC adaptive control).

The public API is re-exported here explicitly (and imported lazily, so that ``import drip_cert``
and the command line stay fast): every name of :data:`__all__` maps to the module defining it.
"""

from __future__ import annotations

import importlib
from typing import Any

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
    "input_constants": "drip_cert.analysis.constants",
    "uncertainty_constants": "drip_cert.analysis.constants",
    "contraction_rate": "drip_cert.analysis.contraction",
    "contraction_metric": "drip_cert.analysis.lmi",
    "delta_iss": "drip_cert.analysis.iss",
    "mu_1": "drip_cert.analysis.lognorm",
    "mu_2": "drip_cert.analysis.lognorm",
    "mu_inf": "drip_cert.analysis.lognorm",
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

__all__ = sorted(_EXPORTS) + ["__version__"]


def __getattr__(name: str) -> Any:
    module = _EXPORTS.get(name)
    if module is None:
        raise AttributeError(f"module 'drip_cert' has no attribute {name!r}")
    return getattr(importlib.import_module(module), name)


def __dir__() -> list[str]:
    return __all__
