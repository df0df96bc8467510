"""The field whose growth constants are sought, and the sound routes' building blocks.

:class:`GrowthField` holds ``vec F`` with the states and the time replaced by real dummy symbols
and computes, with caching, what the routes of :mod:`drip_cert.analysis.growth.regularity` need
(docs/math/l1drac.md section 2):

* route (a), *bounded*: rigorous enclosures of expressions over the whole space
  ``R^n x [t0, T]`` (:meth:`GrowthField.whole_space_enclosures`; ``exp``, ``atan`` and fractional
  powers are given exact enclosures on infinite arguments here), the Lipschitz bound from
  whole-space Jacobian enclosures, and the branch and bound of the growth ratio over the at most
  :data:`BNB_MAX_STATES` states ``F`` depends on;
* route (b), *radial*: the profile ``G`` with ``vec F(a) = G(||a||)`` and one-dimensional suprema
  over ``rho = ||a|| in [0, 1]`` and the tail ``w = 1 / rho in [0, 1]``;
* suprema over time of state-free squares.

Every supremum is an upper bound from :func:`drip_cert.analysis.growth.expr_sup.expr_sup` (branch
and
bound on squared norms) with a rigorously rounded root (:func:`~drip_cert.numerics.rounding.
arb_sqrt_up`).
"""

from __future__ import annotations

import functools
import math
from collections.abc import Sequence

import numpy as np
import sympy as sp
from flint import arb

from drip_cert.analysis.growth.expr_sup import expr_sup
from drip_cert.analysis.growth.rewrites import radial_profile, rewritings, sum_sq
from drip_cert.numerics.interval import UnsupportedExpression, compile_enclosure
from drip_cert.numerics.rounding import arb_hi, arb_lo, arb_sqrt_up, nonneg_spectral_norm_upper

__all__ = ["BNB_MAX_STATES", "GrowthField"]

Interval = tuple[float, float]

BNB_MAX_STATES = 3  #: the bounded growth branch and bound runs over at most this many states
_BNB_RADII = (10.0, 100.0, 1000.0)  #: half-widths of its box, tried in turn
_BNB_SPLITS_LOCAL = 1500  #: its split budget per box
_INF = math.inf
_DIFF_KEPT = 1024  #: derivatives kept (one certify asks for a few hundred, many twice)
_FIELDS_KEPT = 64  #: fields kept (a certify builds ~10 per coordinate system, each twice)


@functools.lru_cache(maxsize=_DIFF_KEPT)
def _diff(e: sp.Expr, x: sp.Symbol) -> sp.Expr:
    """``d e / d x``, kept: the growth and Lipschitz routes of several constants (a constant and
    its matched part, each moment) differentiate the same entries again."""
    return sp.diff(e, x)


