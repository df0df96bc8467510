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
(c) otherwise: a sampled ESTIMATE over spheres of radii up to 1e6
    (:func:`drip_cert.numerics.sampling.growth_ratio_estimate` and
    :func:`~drip_cert.numerics.sampling.holder_estimate`), labelled "estimate, not a bound".

The field and the routes' building blocks are in :mod:`drip_cert.analysis.growth.field`, the
symbolic rewritings in :mod:`drip_cert.analysis.growth.rewrites`, the branch and bound of each
supremum in :mod:`drip_cert.analysis.growth.expr_sup`.

Time dependence: ``t`` is one more interval variable over ``t_range = (t0, T)``. The paper asks
for the constants for all ``t >= 0``; their supremum over ``[0, T]`` suffices for a certificate
on the horizon ``T``, and the notes say so.

Derivative-based bounds assume ``F`` continuous (true for expressions of the parser's whitelist
where they are defined); derivatives of ``Abs``/``Max``/``Min`` are the almost-everywhere ones,
which is enough for these Lipschitz functions, and a jump (``sign``, ``Heaviside``) differentiates
to a ``DiracDelta`` that no enclosure accepts, so no bound is claimed for it.
"""

from __future__ import annotations

import math
from collections.abc import Callable, Sequence

import numpy as np
import sympy as sp
from flint import arb

from drip_cert.analysis.growth.expr_sup import BNB_ATOL, BNB_MAX_SPLITS, BNB_RTOL
from drip_cert.analysis.growth.field import GrowthField
from drip_cert.analysis.growth.rewrites import rewritings, sum_sq
from drip_cert.numerics.rounding import arb_hi, arb_norm2_up
from drip_cert.numerics.sampling import (
    SAMPLE_RADII,
    SAMPLE_SEED,
    SAMPLES_PER_RADIUS,
    growth_ratio_estimate,
    holder_estimate,
)
from drip_cert.provenance import How, Quantity

__all__ = [
    "sup_bound",
    "growth_bound",
    "lipschitz_bound",
    "holder_half_bound",
    "BNB_RTOL",
    "BNB_ATOL",
    "BNB_MAX_SPLITS",
]

Evaluator = Callable[[float, np.ndarray], np.ndarray]
Route = tuple[float, str]  #: a sound bound and the note that says how it was obtained

_ESTIMATE_TIMES = 9  #: time points of [t0, T] sampled by the estimate route
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
    ctx = GrowthField.make(F, states, t, t_range)
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
        arb_norm2_up([max(-lo, hi) for lo, hi in enc]),
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
    ctx = GrowthField.make(F, states, t, t_range)
    tnote = ctx.time_note()
    if ctx.is_zero:
        return Quantity(name, 0.0, How.EXACT, source, "F = 0")
    if not ctx.depends_on_state:
        # the sup over a is attained at a = 0 (the denominator is >= 1 and equals 1 there)
        val, ok = ctx.sup_over_time(sum_sq(ctx.entries))
        if ok:
            how = How.EXACT if not ctx.depends_on_time else How.SOUND
            return Quantity(
                name, val, how, source, "F does not depend on the state: ||F|| at a = 0" + tnote
            )
    return _best_or_estimate(
        ctx,
        _growth_routes(ctx, p),
        name,
        source,
        lambda: _growth_est(ctx, p, name, source, evaluate),
    )


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
    ctx = GrowthField.make(F, states, t, t_range)
    return _regularity(ctx, 1.0, GrowthField.lipschitz_bounds, name, source, evaluate)


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
    ctx = GrowthField.make(F, states, t, t_range)
    return _regularity(ctx, 0.5, _holder_half_routes, name, source, evaluate)


# ----------------------------------------------------------------------------- the routes
def _growth_routes(ctx: GrowthField, p: sp.Rational) -> list[Route]:
    """Sound growth bounds (power ``p``) from the bounded, radial and Lipschitz routes."""
    bounds: list[Route] = []
    enc = ctx.whole_space_enclosures(ctx.entries)
    if enc is not None:
        M = arb_norm2_up([max(-lo, hi) for lo, hi in enc])
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
        head = [sum_sq(gs) / (1 + rho**2) ** p for gs in rewritings(prof)]
        tails = [(w**p * g.subs(rho, 1 / w)) for g in prof]
        tail = [sum_sq(gs) * (1 + w**2) ** (-p) for gs in rewritings(tails)]
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
                sum_sq([e.xreplace({x: 0 for x in ctx.xs}) for e in ctx.entries])
            )
            if ok:
                val = arb_norm2_up([f0, L])
                bounds.append(
                    (
                        val,
                        "Lipschitz route: ||F(a)|| <= ||F(0)|| + L ||a|| <= "
                        "sqrt(||F(0)||^2 + L^2) (1 + ||a||^2)^{1/2} (Cauchy-Schwarz), "
                        f"L <= {L:.6g}",
                    )
                )
    return bounds


def _holder_half_routes(ctx: GrowthField) -> list[Route]:
    """Sound 1/2-Hoelder bounds from the bounded route and the radial route."""
    bounds: list[Route] = []
    enc = ctx.whole_space_enclosures(ctx.entries)
    lips = ctx.lipschitz_bounds() if enc is not None else []
    if enc is not None and lips:
        lip = min(lips)[0]
        diam = arb_norm2_up([arb_hi(arb(hi) - arb(lo)) for lo, hi in enc])
        val = arb_hi((arb(lip) * arb(diam)).sqrt())
        bounds.append(
            (
                val,
                "bounded route: ||F(a)-F(b)|| <= min(L d, D), sup_d min(L d, D) / "
                f"sqrt(d) = sqrt(L D) with L <= {lip:.6g}, D <= {diam:.6g}",
            )
        )
    prof = ctx.radial_profile()
    if prof is not None:
        rho = ctx.rho
        val, msg = ctx.radial_norm_sup([2 * sp.sqrt(rho) * sp.diff(g, rho) for g in prof])
        if val < _INF:
            bounds.append(
                (
                    val,
                    "radial route: F = G(||a||), ||G'(s)|| <= c / (2 sqrt(s)) gives "
                    "||F(a)-F(b)|| <= c (sqrt(r2)-sqrt(r1)) <= c ||a-b||^{1/2}; "
                    "c = sup_s 2 sqrt(s) ||G'(s)|| (exact for G = C0 + C1 sqrt(r))" + msg,
                )
            )
    return bounds


def _regularity(
    ctx: GrowthField,
    exponent: float,
    routes: Callable[[GrowthField], list[Route]],
    name: str,
    source: str,
    evaluate: Evaluator | None,
) -> Quantity:
    """The Lipschitz (``exponent = 1``) or 1/2-Hoelder constant: 0 for a state-free field, else
    the best sound route, else the sampled estimate."""
    if not ctx.depends_on_state:
        return Quantity(name, 0.0, How.EXACT, source, "F does not depend on the state")
    return _best_or_estimate(
        ctx, routes(ctx), name, source, lambda: _holder_est(ctx, exponent, name, source, evaluate)
    )


def _best_or_estimate(
    ctx: GrowthField,
    bounds: list[Route],
    name: str,
    source: str,
    estimate: Callable[[], Quantity],
) -> Quantity:
    """The smallest sound bound (labelled ``sound``), or the estimate when no route applies."""
    if bounds:
        val, how_note = min(bounds)
        return Quantity(name, val, How.SOUND, source, how_note + ctx.time_note())
    return estimate()


def _rational(x: float | sp.Rational, what: str) -> sp.Rational:
    r = sp.Rational(str(x)) if isinstance(x, float) else sp.Rational(x)
    if r <= 0:
        raise ValueError(f"{what} must be positive, got {x!r}")
    return r


# -------------------------------------------------------------------------- route (c)
def _numeric(ctx: GrowthField, evaluate: Evaluator | None) -> Evaluator | None:
    """A batched evaluator of ``vec F``: the caller's, else ``lambdify``, else ``None``."""
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


