"""Sound global growth, Lipschitz and 1/2-Hoelder constants of uncertainty expressions.

L1-DRAC (Gahlawat, Karumanchi, Hovakimyan, arXiv:2509.04619) asks for constants that hold over
*all* of ``R^n``:

* Assumption 4 (growth): ``||Lambda_mu(t, a)||^2 <= Delta_mu^2 (1 + ||a||^2)`` for a drift vector
  (Euclidean norm, ``power = 1``) and ``||Lambda_sigma(t, a)||_F^2 <= Delta_sigma^2
  (1 + ||a||^2)^{1/2}`` for a diffusion matrix (Frobenius norm, ``power = 1/2``); the smallest
  constant is ``sup_a ||F(t, a)|| / (1 + ||a||^2)^{power/2}`` (:func:`growth_bound`);
* Assumption 6 (regularity): ``Lambda_mu`` globally Lipschitz in ``a`` (:func:`lipschitz_bound`)
  and ``Lambda_sigma`` 1/2-Hoelder in ``a`` in the Frobenius norm (:func:`holder_half_bound`).
  DRIP Assumption 1 takes the same constants.

A matrix field ``F`` (n x d) is treated as the vector field ``vec F`` in ``R^{nd}``: the Frobenius
norm of ``F`` is the Euclidean norm of ``vec F``, so one code path serves both.

Routes, each giving a sound upper bound where it applies (the smallest one is returned):

(a) *bounded*: every entry (and, for the Lipschitz constant, every entry of the Jacobian) has a
    finite rigorous interval enclosure over the whole space (:mod:`drip_cert.numerics.interval`
    on the box ``(-inf, inf)^n``; ``exp`` and ``atan`` are given exact enclosures on infinite
    arguments here). Growth: the denominator is ``>= 1``, so ``||F||^2 <= sum max(lo^2, hi^2)``.
    Lipschitz: ``||J||_2 <= || |J| ||_2 <= ||M||_2`` for ``M_ij >= sup |J_ij|``, and ``||M||_2`` is
    bounded rigorously by the Collatz-Wielandt inequality in ball arithmetic. 1/2-Hoelder:
    ``||F(a) - F(b)|| <= min(L d, D)`` with ``D`` the diameter of the enclosure box and ``L`` the
    best Lipschitz bound found, and ``sup_d min(L d, D) / sqrt(d) = sqrt(L D)``. When ``F``
    depends on at most 3 states ``a_S``, the growth supremum (which is the same over ``a_S``
    alone, since ``||a|| >= ||a_S||``) is also bounded by branch and bound on ``[-R, R]^|S|`` and
    by ``M / (1 + R^2)^{p/2}`` outside, ``M`` the whole-space bound of ``||F||``.
(b) *radial*: ``F(a) = G(||a||)`` (found by substituting ``||a||^2 = rho^2`` and checking that no
    state is left). Then ``sup_a ||F|| / (1 + ||a||^2)^{p/2} = sup_{rho >= 0} ||G(rho)|| /
    (1 + rho^2)^{p/2}`` exactly; the Lipschitz constant is exactly ``sup ||G'(rho)||`` (the Jacobian
    is the rank-one ``vec G'(rho) (a / rho)^T``; along a ray the ratio tends to it); and the
    1/2-Hoelder constant is at most ``sup_{s > 0} 2 sqrt(s) ||G'(s)||`` (if ``||G'(s)|| <=
    c / (2 sqrt(s))`` then ``||G(r2) - G(r1)|| <= c (sqrt(r2) - sqrt(r1)) <= c sqrt(r2 - r1) <=
    c ||a - b||^{1/2}``), which is exact for ``G = C0 + C1 sqrt(rho)``. Each one-dimensional
    supremum is bounded by interval branch and bound on ``rho in [0, 1]`` plus the tail
    ``rho = 1 / w``, ``w in [0, 1]``, with the expression rewritten by sympy so that it stays
    finite at ``w = 0``; the enclosure of every box is the intersection of the enclosures of
    several equivalent rewritings (natural extension and mean-value form). Branch and bound runs
    on squared norms (smooth) and takes a rigorously rounded root at the end.
(a') *Lipschitz* (drift, ``power = 1``): ``||F(a)|| <= ||F(0)|| + L ||a|| <= sqrt(||F(0)||^2 +
    L^2) (1 + ||a||^2)^{1/2}`` (Cauchy-Schwarz), with the Lipschitz bound of (a) or (b); this is
    exact for the paper's ``Lambda_mu``.
(c) otherwise: a sampled ESTIMATE over spheres of radii up to 1e6 (the points of
    :func:`drip_cert.analysis.constants.sample_points`), labelled "estimate, not a bound".

Time dependence: ``t`` is one more interval variable over ``t_range = (t0, T)``. The paper asks
for the constants for all ``t >= 0``; their supremum over ``[0, T]`` suffices for a certificate
on the horizon ``T``, and the notes say so.

Derivative-based bounds assume ``F`` continuous (true for expressions of the parser's whitelist
where they are defined); derivatives of ``Abs``/``Max``/``Min`` are the almost-everywhere ones,
which is enough for these Lipschitz functions, and a jump (``sign``, ``Heaviside``) differentiates
to a ``DiracDelta`` that no enclosure accepts, so no bound is claimed for it.
"""