class GrowthField:
    """``vec F`` with the states and time replaced by real dummies, and the routes' helpers.

    Build it with :meth:`make`. A matrix field ``F`` (n x d) is treated as the vector ``vec F``
    (column-major): the Frobenius norm of ``F`` is the Euclidean norm of ``vec F``.
    """

    def __init__(
        self,
        entries: list[sp.Expr],
        xs: tuple[sp.Symbol, ...],
        t: sp.Symbol | None,
        t_range: Interval,
    ) -> None:
        self.entries = entries
        self.xs = xs
        self.t = t
        self.t_range = t_range
        self.rho = sp.Dummy("rho", nonnegative=True)
        self.w = sp.Dummy("w", positive=True)
        self._profile: list[sp.Expr] | None | bool = False
        self._lip: float | None | bool = False
        self._lips: list[tuple[float, str]] | None = None

    @classmethod
    def make(cls, F, states, t, t_range) -> GrowthField:
        """Validate ``F``, ``states``, ``t`` and ``t_range`` and build the field; the same
        arguments give the same field (kept: a growth bound and a Lipschitz or Hoelder bound of
        one constant share its enclosures, radial profile and Lipschitz routes, each a
        deterministic function of the field, computed once).

        Raises
        ------
        ValueError
            Repeated or missing states, a non-finite or reversed ``t_range``, or a symbol in
            ``F`` that is neither a state nor the time.
        """
        try:
            key = (sp.ImmutableMatrix(F), tuple(states), t, (float(t_range[0]), float(t_range[1])))
            hash(key)
        except (TypeError, ValueError, IndexError):  # not hashable: built and checked below
            return cls._build(F, states, t, t_range)
        return _make_kept(*key)

    @classmethod
    def _build(cls, F, states, t, t_range) -> GrowthField:
        """:meth:`make`, not kept."""
        M = sp.Matrix(F)
        states = tuple(states)
        if len(set(states)) != len(states) or not states:
            raise ValueError(f"states must be distinct symbols, got {states!r}")
        xs = tuple(sp.Dummy(f"a{i + 1}", real=True) for i in range(len(states)))
        sub: dict[sp.Symbol, sp.Symbol] = dict(zip(states, xs))
        tt = None
        t0, t1 = float(t_range[0]), float(t_range[1])
        if not (math.isfinite(t0) and math.isfinite(t1) and t0 <= t1):
            raise ValueError(
                f"t_range must be a finite interval (t0, T) with t0 <= T, got {t_range!r}"
            )
        if t is not None and any(e.has(t) for e in M):
            tt = sp.Dummy("t", real=True)
            sub[t] = tt
        entries = [sp.sympify(e).xreplace(sub) for e in M.T]  # vec F, column-major
        extra = set().union(*(e.free_symbols for e in entries)) - set(xs) - {tt}
        if extra:
            raise ValueError(
                f"F holds symbols {sorted(map(str, extra))} that are neither states nor time; "
                "substitute their values first"
            )
        return cls(entries, xs, tt, (t0, t1))

    # -- properties
    @property
    def is_zero(self) -> bool:
        return all(e == 0 for e in self.entries)

    @property
    def depends_on_state(self) -> bool:
        return any(e.has(x) for e in self.entries for x in self.xs)

    @property
    def depends_on_time(self) -> bool:
        return self.t is not None

    def time_note(self) -> str:
        """What the note of a constant says about time (empty for a time-invariant field)."""
        if self.t is None:
            return ""
        return (
            f"; sup over t in [{self.t_range[0]:g}, {self.t_range[1]:g}] (the paper asks for "
            "all t >= 0; [0, T] suffices for a horizon-T certificate)"
        )

    def _tvars(self) -> tuple[list[sp.Symbol], list[Interval]]:
        if self.t is None:
            return [], []
        return [self.t], [self.t_range]

    # -- route (a)
    def whole_space_enclosures(self, exprs: Sequence[sp.Expr]) -> list[Interval] | None:
        """Finite rigorous enclosures of ``exprs`` over ``R^n x [t0, T]``, or ``None``."""
        tv, tb = self._tvars()
        variables = [*self.xs, *tv]
        box = [(-_INF, _INF)] * len(self.xs) + tb
        out = []
        for e in exprs:
            try:
                lo, hi = compile_enclosure(_wrap_unbounded(e), variables, _wrapped_enclose)(box)
            except (UnsupportedExpression, ZeroDivisionError, OverflowError, ValueError):
                return None
            if not (math.isfinite(lo) and math.isfinite(hi)):
                return None
            out.append((lo, hi))
        return out

    def bounded_lipschitz(self) -> float | None:
        """Rigorous ``sup ||d vec F / da||_2`` from whole-space Jacobian enclosures, or ``None``."""
        if self._lip is False:
            jac = [_diff(e, x) for e in self.entries for x in self.xs]
            if any(j.has(sp.DiracDelta) for j in jac):
                self._lip = None
            else:
                enc = self.whole_space_enclosures(jac)
                if enc is None:
                    self._lip = None
                else:
                    M = np.array([max(-lo, hi) for lo, hi in enc]).reshape(
                        len(self.entries), len(self.xs)
                    )
                    self._lip = nonneg_spectral_norm_upper(M)
        return self._lip  # computed above when it was still False (not yet computed)

    def lipschitz_bounds(self) -> list[tuple[float, str]]:
        """Sound Lipschitz bounds (value, route) from the bounded and the radial route."""
        if self._lips is not None:
            return self._lips
        out: list[tuple[float, str]] = []
        lip = self.bounded_lipschitz()
        if lip is not None:
            out.append(
                (
                    lip,
                    "bounded route: spectral norm (Collatz-Wielandt, ball arithmetic) "
                    "of the matrix of rigorous sup |dF_i/da_j| over all of R^n",
                )
            )
        prof = self.radial_profile()
        if prof is not None:
            der = [_diff(g, self.rho) for g in prof]
            if not any(d.has(sp.DiracDelta) for d in der):
                val, msg = self.radial_norm_sup(der)
                if val < _INF:
                    out.append(
                        (
                            val,
                            "radial route: F = G(||a||), L = sup_r ||G'(r)|| (exact for "
                            "radial fields up to the branch-and-bound tolerance)" + msg,
                        )
                    )
        self._lips = out
        return out

    def bounded_growth_bnb(self, p: sp.Rational, M: float) -> tuple[float, str] | None:
        """Growth sup of a bounded ``F`` that depends on at most 3 states, by branch and bound.

        With ``S`` the states ``F`` depends on, ``||a|| >= ||a_S||`` gives the same supremum over
        ``a_S`` alone; on ``[-R, R]^k`` it is bounded by branch and bound, outside by
        ``M / (1 + R^2)^{p/2}`` with ``M`` the whole-space bound of ``||F||``.
        """
        used = [x for x in self.xs if any(e.has(x) for e in self.entries)]
        if not used or len(used) > BNB_MAX_STATES:
            return None
        tv, tb = self._tvars()
        obj = sum_sq(self.entries) / (1 + sum(x**2 for x in used)) ** p
        best: tuple[float, str] | None = None
        for R in _BNB_RADII:
            res = expr_sup(
                [obj], [*used, *tv], [(-R, R)] * len(used) + tb, max_splits=_BNB_SPLITS_LOCAL
            )
            ub = arb_sqrt_up(res.upper)
            tail = arb_hi(arb(M) / (1 + arb(R) ** 2) ** (arb(p.p) / (2 * p.q)))
            val = max(ub, tail)
            if best is None or val < best[0]:
                best = (
                    val,
                    f"bounded route, branch and bound over the {len(used)} state(s) F "
                    f"depends on, on [-{R:g}, {R:g}]^{len(used)} (<= {ub:.9g}) and "
                    f"outside it M / (1 + R^2)^(p/2) <= {tail:.3g} with M = {M:.6g}",
                )
            if tail <= ub:
                break
        return best

    def sup_over_time(self, expr_sq: sp.Expr) -> tuple[float, bool]:
        """Rigorous ``sqrt(sup_t expr_sq)`` of a state-free square (branch and bound in ``t``)."""
        tv, tb = self._tvars()
        if not tv:
            try:
                _, hi = compile_enclosure(expr_sq, [])([])
            except UnsupportedExpression:
                return _INF, False
            hi = arb_sqrt_up(hi)
            return hi, math.isfinite(hi)
        ub = arb_sqrt_up(expr_sup([expr_sq], tv, tb).upper)
        return ub, math.isfinite(ub)

    # -- route (b)
    def radial_profile(self) -> list[sp.Expr] | None:
        """``G(rho)`` with ``vec F(a) = G(||a||)``, or ``None`` when ``F`` is not radial."""
        if self._profile is False:
            self._profile = radial_profile(self.entries, self.xs, self.rho, self.t)
        return self._profile  # type: ignore[return-value]

    def radial_norm_sup(self, exprs: Sequence[sp.Expr]) -> tuple[float, str]:
        """Sound ``sup_{rho >= 0} ||exprs(rho)||`` (``exprs`` in ``rho`` and ``t``), with a note:
        :meth:`radial_sup` of the squared norm of every rewriting, in ``rho`` and in ``w``."""
        rho, w = self.rho, self.w
        head = [sum_sq(gs) for gs in rewritings(exprs)]
        tail = [sum_sq(gs) for gs in rewritings([e.subs(rho, 1 / w) for e in exprs])]
        return self.radial_sup(head, tail)

    def radial_sup(self, head: list[sp.Expr], tail: list[sp.Expr]) -> tuple[float, str]:
        """Sound sup over ``rho >= 0`` of a head form (in rho) and a tail form (in w = 1/rho)."""
        tv, tb = self._tvars()
        h = expr_sup(head, [self.rho, *tv], [(0.0, 1.0), *tb]).upper
        if not math.isfinite(h):
            return _INF, ""
        tl = expr_sup(tail, [self.w, *tv], [(0.0, 1.0), *tb]).upper
        if not math.isfinite(tl):
            return _INF, ""
        h, tl = arb_sqrt_up(h), arb_sqrt_up(tl)
        return max(h, tl), f" (r <= 1: {h:.9g}, r >= 1: {tl:.9g})"


