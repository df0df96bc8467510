"""A forward-invariant ball inside the region where a contraction rate is proved.

A rate proved only on a box ``B`` (interval branch and bound) says nothing about trajectories
that leave ``B``. What the certificate needs is a set that the trajectories provably never leave.
This module proves one from the rate itself.

Proposition (this project's derivation). Let ``F(t, x)`` be the closed-loop vector field,
``B`` a closed box (convex) with ``mu_2(D_x F(t, x)) <= -lambda < 0`` for all ``x in B`` and
``t in [0, T]``, ``x_0 in B`` a point with ``sup_{t <= T} ||F(t, x_0)|| <= eps``, and
``r >= eps / lambda``. If the closed ball ``S = {||x - x_0|| <= r}`` lies in the interior of
``B``, then every solution starting in ``S`` stays in ``S`` on ``[0, T]``.

Proof. For ``x in B`` the segment ``[x_0, x]`` lies in ``B``, so by the mean-value form of the
log-norm bound (DRIP eq. (6); Davydov-Jafarpour-Bullo 2022, Thm 29)
``(x - x_0)^T (F(t, x) - F(t, x_0)) <= -lambda ||x - x_0||^2`` and, with ``e = x - x_0``,
``D^+ ||e|| <= -lambda ||e|| + ||F(t, x_0)|| <= -lambda ||e|| + eps`` while ``x in B``. The
comparison lemma (Khalil, Lemma 3.4) gives ``||e(t)|| <= max(||e(0)||, eps / lambda) <= r``
for as long as the solution stays in ``B``; since ``S`` lies in the interior of ``B``, the first
exit time from ``B`` would find the solution in ``S``, in the interior: a contradiction. ∎

Corollary (tube). If moreover a second trajectory (the learned closed loop) is known to stay
within ``G`` of a trajectory in ``S`` for as long as both stay in ``B`` (a gap bound proved with
the rate on ``B``), and ``G < room := dist(S, boundary of B)``, then it never leaves ``B`` either
(same first-exit argument), so the gap bound holds on all of ``[0, T]``.

A second route proves a *box* ``S`` (the support, or a box between the support and ``B``)
forward invariant by Nagumo's theorem: for a Lipschitz field and a closed box, invariance holds iff
``F_i(t, x) <= 0`` on the face ``x_i = hi_i`` and ``F_i(t, x) >= 0`` on ``x_i = lo_i`` (the
tangent-cone condition); each face is checked by rigorous interval enclosure, bisected up to
:data:`FACE_SPLITS` times. This route needs no rate, only the field; the rate on ``B`` is then
used along segments inside the convex ``S``.

``room`` is computed with outward rounding (the distance rounded down, ``eps`` and ``r`` up); the
point ``x_0`` is found by a float root search (any point is valid; a near-equilibrium makes
``eps`` small), and ``eps`` is a rigorous interval enclosure of ``||F(t, x_0)||`` over the time
range.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Any

import numpy as np
import sympy as sp

from drip_cert.numerics.interval import UnsupportedExpression, enclose_expr
from drip_cert.numerics.rounding import add_up, div_up, down, sq_up, sqrt_up, sum_sq_up, up
from drip_cert.provenance import Scope

__all__ = ["InvariantSet", "best_invariant_set", "invariant_ball", "invariant_box"]

#: subintervals of the time range over which ||F(t, x_0)|| is enclosed (a t-dependent field)
TIME_PIECES = 64
#: largest number of sub-boxes per face of the Nagumo check (bisection budget)
FACE_SPLITS = 256


@dataclass(frozen=True)
class InvariantSet:
    """A forward-invariant set inside the box of the rate: the ball
    ``{||x - centre|| <= radius}`` (:func:`invariant_ball`) or a box (:func:`invariant_box`; then
    ``centre`` is empty and ``radius``, ``eps`` are NaN, the box is named in ``reason``).

    Attributes
    ----------
    proved
        Whether the set is proved forward invariant and to contain the support (``room > 0``).
    centre, radius
        The ball (``radius`` rounded up).
    eps
        Rigorous upper bound of ``sup_t ||F(t, centre)||``.
    room
        Distance from the set to the boundary of the box (rounded down; ``<= 0`` when the set
        does not fit). A trajectory that stays within ``G < room`` of one in the set never
        leaves the box.
    reason
        Why the proof holds or what failed.
    """

    proved: bool
    centre: tuple[float, ...]
    radius: float
    eps: float
    room: float
    reason: str

    def to_dict(self) -> dict[str, Any]:
        """JSON-ready dictionary."""
        return {
            "proved": self.proved,
            "centre": list(self.centre),
            "radius": self.radius,
            "eps": self.eps,
            "room": self.room,
            "reason": self.reason,
        }


def _near_equilibrium(F_num, x_start: np.ndarray) -> np.ndarray:
    """A point where ``F(0, x)`` is small (float root search from ``x_start``; any point is
    valid for the proof, a good one only makes ``eps`` small)."""
    from scipy.optimize import root  # scipy.optimize: keep off the API's import path

    try:
        sol = root(lambda z: np.asarray(F_num(z), dtype=float), x_start, method="hybr")
        z = np.asarray(sol.x, dtype=float)
        if np.all(np.isfinite(z)) and np.linalg.norm(F_num(z)) < np.linalg.norm(F_num(x_start)):
            return z
    except (ValueError, np.linalg.LinAlgError, FloatingPointError):
        pass
    return x_start


def invariant_ball(
    F: sp.MatrixBase,
    states: tuple[sp.Symbol, ...],
    t: sp.Symbol,
    lam: float,
    scope: Scope,
    support: np.ndarray,
    horizon: float,
    F_num,
    enclose=None,
) -> InvariantSet:
    """Prove a forward-invariant ball containing ``support`` inside ``scope.box``.

    Parameters
    ----------
    F
        The closed-loop vector field ``F(t, x)`` (sympy column).
    states, t
        State symbols and the time symbol.
    lam
        The contraction rate proved on ``scope`` (a rigorous lower bound, ``> 0``).
    scope
        Where the rate holds: a box (and possibly a time range covering ``[0, horizon]``).
    support
        ``(n, 2)`` support box of the initial law.
    horizon
        ``T``; the ball is invariant on ``[0, T]``.
    F_num
        ``F_num(x) -> F(0, x)`` in floats (for the root search only).
    enclose
        Interval callback for blocks (see :mod:`drip_cert.numerics.interval`).
    """
    support = np.asarray(support, dtype=float)
    n = support.shape[0]
    if scope.box is None:
        return InvariantSet(True, (0.0,) * n, math.inf, 0.0, math.inf, "the rate holds for all x")
    B = np.array(scope.box, dtype=float)
    if not (lam > 0 and math.isfinite(lam)):
        return InvariantSet(False, (), math.nan, math.nan, -math.inf, "no positive rate")
    if not scope.covers_time(horizon):
        return InvariantSet(
            False, (), math.nan, math.nan, -math.inf, f"the rate does not cover t in [0, {horizon}]"
        )
    x0 = _near_equilibrium(F_num, 0.5 * (support[:, 0] + support[:, 1]))
    x0 = np.clip(x0, B[:, 0], B[:, 1])
    # eps >= sup_t ||F(t, x0)||: enclose every component at the point x0 over pieces of [0, T]
    depends_t = any(e.has(t) for e in F)
    edges = np.linspace(0.0, horizon, TIME_PIECES + 1) if depends_t else np.array([0.0, 0.0])
    variables = [*states, t]
    eps2 = 0.0
    try:
        for a, b in zip(edges[:-1], edges[1:], strict=True):
            box = [(float(v), float(v)) for v in x0] + [(float(a), float(b))]
            mags = []
            for e in F:
                lo, hi = enclose_expr(e, variables, box, enclose)
                mags.append(max(abs(lo), abs(hi)))
            eps2 = max(eps2, sum_sq_up(mags))
    except UnsupportedExpression as exc:
        return InvariantSet(
            False, tuple(map(float, x0)), math.nan, math.nan, -math.inf, f"no enclosure: {exc}"
        )
    eps = sqrt_up(eps2)
    # radius: the farthest corner of the support from x0, and eps / lambda
    far2 = 0.0
    for i in range(n):
        # the differences are rounded to nearest: one ulp up bounds them
        d = up(max(abs(support[i, 0] - x0[i]), abs(support[i, 1] - x0[i])))
        far2 = add_up(far2, sq_up(d))
    r = max(sqrt_up(far2), div_up(eps, lam))
    room = math.inf
    for i in range(n):
        room = min(room, down(x0[i] - B[i, 0]), down(B[i, 1] - x0[i]))
    room = down(room - r)
    centre = tuple(float(v) for v in x0)
    if room > 0:
        return InvariantSet(
            True,
            centre,
            r,
            eps,
            room,
            f"the ball ||x - x0|| <= {r:.6g} around x0 = {_fmt(centre)} (sup_t ||F(t, x0)|| <= "
            f"{eps:.3g}, so r >= eps/lambda = {eps / lam:.3g}) contains the support and lies in "
            f"the box with room {room:.6g}: forward invariant (analysis/contraction/invariance.py)",
        )
    return InvariantSet(
        False,
        centre,
        r,
        eps,
        room,
        f"no forward-invariant set inside the box was found: the ball ||x - x0|| <= {r:.6g} "
        f"around x0 = {_fmt(centre)} that contains the support (and has r >= "
        f"sup_t ||F(t, x0)|| / lambda = {eps / lam:.3g}) does not fit in the box (short by "
        f"{-room:.3g}); enlarge [contraction] region so that it does",
    )


def _face_ok(expr, variables, box: list[tuple[float, float]], sign: int, enclose) -> bool:
    """``sign * expr <= 0`` on ``box`` (rigorous), bisecting the widest side when undecided."""
    stack = [box]
    budget = FACE_SPLITS
    while stack:
        b = stack.pop()
        lo, hi = enclose_expr(expr, variables, b, enclose)
        if (hi <= 0.0) if sign > 0 else (lo >= 0.0):
            continue
        if (lo > 0.0) if sign > 0 else (hi < 0.0):
            return False  # violated on the whole sub-box
        budget -= 1
        widths = [w[1] - w[0] for w in b]
        k = int(np.argmax(widths))
        if budget <= 0 or widths[k] == 0.0:
            return False
        mid = 0.5 * (b[k][0] + b[k][1])
        for half in ((b[k][0], mid), (mid, b[k][1])):
            c = list(b)
            c[k] = half
            stack.append(c)
    return True


def invariant_box(
    F: sp.MatrixBase,
    states: tuple[sp.Symbol, ...],
    t: sp.Symbol,
    S: np.ndarray,
    horizon: float,
    enclose=None,
) -> bool:
    """Whether the closed box ``S`` is forward invariant on ``[0, horizon]`` (Nagumo, faces
    checked by rigorous interval enclosure)."""
    S = np.asarray(S, dtype=float)
    n = S.shape[0]
    variables = [*states, t]
    trange = (0.0, float(horizon)) if any(e.has(t) for e in F) else (0.0, 0.0)
    try:
        for i in range(n):
            for side, sign in ((1, 1), (0, -1)):
                face = [(float(S[j, 0]), float(S[j, 1])) for j in range(n)]
                face[i] = (float(S[i, side]), float(S[i, side]))
                if not _face_ok(F[i], variables, [*face, trange], sign, enclose):
                    return False
    except UnsupportedExpression:
        return False
    return True


def best_invariant_set(
    F: sp.MatrixBase,
    states: tuple[sp.Symbol, ...],
    t: sp.Symbol,
    lam: float,
    scope: Scope,
    support: np.ndarray,
    horizon: float,
    F_num,
    enclose=None,
) -> InvariantSet:
    """The proved invariant set with the largest room: the ball of :func:`invariant_ball`, or a
    box between the support and the region (:func:`invariant_box`)."""
    ball = invariant_ball(F, states, t, lam, scope, support, horizon, F_num, enclose)
    if scope.box is None or ball.room == math.inf:
        return ball
    B = np.array(scope.box, dtype=float)
    support = np.asarray(support, dtype=float)
    best = ball
    if not scope.covers_time(horizon):
        return best
    for frac in (0.5, 0.0):
        S = support + frac * (B - support)
        room = min(
            min(_gap_down(S[i, 0], B[i, 0]), _gap_down(B[i, 1], S[i, 1])) for i in range(len(S))
        )
        if (best.proved and room <= best.room) or not invariant_box(
            F, states, t, S, horizon, enclose
        ):
            continue
        sb = [[float(a), float(b)] for a, b in S]
        best = InvariantSet(
            True,
            (),
            math.nan,
            math.nan,
            room,
            f"the box {sb} contains the support and is forward invariant (Nagumo: every face "
            f"checked by rigorous interval enclosure), inside the box where the rate holds with "
            f"room {room:.6g} (analysis/contraction/invariance.py)",
        )
    return best


def _gap_down(a: float, b: float) -> float:
    """Lower bound of ``a - b`` (exactly 0 when ``a == b``: that subtraction is exact)."""
    return 0.0 if a == b else down(a - b)


def _fmt(v) -> str:
    return "[" + ", ".join(f"{float(x):.4g}" for x in v) + "]"