def _times(ctx: GrowthField) -> np.ndarray:
    if ctx.t is None:
        return np.array([ctx.t_range[0]])
    return np.linspace(ctx.t_range[0], ctx.t_range[1], _ESTIMATE_TIMES)


def _estimate(ctx: GrowthField, value: float, diagnostics: str, name: str, source: str):
    note = (
        "no sound route applies (neither bounded over all of R^n nor radial): sampled over "
        "spheres of radii "
        + ", ".join(f"{r:g}" for r in SAMPLE_RADII)
        + f" ({SAMPLES_PER_RADIUS} directions each, seed {SAMPLE_SEED}); estimate, not a "
        "bound" + diagnostics + ctx.time_note()
    )
    return Quantity(name, value, How.ESTIMATE, source, note)


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


def _growth_est(
    ctx: GrowthField, p: sp.Rational, name: str, source: str, evaluate: Evaluator | None
) -> Quantity:
    fn = _numeric(ctx, evaluate)
    if fn is None:
        return _unevaluable(name, source)
    est = growth_ratio_estimate(fn, len(ctx.xs), float(p), _times(ctx))
    return _estimate(ctx, est.value, est.diagnostics(), name, source)


def _holder_est(
    ctx: GrowthField, exponent: float, name: str, source: str, evaluate: Evaluator | None
) -> Quantity:
    fn = _numeric(ctx, evaluate)
    if fn is None:
        return _unevaluable(name, source)
    est = holder_estimate(fn, len(ctx.xs), exponent, _times(ctx))
    return _estimate(ctx, est.value, est.diagnostics(), name, source)