# ------------------------------------------------------------------ whole-space enclosures
#: ``exp``, ``atan`` and fractional powers behind the enclose callback, so that
#: ``exp(-inf) = 0`` and ``|atan| <= pi/2`` are used on infinite arguments, and so that a sum of
#: squares whose outward-rounded lower end is a denormal below 0 stays in the domain of ``sqrt``
@functools.lru_cache(maxsize=_FIELDS_KEPT)
def _make_kept(F, states, t, t_range) -> GrowthField:
    """:meth:`GrowthField.make` for hashable arguments, kept."""
    return GrowthField._build(F, states, t, t_range)


_ExpW = sp.Function("_growth_exp")
_AtanW = sp.Function("_growth_atan")
_RPowW = sp.Function("_growth_rpow")
_ROUNDING_FLOOR = -1e-300  #: lower ends in [this, 0) are outward rounding of 0, not negative values


def _wrap_unbounded(e: sp.Expr) -> sp.Expr:
    e = e.replace(sp.exp, _ExpW).replace(sp.atan, _AtanW)
    return e.replace(
        lambda z: z.is_Pow and z.exp.is_Rational and not z.exp.is_Integer,
        lambda z: _RPowW(z.base, z.exp),
    )


def _wrapped_enclose(node: sp.Expr, args: list[Interval]) -> Interval | None:
    func = getattr(node, "func", None)
    if func not in (_ExpW, _AtanW, _RPowW):
        return None
    lo, hi = args[0]
    if func == _RPowW:
        q = sp.Rational(node.args[1])
        if _ROUNDING_FLOOR <= lo < 0.0:
            lo = 0.0
        if lo < 0.0 or (q < 0 and lo == 0.0):
            return None  # outside the real domain: no enclosure
        qa = arb(int(q.p)) / arb(int(q.q))

        def pw(x: float) -> arb:
            return arb(0) if x == 0.0 else (arb(x).log() * qa).exp()

        if q > 0:
            return (max(0.0, arb_lo(pw(lo))), _INF if hi == _INF else arb_hi(pw(hi)))
        return (0.0 if hi == _INF else max(0.0, arb_lo(pw(hi))), arb_hi(pw(lo)))
    if node.func == _ExpW:
        vlo = 0.0 if lo == -_INF else max(0.0, arb_lo(arb(lo).exp()))
        vhi = _INF if hi == _INF else arb_hi(arb(hi).exp())
        return (vlo, vhi)
    half_pi = arb.pi() / 2
    vlo = arb_lo(-half_pi) if lo == -_INF else arb_lo(arb(lo).atan())
    vhi = arb_hi(half_pi) if hi == _INF else arb_hi(arb(hi).atan())
    return (vlo, vhi)
