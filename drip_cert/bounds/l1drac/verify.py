"""Rigorous re-check of the L1-DRAC design conditions (16a), (16b), (21a), (21b), (24) in Arb.

Source: A. Gahlawat, S. H. Karumanchi, N. Hovakimyan, "L1-DRAC: Distributionally Robust Adaptive
Control -- Global Results", arXiv:2509.04619 (2025-09-04), Sec. 3.2 (conditions (16), (21), (24))
and Appendix A (the constants and maps they use).

Why
---
The designer's root searches (:mod:`drip_cert.bounds.l1drac.searches`) return points on the
boundary of a condition to a relative ``ROOT_RTOL``: there the float64 margin is a few units of
rounding (1e-17 .. 1e-28 relative were seen), so its sign is a coin toss between two
transcriptions. This module evaluates every condition in Arb ball arithmetic (python-flint) from
the *same* float inputs, which are exact binary numbers, with the *same* code as the float path:
the formulas of :mod:`drip_cert.bounds.l1drac.appendix` and :mod:`drip_cert.bounds.l1drac.sides`
are generic over a numeric backend, and :class:`ArbConstants` hands them the Arb backend
:data:`~drip_cert.bounds.l1drac.backend.ARB`. Each margin (positive = holds,
:func:`~drip_cert.bounds.l1drac.sides.margin_of`) comes out as a ball that contains the exact
real value; a condition is *verified* only when the ball's lower end is > 0, for the strict
inequalities (21a, b) and the non-strict ones (16a, b), (24) alike.

Public surface
--------------
* :data:`ARB_PREC` -- the working precision.
* :data:`CONDITIONS` -- the five conditions, in the order the designer reports them.
* :data:`VERIFY_METHOD` -- the provenance of a verdict obtained here.
* :class:`ArbConstants` -- a read-only Arb view of an
  :class:`~drip_cert.bounds.l1drac.constants.L1Constants`.
* :class:`ArbMargin`, :func:`verify_conditions` -- the margins as Arb balls, their float
  enclosures and the verdicts.
* :func:`budget_24_lower` -- a rigorous lower bound of the right side of (24).
"""

from __future__ import annotations

import dataclasses
import math
from collections.abc import Iterable
from dataclasses import dataclass, field

from flint import arb, ctx

from drip_cert.bounds.l1drac.appendix import reference_constants, true_constants
from drip_cert.bounds.l1drac.backend import ARB
from drip_cert.bounds.l1drac.constants import L1Constants
from drip_cert.bounds.l1drac.sides import (
    budget_24,
    margin_of,
    sides_16a,
    sides_16b,
    sides_21a,
    sides_21b,
    sides_24,
)
from drip_cert.provenance import How

__all__ = [
    "ARB_PREC",
    "CONDITIONS",
    "VERIFY_METHOD",
    "ArbConstants",
    "ArbMargin",
    "verify_conditions",
    "budget_24_lower",
]

#: Working precision (bits) of the Arb evaluation. The inputs are exact doubles, so the balls only
#: carry rounding of the evaluation itself: at 128 bits their radii are ~1e-35 relative to the
#: terms, far below the smallest margin the designer's back-off creates (1e-9 relative), so the
#: verdict is decided at once. Any precision gives a rigorous verdict; a lower one only rejects
#: more.
ARB_PREC = 128

#: The five conditions of Sec. 3.2, in the order the designer reports them.
CONDITIONS: tuple[str, ...] = ("16a", "16b", "21a", "21b", "24")

#: The method by which a design's verdict is obtained: every condition evaluated in Arb ball
#: arithmetic from the exact float inputs ("verified in rigorous arithmetic" is How.EXACT in
#: drip_cert.provenance). A design's label is weakest(VERIFY_METHOD, inputs): see
#: drip_cert.bounds.l1drac.result.L1Design.label.
VERIFY_METHOD = How.EXACT


class ArbConstants:
    """Read-only view of an :class:`~drip_cert.bounds.l1drac.constants.L1Constants` in Arb.

    Every real field is the exact Arb ball of its float value; ``p_star``, ``m`` (ints) and
    ``lip_f`` (bool) are unchanged; ``num`` is :data:`~drip_cert.bounds.l1drac.backend.ARB`. The
    appendix formulas read only these attributes, so the same code evaluates them in ball
    arithmetic.
    """

    num = ARB

    # the fields of L1Constants (set in __init__), declared so that an ArbConstants is an
    # L1ConstantsLike for the type checker
    lam: arb
    Delta_f: arb
    Delta_p: arb
    L_p: arb
    L_p_hat: arb
    Delta_g: arb
    Delta_g_dot: arb
    Delta_g_perp: arb
    Delta_Theta: arb
    Delta_star: arb
    p_star: int
    Delta_mu: arb
    Delta_sigma: arb
    Delta_mu_par: arb
    Delta_mu_perp: arb
    Delta_sigma_par: arb
    Delta_sigma_perp: arb
    Delta_p_par: arb
    Delta_p_perp: arb
    L_p_par: arb
    L_p_perp: arb
    L_p_par_hat: arb
    L_p_perp_hat: arb
    L_mu: arb
    L_mu_hat: arb
    L_mu_par: arb
    L_mu_par_hat: arb
    L_mu_perp: arb
    L_mu_perp_hat: arb
    L_sigma: arb
    L_sigma_hat: arb
    L_sigma_par: arb
    L_sigma_par_hat: arb
    L_sigma_perp: arb
    L_sigma_perp_hat: arb
    L_f: arb
    lip_f: bool
    m: int
    alpha: arb
    eps_r: arb
    eps_a: arb

    def __init__(self, c: L1Constants) -> None:
        for f in dataclasses.fields(c):
            v = getattr(c, f.name)
            object.__setattr__(self, f.name, arb(v) if isinstance(v, float) else v)

    def __setattr__(self, name: str, value: object) -> None:
        raise AttributeError(f"ArbConstants is read-only (tried to set {name!r})")


