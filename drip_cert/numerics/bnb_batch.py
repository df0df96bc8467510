"""Batched best-first branch and bound: a rigorous upper bound of the maximum of a function on a
box, with many sub-boxes bounded per call.

The caller supplies ``bound(boxes) -> (upper, value, point)`` for a batch of sub-boxes
``(K, d, 2)``: ``upper[k] >= sup f`` on box ``k`` (rigorous), ``value[k] = f(point[k])`` for a
point of the box (an estimate from below of its maximum, NaN when unknown). Each round splits the
``batch`` sub-boxes with the largest upper bounds in half along their widest side (relative to
the initial box) and bounds all children in one call, so the per-box cost is that of vectorised
numpy rather than of a Python loop (:func:`drip_cert.numerics.bnb.maximize` bounds one box per
call).

Soundness: the live and the settled sub-boxes always partition the box, so the largest of their
upper bounds bounds ``sup f`` whenever ``bound`` is rigorous. A sub-box whose upper bound is
within ``atol`` of the best sampled value (or below ``settle_below``) is *settled*: it is never
split again, and only the largest settled bound is kept. A stopped search returns the same kind
of bound, only looser.
"""

from __future__ import annotations

import math
import time
from collections.abc import Callable
from dataclasses import dataclass

import numpy as np

__all__ = ["BatchBnbResult", "maximize_batch"]

BatchBound = Callable[[np.ndarray], tuple[np.ndarray, np.ndarray, np.ndarray]]

_STOPS = ("converged", "below", "max_boxes", "max_time", "min_width")


@dataclass(frozen=True)
class BatchBnbResult:
    """Outcome of :func:`maximize_batch`.

    Attributes
    ----------
    upper
        Certified upper bound of ``sup f`` on the box (sound when ``bound`` is).
    lower
        Best sampled value (an estimate from below; ``-inf`` when none).
    argmax
        Where ``lower`` was found (``None`` when nothing was sampled).
    n_boxes
        Sub-boxes bounded.
    stop
        ``'converged'`` (gap within ``atol``), ``'below'`` (every bound below ``stop_below``),
        ``'max_boxes'``, ``'max_time'`` or ``'min_width'``.
    time_to_below
        Wall time at which the global upper bound first fell below ``stop_below`` (NaN when it
        never did or no threshold was given).
    """

    upper: float
    lower: float
    argmax: tuple[float, ...] | None
    n_boxes: int
    stop: str
    time_to_below: float = math.nan

    def __post_init__(self) -> None:
        if self.stop not in _STOPS:
            raise ValueError(f"stop must be one of {_STOPS}, got {self.stop!r}")

    @property
    def converged(self) -> bool:
        """Whether the search ended with its goal met (gap or threshold)."""
        return self.stop in ("converged", "below")

    @property
    def gap(self) -> float:
        """``upper - lower``."""
        return self.upper - self.lower


def maximize_batch(
    box: np.ndarray,
    bound: BatchBound,
    *,
    atol: float = 0.0,
    max_boxes: int = 1_000_000,
    max_time_s: float = math.inf,
    batch: int = 256,
    min_width: float = 0.0,
    stop_below: float | None = None,
    initial: tuple[float, np.ndarray] | None = None,
) -> BatchBnbResult:
    """Batched best-first branch and bound for ``sup f`` over ``box`` (``(d, 2)``).

    Parameters
    ----------
    box
        ``(d, 2)`` finite box.
    bound
        ``bound(boxes (K, d, 2)) -> (upper (K,), value (K,), point (K, d))``; see the module
        docstring.
    atol
        Stop when ``upper - lower <= atol``.
    max_boxes, max_time_s
        Budgets (checked before each round).
    batch
        Sub-boxes split per round (so ``2 batch`` bounded per call).
    min_width
        A sub-box whose widest relative side is at most this is not split (it stays live).
    stop_below
        Stop as soon as the global upper bound is below this (e.g. 0 to prove a sign).
    initial
        ``(value, point)`` known before the search (dense sampling).
    """
    box0 = np.asarray(box, dtype=float).reshape(-1, 2)
    t0 = time.perf_counter()
    w0 = box0[:, 1] - box0[:, 0]
    scale = np.where(w0 > 0, w0, np.inf)
    lb, arg = -math.inf, None
    if initial is not None:
        lb, arg = float(initial[0]), np.asarray(initial[1], dtype=float)

    def evaluate(bs: np.ndarray) -> np.ndarray:
        nonlocal lb, arg
        ub, val, pts = bound(bs)
        ub = np.where(np.isnan(ub), np.inf, np.asarray(ub, dtype=float))
        val = np.where(np.isnan(val), -np.inf, np.asarray(val, dtype=float))
        k = int(np.argmax(val))
        if val[k] > lb:
            lb, arg = float(val[k]), np.asarray(pts[k], dtype=float)
        return ub

    live = box0[None].copy()
    ub = evaluate(live)
    n_boxes = 1
    settled = -math.inf
    t_below = math.nan
    while True:
        top = float(ub.max()) if ub.size else -math.inf
        glob = max(top, settled)
        if stop_below is not None and glob < stop_below and math.isnan(t_below):
            t_below = time.perf_counter() - t0
        if math.isfinite(lb) and glob - lb <= atol:
            stop = "converged"
            break
        if stop_below is not None and glob < stop_below:
            stop = "below"
            break
        # settle the sub-boxes that need no more splitting
        done = ub <= lb + atol
        if stop_below is not None:
            done |= ub < stop_below
        if np.any(done):
            settled = max(settled, float(ub[done].max()))
            live, ub = live[~done], ub[~done]
        if n_boxes >= max_boxes:
            stop = "max_boxes"
            break
        if time.perf_counter() - t0 > max_time_s:
            stop = "max_time"
            break
        k = min(batch, live.shape[0])
        idx = np.argpartition(-ub, k - 1)[:k] if k < live.shape[0] else np.arange(live.shape[0])
        parents = live[idx]
        rel = (parents[:, :, 1] - parents[:, :, 0]) / scale
        axis = np.argmax(rel, axis=1)
        split = rel[np.arange(k), axis] > min_width
        if not np.any(split):
            stop = "min_width"
            break
        idx, parents, axis = idx[split], parents[split], axis[split]
        rows = np.arange(parents.shape[0])
        mid = 0.5 * (parents[rows, axis, 0] + parents[rows, axis, 1])
        left, right = parents.copy(), parents.copy()
        left[rows, axis, 1] = mid
        right[rows, axis, 0] = mid
        children = np.concatenate([left, right])
        cub = evaluate(children)
        n_boxes += children.shape[0]
        keep = np.ones(live.shape[0], dtype=bool)
        keep[idx] = False
        live = np.concatenate([live[keep], children])
        ub = np.concatenate([ub[keep], cub])
    top = float(ub.max()) if ub.size else -math.inf
    return BatchBnbResult(
        upper=max(top, settled),
        lower=lb,
        argmax=None if arg is None else tuple(float(v) for v in arg),
        n_boxes=n_boxes,
        stop=stop,
        time_to_below=t_below,
    )