from __future__ import annotations

import heapq
import itertools
import math
from collections.abc import Callable, Sequence

import numpy as np
import sympy as sp
from flint import arb

from drip_cert.numerics.interval import MatrixEnclosure, UnsupportedExpression, compile_enclosure
from drip_cert.numerics.rounding import arb_hi as _arb_hi
from drip_cert.numerics.rounding import arb_lo as _arb_lo
from drip_cert.numerics.sampling import (
    SAMPLE_RADII,
    SAMPLE_SEED,
    SAMPLES_PER_RADIUS,
    sample_points,
)
from drip_cert.provenance import How, Quantity

__all__ = [
    "growth_bound",
    "lipschitz_bound",
    "holder_half_bound",
    "BNB_RTOL",
    "BNB_ATOL",
    "BNB_MAX_SPLITS",
]

Interval = tuple[float, float]
Evaluator = Callable[[float, np.ndarray], np.ndarray]

BNB_RTOL = 1e-7  #: branch and bound stops when its upper bound is within this of the best value
BNB_ATOL = 1e-12  #: absolute part of the stopping rule (values near 0)
BNB_MAX_SPLITS = 4000  #: at most this many box splits per supremum (the answer stays sound)
_GIVE_UP_WIDTH = 1e-9  #: a box this narrow (relative) whose enclosure is still infinite: give up
_BNB_MAX_STATES = 3  #: the bounded growth branch and bound runs over at most this many states
_BNB_RADII = (10.0, 100.0, 1000.0)  #: half-widths of its box, tried in turn
_BNB_SPLITS_LOCAL = 1500  #: its split budget per box
_ESTIMATE_TIMES = 9  #: time points of [t0, T] sampled by the estimate route
_HOLDER_SCALES = (1e-6, 1e-4, 1e-2, 1e-1, 1.0, 10.0, 100.0, 1e3)  #: pair distances sampled
_GROWTH_SOURCE = "L1-DRAC Assumption 4 / DRIP Assumption 1"
_REG_SOURCE = "L1-DRAC Assumption 6 / DRIP Assumption 1"
_INF = math.inf


# ------------------------------------------------------------------------------- public API
def sup_bound(
    F: sp.MatrixBase,
    states: Sequence[sp.Symbol],
    t: sp.Symbol | None = None,
    t_range: tuple[float, float] = (0.0, 0.0),
    name: str = "sup",
    *,
    source: str = "",
) -> Quantity:
    """Rigorous ``sup_{t, a} ||F(t, a)||`` (Euclidean / Frobenius) over all of ``R^n``.

    From whole-space interval enclosures of the entries (the bounded route of
    :func:`growth_bound`); ``inf`` (sound: no finite bound was proved) when an entry has no finite
    enclosure, e.g. because it grows with ``a``. Used for the time-Lipschitz constants (the
    "hats" of L1-DRAC Assumptions 1, 5, 6) as ``sup ||d/dt F||`` (mean-value theorem in ``t``).
    """
    ctx = _Context.make(F, states, t, t_range)
    if ctx.is_zero:
        return Quantity(name, 0.0, How.EXACT, source, "F = 0")
    enc = ctx.whole_space_enclosures(ctx.entries)
    if enc is None:
        return Quantity(
            name,
            _INF,
            How.SOUND,
            source,
            "no finite whole-space enclosure (the term may grow with the state): no finite "
            "bound; give it in [constants] if you know one" + ctx.time_note(),
        )
    return Quantity(
        name,
        _sqrt_sum_sq_up([max(-lo, hi) for lo, hi in enc]),
        How.SOUND,
        source,
        "rigorous whole-space entry enclosures" + ctx.time_note(),
    )