@dataclass(frozen=True)
class ArbMargin:
    """The rigorous margin of one condition: an enclosure ``[lo, hi]`` of the exact margin.

    Attributes
    ----------
    eq
        The condition: "16a", "16b", "21a", "21b" or "24".
    lo
        The Arb ball's lower end rounded down to a float (``-inf`` for a non-finite ball).
    hi
        The ball's upper end rounded up to a float (``+inf`` for a non-finite ball).
    verified
        The ball's lower end is > 0: the condition holds at the given float inputs with a
        strictly positive margin, proved in rigorous arithmetic.
    ball
        The Arb ball itself (not compared, not printed).
    """

    eq: str
    lo: float
    hi: float
    verified: bool
    ball: arb = field(compare=False, repr=False)


def _down(x: arb) -> float:
    """The largest float <= the exact value of the zero-radius ball ``x``."""
    f = float(x)
    if arb(f) > x:
        f = math.nextafter(f, -math.inf)
    return f


def _up(x: arb) -> float:
    """The smallest float >= the exact value of the zero-radius ball ``x``."""
    f = float(x)
    if arb(f) < x:
        f = math.nextafter(f, math.inf)
    return f


def _enclose(eq: str, m: arb) -> ArbMargin:
    if not m.is_finite():
        return ArbMargin(eq, -math.inf, math.inf, False, m)
    return ArbMargin(eq, _down(m.lower()), _up(m.upper()), bool(m > 0), m)


def verify_conditions(
    c: L1Constants,
    p: int,
    omega: float,
    *,
    lambda_s: float | None = None,
    Ts: float | None = None,
    rho_r: float | None = None,
    rho_a: float | None = None,
    which: Iterable[str] = CONDITIONS,
    prec: int = ARB_PREC,
) -> dict[str, ArbMargin]:
    """Verify the conditions ``which`` at one design point in Arb ball arithmetic.

    Implements (16a), (16b), (21a), (21b) and (24) of L1-DRAC with the appendix maps (A.1)-(A.19)
    and (18b, c), (22), (23), (25a-c), through the same generic code as the float path. A
    condition whose parameters are missing (``None``) is skipped. The margin is
    :func:`~drip_cert.bounds.l1drac.sides.margin_of` (positive = holds). The caller checks
    ``p``, ``omega != 2 lambda`` and positivity (:mod:`drip_cert.bounds.l1drac.conditions`
    does); a ball that is not finite is never verified.

    Parameters
    ----------
    c
        The paper's constants (floats).
    p
        Moment order in ``{1..p_star}``.
    omega, lambda_s, Ts, rho_r, rho_a
        The design point (floats, taken as exact binary numbers).
    which
        The conditions to evaluate.
    prec
        Arb working precision in bits (:data:`ARB_PREC`).

    Returns
    -------
    dict
        ``eq -> ArbMargin`` for each evaluated condition: the margin ball, a float enclosure
        ``[lo, hi]`` of the exact margin at the given float inputs, and ``verified`` = the
        enclosure's lower end is > 0.
    """
    want = set(which)
    out: dict[str, arb] = {}
    with ctx.workprec(prec):
        ac = ArbConstants(c)
        w = arb(omega)
        rr = None if rho_r is None else arb(rho_r)
        ra = None if rho_a is None else arb(rho_a)
        if rr is not None and want & {"16a", "21a"}:
            rc = reference_constants(ac, p)
            if "16a" in want:
                out["16a"] = margin_of("16a", *sides_16a(ac, rc, w, rr))
            if "21a" in want:
                out["21a"] = margin_of("21a", *sides_21a(ac, rc, w, rr))
        if ra is not None and want & {"16b", "21b", "24"}:
            tc = true_constants(ac, p)
            if "16b" in want:
                out["16b"] = margin_of("16b", *sides_16b(ac, tc, w, ra))
            if rr is not None and "21b" in want:
                out["21b"] = margin_of("21b", *sides_21b(ac, tc, w, rr, ra))
            if rr is not None and lambda_s is not None and Ts is not None and "24" in want:
                lhs, rhs = sides_24(ac, tc, p, w, arb(lambda_s), arb(Ts), rr, ra)
                out["24"] = margin_of("24", lhs, rhs)
    return {eq: _enclose(eq, m) for eq, m in out.items()}


def budget_24_lower(
    c: L1Constants, p: int, omega: float, rho_r: float, rho_a: float, *, prec: int = ARB_PREC
) -> float:
    """A float lower bound of the right side of (24), ``(1 - k_a) rho_a^2 - Gamma_a -
    Theta_a / |2 lambda - omega|``, from its Arb enclosure (``-inf`` if not finite).

    Near the smallest rho_a this budget is a small difference of large terms, so its float64
    value can be wrong in its leading digits; the designer's Ts search uses this bound instead.
    """
    with ctx.workprec(prec):
        ac = ArbConstants(c)
        m = budget_24(ac, true_constants(ac, p), arb(omega), arb(rho_r), arb(rho_a))
    return _down(m.lower()) if m.is_finite() else -math.inf
