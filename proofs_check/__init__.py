"""Machine checks of the derivations of the DRIP paper and of L1-DRAC that drip-cert relies on.

Run ``python -m proofs_check`` (``--json``, ``--only SUBSTRING``, ``--quick``, ``--seed N``).
One module per result; the errata the checks establish are written down in
``proofs_check/ERRATA.md``. See :mod:`proofs_check._core` for the verdicts and the residual.
"""

from __future__ import annotations

import importlib

from proofs_check._core import CheckResult, Context, Verdict, registry, run_checks

MODULES = (
    "proofs_check.delta_iss",
    "proofs_check.corollary_discrete",
    "proofs_check.decomposition",
    "proofs_check.tasil_gap",
    "proofs_check.tasil_rates",
    "proofs_check.tasil_comparison",
    "proofs_check.tasil_tube",
    "proofs_check.tasil_difference",
    "proofs_check.l1drac_probability",
    "proofs_check.l1drac_adaptation",
    "proofs_check.l1drac_maps",
    "proofs_check.paper_example",
    "proofs_check.paper_text",
    "proofs_check.invariance",
    "proofs_check.sde_moments",
    "proofs_check.l1drac_exit",
    "proofs_check.coordinates",
    "proofs_check.slope_lmi",
    "proofs_check.implementation",
)


def load_all() -> None:
    """Import every check module (each registers its checks on import)."""
    for mod in MODULES:
        importlib.import_module(mod)


__all__ = ["CheckResult", "Context", "Verdict", "load_all", "registry", "run_checks"]
