"""The result of the L1-DRAC designer: :class:`L1Design`.

Source: A. Gahlawat, S. H. Karumanchi, N. Hovakimyan, "L1-DRAC: Distributionally Robust Adaptive
Control -- Global Results", arXiv:2509.04619 (2025-09-04), Sec. 3.2 (the parameters and radii)
and Theorem 4.1 (kappa, (130a)).
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field
from typing import Any

from drip_cert.bounds.l1drac.backoff import BACKOFF_GROWTH, BACKOFF_START, BACKOFF_STEPS
from drip_cert.bounds.l1drac.conditions import ConditionResult
from drip_cert.bounds.l1drac.searches import ROOT_RTOL
from drip_cert.bounds.l1drac.verify import ARB_PREC, VERIFY_METHOD
from drip_cert.provenance import How, json_float, weakest

__all__ = ["L1Design"]


@dataclass(frozen=True)
class L1Design:
    """Result of :func:`~drip_cert.bounds.l1drac.designer.design`: the control parameters, the
    radii and every condition's verdict.

    ``feasible`` is True iff all five conditions are in ``conditions`` and every one is
    *verified*: re-evaluated at the returned point in Arb ball arithmetic, with a margin ball
    whose lower end is > 0 (:class:`~drip_cert.bounds.l1drac.conditions.ConditionResult`).
    ``kappa`` is ``rho * delta^{-1/(2p)}`` (the Markov step of Theorem 4.1, valid for any delta
    in (0, 1) at this p; see :func:`~drip_cert.bounds.l1drac.radii.kappa_markov`), None unless
    delta was given. ``how`` says for each parameter whether it was "given" or "found" (not a
    provenance label: see :meth:`label`). ``reason`` names the failing or unverified condition
    and by how much when infeasible. ``backoff`` gives, for each free parameter moved off its
    float root, the factor applied (rho_r and rho_a were multiplied by it, Ts divided by it; see
    :mod:`drip_cert.bounds.l1drac.backoff`).
    """

    feasible: bool
    p: int
    omega: float | None
    lambda_s: float | None
    Ts: float | None
    rho_r: float | None
    rho_a: float | None
    rho: float | None
    kappa: float | None
    conditions: tuple[ConditionResult, ...]
    reason: str
    notes: tuple[str, ...] = ()
    delta: float | None = None
    how: tuple[tuple[str, str], ...] = ()
    seconds: float = field(default=math.nan, compare=False)
    backoff: tuple[tuple[str, float], ...] = ()

    @property
    def verified(self) -> bool:
        """All five conditions present and Arb-verified (the same as :attr:`feasible`)."""
        return len(self.conditions) == 5 and all(r.verified for r in self.conditions)

    @property
    def min_verified_margin(self) -> float:
        """The smallest rigorous lower end of the margins (``-inf`` without conditions)."""
        return min((r.margin_lo for r in self.conditions), default=-math.inf)

    def label(self, inputs: Any = ()) -> How:
        """The provenance of this design's verdict: ``weakest(VERIFY_METHOD, inputs)``.

        ``inputs`` are the labels of the constants the design was computed from
        (:class:`~drip_cert.provenance.Quantity`, :class:`~drip_cert.provenance.How` or their
        strings); the constants object itself holds plain floats and carries none.
        """
        return weakest(VERIFY_METHOD, inputs)

    def to_dict(self) -> dict[str, Any]:
        """JSON-ready dictionary (keys: feasible, p, omega, lambda_s, Ts, rho_r, rho_a, rho,
        kappa, delta, conditions, reason, notes, how, tolerance, seconds, verified, backoff,
        verification)."""

        def f(x: float | None) -> float | str | None:
            return None if x is None else json_float(x)

        return {
            "feasible": bool(self.feasible),
            "p": self.p,
            "omega": f(self.omega),
            "lambda_s": f(self.lambda_s),
            "Ts": f(self.Ts),
            "rho_r": f(self.rho_r),
            "rho_a": f(self.rho_a),
            "rho": f(self.rho),
            "kappa": f(self.kappa),
            "delta": f(self.delta),
            "conditions": [r.to_dict() for r in self.conditions],
            "reason": self.reason,
            "notes": list(self.notes),
            "how": dict(self.how),
            "tolerance": {
                "root_rtol": ROOT_RTOL,
                "note": "before the back-off, found radii are minimal and Ts maximal to this "
                "relative tolerance; every condition was re-evaluated at the returned point",
            },
            "seconds": json_float(self.seconds),
            "verified": bool(self.verified),
            "backoff": {k: json_float(v) for k, v in self.backoff},
            "verification": {
                "arithmetic": f"Arb ball arithmetic (python-flint), {ARB_PREC} bits",
                "rule": "a condition is verified when the lower end of its margin ball is > 0",
                "min_margin_lo": json_float(self.min_verified_margin),
                "backoff_start": BACKOFF_START,
                "backoff_growth": BACKOFF_GROWTH,
                "backoff_steps": BACKOFF_STEPS,
            },
        }