def growth_bound(
    F: sp.MatrixBase,
    states: Sequence[sp.Symbol],
    t: sp.Symbol | None = None,
    t_range: tuple[float, float] = (0.0, 0.0),
    power: float | sp.Rational = 1,
    name: str = "Delta",
    *,
    source: str = _GROWTH_SOURCE,
    evaluate: Evaluator | None = None,
) -> Quantity:
    """Growth constant ``sup_{t, a} ||F(t, a)|| / (1 + ||a||^2)^{power/2}`` (L1-DRAC Assumption 4).

    Parameters
    ----------
    F
        ``sympy.Matrix`` (n x 1 drift uncertainty, Euclidean norm; n x d diffusion uncertainty,
        Frobenius norm) in ``states`` and ``t``.
    states
        The state symbols ``a = (a_1, ..., a_n)``.
    t, t_range
        The time symbol (or ``None``) and the interval ``[t0, T]`` its supremum is taken over.
    power
        ``1`` for ``||F||^2 <= D^2 (1 + ||a||^2)``, ``1/2`` for
        ``||F||_F^2 <= D^2 (1 + ||a||^2)^{1/2}``.
    name, source
        Recorded in the returned :class:`~drip_cert.provenance.Quantity`.
    evaluate
        Optional batched evaluator ``(t, X (N, n)) -> (N, ...)`` for the sampled estimate (needed
        only when ``F`` holds undefined functions, e.g. learned blocks).

    Returns
    -------
    Quantity
        ``How.EXACT`` for a constant ``F``; ``How.SOUND`` (never below the supremum) from the
        bounded or radial route; ``How.ESTIMATE`` otherwise, with the route in the note.
    """
    p = _rational(power, "power")
    ctx = _Context.make(F, states, t, t_range)
    tnote = ctx.time_note()
    if ctx.is_zero:
        return Quantity(name, 0.0, How.EXACT, source, "F = 0")
    if not ctx.depends_on_state:
        # the sup over a is attained at a = 0 (the denominator is >= 1 and equals 1 there)
        val, ok = ctx.sup_over_time(_sum_sq(ctx.entries))
        if ok:
            how = How.EXACT if not ctx.depends_on_time else How.SOUND
            return Quantity(
                name, val, how, source, "F does not depend on the state: ||F|| at a = 0" + tnote
            )
    bounds: list[tuple[float, str]] = []
    enc = ctx.whole_space_enclosures(ctx.entries)
    if enc is not None:
        M = _sqrt_sum_sq_up([max(-lo, hi) for lo, hi in enc])
        bounds.append(
            (
                M,
                "bounded route: ||F||^2 <= sum of max(lo^2, hi^2) of rigorous entry "
                "enclosures over all of R^n (denominator >= 1)",
            )
        )
        local = ctx.bounded_growth_bnb(p, M)
        if local is not None:
            bounds.append(local)
    prof = ctx.radial_profile()
    if prof is not None:
        rho, w = ctx.rho, ctx.w
        head = [_sum_sq(gs) / (1 + rho**2) ** p for gs in _rewritings_list(prof)]
        tails = [(w**p * g.subs(rho, 1 / w)) for g in prof]
        tail = [_sum_sq(gs) * (1 + w**2) ** (-p) for gs in _rewritings_list(tails)]
        val, msg = ctx.radial_sup(head, tail)
        if val < _INF:
            bounds.append(
                (
                    val,
                    "radial route: F depends on a only through r = ||a||; "
                    "sup_r ||G(r)|| / (1 + r^2)^{p/2} by interval branch and bound "
                    "on r in [0, 1] and on w = 1/r in [0, 1]" + msg,
                )
            )
    if p == 1:
        lips = ctx.lipschitz_bounds()
        if lips:
            L = min(lips)[0]
            f0, ok = ctx.sup_over_time(
                _sum_sq([e.xreplace({x: 0 for x in ctx.xs}) for e in ctx.entries])
            )
            if ok:
                val = _sqrt_sum_sq_up([f0, L])
                bounds.append(
                    (
                        val,
                        "Lipschitz route: ||F(a)|| <= ||F(0)|| + L ||a|| <= "
                        "sqrt(||F(0)||^2 + L^2) (1 + ||a||^2)^{1/2} (Cauchy-Schwarz), "
                        f"L <= {L:.6g}",
                    )
                )
    if bounds:
        val, how_note = min(bounds)
        return Quantity(name, val, How.SOUND, source, how_note + tnote)
    return _growth_estimate(ctx, p, name, source, evaluate)


