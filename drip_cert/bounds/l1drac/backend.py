"""The two numeric backends of the L1-DRAC formulas: float64 and Arb ball arithmetic.

Every formula of :mod:`drip_cert.bounds.l1drac.appendix` and :mod:`drip_cert.bounds.l1drac.sides`
is written once, generic over a small backend (``const``, ``sqrt``, ``exp``, ``expm1``, ``max``,
``mid``, ``series_remainder``, ``series_terms``). :data:`FLOAT` (:mod:`math`) runs the designer's
fast searches; :data:`ARB` (python-flint ``arb`` balls) re-evaluates the same code rigorously
(:mod:`drip_cert.bounds.l1drac.verify`). A constants object carries its backend as ``num``.

Public surface
--------------
* :data:`Real` -- a number of either backend.
* :class:`Backend` -- the interface both backends provide (a structural type).
* :class:`FloatOps`, :data:`FLOAT` -- the float64 backend.
* :class:`ArbOps`, :data:`ARB` -- the Arb backend (use inside ``flint.ctx.workprec``).
"""

from __future__ import annotations

import math
from typing import Any, Protocol, TypeAlias

from flint import arb

__all__ = ["Real", "Backend", "FloatOps", "FLOAT", "ArbOps", "ARB"]

#: A real number of the active backend: ``float`` (:data:`FLOAT`) or ``flint.arb`` (:data:`ARB`).
Real: TypeAlias = Any


class Backend(Protocol):
    """What the generic formulas use of a backend; :class:`FloatOps` and :class:`ArbOps` provide it.

    The two backends are used interchangeably (a constants object's ``num``) but are not
    subclasses of one another: one returns floats, the other Arb balls.
    """

    @property
    def series_terms(self) -> int:
        """How many terms of a series in x with |x| < 1e-2 reach the backend's precision."""
        ...

    def const(self, x: Real, /) -> Real:
        """A number of this backend equal to ``x``."""
        ...

    def sqrt(self, x: Real, /) -> Real:
        """Square root."""
        ...

    def exp(self, x: Real, /) -> Real:
        """e^x."""
        ...

    def expm1(self, x: Real, /) -> Real:
        """e^x - 1."""
        ...

    def max(self, a: Real, b: Real, /) -> Real:
        """max(a, b)."""
        ...

    def mid(self, x: Real, /) -> float:
        """A float that chooses between two valid formulas."""
        ...

    def series_remainder(self, total: Real, x: Real, n: int, denom: float, /) -> Real:
        """``total`` plus the remainder of a truncated series."""
        ...


class FloatOps:
    """The float64 backend: :mod:`math`'s functions; the designer's searches run on it.

    The Arb backend (:class:`ArbOps`) has the same methods.
    """

    #: Terms k = 0..8 of a series in x with |x| < 1e-2 reach float64 precision (x^9/11! < 1e-25).
    series_terms = 9

    @staticmethod
    def const(x: float) -> float:
        """A number of this backend equal to ``x`` (float, int)."""
        return float(x)

    sqrt = staticmethod(math.sqrt)
    exp = staticmethod(math.exp)
    expm1 = staticmethod(math.expm1)

    @staticmethod
    def max(a: float, b: float) -> float:
        """max(a, b)."""
        return max(a, b)

    @staticmethod
    def mid(x: float) -> float:
        """The float used to choose between two valid formulas (the value itself here)."""
        return x

    @staticmethod
    def series_remainder(total: float, x: float, n: int, denom: float) -> float:
        """``total`` plus the remainder ``|x|^n / (denom (1 - |x|))`` of a truncated series.

        In float64 the remainder is below an ulp of ``total`` where the series is used, so the
        total is returned unchanged; the Arb backend adds it as a ball radius.
        """
        return total


#: The float64 backend (the default of every constants object).
FLOAT = FloatOps()


class ArbOps:
    """The Arb backend (python-flint ``arb`` balls).

    Same methods as :class:`FloatOps` (both are a :class:`Backend`); every result is a ball that
    contains the exact value. Use inside ``flint.ctx.workprec``
    (:func:`drip_cert.bounds.l1drac.verify.verify_conditions` does).
    """

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
