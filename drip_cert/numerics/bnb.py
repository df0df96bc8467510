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

Users: :func:`drip_cert.analysis.contraction.contraction_rate` (``max mu_2`` of an interval
Jacobian, docs/math/contraction.md section 3.4) and :mod:`drip_cert.analysis.expr_sup` (the
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


def _sample_points(b: Box, corners: bool) -> list[np.ndarray]:
    centre = 0.5 * (b[:, 0] + b[:, 1])
    pts = [centre]
    if corners and b.shape[0] <= CORNER_MAX_DIM:
        pts += [np.array(c, dtype=float) for c in itertools.product(*b)]
    return pts


def maximize(
    box: np.ndarray | Sequence[tuple[float, float]],
    upper: UpperFn,
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
) -> BnbResult:
    """Best-first branch and bound for ``sup f`` over ``box``.

    Parameters
    ----------
    box
        ``(d, 2)``: the box, one ``(lo, hi)`` row per variable (finite ends).
    upper
        ``upper(B) >= sup_{x in B} f(x)`` for every sub-box ``B`` (a ``(d, 2)`` array). The result
        is sound exactly when this is.
    value
        ``value(x) = f(x)`` at a point ``x`` (a ``(d,)`` array), or ``None``. Sampled at the
        centre of every new sub-box (and at its corners, see ``corners``); NaN values are
        ignored. Only for stopping and for the witness.
    atol, rtol
        Stop when ``upper - lower <= atol + rtol |lower|`` (``lower`` finite).
    max_boxes
        Stop before a split once this many sub-boxes have been evaluated.
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

    Returns
    -------
    BnbResult
    """
    box0 = np.array(box, dtype=float).reshape(-1, 2)
    w0 = box0[:, 1] - box0[:, 0]
    scale = np.where(w0 > 0, w0, 1.0)
    if active is not None:
        scale = np.where(np.asarray(active, dtype=bool), scale, np.inf)

    def ub_of(b: Box) -> float:
        u = float(upper(b))
        return math.inf if u != u else u

    lb, arg = -math.inf, None
    if initial is not None:
        lb, arg = float(initial[0]), np.asarray(initial[1], dtype=float)

    def sample(b: Box) -> None:
        nonlocal lb, arg
        if value is None:
            return
        for p in _sample_points(b, corners):
            v = value(p)
            if v > lb:
                lb, arg = float(v), p

    if initial is None:
        sample(box0)
    counter = itertools.count()
    heap = [(-ub_of(box0), 0, next(counter), box0)]
    n_boxes = 1
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
        neg_ub, neg_depth, _, b = heapq.heappop(heap)
        rel = (b[:, 1] - b[:, 0]) / scale
        k = int(np.argmax(rel))
        if rel[k] <= min_width:
            heapq.heappush(heap, (neg_ub, neg_depth, next(counter), b))
            stop = "min_width"
            break
        mid = 0.5 * (b[k, 0] + b[k, 1])
        depth = neg_depth - 1 if prefer_deep else 0
        for half in ((b[k, 0], mid), (mid, b[k, 1])):
            child = b.copy()
            child[k] = half
            n_boxes += 1
            heapq.heappush(heap, (-ub_of(child), depth, next(counter), child))
            sample(child)
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