def lipschitz_bound(
    F: sp.MatrixBase,
    states: Sequence[sp.Symbol],
    t: sp.Symbol | None = None,
    t_range: tuple[float, float] = (0.0, 0.0),
    name: str = "L",
    *,
    source: str = _REG_SOURCE,
    evaluate: Evaluator | None = None,
) -> Quantity:
    """Global Lipschitz constant in ``a``: ``sup ||F(t, a) - F(t, b)|| / ||a - b||`` (Frobenius
    norm for a matrix field; L1-DRAC Assumption 6).

    Parameters and return value as in :func:`growth_bound`.
    """
    ctx = _Context.make(F, states, t, t_range)
    tnote = ctx.time_note()
    if not ctx.depends_on_state:
        return Quantity(name, 0.0, How.EXACT, source, "F does not depend on the state")
    bounds = ctx.lipschitz_bounds()
    if bounds:
        val, how_note = min(bounds)
        return Quantity(name, val, How.SOUND, source, how_note + tnote)
    return _holder_estimate(ctx, 1.0, name, source, evaluate)


def holder_half_bound(
    F: sp.MatrixBase,
    states: Sequence[sp.Symbol],
    t: sp.Symbol | None = None,
    t_range: tuple[float, float] = (0.0, 0.0),
    name: str = "L_sigma",
    *,
    source: str = _REG_SOURCE,
    evaluate: Evaluator | None = None,
) -> Quantity:
    """Global 1/2-Hoelder constant in ``a``: ``sup ||F(t, a) - F(t, b)||_F / ||a - b||^{1/2}``
    (L1-DRAC Assumption 6, the diffusion uncertainty).

    Parameters and return value as in :func:`growth_bound`.
    """
    ctx = _Context.make(F, states, t, t_range)
    tnote = ctx.time_note()
    if not ctx.depends_on_state:
        return Quantity(name, 0.0, How.EXACT, source, "F does not depend on the state")
    bounds: list[tuple[float, str]] = []
    enc = ctx.whole_space_enclosures(ctx.entries)
    lips = ctx.lipschitz_bounds() if enc is not None else []
    if enc is not None and lips:
        lip = min(lips)[0]
        diam = _sqrt_sum_sq_up([_sub_up(hi, lo) for lo, hi in enc])
        val = _arb_hi((arb(lip) * arb(diam)).sqrt())
        bounds.append(
            (
                val,
                "bounded route: ||F(a)-F(b)|| <= min(L d, D), sup_d min(L d, D) / "
                f"sqrt(d) = sqrt(L D) with L <= {lip:.6g}, D <= {diam:.6g}",
            )
        )
    prof = ctx.radial_profile()
    if prof is not None:
        rho, w = ctx.rho, ctx.w
        h = [2 * sp.sqrt(rho) * sp.diff(g, rho) for g in prof]
        head = [_sum_sq(gs) for gs in _rewritings_list(h)]
        tail = [_sum_sq(gs) for gs in _rewritings_list([e.subs(rho, 1 / w) for e in h])]
        val, msg = ctx.radial_sup(head, tail)
        if val < _INF:
            bounds.append(
                (
                    val,
                    "radial route: F = G(||a||), ||G'(s)|| <= c / (2 sqrt(s)) gives "
                    "||F(a)-F(b)|| <= c (sqrt(r2)-sqrt(r1)) <= c ||a-b||^{1/2}; "
                    "c = sup_s 2 sqrt(s) ||G'(s)|| (exact for G = C0 + C1 sqrt(r))" + msg,
                )
            )
    if bounds:
        val, how_note = min(bounds)
        return Quantity(name, val, How.SOUND, source, how_note + tnote)
    return _holder_estimate(ctx, 0.5, name, source, evaluate)


