"""L1-DRAC certificate calculator: the paper's constants, its design conditions, and a designer.

Source: A. Gahlawat, S. H. Karumanchi, N. Hovakimyan, "L1-DRAC: Distributionally Robust Adaptive
Control -- Global Results", arXiv:2509.04619 (2025-09-04). Sec. 3.2 (conditions (16), (21), (24)),
Sec. 4 (Lemma 4.4, Theorem 4.1), Appendix A. The transcription used is ``docs/math/l1drac.md``;
every formula was re-checked against the PDF.

One concept per module; each imports only the modules above it in this list:

* :mod:`~drip_cert.bounds.l1drac.backend` -- the float64 and Arb numeric backends.
* :mod:`~drip_cert.bounds.l1drac.constants` -- :class:`L1Constants` (Assumptions 1-8), validated.
* :mod:`~drip_cert.bounds.l1drac.request` -- :class:`DesignRequest`, what the user fixes.
* :mod:`~drip_cert.bounds.l1drac.appendix` -- the Appendix A constants and maps (A.1)-(A.19).
* :mod:`~drip_cert.bounds.l1drac.sides` -- Gamma, Theta, Upsilon_a (18b, c), (22), (23), (25) and
  the two sides of each condition.
* :mod:`~drip_cert.bounds.l1drac.verify` -- the conditions re-evaluated in Arb ball arithmetic.
* :mod:`~drip_cert.bounds.l1drac.conditions` -- :class:`ConditionResult`, the conditions (16a),
  (16b), (21a), (21b), (24) with float64 and Arb verdicts.
* :mod:`~drip_cert.bounds.l1drac.searches` -- the monotone root searches for rho_r, rho_a, Ts.
* :mod:`~drip_cert.bounds.l1drac.backoff` -- the move of a float design into the interior.
* :mod:`~drip_cert.bounds.l1drac.result` -- :class:`L1Design`, the designer's result.
* :mod:`~drip_cert.bounds.l1drac.radii` -- Theorem 4.1: p for delta, kappa, the ultimate bound.
* :mod:`~drip_cert.bounds.l1drac.mean` -- the mean-gap bound and the best-order kappa at one
  controller (:func:`mean_gap_bound`).
* :mod:`~drip_cert.bounds.l1drac.solve` -- the searches at one objective (``solve``).
* :mod:`~drip_cert.bounds.l1drac.designer` -- :func:`design` (the objectives),
  :func:`pareto_front`, :func:`knife_edge` and :func:`tradeoff_table`.
* :mod:`~drip_cert.bounds.l1drac.toml` -- a ``design-l1`` constants file.
* :mod:`~drip_cert.bounds.l1drac.system` -- the constants of a System and the certificate's
  L1-DRAC section.

This package re-exports the user-facing names; the modules of the package import each other
directly, never through this file.
"""

from drip_cert.bounds.l1drac.backoff import BACKOFF_GROWTH, BACKOFF_START, BACKOFF_STEPS
from drip_cert.bounds.l1drac.conditions import (
    ConditionResult,
    condition_16a,
    condition_16b,
    condition_21a,
    condition_21b,
    condition_24,
    evaluate_conditions,
)
from drip_cert.bounds.l1drac.constants import CONSTANT_NAMES, L1Constants
from drip_cert.bounds.l1drac.designer import (
    TradeoffRow,
    design,
    knife_edge,
    pareto_front,
    tradeoff_table,
)
from drip_cert.bounds.l1drac.mean import MeanGapBound, mean_gap_bound
from drip_cert.bounds.l1drac.radii import kappa_markov, p_for_delta, ultimate_bound
from drip_cert.bounds.l1drac.request import OBJECTIVES, PRACTICAL_TS, DesignRequest
from drip_cert.bounds.l1drac.result import FrontPoint, L1Design
from drip_cert.bounds.l1drac.searches import ROOT_RTOL, largest_Ts, smallest_rho_a, smallest_rho_r
from drip_cert.bounds.l1drac.verify import VERIFY_METHOD

__all__ = [
    "CONSTANT_NAMES",
    "ROOT_RTOL",
    "BACKOFF_START",
    "BACKOFF_GROWTH",
    "BACKOFF_STEPS",
    "VERIFY_METHOD",
    "L1Constants",
    "DesignRequest",
    "ConditionResult",
    "L1Design",
    "TradeoffRow",
    "condition_16a",
    "condition_16b",
    "condition_21a",
    "condition_21b",
    "condition_24",
    "evaluate_conditions",
    "smallest_rho_r",
    "smallest_rho_a",
    "largest_Ts",
    "design",
    "pareto_front",
    "knife_edge",
    "FrontPoint",
    "OBJECTIVES",
    "PRACTICAL_TS",
    "tradeoff_table",
    "p_for_delta",
    "kappa_markov",
    "ultimate_bound",
    "MeanGapBound",
    "mean_gap_bound",
]
