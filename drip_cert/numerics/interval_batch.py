"""Batched interval enclosures of sympy expressions: many boxes per call, in numpy.

:func:`compile_batch` turns a sympy expression into a function that maps ``K`` boxes (an array
``(K, d, 2)``) to two ``(K,)`` arrays ``lo <= expr <= hi`` on each box: the natural interval
extension of :mod:`drip_cert.numerics.interval`, node for node, with every node a numpy operation
over the whole batch instead of a Python call per box. :class:`BatchEnclosure` intersects it with
the mean-value form, as :class:`~drip_cert.numerics.interval.MatrixEnclosure` does.

Soundness of the rounding (the rules of :mod:`drip_cert.numerics.rounding`)
--------------------------------------------------------------------------
* ``+ -`` and ``*`` (the four end products), ``1/x`` and ``sqrt``: IEEE-754 correctly rounded
  operations, each moved one ulp outward (``np.nextafter``).
* Integer powers: repeated multiplication of ``|x|`` with every product rounded outward (``x^k``
  is monotone in ``|x|``), the sign from the parity; even powers of an interval holding 0 start
  at 0. Powers ``p/2`` are ``sqrt`` then the integer power (both monotone on ``x >= 0``).
* ``exp log sin cos tanh atan sinh cosh sech``: numpy's libm at the interval's ends, widened by
  :data:`~drip_cert.numerics.rounding.LIBM_REL` (relative) and
  :data:`~drip_cert.numerics.rounding.LIBM_ABS` (absolute), as
  :mod:`drip_cert.numerics.interval_np` does; sound as long as the platform's libm meets that
  budget (8 ulps; glibc documents at most 1-4). ``sin``/``cos`` take ``[-1, 1]`` ends wherever
  an extremum ``offset + 2 k pi`` may lie in the interval, decided with a margin of ``1e-9``
  periods (wider is looser, never wrong).
* Constant sub-trees are enclosed once, by the scalar evaluator (Arb).
* NaN means "no information" (``inf - inf``, a domain violation such as ``log`` of an interval
  reaching 0): the caller reads it as an unbounded enclosure.

So the enclosure of each box contains the scalar one of
:func:`~drip_cert.numerics.interval.compile_enclosure` up to libm's budget: wider by at most the
libm widening where the scalar evaluator uses Arb (tested on random boxes). Nodes without a
batched form here (undefined functions, ``erf``, ``tan``, non-dyadic rational powers, ...) raise
:class:`~drip_cert.numerics.interval.UnsupportedExpression` at compile time, so the caller falls
back to the scalar evaluator.
"""

from __future__ import annotations

import math
from collections.abc import Callable, Sequence

import numpy as np
import sympy as sp
from sympy.core.function import AppliedUndef

from drip_cert.numerics.interval import (
    UnsupportedExpression,
    cancellation_free,
    enclose_constant,
    is_smooth,
)
from drip_cert.numerics.rounding import (
    LIBM_REL,
    add_down_np,
    add_up_np,
    down_np,
    up_np,
    widen_np,
)

__all__ = ["BatchEnclosure", "compile_batch"]

Pair = tuple[np.ndarray, np.ndarray]
_BFn = Callable[[np.ndarray], Pair]

SIN_MARGIN = 1e-9
"""Periods of margin when deciding whether ``sin``/``cos`` reach an extremum inside an interval:
covers the float error of ``(x - offset) / (2 pi)`` (a few ulps of ``|x| / 2 pi``) for
``|x| < 1e6``; above that the decision is skipped and ``[-1, 1]`` taken (sound, looser)."""
SIN_FULL_WIDTH = 6.0  #: an interval this wide (> 2 pi - 0.3) is given ``[-1, 1]`` as in the scalar
SIN_MAX_ABS = 1e6  #: above this ``|x|`` the extremum test is skipped: ``[-1, 1]``


def _libm(fn: Callable[[np.ndarray], np.ndarray], x: np.ndarray) -> Pair:
    return widen_np(fn(x), LIBM_REL)


def _mul(alo, ahi, blo, bhi) -> Pair:
    """``a * b`` with ``0 * inf = 0`` (an operand's NaN stays NaN).

    Without a NaN among the four products their min and max are those of
    :func:`_mul_stacked` (signed zeros aside, which the outward rounding maps to the same
    numbers), computed without stacking; with one, :func:`_mul_stacked` decides."""
    p1, p2, p3, p4 = alo * blo, alo * bhi, ahi * blo, ahi * bhi
    lo = np.minimum(np.minimum(p1, p2), np.minimum(p3, p4))
    hi = np.maximum(np.maximum(p1, p2), np.maximum(p3, p4))
    if np.isnan(lo).any() or np.isnan(hi).any():
        return _mul_stacked(alo, ahi, blo, bhi)
    return down_np(lo), up_np(hi)