# ----------------------------------------------------------------------------- the context
class _Context:
    """``vec F`` with the states and time replaced by real dummies, and the routes' helpers."""

    def __init__(self, entries, xs, t, t_range, user_states, user_t):
        self.entries: list[sp.Expr] = entries
        self.xs: tuple[sp.Symbol, ...] = xs
        self.t: sp.Symbol | None = t
        self.t_range = t_range
        self.user_states = user_states
        self.user_t = user_t
        self.rho = sp.Dummy("rho", nonnegative=True)
        self.w = sp.Dummy("w", positive=True)
        self._profile: list[sp.Expr] | None | bool = False
        self._lip: float | None | bool = False
        self._lips: list[tuple[float, str]] | None = None

    @classmethod
    def make(cls, F, states, t, t_range) -> _Context:
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
        return cls(entries, xs, tt, (t0, t1), states, t)

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
            jac = [sp.diff(e, x) for e in self.entries for x in self.xs]
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
                    self._lip = _spectral_upper(M)
        return self._lip  # type: ignore[return-value]

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
            rho, w = self.rho, self.w
            der = [sp.diff(g, rho) for g in prof]
            if not any(d.has(sp.DiracDelta) for d in der):
                head = [_sum_sq(gs) for gs in _rewritings_list(der)]
                tail = [_sum_sq(gs) for gs in _rewritings_list([d.subs(rho, 1 / w) for d in der])]
                val, msg = self.radial_sup(head, tail)
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
        if not used or len(used) > _BNB_MAX_STATES:
            return None
        tv, tb = self._tvars()
        obj = _sum_sq(self.entries) / (1 + sum(x**2 for x in used)) ** p
        best: tuple[float, str] | None = None
        for R in _BNB_RADII:
            ub_sq, _ = _bnb_sup(
                [obj], [*used, *tv], [(-R, R)] * len(used) + tb, max_splits=_BNB_SPLITS_LOCAL
            )
            ub = _sqrt_up(ub_sq)
            tail = _arb_hi(arb(M) / (1 + arb(R) ** 2) ** (arb(p.p) / (2 * p.q)))
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
            hi = _sqrt_up(hi)
            return hi, math.isfinite(hi)
        ub_sq, _ = _bnb_sup([expr_sq], tv, tb)
        ub = _sqrt_up(ub_sq)
        return ub, math.isfinite(ub)

    # -- route (b)
    def radial_profile(self) -> list[sp.Expr] | None:
        """``G(rho)`` with ``vec F(a) = G(||a||)``, or ``None`` when ``F`` is not radial."""
        if self._profile is False:
            self._profile = _radial_profile(self.entries, self.xs, self.rho, self.t)
        return self._profile  # type: ignore[return-value]

    def radial_sup(self, head: list[sp.Expr], tail: list[sp.Expr]) -> tuple[float, str]:
        """Sound sup over ``rho >= 0`` of a head form (in rho) and a tail form (in w = 1/rho)."""
        tv, tb = self._tvars()
        h, _ = _bnb_sup(head, [self.rho, *tv], [(0.0, 1.0), *tb])
        if not math.isfinite(h):
            return _INF, ""
        tl, _ = _bnb_sup(tail, [self.w, *tv], [(0.0, 1.0), *tb])
        if not math.isfinite(tl):
            return _INF, ""
        h, tl = _sqrt_up(h), _sqrt_up(tl)
        return max(h, tl), f" (r <= 1: {h:.9g}, r >= 1: {tl:.9g})"


# ---------------------------------------------------------------------------- radial helpers
def _radial_profile(entries, xs, rho, t) -> list[sp.Expr] | None:
    s2 = sum(x**2 for x in xs)
    out = []
    for e in entries:
        g = e.xreplace({s2: rho**2})
        if g.has(*xs):
            g = g.subs(s2, rho**2)
        if len(xs) == 1 and g.has(xs[0]):
            g = g.xreplace({sp.Abs(xs[0]): rho}).subs(xs[0] ** 2, rho**2)
        if g.has(*xs):
            return None
        out.append(g)
    # numerical sanity check of the rewriting at a few points (it is an identity by construction)
    rng = np.random.default_rng(7)
    for _ in range(3):
        a = rng.normal(size=len(xs)) * 1.7
        tv = {t: 0.37} if t is not None else {}
        r = float(np.linalg.norm(a))
        for e, g in zip(entries, out):
            try:
                v1 = complex(e.xreplace({**dict(zip(xs, map(sp.Float, a))), **tv}).evalf(30))
                v2 = complex(g.xreplace({rho: sp.Float(r), **tv}).evalf(30))
            except (TypeError, ValueError):
                return None
            if not abs(v1 - v2) <= 1e-12 * (1.0 + abs(v1)):
                return None
    return out


def _rewrites(e: sp.Expr) -> list[sp.Expr]:
    """Equivalent forms of ``e`` (identities for positive symbols), the cheap ones first."""
    forms = [e]
    for fn in (
        sp.expand,
        lambda z: sp.cancel(sp.together(z)),
        sp.powsimp,
        lambda z: sp.simplify(z) if sp.count_ops(z) < 150 else z,
    ):
        try:
            f = fn(e)
        except (TypeError, ValueError, NotImplementedError, RecursionError):  # pragma: no cover
            continue
        if all(f != g for g in forms):
            forms.append(f)
    return forms


def _rewritings_list(exprs: Sequence[sp.Expr]) -> list[list[sp.Expr]]:
    """The k-th rewriting of every entry (a list of k-th forms), for the candidate objectives."""
    per = [_rewrites(e) for e in exprs]
    k = max((len(p) for p in per), default=1)
    return [[p[min(i, len(p) - 1)] for p in per] for i in range(k)]


