"""One best-first branch and bound: a rigorous upper bound of the maximum of a function on a box.

The caller supplies ``upper(B)``, an upper bound of ``f`` on every sub-box ``B`` (an interval
enclosure, a log-norm bound of an interval matrix, ...), and optionally ``value(x)``, the value
of ``f`` at a point. :func:`maximize` keeps the sub-boxes of a partition of the box in a heap keyed
by their upper bounds, always splits the one with the largest bound (best first) in half along its
widest side (relative to the initial box), and stops when the largest bound is within the
tolerance of the best sampled value, or when a budget is spent.

Soundness: the sub-boxes in the heap always cover the box, so the largest of their upper bounds
bounds ``sup f`` on the box, whenever the caller's ``upper`` is rigorous on every sub-box. A
stopped search (budget, time, a box too thin to split) returns that same bound: looser, never
wrong. A NaN from ``upper`` is read as ``+inf`` (no information). The sampled values serve only
to stop early and to report a witness; they are estimates of the maximum from below.

Batched use: with ``upper_many`` (bounds of many sub-boxes per call, e.g.
:class:`~drip_cert.numerics.interval_batch.BatchEnclosure`) and ``batch > 1`` each round splits
up to ``batch`` of the sub-boxes with the largest bounds (the round size doubling from 1) and
bounds all children in one call; ``batch = 1`` is the one-box-at-a-time search, bit for bit. The
heap covers the box in both, so the bound is sound for every ``batch``.

Users: :func:`drip_cert.analysis.contraction.rate.contraction_rate` (``max mu_2`` of an interval
Jacobian, docs/math/contraction.md section 3.4) and :mod:`drip_cert.analysis.growth.expr_sup` (the
one-dimensional and small-box suprema of the growth constants, docs/math/l1drac.md section 2).
"""

from __future__ import annotations

import heapq
import itertools
import math
import time
from collections.abc import Callable, Sequence
from dataclasses import dataclass

import numpy as np

__all__ = ["BnbResult", "CORNER_MAX_DIM", "maximize"]

CORNER_MAX_DIM = 3  #: with ``corners=True`` the corners are sampled only up to this dimension

Box = np.ndarray  #: ``(d, 2)`` float array, one ``(lo, hi)`` row per variable
UpperFn = Callable[[Box], float]
ValueFn = Callable[[np.ndarray], float]
UpperManyFn = Callable[[np.ndarray], np.ndarray]  #: ``(K, d, 2)`` boxes -> ``(K,)`` upper bounds
ValueManyFn = Callable[[np.ndarray], np.ndarray]  #: ``(P, d)`` points -> ``(P,)`` values

_STOPS = ("converged", "max_boxes", "max_time", "min_width")


@dataclass(frozen=True)
class BnbResult:
    """Outcome of :func:`maximize`.

    Attributes
    ----------
    upper
        Certified upper bound of ``sup f`` on the box (sound when the caller's ``upper`` is);
        ``inf`` when no finite bound was found.
    lower
        Best sampled value (``-inf`` when nothing was sampled): an estimate of the maximum from
        below, used only for stopping.
    argmax
        The point where ``lower`` was found (``None`` when nothing was sampled).
    n_boxes
        Sub-boxes whose upper bound was evaluated (``1 + 2 * splits``).
    converged
        Whether ``upper - lower`` met the tolerance.
    stop
        Why the search stopped: ``'converged'``, ``'max_boxes'``, ``'max_time'`` or
        ``'min_width'`` (the box to split is thinner than ``min_width`` on every side).
    """

    upper: float
    lower: float
    argmax: tuple[float, ...] | None
    n_boxes: int
    converged: bool
    stop: str

    def __post_init__(self) -> None:
        if self.stop not in _STOPS:
            raise ValueError(f"stop must be one of {_STOPS}, got {self.stop!r}")

    @property
    def gap(self) -> float:
        """``upper - lower`` (``inf`` when nothing was sampled)."""
        return self.upper - self.lower