def _mul_stacked(alo, ahi, blo, bhi) -> Pair:
    """:func:`_mul` on the four products stacked (the NaN cases: ``0 * inf`` is 0)."""
    a = np.stack([alo, alo, ahi, ahi])
    b = np.stack([blo, bhi, blo, bhi])
    ps = a * b
    if np.isnan(ps).any():  # 0 * inf, or a NaN operand
        ps = np.where(np.isnan(ps) & ~np.isnan(a) & ~np.isnan(b), 0.0, ps)
    return down_np(ps.min(axis=0)), up_np(ps.max(axis=0))


def _add(alo, ahi, blo, bhi) -> Pair:
    return add_down_np(alo, blo), add_up_np(ahi, bhi)


def _recip(lo, hi) -> Pair:
    zero = (lo <= 0.0) & (hi >= 0.0)
    rlo = down_np(1.0 / hi)
    rhi = up_np(1.0 / lo)
    return np.where(zero, -np.inf, rlo), np.where(zero, np.inf, rhi)


def _pow_mag(a: np.ndarray, k: int, rnd) -> np.ndarray:
    """``a^k`` for ``a >= 0`` by repeated multiplication, each product rounded by ``rnd``."""
    out = a
    for _ in range(k - 1):
        out = rnd(out * a)
    return out


def _ipow(lo, hi, k: int) -> Pair:
    if k == 0:
        return np.ones_like(lo), np.ones_like(hi)
    if k < 0:
        plo, phi = _ipow(lo, hi, -k)
        return _recip(plo, phi)
    if k == 1:
        return lo, hi
    if k % 2 == 1:  # odd: increasing; x^k = sign(x) |x|^k
        lo_m = np.where(lo >= 0, _pow_mag(np.abs(lo), k, down_np), _pow_mag(np.abs(lo), k, up_np))
        hi_m = np.where(hi >= 0, _pow_mag(np.abs(hi), k, up_np), _pow_mag(np.abs(hi), k, down_np))
        return np.where(lo >= 0, lo_m, -lo_m), np.where(hi >= 0, hi_m, -hi_m)
    mlo = np.where(lo >= 0, lo, np.where(hi <= 0, -hi, 0.0))  # min |x| on the interval
    mhi = np.maximum(np.abs(lo), np.abs(hi))
    return _pow_mag(mlo, k, down_np), _pow_mag(mhi, k, up_np)


def _sqrt(lo, hi) -> Pair:
    bad = lo < 0.0
    slo = np.maximum(down_np(np.sqrt(np.maximum(lo, 0.0))), 0.0)
    shi = up_np(np.sqrt(hi))
    return np.where(bad, np.nan, slo), np.where(bad, np.nan, shi)


def _monotone(fn) -> Callable[[np.ndarray, np.ndarray], Pair]:
    def op(lo, hi):
        return _libm(fn, lo)[0], _libm(fn, hi)[1]

    return op


def _exp(lo, hi) -> Pair:
    elo = np.where(lo == -np.inf, 0.0, np.maximum(_libm(np.exp, lo)[0], 0.0))
    ehi = _libm(np.exp, hi)[1]
    return elo, ehi


def _log(lo, hi) -> Pair:
    bad = lo <= 0.0  # the scalar evaluator refuses a log reaching 0 (strict domain)
    llo = _libm(np.log, np.where(bad, 1.0, lo))[0]
    lhi = _libm(np.log, np.where(bad, 1.0, hi))[1]
    return np.where(bad, np.nan, llo), np.where(bad, np.nan, lhi)


def _clip(p: Pair, a: float, b: float) -> Pair:
    return np.clip(p[0], a, b), np.clip(p[1], a, b)


def _abs(lo, hi) -> Pair:
    alo = np.where(lo >= 0, lo, np.where(hi <= 0, -hi, 0.0))
    return alo, np.maximum(np.abs(lo), np.abs(hi))


def _cosh(lo, hi) -> Pair:
    alo, ahi = _abs(lo, hi)
    return np.maximum(_libm(np.cosh, alo)[0], 1.0), _libm(np.cosh, ahi)[1]


def _sech(lo, hi) -> Pair:
    """``1 / cosh``: libm's error and one division, so widened by twice the libm budget."""
    alo, ahi = _abs(lo, hi)
    vlo = widen_np(1.0 / np.cosh(ahi), 2.0 * LIBM_REL)[0]
    vhi = widen_np(1.0 / np.cosh(alo), 2.0 * LIBM_REL)[1]
    return _clip((vlo, vhi), 0.0, 1.0)