# ---------------------------------------------------------------------- branch and bound
def _bnb_sup(
    cands: Sequence[sp.Expr],
    variables: Sequence[sp.Symbol],
    box: Sequence[Interval],
    rtol: float = BNB_RTOL,
    atol: float = BNB_ATOL,
    max_splits: int = BNB_MAX_SPLITS,
) -> tuple[float, float]:
    """Rigorous upper bound (and a sampled lower value) of ``sup expr`` over ``box``.

    ``cands`` are equivalent forms of one expression; the enclosure of a box is the best of
    theirs. Returns ``(ub, lb)`` with ``ub >= sup`` (``inf`` when no finite bound was found).
    """
    encs = []
    for c in dict.fromkeys(cands):
        try:
            encs.append(MatrixEnclosure(sp.Matrix([[c]]), list(variables)))
        except UnsupportedExpression:
            continue
    if not encs:
        return _INF, math.nan
    point = None
    for c in cands:
        try:
            point = sp.lambdify(list(variables), c, "math")
            break
        except Exception:  # noqa: BLE001 - lambdify of unusual nodes; lower values are optional
            continue

    def upper(b: list[Interval]) -> float:
        best = _INF
        for enc in encs:
            try:
                hi = float(enc(b)[1][0, 0])
            except (UnsupportedExpression, ZeroDivisionError, OverflowError, ValueError):
                continue
            if hi == hi:
                best = min(best, hi)
        return best

    def value(pt: Sequence[float]) -> float:
        try:
            v = float(point(*pt))  # type: ignore[misc]
        except (ValueError, ZeroDivisionError, OverflowError, TypeError):
            return -_INF
        return v if v == v else -_INF

    def lower(b: list[Interval]) -> float:
        """A sampled value (midpoint and, in up to 3 dimensions, corners): only for stopping."""
        if point is None:
            return -_INF
        best = value([0.5 * (lo + hi) for lo, hi in b])
        if len(b) <= 3:
            for corner in itertools.product(*b):
                best = max(best, value(corner))
        return best

    widths0 = [max(hi - lo, 0.0) for lo, hi in box]
    box0 = [(float(lo), float(hi)) for lo, hi in box]
    lb = lower(box0)
    counter = itertools.count()
    heap = [(-upper(box0), 0, next(counter), box0)]
    for _ in range(max_splits):
        neg_ub, neg_depth, _, b = heapq.heappop(heap)
        ub = -neg_ub
        if ub <= lb + atol + rtol * abs(lb):
            return ub, lb
        rel = [(hi - lo) / w0 if w0 > 0 else 0.0 for (lo, hi), w0 in zip(b, widths0)]
        k = int(np.argmax(rel))
        if rel[k] <= _GIVE_UP_WIDTH:
            return (ub, lb) if math.isfinite(ub) else (_INF, lb)
        lo, hi = b[k]
        mid = 0.5 * (lo + hi)
        for part in ((lo, mid), (mid, hi)):
            child = list(b)
            child[k] = part
            lb = max(lb, lower(child))
            heapq.heappush(heap, (-upper(child), neg_depth - 1, next(counter), child))
    return -heap[0][0], lb


# ------------------------------------------------------------------ whole-space enclosures
#: ``exp``, ``atan`` and fractional powers behind the enclose callback, so that
#: ``exp(-inf) = 0`` and ``|atan| <= pi/2`` are used on infinite arguments, and so that a sum of
#: squares whose outward-rounded lower end is a denormal below 0 stays in the domain of ``sqrt``
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
            return (max(0.0, _arb_lo(pw(lo))), _INF if hi == _INF else _arb_hi(pw(hi)))
        return (0.0 if hi == _INF else max(0.0, _arb_lo(pw(hi))), _arb_hi(pw(lo)))
    if node.func == _ExpW:
        vlo = 0.0 if lo == -_INF else max(0.0, _arb_lo(arb(lo).exp()))
        vhi = _INF if hi == _INF else _arb_hi(arb(hi).exp())
        return (vlo, vhi)
    half_pi = arb.pi() / 2
    vlo = _arb_lo(-half_pi) if lo == -_INF else _arb_lo(arb(lo).atan())
    vhi = _arb_hi(half_pi) if hi == _INF else _arb_hi(arb(hi).atan())
    return (vlo, vhi)


# ----------------------------------------------------------------------- rigorous scalars
# _arb_lo / _arb_hi: float ends of an Arb ball moved one ulp outward (drip_cert.numerics.rounding)