def _sample_points_many(bs: np.ndarray, corners: bool) -> np.ndarray:
    """The points sampled in every box ``(K, d, 2)``, box after box (``(P, d)``): its centre,
    then (with ``corners`` and ``d <= CORNER_MAX_DIM``) its corners in ``itertools.product``
    order."""
    centre = 0.5 * (bs[:, :, 0] + bs[:, :, 1])
    d = bs.shape[1]
    if not (corners and d <= CORNER_MAX_DIM):
        return centre
    # itertools.product(*b) order: the first variable varies slowest
    bits = np.array(list(itertools.product((0, 1), repeat=d)), dtype=int)  # (2^d, d)
    corner = bs[:, np.arange(d)[None, :], bits]  # (K, 2^d, d)
    return np.concatenate([centre[:, None, :], corner], axis=1).reshape(-1, d)


def maximize(
    box: np.ndarray | Sequence[tuple[float, float]],
    upper: UpperFn | None,
    value: ValueFn | None = None,
    *,
    atol: float = 0.0,
    rtol: float = 0.0,
    max_boxes: int = 10_000,
    max_time_s: float = math.inf,
    min_width: float = 0.0,
    active: Sequence[bool] | None = None,
    corners: bool = False,
    initial: tuple[float, Sequence[float] | np.ndarray] | None = None,
    prefer_deep: bool = False,
    upper_many: UpperManyFn | None = None,
    value_many: ValueManyFn | None = None,
    batch: int = 1,
) -> BnbResult:
    """Best-first branch and bound for ``sup f`` over ``box``.

    Parameters
    ----------
    box
        ``(d, 2)``: the box, one ``(lo, hi)`` row per variable (finite ends).
    upper
        ``upper(B) >= sup_{x in B} f(x)`` for every sub-box ``B`` (a ``(d, 2)`` array). The result
        is sound exactly when this is. ``None`` when ``upper_many`` is given.
    value
        ``value(x) = f(x)`` at a point ``x`` (a ``(d,)`` array), or ``None``. Sampled at the
        centre of every new sub-box (and at its corners, see ``corners``); NaN values are
        ignored. Only for stopping and for the witness.
    atol, rtol
        Stop when ``upper - lower <= atol + rtol |lower|`` (``lower`` finite).
    max_boxes
        Stop before a split once this many sub-boxes have been evaluated (a round of ``batch``
        splits never passes it: the same count of splits as one box at a time).
    max_time_s
        Stop before a split once this much wall time has passed.
    min_width
        Stop when the box to split is, on its widest side, at most this fraction of the initial
        box's width there (``0`` stops only at point boxes).
    active
        Per variable, whether it may be split (default: all); a variable ``f`` does not depend on
        is never split.
    corners
        Also sample the corners of every sub-box of dimension at most :data:`CORNER_MAX_DIM`.
    initial
        ``(value, point)`` known before the search (e.g. from dense sampling). When given, the
        initial box itself is not sampled; otherwise it is, like every sub-box.
    prefer_deep
        Among sub-boxes with equal upper bounds split the deepest first (depth first on flat
        objectives); otherwise the oldest first.
    upper_many, value_many
        Batched forms: ``upper_many(boxes (K, d, 2)) -> (K,)`` and ``value_many(points (P, d))
        -> (P,)``, used instead of ``upper`` / ``value`` when given (one call per round).
    batch
        At most this many sub-boxes split per round, the ones with the largest bounds (those
        not yet within the tolerance); the round size doubles from 1 up to ``batch``. ``1`` is
        the one-box-at-a-time search. Every sub-box still has a rigorous bound and the heap still
        covers the box, so the result is sound for every ``batch``; it may differ from the
        one-at-a-time result within the stopping tolerance.

    Returns
    -------
    BnbResult
    """
    box0 = np.array(box, dtype=float).reshape(-1, 2)
    w0 = box0[:, 1] - box0[:, 0]
    scale = np.where(w0 > 0, w0, 1.0)
    if active is not None:
        scale = np.where(np.asarray(active, dtype=bool), scale, np.inf)
    if upper_many is None:
        if upper is None:
            raise ValueError("maximize needs upper or upper_many")
        scalar_upper = upper

        def upper_many(bs: np.ndarray) -> np.ndarray:
            return np.array([float(scalar_upper(b)) for b in bs])

    if value_many is None and value is not None:
        scalar_value = value

        def value_many(ps: np.ndarray) -> np.ndarray:
            return np.array([float(scalar_value(p)) for p in ps])

    def ubs_of(bs: np.ndarray) -> list[float]:
        u = np.asarray(upper_many(bs), dtype=float).reshape(-1)
        return [math.inf if x != x else float(x) for x in u]

    lb, arg = -math.inf, None
    if initial is not None:
        lb, arg = float(initial[0]), np.asarray(initial[1], dtype=float)

    def sample(bs: np.ndarray) -> None:
        nonlocal lb, arg
        if value_many is None:
            return
        pts = _sample_points_many(bs, corners)
        vals = np.asarray(value_many(pts), dtype=float).reshape(-1)
        vals = np.where(np.isnan(vals), -np.inf, vals)
        i = int(np.argmax(vals))  # the first of equal values, as one point at a time
        if vals[i] > lb:
            lb, arg = float(vals[i]), pts[i]

    if initial is None:
        sample(box0[None])
    counter = itertools.count()
    heap = [(-ubs_of(box0[None])[0], 0, next(counter), box0)]
    n_boxes = 1
    round_size = 1
    deadline = time.perf_counter() + max_time_s
    while True:
        ub = -heap[0][0]
        if math.isfinite(lb) and ub - lb <= atol + rtol * abs(lb):
            stop = "converged"
            break
        if n_boxes >= max_boxes:
            stop = "max_boxes"
            break
        if time.perf_counter() > deadline:
            stop = "max_time"
            break
        want = min(round_size, (max_boxes - n_boxes + 1) // 2)
        round_size = min(2 * round_size, max(1, batch))
        popped: list[tuple[float, int, Box]] = []  # (-upper, -depth, box), best first
        thin = False
        while heap and len(popped) < want:
            neg_ub, neg_depth, _, b = heap[0]
            if popped and math.isfinite(lb) and -neg_ub - lb <= atol + rtol * abs(lb):
                break  # this one and those below need no split
            rel = (b[:, 1] - b[:, 0]) / scale
            if rel.max() <= min_width:
                thin = True
                break
            heapq.heappop(heap)
            popped.append((neg_ub, neg_depth, b))
        if not popped:
            assert thin
            stop = "min_width"
            break
        parents = np.array([b for _, _, b in popped])
        rows = np.arange(len(popped))
        axis = np.argmax((parents[:, :, 1] - parents[:, :, 0]) / scale, axis=1)
        mid = 0.5 * (parents[rows, axis, 0] + parents[rows, axis, 1])
        left, right = parents.copy(), parents.copy()
        left[rows, axis, 1] = mid
        right[rows, axis, 0] = mid
        children = np.stack([left, right], axis=1).reshape(-1, *box0.shape)  # L0 R0 L1 R1 ...
        n_boxes += children.shape[0]
        for i, u in enumerate(ubs_of(children)):
            neg_depth = popped[i // 2][1]
            depth = neg_depth - 1 if prefer_deep else 0
            heapq.heappush(heap, (-u, depth, next(counter), children[i]))
        sample(children)
    ub = -heap[0][0]
    converged = math.isfinite(lb) and ub - lb <= atol + rtol * abs(lb)
    return BnbResult(
        upper=ub,
        lower=lb,
        argmax=None if arg is None else tuple(float(v) for v in arg),
        n_boxes=n_boxes,
        converged=converged,
        stop=stop,
    )
