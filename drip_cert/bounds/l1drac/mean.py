"""The mean gap and the tail radius of an L1-DRAC design: the best moment order at one controller.

Source: A. Gahlawat, S. H. Karumanchi, N. Hovakimyan, "L1-DRAC: Distributionally Robust Adaptive
Control -- Global Results", arXiv:2509.04619 (2025-09-04), Theorem 4.1 (129), (130); DRIP Theorem
``thm:L1DRAC`` (``eqn:result:1``, the inclusion of L_p spaces); docs/math/l1drac.md section 5.6.

A design at order ``p`` bounds ``||X_t - X*_t||_{L_2p} < rho(p)``; the high-probability radius
``kappa`` needs that order. The *mean* gap ``max_t E||X_t - X*_t||`` (DRIP's uncertainty gap, the
statistic validation measures) is bounded by every ``rho(q)``, ``q = 1..p``, for which the
hypotheses of Theorem 4.1 hold **at the same controller** (``omega``, ``lambda_s``, ``T_s``):
``E||Z|| <= ||Z||_{L_2q}`` (Jensen). So the smallest of these radii bounds it too. Likewise
the Markov step of (130a) holds at every order, ``P(||X_t - X*_t|| >= rho(q) delta^{-1/(2q)})
< delta`` for each ``q = 1..p``, so the smallest of these radii is a valid
``kappa(delta)``. Each ``rho(q)`` is a complete design at the design's fixed controller
parameters (smallest radii for (16), (21), (24) at order ``q``), verified in Arb by the
designer like any other design.

Public surface
--------------
* :class:`MeanGapBound`
* :func:`mean_gap_bound` -- the bound of a feasible design.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Any

from drip_cert.bounds.l1drac.constants import L1Constants
from drip_cert.bounds.l1drac.designer import design
from drip_cert.bounds.l1drac.radii import kappa_markov
from drip_cert.bounds.l1drac.request import DesignRequest
from drip_cert.bounds.l1drac.result import L1Design
from drip_cert.provenance import json_float

__all__ = ["MeanGapBound", "mean_gap_bound"]


@dataclass(frozen=True)
class MeanGapBound:
    """``max_t E||X_t - X*_t|| < value`` and ``P(||X_t - X*_t|| >= kappa) < delta`` from the
    verified ``rho(q)``, ``q = 1..p`` (the design's order), at one controller
    (docs/math/l1drac.md section 5.6).

    ``by_p[q - 1]`` is ``rho(q)`` at the controller (``None`` where order ``q`` is infeasible
    there), ``p`` the order that attains ``value``; ``kappa`` the smallest
    ``rho(q) delta^{-1/(2q)}`` over the feasible ``q`` and ``kappa_p`` its order (both ``None``
    without ``delta``); ``omega``, ``lambda_s``, ``Ts`` the controller every ``rho(q)`` was
    verified at (the design's).
    """

    value: float
    p: int
    by_p: tuple[float | None, ...]
    omega: float
    lambda_s: float
    Ts: float
    delta: float | None = None
    kappa: float | None = None
    kappa_p: int | None = None

    def to_dict(self) -> dict[str, Any]:
        """JSON-ready: value, p, by_p, kappa, kappa_p, delta, omega, lambda_s, Ts, note."""
        return {
            "value": json_float(self.value),
            "p": self.p,
            "by_p": [None if r is None else json_float(r) for r in self.by_p],
            "kappa": None if self.kappa is None else json_float(self.kappa),
            "kappa_p": self.kappa_p,
            "delta": None if self.delta is None else json_float(self.delta),
            "omega": json_float(self.omega),
            "lambda_s": json_float(self.lambda_s),
            "Ts": json_float(self.Ts),
            "note": "value bounds max_t E||X_t - X*_t||: the smallest rho(q), q <= p (Jensen: "
            "E||Z|| <= ||Z||_L2q); kappa = min_q rho(q) delta^(-1/(2q)) (Markov at each order); "
            "every rho(q) a design verified in Arb at the same omega, lambda_s, T_s "
            "(docs/math/l1drac.md section 5.6)",
        }


def _at_controller(c: L1Constants, d: L1Design, q: int) -> L1Design:
    """The smallest-radius design of order ``q`` at ``d``'s omega, lambda_s and T_s."""
    req = DesignRequest(
        p=q,
        omega=d.omega,
        lambda_s=d.lambda_s,
        Ts=d.Ts,
        objective="rho_at_Ts",
        front=False,
    )
    return design(c, req)


def mean_gap_bound(c: L1Constants, d: L1Design) -> MeanGapBound | None:
    """The mean-gap bound and the best-order ``kappa`` at the controller of the feasible ``d``.

    Each order ``q = 1..d.p`` is designed at ``d``'s fixed omega, lambda_s, T_s with the radii
    free (the smallest that satisfy (16), (21), (24) at order ``q``) and counts only when the
    designer returns it feasible (every condition verified in Arb) with those very parameters;
    ``rho(d.p)`` is the smaller of that and ``d.rho`` (radii a user fixed are valid too). Orders
    above ``d.p`` are not used: ``alpha`` and ``Delta_star`` are only known to bound the
    quantities of (18a) and Assumption 3 up to the design's order. ``None`` when ``d`` is
    infeasible.
    """
    if not d.feasible or d.rho is None or None in (d.omega, d.lambda_s, d.Ts):
        return None
    w, ls, Ts = float(d.omega), float(d.lambda_s), float(d.Ts)  # type: ignore[arg-type]
    by_p: list[float | None] = []
    for q in range(1, d.p + 1):
        dq = _at_controller(c, d, q)
        same = (dq.omega, dq.lambda_s, dq.Ts) == (w, ls, Ts)
        ok = dq.feasible and dq.verified and same and dq.rho is not None
        r = float(dq.rho) if ok else math.inf  # type: ignore[arg-type]
        if q == d.p:  # the design's own radii (a user may have fixed them larger) are valid too
            r = min(r, float(d.rho))
        by_p.append(r if math.isfinite(r) else None)
    value, p = min((r, q) for q, r in enumerate(by_p, start=1) if r is not None)
    kappa = kappa_p = None
    if d.delta is not None:
        kappa, kappa_p = min(
            (kappa_markov(r, q, d.delta), q) for q, r in enumerate(by_p, start=1) if r is not None
        )
    return MeanGapBound(
        value=value,
        p=p,
        by_p=tuple(by_p),
        omega=w,
        lambda_s=ls,
        Ts=Ts,
        delta=d.delta,
        kappa=kappa,
        kappa_p=kappa_p,
    )
