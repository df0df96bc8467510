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

__all__ = ["L1Design", "FrontPoint", "KNIFE_EDGE_TS_MIN", "KNIFE_EDGE_RTOL", "knife_edge"]

#: A design with a smaller ``Ts`` (seconds) is a knife edge: sampling faster than 1 GHz is no
#: controller hardware's, and there ``Ts`` is set by the cancellation in the right side of (24)
#: (the paper-4d learned loop's smallest-rho design has Ts = 1.8e-55 s), not by the hardware.
KNIFE_EDGE_TS_MIN = 1e-9
#: A design whose verified margin of (21b) is below this fraction of the right side of (21b) is
#: a knife edge. That margin is exactly the right side of (24), the room left for the sampling
#: error: when it is a 1e-6 part of the terms it is the difference of, a relative change of 1e-6
#: in any constant (e.g. the next digit of an estimated lambda) removes it, and the largest Ts
#: that (24) allows falls with it (Ts ~ room^2 with diffusion, docs/math/l1drac.md section 8).
#: The binding conditions of a minimal radius ((16a) or (21a) at rho_r, (24) at the smallest
#: rho_a for a given Ts) have margins of the back-off's size (1e-9 relative) by construction and
#: are not knife edges: each is an up-set in its radius, so a larger radius only widens them.
KNIFE_EDGE_RTOL = 1e-6


@dataclass(frozen=True, kw_only=True)
class FrontPoint:
    """One point of the (Ts, rho) Pareto front of L1-DRAC designs (Sec. 3.2; rho is (17)).

    Every point is a complete design returned by the designer with ``feasible=True``: its five
    conditions (16a), (16b), (21a), (21b), (24) were re-evaluated at these float values in Arb
    ball arithmetic with a margin ball whose lower end is > 0 (``verified``). ``knife_edge`` is
    empty, or why the point is a knife edge
    (:func:`~drip_cert.bounds.l1drac.designer.knife_edge`). ``source`` says how the point was
    found: ``"Ts grid"`` (smallest rho at a grid Ts), ``"min_rho"`` (the infimum of rho),
    ``"fixed radii"`` (the largest Ts at the user's radii) or ``"chosen"`` (the design returned).
    """

    Ts: float
    rho: float
    rho_r: float
    rho_a: float
    omega: float
    lambda_s: float
    verified: bool
    knife_edge: str = ""
    source: str = ""

    def to_dict(self) -> dict[str, Any]:
        """JSON-ready: Ts, rho, rho_r, rho_a, omega, lambda_s, verified, knife_edge, source."""
        return {
            "Ts": json_float(self.Ts),
            "rho": json_float(self.rho),
            "rho_r": json_float(self.rho_r),
            "rho_a": json_float(self.rho_a),
            "omega": json_float(self.omega),
            "lambda_s": json_float(self.lambda_s),
            "verified": bool(self.verified),
            "knife_edge": self.knife_edge,
            "source": self.source,
        }


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

    ``objective`` is the objective served (:data:`~drip_cert.bounds.l1drac.request.OBJECTIVES`),
    ``choice`` why this point was returned, ``knife_edge`` empty or why the design is a knife
    edge, ``front`` the (Ts, rho) Pareto front (sorted by Ts; empty when not computed).
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
    objective: str = ""
    choice: str = ""
    knife_edge: str = ""
    front: tuple[FrontPoint, ...] = ()
    rho_budget: float | None = None
    practical_Ts: float | None = None

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
        verification, objective, choice, knife_edge, front, rho_budget, practical_Ts).

        ``knife_edge`` is ``{"is": bool, "reason": str, "rules": {...}}`` (the thresholds of
        :func:`~drip_cert.bounds.l1drac.designer.knife_edge`); ``front`` a list of
        :meth:`FrontPoint.to_dict`."""

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
            "objective": self.objective,
            "choice": self.choice,
            "knife_edge": {
                "is": bool(self.knife_edge),
                "reason": self.knife_edge,
                "rules": {
                    "Ts_min": KNIFE_EDGE_TS_MIN,
                    "rel_margin_21b_min": KNIFE_EDGE_RTOL,
                    "note": "a knife edge has Ts < Ts_min, or a verified margin of (21b) -- the "
                    "room (24) has for the sampling error -- below rel_margin_21b_min times "
                    "the right side of (21b)",
                },
            },
            "front": [pt.to_dict() for pt in self.front],
            "rho_budget": f(self.rho_budget),
            "practical_Ts": f(self.practical_Ts),
        }


def knife_edge(d: L1Design) -> str:
    """Why the design ``d`` is a knife edge, or ``""`` when it is not (or is not feasible).

    A feasible design is a knife edge when ``Ts < KNIFE_EDGE_TS_MIN`` or when the verified
    margin of (21b) -- the lower end of its Arb margin ball, which is the right side of (24),
    the room left for the sampling error of (25a-c) -- is below ``KNIFE_EDGE_RTOL`` times the
    right side of (21b), ``(1 - k_a) rho_a^2 - Gamma_a`` (L1-DRAC (16b), (21b), (24)).
    """
    if not d.feasible or d.Ts is None:
        return ""
    why = []
    if d.Ts < KNIFE_EDGE_TS_MIN:
        why.append(
            f"T_s = {d.Ts:.3g} s is below {KNIFE_EDGE_TS_MIN:g} s (faster than any controller "
            "hardware samples)"
        )
    for r in d.conditions:
        if r.eq == "21b":
            rel = r.margin_lo / abs(r.rhs) if r.rhs != 0 else -math.inf
            if not rel >= KNIFE_EDGE_RTOL:
                why.append(
                    f"(21b) leaves (24) a room of {r.margin_lo:.3g}, a {rel:.1e} part of its "
                    f"right side {r.rhs:.6g} (below {KNIFE_EDGE_RTOL:g}): the smallest rho_a "
                    "binds (21b) and Ts is set by cancellation"
                )
    return "; ".join(why)