def _sub_up(hi: float, lo: float) -> float:
    return _arb_hi(arb(hi) - arb(lo))


def _sqrt_sum_sq_up(values: Sequence[float]) -> float:
    """Rigorous upper bound of ``sqrt(sum v^2)``."""
    acc = arb(0)
    for v in values:
        acc += arb(float(v)) ** 2
    return _arb_hi(acc.sqrt())


def _spectral_upper(M: np.ndarray) -> float:
    """Rigorous upper bound of ``||M||_2`` for an entrywise nonnegative float matrix.

    ``||M||_2^2 = rho(M^T M)`` and, for a nonnegative matrix ``B`` and any positive vector ``v``,
    ``rho(B) <= max_i (B v)_i / v_i`` (Collatz-Wielandt: ``diag(v)^{-1} B diag(v)`` has these row
    sums). ``v`` is the numerical top right singular vector (made positive); the products are in
    ball arithmetic. The Frobenius norm is a second bound; the smaller one is returned.
    """
    M = np.asarray(M, dtype=float)
    if not np.any(M):
        return 0.0
    fro = _sqrt_sum_sq_up(M.ravel().tolist())
    _, _, vt = np.linalg.svd(M)
    v = np.abs(vt[0])
    v = np.maximum(v, 1e-8 * float(v.max()))
    rows, cols = M.shape
    Ma = [[arb(float(M[i, j])) for j in range(cols)] for i in range(rows)]
    va = [arb(float(x)) for x in v]
    Mv = [sum((Ma[i][j] * va[j] for j in range(cols)), arb(0)) for i in range(rows)]
    ratios = []
    for j in range(cols):
        btv = sum((Ma[i][j] * Mv[i] for i in range(rows)), arb(0))
        ratios.append(_arb_hi(btv / va[j]))
    best = max(ratios)
    cw = _arb_hi(arb(best).sqrt())
    return min(fro, cw)


def _rational(x: float | sp.Rational, what: str) -> sp.Rational:
    r = sp.Rational(str(x)) if isinstance(x, float) else sp.Rational(x)
    if r <= 0:
        raise ValueError(f"{what} must be positive, got {x!r}")
    return r


def _sum_sq(entries: Sequence[sp.Expr]) -> sp.Expr:
    """``||entries||^2``: branch and bound runs on squares (smooth, so the mean-value form
    applies; ``sqrt(g^2)`` would become the non-smooth ``|g|``) and takes the root at the end."""
    return sum((e**2 for e in entries), sp.Integer(0))


def _sqrt_up(x: float) -> float:
    """Rigorous upper bound of ``sqrt(x)`` for ``x >= 0`` (``inf`` stays ``inf``)."""
    if not math.isfinite(x):
        return _INF
    return _arb_hi(arb(max(x, 0.0)).sqrt())


# -------------------------------------------------------------------------- route (c)
def _numeric(ctx: _Context, evaluate: Evaluator | None) -> Evaluator | None:
    if evaluate is not None:
        return evaluate
    args = [ctx.t if ctx.t is not None else sp.Dummy("t"), *ctx.xs]
    try:
        fns = [
            sp.lambdify(args, e, modules=[{"Max": np.maximum, "Min": np.minimum}, "numpy"])
            for e in ctx.entries
        ]
    except Exception:  # noqa: BLE001 - e.g. undefined functions (learned blocks)
        return None

    def call(tt: float, X: np.ndarray) -> np.ndarray:
        cols = [np.broadcast_to(np.asarray(f(tt, *X.T), dtype=float), (len(X),)) for f in fns]
        return np.stack(cols, axis=1)

    try:
        call(0.0, np.zeros((2, len(ctx.xs))))
    except Exception:  # noqa: BLE001
        return None
    return call


def _times(ctx: _Context) -> np.ndarray:
    if ctx.t is None:
        return np.array([ctx.t_range[0]])
    return np.linspace(ctx.t_range[0], ctx.t_range[1], _ESTIMATE_TIMES)


def _nan_note(fn: Evaluator, ctx: _Context, X: np.ndarray) -> str:
    with np.errstate(all="ignore"):
        vals = fn(float(ctx.t_range[0]), X)
    bad = int(np.sum(~np.all(np.isfinite(vals.reshape(len(X), -1)), axis=1)))
    if bad:
        return (
            f"; F is not finite (undefined) at {bad} of {len(X)} sampled points, which "
            "were skipped: the assumption asks for F defined on all of R^n"
        )
    return ""


