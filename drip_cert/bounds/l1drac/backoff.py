"""Back-off of a float design into the interior, until Arb verifies every condition.

Source: A. Gahlawat, S. H. Karumanchi, N. Hovakimyan, "L1-DRAC: Distributionally Robust Adaptive
Control -- Global Results", arXiv:2509.04619 (2025-09-04), Sec. 3.2 (conditions (16), (21), (24)).

A float root sits on the boundary of its condition: its float64 margin is rounding noise, whose
sign another transcription may flip. The designer (:func:`drip_cert.bounds.l1drac.designer.design`)
therefore never returns a root as found. :func:`back_off` moves each *free* parameter into the
interior by a relative ``f = BACKOFF_START`` (rho_r and rho_a multiplied by ``1 + f``, Ts divided
by ``1 + f``), in the order rho_r, rho_a, Ts (rho_a and Ts are re-solved after the parameters
before them moved), and re-checks the conditions that parameter closes in Arb ball arithmetic
(:func:`drip_cert.bounds.l1drac.verify.verify_conditions`, the same formulas) and in float64;
unless the margin ball's lower end is > 0 and the float64 margin is positive too, it retries with
``f`` multiplied by ``BACKOFF_GROWTH``, at most ``BACKOFF_STEPS`` times (so ``f <= 1e-3``), and
otherwise reports the design infeasible with the reason (details in :func:`back_off`). Every
feasible set is an up-set in rho_r and rho_a and, on the monotone envelope of (24), a down-set in
Ts (the proofs in :mod:`drip_cert.bounds.l1drac.searches`), so a step into the interior keeps
every condition and makes its margin strictly positive. Parameters the user fixed are never
changed: for them the verdict is the Arb-verified one.

Public surface
--------------
* :data:`BACKOFF_START`, :data:`BACKOFF_GROWTH`, :data:`BACKOFF_STEPS` -- the back-off schedule.
* :class:`BackOff`, :func:`back_off` -- the moved design point, or why none was verified.
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass

from drip_cert.bounds.l1drac.appendix import RefConstants, TrueConstants
from drip_cert.bounds.l1drac.conditions import DesignPoint, float_conditions
from drip_cert.bounds.l1drac.constants import L1Constants
from drip_cert.bounds.l1drac.request import DesignRequest
from drip_cert.bounds.l1drac.searches import max_Ts, min_rho_a
from drip_cert.bounds.l1drac.verify import budget_24_lower, verify_conditions

__all__ = [
    "BACKOFF_START",
    "BACKOFF_GROWTH",
    "BACKOFF_STEPS",
    "BackOff",
    "backoff_factors",
    "back_off",
]

#: First relative back-off of a free parameter from its float root: 1000 x ROOT_RTOL, so that it
#: clears the root's own uncertainty and the float64 rounding of the margins (~1e-16 relative)
#: by orders of magnitude, while moving rho by a negligible 1e-9 relative.
BACKOFF_START = 1e-9
#: Factor by which the relative back-off grows at each retry (geometric: a few retries span any
#: plausible loss of digits).
BACKOFF_GROWTH = 10.0
#: Retries per parameter before the design is declared infeasible; the largest relative back-off
#: is BACKOFF_START * BACKOFF_GROWTH**(BACKOFF_STEPS - 1) = 1e-3 (a margin not resolved by then
#: is not a rounding matter).
BACKOFF_STEPS = 7


@dataclass(frozen=True)
class BackOff:
    """The design point after :func:`back_off` (the last one tried when ``reason`` is set)."""

    rho_r: float
    rho_a: float
    Ts: float
    factors: tuple[tuple[str, float], ...]
    reason: str


def backoff_factors() -> tuple[float, ...]:
    """1 + BACKOFF_START * BACKOFF_GROWTH^k, k = 0 .. BACKOFF_STEPS - 1."""
    return tuple(1.0 + BACKOFF_START * BACKOFF_GROWTH**k for k in range(BACKOFF_STEPS))


def _verified_factor(
    c: L1Constants,
    rc: RefConstants,
    tc: TrueConstants,
    p: int,
    omega: float,
    name: str,
    which: tuple[str, ...],
    point: Callable[[float], DesignPoint],
) -> tuple[float, str]:
    """The first factor of :func:`backoff_factors` at which the conditions ``which`` hold at
    ``point(factor)`` both Arb-verified and in float64, else the first Arb-verified one; when none
    is verified, the last factor and why (naming the parameter ``name``)."""
    first_verified: float | None = None
    fac, pt = 1.0, point(1.0)
    for fac in backoff_factors():
        pt = point(fac)
        v = verify_conditions(c, p, omega, which=which, **pt)
        if not all(m.verified for m in v.values()):
            continue
        fl = float_conditions(c, rc, tc, p, omega, which, **pt)
        if all(r.holds for r in fl):
            return fac, ""
        if first_verified is None:
            first_verified = fac
    if first_verified is not None:  # verified, but float64 rounding still hides the margin
        return first_verified, ""
    v = verify_conditions(c, p, omega, which=which, **pt)
    fl = float_conditions(c, rc, tc, p, omega, which, **pt)
    return fac, "; ".join(
        f"({r.eq}) is not verified with a positive margin after backing {name} off its float "
        f"root by a relative {fac - 1.0:.0e} (float64 margin {r.margin:.6g}, Arb enclosure "
        f"[{v[r.eq].lo:.6g}, {v[r.eq].hi:.6g}])"
        for r in fl
        if not v[r.eq].verified
    )


def back_off(
    c: L1Constants,
    rc: RefConstants,
    tc: TrueConstants,
    req: DesignRequest,
    p: int,
    omega: float,
    lambda_s: float,
    rho_r: float,
    rho_a: float,
    Ts: float,
) -> BackOff:
    """Move the free parameters of a complete float design off their roots, into the interior.

    In the order rho_r, rho_a, Ts (the module docstring): for each free parameter, the relative
    back-off ``f`` runs through :func:`backoff_factors` until the conditions that parameter
    closes are Arb-verified -- (16a), (21a) for rho_r; (16b), (21b) (and (24) when Ts is fixed)
    for rho_a; (24) for Ts -- and hold in float64 as well. The second requirement keeps the
    margin above the float64 rounding of the conditions, which is what any other float
    transcription sees: near the smallest rho_a the right side of (24) is a small difference of
    large terms, and a margin that Arb resolves can still be below that rounding. If no step
    meets both, the first Arb-verified step is taken (the verdict is the verified one; the
    design notes the float disagreement); if none is verified, the design is infeasible. rho_a is
    re-solved at the moved rho_r and Ts at the moved radii (both feasible sets shrink as rho_r
    grows). Given parameters are not touched.

    The Ts search of this stage compares the envelope of (24) with the Arb lower bound of its
    right side (:func:`~drip_cert.bounds.l1drac.verify.budget_24_lower`), not with its float64
    value, which can be off in its leading digits for the reason above and would put the float
    root of Ts far from the verified one.
    """
    factors: list[tuple[str, float]] = []

    def search(
        name: str, which: tuple[str, ...], point: Callable[[float], DesignPoint]
    ) -> tuple[float, str]:
        fac, why = _verified_factor(c, rc, tc, p, omega, name, which, point)
        factors.append((name, fac))
        return fac, why

    def fail(reason: str) -> BackOff:
        return BackOff(rho_r, rho_a, Ts, tuple(factors), reason)

    if req.rho_r is None:
        r0 = rho_r
        fac, why = search("rho_r", ("16a", "21a"), lambda f: {"rho_r": r0 * f})
        rho_r = r0 * fac
        if why:
            return fail(why)
        if req.rho_a is None:
            a = min_rho_a(c, tc, p, omega, rho_r, lambda_s, req.Ts, ("16b", "21b", "24"))
            if a is None:
                return fail(f"no rho_a satisfies (16b), (21b) at the moved rho_r = {rho_r:.17g}")
            rho_a = a
    if req.rho_a is None:
        a0 = rho_a
        which = ("16b", "21b") + (("24",) if req.Ts is not None else ())
        fac, why = search(
            "rho_a",
            which,
            lambda f: {"rho_r": rho_r, "rho_a": a0 * f, "lambda_s": lambda_s, "Ts": req.Ts},
        )
        rho_a = a0 * fac
        if why:
            return fail(why)
    if req.Ts is None:
        budget = budget_24_lower(c, p, omega, rho_r, rho_a)
        t = max_Ts(c, tc, p, omega, lambda_s, rho_r, rho_a, budget)
        if t is None:
            return fail(
                f"(24) cannot hold for any Ts at rho_r = {rho_r:.17g}, rho_a = {rho_a:.17g}: "
                f"the rigorous lower bound of its right side is {budget:.6g}"
            )
        t0 = t
        fac, why = search(
            "Ts",
            ("24",),
            lambda f: {"rho_r": rho_r, "rho_a": rho_a, "lambda_s": lambda_s, "Ts": t0 / f},
        )
        Ts = t0 / fac
        if why:
            return fail(why)
    return BackOff(rho_r, rho_a, Ts, tuple(factors), "")
