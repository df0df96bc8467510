"""Rigorous re-check of the L1-DRAC design conditions (16a), (16b), (21a), (21b), (24) in Arb.

Source: A. Gahlawat, S. H. Karumanchi, N. Hovakimyan, "L1-DRAC: Distributionally Robust Adaptive
Control -- Global Results", arXiv:2509.04619 (2025-09-04), Sec. 3.2 (conditions (16), (21), (24))
and Appendix A (the constants and maps they use).

Why
---
The designer's root searches (:mod:`drip_cert.bounds.l1drac`) return points on the boundary of a
condition to a relative ``ROOT_RTOL``: there the float64 margin is a few units of rounding
(1e-17 .. 1e-28 relative were seen), so its sign is a coin toss between two transcriptions. This
module evaluates every condition in Arb ball arithmetic (python-flint) from the *same* float
inputs, which are exact binary numbers, with the *same* code as the float path: the formulas of
:mod:`drip_cert.bounds.l1drac_appendix` are generic over a numeric backend, and
:class:`ArbConstants` hands them the Arb backend :data:`ARB`. Each margin (positive = holds,
:func:`~drip_cert.bounds.l1drac_appendix.margin_of`) comes out as a ball that contains the exact
real value; a condition is *verified* only when the ball's lower end is > 0, for the strict
inequalities (21a, b) and the non-strict ones (16a, b), (24) alike.

Public surface
--------------
* :data:`ARB_PREC` -- the working precision.
* :class:`ArbOps`, :data:`ARB` -- the Arb backend of the appendix formulas.
* :class:`ArbConstants` -- a read-only Arb view of an :class:`~drip_cert.bounds.l1drac.L1Constants`.
* :func:`margin_balls` -- the margins as Arb balls.
* :class:`ArbMargin`, :func:`verify_conditions` -- the margins as float enclosures + verdicts.
"""

from __future__ import annotations

import dataclasses
import math
from collections.abc import Iterable
from dataclasses import dataclass
from typing import TYPE_CHECKING

from flint import arb, ctx

from drip_cert.bounds.l1drac_appendix import (
    FloatOps,
    Real,
    budget_a,
    margin_of,
    reference_constants,
    sides_16a,
    sides_16b,
    sides_21a,
    sides_21b,
    sides_24,
    true_constants,
)

if TYPE_CHECKING:  # pragma: no cover
    from drip_cert.bounds.l1drac import L1Constants

__all__ = [
    "ARB_PREC",
    "CONDITIONS",
    "ArbOps",
    "ARB",
    "ArbConstants",
    "ArbMargin",
    "margin_balls",
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


class ArbOps(FloatOps):
    """The Arb backend of :mod:`drip_cert.bounds.l1drac_appendix` (python-flint ``arb`` balls).

    Same methods as :class:`~drip_cert.bounds.l1drac_appendix.FloatOps`; every result is a ball
    that contains the exact value. Use inside ``flint.ctx.workprec`` (:func:`margin_balls` does).
    """

    name = "arb"
    #: Terms of a series in x with |x| < 1e-2 (as in _phi2): the remainder x^20/22! < 1e-61
    #: is far below the 128-bit rounding, so the series adds no visible width to the ball.
    series_terms = 20

    @staticmethod
    def const(x: Real) -> arb:
        """The exact ball of a float or an int (doubles and integers are exact in Arb)."""
        return x if isinstance(x, arb) else arb(x)

    @staticmethod
    def sqrt(x: Real) -> arb:
        """Square root (a NaN ball when the ball reaches below 0: never verified)."""
        return ArbOps.const(x).sqrt()

    @staticmethod
    def exp(x: Real) -> arb:
        """e^x."""
        return ArbOps.const(x).exp()

    @staticmethod
    def expm1(x: Real) -> arb:
        """e^x - 1 (no cancellation near 0)."""
        return ArbOps.const(x).expm1()

    @staticmethod
    def max(a: Real, b: Real) -> arb:
        """A ball containing max(a, b) for every a, b in the balls."""
        return ArbOps.const(a).max(ArbOps.const(b))

    @staticmethod
    def mid(x: Real) -> float:
        """The ball's midpoint as a float (only chooses between two valid formulas)."""
        return float(ArbOps.const(x).mid())

    @staticmethod
    def series_remainder(total: Real, x: Real, n: int, denom: float) -> arb:
        """``total`` widened by ``|x|^n / (denom (1 - |x|))``, the remainder of a series whose
        k-th term (k >= n) is at most ``|x|^k / denom``; NaN when ``|x| >= 1`` is possible."""
        xa = abs(ArbOps.const(x)).upper()
        if not xa < 1:
            return arb.nan()
        bound = (xa**n / (arb(denom) * (1 - xa))).upper()
        return ArbOps.const(total) + bound.union(-bound)


#: The Arb backend.
ARB = ArbOps()


class ArbConstants:
    """Read-only view of an :class:`~drip_cert.bounds.l1drac.L1Constants` for the Arb backend.

    Every real field is the exact Arb ball of its float value; ``p_star``, ``m`` (ints) and
    ``lip_f`` (bool) are unchanged; ``num`` is :data:`ARB`. The appendix formulas read only these
    attributes, so the same code evaluates them in ball arithmetic.
    """

    num = ARB

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
    """

    eq: str
    lo: float
    hi: float
    verified: bool


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
        return ArbMargin(eq, -math.inf, math.inf, False)
    return ArbMargin(eq, _down(m.lower()), _up(m.upper()), bool(m > 0))


def margin_balls(
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
) -> dict[str, arb]:
    """The margins of the conditions ``which`` as Arb balls, from the exact float inputs.

    Implements (16a), (16b), (21a), (21b) and (24) of L1-DRAC with the appendix maps (A.1)-(A.19)
    and (18b, c), (22), (23), (25a-c), through the same generic code as the float path. A
    condition whose parameters are missing (``None``) is skipped. The margin is
    :func:`~drip_cert.bounds.l1drac_appendix.margin_of` (positive = holds). The caller checks
    ``p``, ``omega != 2 lambda`` and positivity (:mod:`drip_cert.bounds.l1drac` does); a ball
    that is not finite is never verified.

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
        ``eq -> arb`` for each evaluated condition.
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
    return out


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

    Same parameters as :func:`margin_balls`. Returns ``eq -> ArbMargin``: a float enclosure
    ``[lo, hi]`` of the exact margin of (16a), (16b), (21a), (21b), (24) at the given float
    inputs, and ``verified`` = the enclosure's lower end is > 0.
    """
    balls = margin_balls(
        c,
        p,
        omega,
        lambda_s=lambda_s,
        Ts=Ts,
        rho_r=rho_r,
        rho_a=rho_a,
        which=which,
        prec=prec,
    )
    return {eq: _enclose(eq, m) for eq, m in balls.items()}


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
        b, th, _ = budget_a(ac, true_constants(ac, p), arb(omega), arb(rho_r), arb(rho_a))
        m = b - th
    return _down(m.lower()) if m.is_finite() else -math.inf
