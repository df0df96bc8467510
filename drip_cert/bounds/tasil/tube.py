"""The TaSIL sure bound along the expert's reachable tube, on a finite horizon.

Implements docs/math/tasil.md section 3.10 (a construction of this project). With the learned loop
contracting at ``lambda_IL`` on all of ``R^n`` and the expert loop at ``lambda*`` on all of
``R^n`` (both Euclidean, autonomous), every expert trajectory from the support ``K`` obeys

    ||x*(t, xi) - c|| <= e^{-lambda* t} R0 + phi (1 - e^{-lambda* t}) / lambda* =: r(t)  (3.10a)

(``R0 = max_K ||xi - c||``, ``phi >= ||F*(c)||``, any centre ``c``), so ``x*(t, xi)`` lies in
``S_t = S cap B(c, r(t))`` (``S`` a proved invariant box). The comparison bound of section 3.7 with
the time-resolved sup ``H(s) = sup_{S_s} ||pi_IL - pi*||`` gives

    gap(t) <= int_0^t e^{-lambda_IL (t - s)} ||g||_2 H(s) ds,                             (3.10b)

evaluated on a grid ``0 = t_0 < ... < t_K = T`` with ``H`` bounded on each interval by its sup
over ``S cap B(c, max(r(t_k), r(t_{k+1})))`` (r is monotone). The bound ``b`` moves monotonically
between its grid values on each interval, so ``max_k b(t_k)`` is the exact max over ``[0, T]`` of
the piecewise bound. Every closed form is evaluated in Arb and rounded up.

Public surface
--------------
* :func:`horizon_factor_up` -- ``(1 - e^{-lambda T}) / lambda``, rounded up.
* :func:`tube_radii_up` -- (3.10a) on a grid, rounded up.
* :func:`time_resolved_gap_up` -- (3.10b) for a piecewise-constant ``H``, rounded up.
* :class:`TubeBound`, :func:`tube_bound` -- the bound for a system, with its pieces;
  :func:`expert_tube_bound` -- the same after checking its hypotheses (certificate assembly).
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from dataclasses import dataclass, field
from typing import Any

import numpy as np
from flint import arb

from drip_cert.analysis.contraction.learned_loop import sup_policy_difference
from drip_cert.analysis.networks.block_enclosure import block_enclose_callback
from drip_cert.errors import SpecError
from drip_cert.numerics.bnb import maximize
from drip_cert.numerics.interval import MatrixEnclosure, UnsupportedExpression, enclose_expr
from drip_cert.numerics.rounding import (
    add_up_np,
    arb_hi,
    div_up,
    mul_up,
    norm2_up_np,
    sub_down_np,
    sub_up_np,
    sum_up,
)
from drip_cert.provenance import json_float

__all__ = [
    "TUBE_INTERVALS",
    "TUBE_MAX_INTERVALS",
    "TUBE_DECAY",
    "NEWTON_STEPS",
    "BOX_RATE_MAX_BOXES",
    "BOX_RATE_RTOL",
    "BoxTube",
    "TubeBound",
    "weighted_inf_rate",
    "box_tubes",
    "horizon_factor_up",
    "tube_radii_up",
    "time_resolved_gap_up",
    "expert_centre",
    "tube_bound",
    "expert_tube_bound",
]

#: fewest intervals of the uniform time grid of (3.10b): each costs one branch and bound of
#: sup ||pi_IL - pi*|| over the interval's set (a count of work, the same on every machine).
#: 20: on the paper example (lambda* T = 1) the staircase of H costs 7 % of rho_TaSIL at 10
#: intervals against 20 (2.20e-6 -> 2.05e-6 proved; 1.90e-6 for the sampled continuous H)
TUBE_INTERVALS = 20
#: most intervals: the grid takes ceil(lambda* T / log(TUBE_DECAY)) intervals within these two
#: bounds, so that r(t) falls by at most that factor per interval (the staircase of H follows it)
TUBE_MAX_INTERVALS = 24
#: largest decay of the tube's radius over one grid interval, e^{lambda* h} (see above)
TUBE_DECAY = 1.5
#: work budget (sub-boxes, a count of work) of the branch and bound of the expert's weighted
#: inf-norm log norm over S (section 3.11): a constant Jacobian needs one box
BOX_RATE_MAX_BOXES = 200
#: its relative tolerance: a rate 5 % below the true one widens the box tube by at most that much
#: in the exponent
BOX_RATE_RTOL = 0.05
#: Newton steps for the numerical equilibrium used as the tube's centre (any centre is sound:
#: phi = ||F*(c)|| is enclosed rigorously, a poor centre only widens the tube)
NEWTON_STEPS = 20


def _check_rate(name: str, lam: float) -> None:
    if not (math.isfinite(lam) and lam > 0):
        raise SpecError(f"{name} = {lam!r} must be a finite rate > 0", field=name)


def horizon_factor_up(lam: float, T: float) -> float:
    """``(1 - e^{-lambda T}) / lambda`` rounded up (Arb), ``<= min(T, 1/lambda)``."""
    _check_rate("lambda", lam)
    if not (math.isfinite(T) and T >= 0):
        raise SpecError(f"horizon T = {T!r} must be finite and >= 0", field="horizon")
    a = arb(lam)
    return arb_hi(-((-a * arb(T)).expm1()) / a)


def tube_radii_up(
    R0: float, phi: float, lam_star: float, times: Sequence[float] | np.ndarray
) -> np.ndarray:
    """(3.10a) ``e^{-lambda* t} R0 + phi (1 - e^{-lambda* t}) / lambda*`` at ``times``, rounded
    up."""
    _check_rate("lambda*", lam_star)
    a = arb(lam_star)
    out = []
    for t in times:
        e = (-a * arb(float(t))).exp()
        out.append(arb_hi(e * arb(R0) + arb(phi) * (1 - e) / a))
    return np.asarray(out, dtype=float)


def time_resolved_gap_up(
    times: Sequence[float] | np.ndarray, H: Sequence[float], lam_il: float, g_norm: float
) -> np.ndarray:
    """(3.10b) at the grid ``times`` for ``H`` constant (``H[k]``) on ``[t_k, t_{k+1}]``, rounded
    up.

    ``b(t_0) = 0``, ``b(t_{k+1}) = e^{-lambda_IL h_k} b(t_k) + ||g|| H_k (1 - e^{-lambda_IL h_k}) /
    lambda_IL`` with ``h_k = t_{k+1} - t_k`` (exact for the piecewise-constant integrand). Between
    grid points ``b`` is a convex combination of ``b(t_k)`` and ``||g|| H_k / lambda_IL`` moving
    monotonically, so ``max_k b(t_k)`` is its max over ``[t_0, t_K]``.
    """
    _check_rate("lambda_IL", lam_il)
    ts = np.asarray(times, dtype=float)
    if ts.ndim != 1 or len(H) != ts.size - 1 or np.any(np.diff(ts) <= 0):
        raise SpecError("times must increase and H have one value per interval", field="times")
    a, G = arb(lam_il), arb(g_norm)
    b = arb(0)
    out = [0.0]
    for k, h in enumerate(np.diff(ts)):
        e = (-a * arb(float(h))).exp()
        b = e * b + G * arb(float(H[k])) * (1 - e) / a
        out.append(arb_hi(b))
    return np.asarray(out, dtype=float)


def _mu_inf_w_up(lo: np.ndarray, hi: np.ndarray, w: np.ndarray) -> float:
    """Upper bound of ``mu_inf(W J W^{-1}) = max_i (J_ii + sum_{j != i} |J_ij| w_i / w_j)``
    for every ``J`` in the interval matrix ``[lo, hi]`` (``W = diag(w)``, ``w > 0``; (3.11b)),
    every product and sum rounded up."""
    n = lo.shape[0]
    rows = []
    for i in range(n):
        terms = [float(hi[i, i])]
        for j in range(n):
            if j != i:
                mag = max(abs(float(lo[i, j])), abs(float(hi[i, j])))
                terms.append(mul_up(mag, div_up(float(w[i]), float(w[j]))))
        rows.append(sum_up(terms))
    return max(rows)


def weighted_inf_rate(s: Any, S: np.ndarray, w: np.ndarray) -> float | None:
    """A rate ``lambda_W > 0`` with ``mu_inf(W J*(x) W^{-1}) <= -lambda_W`` for every ``x`` in the
    box ``S`` (``W = diag(w)``, ``J*`` the expert loop's Jacobian), or ``None``.

    Branch and bound (:data:`BOX_RATE_MAX_BOXES` sub-boxes, a count of work) of the interval
    Jacobian's weighted row sums (:func:`_mu_inf_w_up`, entries by
    :class:`~drip_cert.numerics.interval.MatrixEnclosure`); ``None`` when the bound is not
    negative, the loop depends on t, or an expression cannot be enclosed.
    """
    J = s.closed_loop_jacobian("expert")
    if J.has(s.t):
        return None
    n = len(s.states)
    w = np.asarray(w, dtype=float)
    enclose = block_enclose_callback(s.blocks) if s.blocks else None
    try:
        menc = MatrixEnclosure(J, s.states, enclose)
        menc(S)
    except UnsupportedExpression:
        return None
    j_num = s.lower(J)

    def upper(B: np.ndarray) -> float:
        lo, hi = menc(B)
        return _mu_inf_w_up(lo.reshape(n, n), hi.reshape(n, n), w)

    def value(x: np.ndarray) -> float:
        M = np.asarray(j_num(0.0, x), dtype=float).reshape(n, n) * (w[:, None] / w[None, :])
        d = np.diag(M)
        return float(np.max(d + np.sum(np.abs(M), axis=1) - np.abs(d)))

    res = maximize(S, upper, value, rtol=BOX_RATE_RTOL, max_boxes=BOX_RATE_MAX_BOXES)
    mu = res.upper
    return -mu if math.isfinite(mu) and mu < 0 else None


@dataclass(frozen=True)
class BoxTube:
    """The expert's tube in a weighted inf-norm (docs/math/tasil.md section 3.11).

    ``||W (x*(t, xi) - c)||_inf <= r(t)`` with ``r`` of (3.10a) for the rate ``lam`` of
    :func:`weighted_inf_rate`, ``R0 >= max_K ||W (xi - c)||_inf`` and ``phi >= ||W F*(c)||_inf``:
    the box ``|x_i - c_i| <= r(t) / w_i``.
    """

    weights: tuple[float, ...]
    lam: float
    R0: float
    phi: float
    radius: tuple[float, ...]

    def half_widths(self, k: int) -> np.ndarray:
        """``max(r(t_k), r(t_{k+1})) / w``, rounded up: the box of grid interval ``k``."""
        rk = max(self.radius[k], self.radius[k + 1])
        return np.asarray([div_up(rk, w) for w in self.weights], dtype=float)

    def to_dict(self) -> dict[str, Any]:
        """JSON-ready."""
        return {
            "weights": [json_float(w) for w in self.weights],
            "rate": json_float(self.lam),
            "R0": json_float(self.R0),
            "phi": json_float(self.phi),
            "radius": [json_float(r) for r in self.radius],
        }


def box_tubes(
    s: Any, S: np.ndarray, c: np.ndarray, field_mag: np.ndarray, times: np.ndarray
) -> list[BoxTube]:
    """The box tubes of section 3.11 for the weights ``1`` and ``1 / half-width of the support``
    (when the support is not a cube), each where its rate is proved on the hull of ``S`` and
    ``c`` (a convex set holding every expert trajectory and the centre).

    ``field_mag``: rigorous upper bounds of ``|F*_i(c)|``.
    """
    support = np.asarray(s.support, dtype=float)
    hull = np.stack([np.minimum(S[:, 0], c), np.maximum(S[:, 1], c)], axis=1)
    half = 0.5 * (support[:, 1] - support[:, 0])
    cands = [np.ones(len(c))]
    if np.all(half > 0) and not np.allclose(half, half[0]):
        cands.append(1.0 / half)
    # |xi_i - c_i| <= far_i on K, every difference rounded up
    far = np.maximum(np.maximum(sub_up_np(support[:, 1], c), sub_up_np(c, support[:, 0])), 0.0)
    out = []
    for w in cands:
        lam = weighted_inf_rate(s, hull, w)
        if lam is None:
            continue
        R0 = max(mul_up(float(wi), float(fi)) for wi, fi in zip(w, far))
        phi = max(mul_up(float(wi), float(mi)) for wi, mi in zip(w, field_mag))
        radius = tube_radii_up(R0, phi, lam, times)
        out.append(
            BoxTube(
                weights=tuple(float(x) for x in w),
                lam=lam,
                R0=R0,
                phi=phi,
                radius=tuple(float(r) for r in radius),
            )
        )
    return out


@dataclass(frozen=True)
class TubeBound:
    """The sure TaSIL bound (3.10b) along the expert's tube (docs/math/tasil.md section 3.10).

    Attributes
    ----------
    times
        The grid ``t_0 = 0 < ... < t_K = T``.
    radius
        ``r(t_k)`` of (3.10a), rounded up.
    H
        Per interval, the sound sup of ``||pi_IL - pi*||`` over ``S cap B(c, max r)``.
    rho_t
        ``rho_TaSIL(t_k)``: (3.10b) at the grid, rounded up.
    rho
        ``max_k rho_t``: the sure bound of ``sup_{t <= T} gap`` for every initial state of the
        support.
    centre, phi, R0
        The tube's centre, the bound on ``||F*(c)||`` and ``max_K ||xi - c||``.
    lam_star, lam_il, g_norm
        The rates and ``sup||g||_2`` used.
    H_notes
        Per interval, how ``H`` was obtained (the branch and bound's note: its box count and
        stop reason, or that the sup over all of ``S`` was reused).
    box_tubes
        The weighted inf-norm tubes of section 3.11 that cut the sets (empty when none is
        proved).
    sets
        Per interval, the box ``S`` cut by the box tubes over which ``H`` is the sup (with the
        ball ``B(c, max r)`` where it does not cover the box).
    inputs
        The ``Quantity`` sups behind ``H`` (their labels carry into the TaSIL check).
    """

    times: tuple[float, ...]
    radius: tuple[float, ...]
    H: tuple[float, ...]
    rho_t: tuple[float, ...]
    rho: float
    centre: tuple[float, ...]
    phi: float
    R0: float
    lam_star: float
    lam_il: float
    g_norm: float
    H_notes: tuple[str, ...]
    box_tubes: tuple[BoxTube, ...] = ()
    sets: tuple[tuple[tuple[float, float], ...], ...] = ()
    inputs: tuple[Any, ...] = field(default=(), compare=False)

    def to_dict(self) -> dict[str, Any]:
        """JSON-ready: every attribute (lists for the grids)."""
        return {
            "times": [json_float(t) for t in self.times],
            "radius": [json_float(r) for r in self.radius],
            "H": [json_float(h) for h in self.H],
            "rho_t": [json_float(r) for r in self.rho_t],
            "rho": json_float(self.rho),
            "centre": [json_float(c) for c in self.centre],
            "phi": json_float(self.phi),
            "R0": json_float(self.R0),
            "lambda_expert": json_float(self.lam_star),
            "lambda_learned": json_float(self.lam_il),
            "g_norm": json_float(self.g_norm),
            "H_notes": list(self.H_notes),
            "box_tubes": [b.to_dict() for b in self.box_tubes],
            "sets": [[[json_float(a), json_float(b)] for a, b in box] for box in self.sets],
            "source": "docs/math/tasil.md sections 3.10, 3.11",
        }


def expert_centre(s: Any, S: np.ndarray) -> tuple[np.ndarray, float] | None:
    """A centre ``c`` (a numerical equilibrium of the expert loop near the centre of ``S``) and a
    rigorous upper bound of ``||F*(c)||_2``; ``None`` for a loop that depends on t."""
    got = _centre_field(s, S)
    if got is None:
        return None
    c, mags = got
    phi = float(norm2_up_np(mags))
    return (c, phi) if math.isfinite(phi) else None


def _centre_field(s: Any, S: np.ndarray) -> tuple[np.ndarray, np.ndarray] | None:
    """The centre of :func:`expert_centre` and rigorous upper bounds of ``|F*_i(c)|``."""

    F = s.closed_loop("expert")
    if F.has(s.t):
        return None
    f_num, j_num = s.lower(F), s.lower(s.closed_loop_jacobian("expert"))
    c = 0.5 * (S[:, 0] + S[:, 1])
    for _ in range(NEWTON_STEPS):
        try:
            step = np.linalg.solve(np.asarray(j_num(0.0, c), dtype=float), f_num(0.0, c))
        except np.linalg.LinAlgError:
            break
        nxt = c - np.asarray(step, dtype=float).reshape(-1)
        if not np.all(np.isfinite(nxt)):
            break
        c = nxt
    enclose = block_enclose_callback(s.blocks) if s.blocks else None
    pt = np.stack([c, c], axis=1)
    mags = []
    for e in F:
        lo, hi = enclose_expr(e, s.states, pt, enclose)
        mags.append(max(abs(lo), abs(hi)))
    return c, np.asarray(mags, dtype=float)


def tube_bound(
    s: Any,
    S: np.ndarray | None,
    lam_star: float,
    lam_il: float,
    g_norm: float,
    sup_fn: Any,
    H_full: float | None = None,
    intervals: int | None = None,
    boxes: bool = True,
) -> TubeBound | None:
    """(3.10b) for system ``s`` whose expert trajectories from the support stay in the box ``S``.

    ``sup_fn(box, ball)`` returns a sound ``Quantity`` bounding ``sup ||pi_IL - pi*||`` over
    ``box cap B(ball)`` (``ball = (centre, radius)`` or ``None`` for the box alone, see
    :func:`~drip_cert.analysis.contraction.learned_loop.sup_policy_difference`); ``H_full`` the sup
    over all
    of ``S`` when already known (reused where the set is all of ``S``). The caller guarantees the
    hypotheses: both rates proved on all ``x``, all ``t``, the expert loop autonomous, ``S``
    proved to hold every expert trajectory from the support on ``[0, T]``. Without ``S`` the
    tube itself gives one: the box around ``B(c, max_t r(t))`` (r moves monotonically from ``R0``
    towards ``phi / lambda*``). With ``boxes`` the set of each interval is also cut by the
    weighted inf-norm tubes of section 3.11 (:func:`box_tubes`) where their rates are proved on
    ``S``. ``None`` when no centre is found.
    """
    support = np.asarray(s.support, dtype=float)
    cen = _centre_field(s, support if S is None else S)
    if cen is None:
        return None
    c, mags = cen
    phi = float(norm2_up_np(mags))
    if not math.isfinite(phi):
        return None
    far = np.maximum(np.maximum(sub_up_np(support[:, 1], c), sub_up_np(c, support[:, 0])), 0.0)
    R0 = float(norm2_up_np(far))
    if S is None:
        big = float(np.max(tube_radii_up(R0, phi, lam_star, [0.0, float(s.horizon)])))
        S = np.stack([sub_down_np(c, big), add_up_np(c, big)], axis=1)
        H_full = None
    if intervals is None:
        need = math.ceil(lam_star * float(s.horizon) / math.log(TUBE_DECAY))
        intervals = min(TUBE_MAX_INTERVALS, max(TUBE_INTERVALS, need))
    times = np.linspace(0.0, float(s.horizon), intervals + 1)
    radius = tube_radii_up(R0, phi, lam_star, times)
    tubes = box_tubes(s, S, c, mags, times) if boxes else []
    H: list[float] = []
    notes: list[str] = []
    qs: list[Any] = []
    sets: list[tuple[tuple[float, float], ...]] = []
    for k in range(intervals):
        rk = float(max(radius[k], radius[k + 1]))
        box = S.copy()
        for tb in tubes:
            hw = tb.half_widths(k)
            box[:, 0] = np.maximum(box[:, 0], sub_down_np(c, hw))
            box[:, 1] = np.minimum(box[:, 1], add_up_np(c, hw))
        sets.append(tuple((float(a), float(b)) for a, b in box))
        if np.any(box[:, 0] > box[:, 1]):  # no expert trajectory is there: nothing to bound
            H.append(0.0)
            notes.append("the tubes do not meet S: empty")
            continue
        cover = float(norm2_up_np(np.maximum(sub_up_np(box[:, 1], c), sub_up_np(c, box[:, 0]))))
        ball = None if rk >= cover else (c, rk)
        if H_full is not None and ball is None and np.array_equal(box, S):
            H.append(H_full)
            notes.append("the set is all of S: the sup over S")
            continue
        q = sup_fn(box, ball)
        if q is None or not math.isfinite(q.value):
            return None
        H.append(min(q.value, H_full) if H_full is not None else q.value)
        notes.append(q.note)
        qs.append(q)
    rho_t = time_resolved_gap_up(times, H, lam_il, g_norm)
    return TubeBound(
        times=tuple(float(t) for t in times),
        radius=tuple(float(r) for r in radius),
        H=tuple(H),
        rho_t=tuple(float(r) for r in rho_t),
        rho=float(np.max(rho_t)),
        centre=tuple(float(x) for x in c),
        phi=phi,
        R0=R0,
        lam_star=lam_star,
        lam_il=lam_il,
        g_norm=g_norm,
        H_notes=tuple(notes),
        box_tubes=tuple(tubes),
        sets=tuple(sets),
        inputs=tuple(qs),
    )


def expert_tube_bound(
    s: Any, S: np.ndarray | None, r: Any, rl: Any, g_norm: Any, uniform_h0: Any
) -> TubeBound | None:
    """:func:`tube_bound` when its hypotheses are proved, else ``None``.

    ``r``, ``rl``: the expert's and the learned loop's Euclidean
    :class:`~drip_cert.analysis.contraction.rate.ContractionResult`; each must hold, be proved (not
    an
    estimate), on all ``x`` and (the expert's) for ``t`` in ``[0, T]``. ``g_norm``: the
    ``Quantity`` ``sup||g||_2``; ``S`` a box proved to hold the expert trajectories (or
    ``None``: the tube's own ball) and ``uniform_h0`` the sound sup over all of it (or ``None``).
    """

    for res in (r, rl):
        if not (res.holds and res.how.proved and res.scope.all_x and res.rate > 0):
            return None
    if not r.scope.covers_time(s.horizon):
        return None
    return tube_bound(
        s,
        None if S is None else np.asarray(S, dtype=float),
        float(r.rate),
        float(rl.rate),
        float(g_norm.value),
        lambda box, ball: sup_policy_difference(s, box, ball),
        H_full=None if uniform_h0 is None else float(uniform_h0.value),
    )