def _reaches(lo, hi, offset: float) -> np.ndarray:
    """Whether ``[lo, hi]`` may contain ``offset + 2 k pi`` (conservative, see ``SIN_MARGIN``)."""
    period = 2.0 * math.pi
    kl = np.ceil((lo - offset) / period - SIN_MARGIN)
    kh = np.floor((hi - offset) / period + SIN_MARGIN)
    return kl <= kh


def _periodic(fn, max_at: float, min_at: float) -> Callable[[np.ndarray, np.ndarray], Pair]:
    def op(lo, hi):
        a_lo, a_hi = _libm(fn, lo)
        b_lo, b_hi = _libm(fn, hi)
        rlo, rhi = np.minimum(a_lo, b_lo), np.maximum(a_hi, b_hi)
        full = ~((hi - lo) < SIN_FULL_WIDTH) | ~(np.maximum(np.abs(lo), np.abs(hi)) < SIN_MAX_ABS)
        rhi = np.where(full | _reaches(lo, hi, max_at), 1.0, rhi)
        rlo = np.where(full | _reaches(lo, hi, min_at), -1.0, rlo)
        return _clip((rlo, rhi), -1.0, 1.0)

    return op


def _sign(lo, hi) -> Pair:
    return np.sign(lo), np.sign(hi)


def _heaviside(lo, hi) -> Pair:
    return np.where(lo <= 0, 0.0, 1.0), np.where(hi >= 0, 1.0, 0.0)


_UNARY: dict[type, Callable[[np.ndarray, np.ndarray], Pair]] = {
    sp.exp: _exp,
    sp.log: _log,
    sp.sin: _periodic(np.sin, math.pi / 2, -math.pi / 2),
    sp.cos: _periodic(np.cos, 0.0, math.pi),
    sp.tanh: lambda lo, hi: _clip(_monotone(np.tanh)(lo, hi), -1.0, 1.0),
    sp.atan: _monotone(np.arctan),
    sp.sinh: _monotone(np.sinh),
    sp.cosh: _cosh,
    sp.sech: _sech,
    sp.Abs: _abs,
    sp.sign: _sign,
    sp.Heaviside: _heaviside,
}


def _fold(op, parts: list[_BFn]) -> _BFn:
    def folded(box: np.ndarray) -> Pair:
        lo, hi = parts[0](box)
        for p in parts[1:]:
            blo, bhi = p(box)
            lo, hi = op(lo, hi, blo, bhi)
        return lo, hi

    return folded


def _max(alo, ahi, blo, bhi) -> Pair:
    return np.maximum(alo, blo), np.maximum(ahi, bhi)


def _min(alo, ahi, blo, bhi) -> Pair:
    return np.minimum(alo, blo), np.minimum(ahi, bhi)


def _compile(expr: sp.Expr, index: dict[sp.Symbol, int]) -> _BFn:
    if expr.is_Symbol:
        if expr not in index:
            raise UnsupportedExpression(f"symbol {expr} is not a variable of the box")
        i = index[expr]
        return lambda box: (box[:, i, 0], box[:, i, 1])
    if not expr.free_symbols and not expr.has(AppliedUndef):
        clo, chi = enclose_constant(expr)
        return lambda box: (np.full(box.shape[0], clo), np.full(box.shape[0], chi))
    if expr.is_Add:
        return _fold(_add, [_compile(a, index) for a in expr.args])
    if expr.is_Mul:
        return _fold(_mul, [_compile(a, index) for a in expr.args])
    if expr.is_Pow:
        base, ex = expr.args
        fb = _compile(base, index)
        if ex.is_Integer:
            k = int(ex)
            return lambda box: _ipow(*fb(box), k)
        if ex.is_Rational and int(ex.q) == 2:
            k2 = int(ex.p)
            return lambda box: _ipow(*_sqrt(*fb(box)), k2)
        raise UnsupportedExpression(f"no batched form of the power {expr}")
    head = expr.func
    if head in _UNARY and len(expr.args) == 1:  # Heaviside(x, H0) has no batched form
        op = _UNARY[head]
        fa = _compile(expr.args[0], index)
        return lambda box: op(*fa(box))
    if head in (sp.Max, sp.Min):
        return _fold(_max if head is sp.Max else _min, [_compile(a, index) for a in expr.args])
    raise UnsupportedExpression(f"no batched form of {head} (use the scalar evaluator)")