def _estimate_note(extra: str) -> str:
    return (
        "no sound route applies (neither bounded over all of R^n nor radial): sampled over "
        "spheres of radii "
        + ", ".join(f"{r:g}" for r in SAMPLE_RADII)
        + f" ({SAMPLES_PER_RADIUS} directions each, seed {SAMPLE_SEED}); estimate, not a "
        "bound" + extra
    )


def _unevaluable(name: str, source: str) -> Quantity:
    """The constant when no sound route applies and ``F`` cannot be evaluated either."""
    return Quantity(
        name,
        math.nan,
        How.ESTIMATE,
        source,
        "no sound route applies and F cannot be evaluated numerically; give the "
        "constant in [constants]",
    )


def _growth_estimate(
    ctx: _Context, p: sp.Rational, name: str, source: str, evaluate: Evaluator | None
) -> Quantity:
    fn = _numeric(ctx, evaluate)
    if fn is None:
        return _unevaluable(name, source)
    n = len(ctx.xs)
    X = sample_points(n)
    radii = np.linalg.norm(X, axis=1)
    best = 0.0
    per_radius: dict[float, float] = {}
    with np.errstate(all="ignore"):
        for tt in _times(ctx):
            vals = fn(float(tt), X).reshape(len(X), -1)
            ratio = np.linalg.norm(vals, axis=1) / (1.0 + radii**2) ** (float(p) / 2.0)
            for r in SAMPLE_RADII:
                sel = np.isclose(radii, r, rtol=1e-9, atol=1e-12)
                if np.any(sel):
                    m = float(np.nanmax(ratio[sel]))
                    per_radius[r] = max(per_radius.get(r, 0.0), m)
            best = max(best, float(np.nanmax(ratio)))
    extra = _nan_note(fn, ctx, X)
    r_top, r_prev = SAMPLE_RADII[-1], SAMPLE_RADII[-2]
    if per_radius.get(r_top, 0.0) > 10.0 * max(per_radius.get(r_prev, 0.0), 1e-300):
        extra += (
            "; the sampled ratio still grows tenfold from radius "
            f"{r_prev:g} to {r_top:g}: the constant is likely infinite"
        )
    return Quantity(name, best, How.ESTIMATE, source, _estimate_note(extra) + ctx.time_note())


def _holder_estimate(
    ctx: _Context, exponent: float, name: str, source: str, evaluate: Evaluator | None
) -> Quantity:
    fn = _numeric(ctx, evaluate)
    if fn is None:
        return _unevaluable(name, source)
    n = len(ctx.xs)
    rng = np.random.default_rng(SAMPLE_SEED + 1)
    A = sample_points(n)
    radii = np.linalg.norm(A, axis=1)
    top = np.isclose(radii, SAMPLE_RADII[-1])
    prev = np.isclose(radii, SAMPLE_RADII[-2])
    best, best_top, best_prev = 0.0, 0.0, 0.0
    by_scale = []
    with np.errstate(all="ignore"):
        for scale in _HOLDER_SCALES:
            d = rng.normal(size=A.shape)
            d /= np.linalg.norm(d, axis=1, keepdims=True)
            B = A + scale * d
            s_best = 0.0
            for k, (P, Q) in enumerate(((A, B), (np.zeros_like(A), scale * d))):
                dist = np.linalg.norm(P - Q, axis=1)
                for tt in _times(ctx):
                    num = np.linalg.norm(
                        (fn(float(tt), P) - fn(float(tt), Q)).reshape(len(P), -1), axis=1
                    )
                    ratio = num / dist**exponent
                    if np.any(np.isfinite(ratio)):
                        s_best = max(s_best, float(np.nanmax(ratio)))
                    if k == 0:
                        best_top = max(best_top, float(np.nanmax(ratio[top], initial=0.0)))
                        best_prev = max(best_prev, float(np.nanmax(ratio[prev], initial=0.0)))
            by_scale.append(s_best)
            best = max(best, s_best)
    kind = "Lipschitz" if exponent == 1.0 else "1/2-Hoelder"
    extra = (
        _nan_note(fn, ctx, A)
        + f"; {kind} ratio over point pairs at distances "
        + ", ".join(f"{s:g}" for s in _HOLDER_SCALES)
    )
    if (
        by_scale[-1] > 10.0 * max(by_scale[-3], 1e-300)
        or by_scale[0] > 10.0 * max(by_scale[2], 1e-300)
        or best_top > 10.0 * max(best_prev, 1e-300)
    ):
        extra += (
            "; the sampled ratio keeps growing at the extreme distances or radii: the "
            "constant is likely infinite"
        )
    return Quantity(name, best, How.ESTIMATE, source, _estimate_note(extra) + ctx.time_note())