def compile_batch(expr: sp.Expr | float, variables: Sequence[sp.Symbol]) -> _BFn:
    """The batched natural interval extension of ``expr``.

    Parameters
    ----------
    expr
        A real sympy expression in ``variables`` (with the cancellation-free rewriting of
        :func:`~drip_cert.numerics.interval.cancellation_free` applied here, as the scalar
        evaluator does).
    variables
        The symbols, in the order of the boxes' rows.

    Returns
    -------
    callable
        ``F(boxes (K, d, 2)) -> (lo (K,), hi (K,))`` with ``lo <= expr(x) <= hi`` for every ``x``
        in box ``k`` (NaN: no information).

    Raises
    ------
    UnsupportedExpression
        A node has no batched form here (use the scalar evaluator).
    """
    fn = _compile_raw(expr, variables)

    def call(boxes: np.ndarray) -> Pair:
        with np.errstate(all="ignore"):  # inf - inf and the like: NaN, read as no information
            return fn(np.asarray(boxes, dtype=float))

    return call


def _compile_raw(expr: sp.Expr | float, variables: Sequence[sp.Symbol]) -> _BFn:
    index = {s: i for i, s in enumerate(variables)}
    return _compile(cancellation_free(sp.sympify(expr)), index)


class BatchEnclosure:
    """Rigorous enclosure of a scalar expression over many boxes: the natural extension
    intersected with the mean-value form ``e(c) + sum_k [d_k e](B) (B_k - c_k)`` (Moore 1966,
    Sec. 6.4), box by box, as :class:`~drip_cert.numerics.interval.MatrixEnclosure` does.

    Parameters
    ----------
    expr
        The sympy expression.
    variables
        Symbols of the box rows.

    Raises
    ------
    UnsupportedExpression
        The expression has no batched natural extension.
    """

    def __init__(self, expr: sp.Expr, variables: Sequence[sp.Symbol]) -> None:
        expr = sp.sympify(expr)
        self.variables = tuple(variables)
        self._natural = _compile_raw(expr, variables)
        self._grads: list[_BFn | None] | None = None
        if expr.free_symbols & set(variables) and is_smooth(expr):
            try:
                self._grads = [
                    _compile_raw(sp.diff(expr, v), variables) if expr.has(v) else None
                    for v in variables
                ]
            except UnsupportedExpression:
                self._grads = None

    def at_points(self, points: np.ndarray) -> Pair:
        """``(lo, hi)``, each ``(P,)``, enclosing the expression at each point of ``points``
        ``(P, d)``: the natural extension on the degenerate boxes ``[p, p]`` (NaN: no
        information, e.g. outside the domain)."""
        pts = np.asarray(points, dtype=float)
        with np.errstate(all="ignore"):
            return _nan_both(*self._natural(np.stack([pts, pts], axis=-1)))

    def __call__(self, boxes: np.ndarray) -> Pair:
        """``(lo, hi)``, each ``(K,)``, for the boxes ``(K, d, 2)`` (NaN: no information)."""
        with np.errstate(all="ignore"):  # inf - inf and the like: NaN, read as no information
            return self._enclose(np.asarray(boxes, dtype=float))

    def _enclose(self, boxes: np.ndarray) -> Pair:
        lo, hi = self._natural(boxes)
        if self._grads is None:
            return _nan_both(lo, hi)
        c = 0.5 * (boxes[:, :, 0] + boxes[:, :, 1])
        centre = np.stack([c, c], axis=-1)
        mlo, mhi = self._natural(centre)
        for k, g in enumerate(self._grads):
            if g is None:
                continue
            glo, ghi = g(boxes)
            dlo = down_np(boxes[:, k, 0] - c[:, k])
            dhi = up_np(boxes[:, k, 1] - c[:, k])
            plo, phi = _mul(glo, ghi, dlo, dhi)
            mlo, mhi = _add(mlo, mhi, plo, phi)
        # intersect where the mean-value form is informative; keep the union if rounding made
        # the two disjoint (the scalar rule)
        ok = ~(np.isnan(mlo) | np.isnan(mhi))
        ilo = np.where(ok, np.maximum(lo, mlo), lo)
        ihi = np.where(ok, np.minimum(hi, mhi), hi)
        disjoint = ilo > ihi
        ilo = np.where(disjoint, np.minimum(lo, mlo), ilo)
        ihi = np.where(disjoint, np.maximum(hi, mhi), ihi)
        return _nan_both(ilo, ihi)


def _nan_both(lo: np.ndarray, hi: np.ndarray) -> Pair:
    """A NaN at either end means no information at both."""
    bad = np.isnan(lo) | np.isnan(hi)
    return np.where(bad, np.nan, lo), np.where(bad, np.nan, hi)
