"""Sampled estimates of growth and Hoelder constants (labelled ``estimate`` by their callers).

Points lie on spheres of fixed radii around the origin, directions drawn from a seeded generator,
so every report is reproducible. A sampled supremum is a lower bound of the true one: it can only
make a verdict conditional, never certify. The results carry diagnostics (points where the field
is not finite, a ratio that keeps growing at the largest radii or distances, which suggests an
infinite constant); the caller labels the value and decides what to do with them.
"""

from __future__ import annotations

from collections.abc import Callable, Sequence
from dataclasses import dataclass

import numpy as np

__all__ = [
    "GROWTH_FACTOR",
    "HOLDER_SCALES",
    "SAMPLE_RADII",
    "SAMPLE_SEED",
    "SAMPLES_PER_RADIUS",
    "GrowthEstimate",
    "HolderEstimate",
    "growth_ratio_estimate",
    "holder_estimate",
    "sample_points",
]

SAMPLE_RADII = (0.0, 0.1, 0.3, 1.0, 3.0, 10.0, 30.0, 100.0, 1e3, 1e4, 1e6)
#: radii at which growth ratios are sampled; 1e6 stands in for the limit r -> infinity
SAMPLES_PER_RADIUS = 256  #: random directions per radius for sampled estimates
SAMPLE_SEED = 20260101  #: fixed seed of the sampled estimates (reproducible reports)
HOLDER_SCALES = (1e-6, 1e-4, 1e-2, 1e-1, 1.0, 10.0, 100.0, 1e3)
#: distances of the point pairs of the Lipschitz / Hoelder estimate
GROWTH_FACTOR = 10.0
#: a sampled ratio that grows by more than this factor towards the extreme radii (or distances)
#: is reported as likely infinite
_TINY = 1e-300  #: floor of a denominator of the growth test (a ratio of 0 is not growth)

Field = Callable[[float, np.ndarray], np.ndarray]
"""A batched field ``fn(t, X (N, n)) -> (N, ...)``; it may return NaN or inf where undefined."""


def _directions(n: int, k: int, rng: np.random.Generator) -> np.ndarray:
    v = rng.normal(size=(k, n))
    v /= np.linalg.norm(v, axis=1, keepdims=True)
    return v


def sample_points(n: int, center: np.ndarray | None = None, seed: int = SAMPLE_SEED) -> np.ndarray:
    """Points on spheres of radii :data:`SAMPLE_RADII` (plus the origin and the center)."""
    rng = np.random.default_rng(seed)
    pts = [np.zeros((1, n))]
    for r in SAMPLE_RADII[1:]:
        pts.append(r * _directions(n, SAMPLES_PER_RADIUS, rng))
    if center is not None:
        pts.append(center[None, :])
    return np.concatenate(pts)


def _nan_max(x: np.ndarray, initial: float = -np.inf) -> float:
    """``max(initial, max of the non-NaN entries)`` (no warning on an all-NaN slice)."""
    x = x[~np.isnan(x)]
    return max(initial, float(x.max())) if x.size else initial


def _grows(top: float, below: float) -> bool:
    return top > GROWTH_FACTOR * max(below, _TINY)


def _n_nonfinite(vals: np.ndarray, n_points: int) -> int:
    return int(np.sum(~np.all(np.isfinite(vals.reshape(n_points, -1)), axis=1)))


def _nonfinite_note(n_bad: int, n_points: int) -> str:
    if not n_bad:
        return ""
    return (
        f"; F is not finite (undefined) at {n_bad} of {n_points} sampled points, which "
        "were skipped: the assumption asks for F defined on all of R^n"
    )


@dataclass(frozen=True)
class GrowthEstimate:
    """Sampled ``sup ||F(t, a)|| / (1 + ||a||^2)^{power/2}`` (:func:`growth_ratio_estimate`).

    Attributes
    ----------
    value
        The largest sampled ratio (0 when no point gave a number).
    argmax
        The point ``a`` where it was found.
    per_radius
        The largest ratio on each sphere of :data:`SAMPLE_RADII` (0 where none was finite).
    n_nonfinite
        Sampled points (at the first time) where ``F`` was not finite; they are skipped.
    n_points
        Sampled points per time.
    """

    value: float
    argmax: tuple[float, ...]
    per_radius: tuple[float, ...]
    n_nonfinite: int
    n_points: int

    @property
    def likely_infinite(self) -> bool:
        """Whether the ratio still grows :data:`GROWTH_FACTOR`-fold between the two largest
        radii (the constant is then likely infinite)."""
        return _grows(self.per_radius[-1], self.per_radius[-2])

    def diagnostics(self) -> str:
        """Text for the caller's note (``""`` when there is nothing to say), ``"; "``-led."""
        out = _nonfinite_note(self.n_nonfinite, self.n_points)
        if self.likely_infinite:
            out += (
                "; the sampled ratio still grows tenfold from radius "
                f"{SAMPLE_RADII[-2]:g} to {SAMPLE_RADII[-1]:g}: the constant is likely infinite"
            )
        return out


@dataclass(frozen=True)
class HolderEstimate:
    """Sampled ``sup ||F(t, a) - F(t, b)|| / ||a - b||^exponent`` (:func:`holder_estimate`).

    Attributes
    ----------
    value
        The largest sampled ratio (0 when no pair gave a number).
    exponent
        ``1`` (Lipschitz) or ``1/2`` (Hoelder).
    by_scale
        The largest ratio at each pair distance of :data:`HOLDER_SCALES`.
    top_radius, below_top_radius
        The largest ratio of the pairs based at the two largest radii of :data:`SAMPLE_RADII`.
    n_nonfinite, n_points
        As in :class:`GrowthEstimate`.
    """

    value: float
    exponent: float
    by_scale: tuple[float, ...]
    top_radius: float
    below_top_radius: float
    n_nonfinite: int
    n_points: int

    @property
    def likely_infinite(self) -> bool:
        """Whether the ratio grows :data:`GROWTH_FACTOR`-fold towards the largest or the
        smallest distances, or towards the largest radius."""
        s = self.by_scale
        return (
            _grows(s[-1], s[-3])
            or _grows(s[0], s[2])
            or _grows(self.top_radius, self.below_top_radius)
        )

    def diagnostics(self) -> str:
        """Text for the caller's note, ``"; "``-led (the distances sampled, and any warning)."""
        kind = "Lipschitz" if self.exponent == 1.0 else "1/2-Hoelder"
        out = (
            _nonfinite_note(self.n_nonfinite, self.n_points)
            + f"; {kind} ratio over point pairs at distances "
            + ", ".join(f"{s:g}" for s in HOLDER_SCALES)
        )
        if self.likely_infinite:
            out += (
                "; the sampled ratio keeps growing at the extreme distances or radii: the "
                "constant is likely infinite"
            )
        return out


def growth_ratio_estimate(
    fn: Field,
    n: int,
    power: float,
    times: Sequence[float] | np.ndarray,
    seed: int = SAMPLE_SEED,
) -> GrowthEstimate:
    """Sampled ``sup_{t, a} ||fn(t, a)|| / (1 + ||a||^2)^{power/2}`` over :func:`sample_points`.

    ``power = 1`` is the drift form ``||F||^2 <= D^2 (1 + ||a||^2)``; ``power = 1/2`` is the
    diffusion form ``||F||_F^2 <= D^2 (1 + ||a||^2)^{1/2}`` of L1-DRAC Assumption 4. Points where
    ``fn`` is NaN are skipped.
    """
    X = sample_points(n, seed=seed)
    radii = np.linalg.norm(X, axis=1)
    best, arg = 0.0, X[0]
    per_radius = [0.0] * len(SAMPLE_RADII)
    n_bad = 0
    with np.errstate(all="ignore"):
        for i, tt in enumerate(times):
            vals = np.asarray(fn(float(tt), X), dtype=float).reshape(len(X), -1)
            if i == 0:
                n_bad = _n_nonfinite(vals, len(X))
            ratio = np.linalg.norm(vals, axis=1) / (1.0 + radii**2) ** (float(power) / 2.0)
            for j, r in enumerate(SAMPLE_RADII):
                sel = np.isclose(radii, r, rtol=1e-9, atol=1e-12)
                if np.any(sel):
                    per_radius[j] = _nan_max(ratio[sel], per_radius[j])
            if not np.all(np.isnan(ratio)):
                k = int(np.nanargmax(ratio))
                if ratio[k] > best:
                    best, arg = float(ratio[k]), X[k]
    return GrowthEstimate(
        value=best,
        argmax=tuple(float(v) for v in arg),
        per_radius=tuple(per_radius),
        n_nonfinite=n_bad,
        n_points=len(X),
    )


def holder_estimate(
    fn: Field,
    n: int,
    exponent: float,
    times: Sequence[float] | np.ndarray,
    seed: int = SAMPLE_SEED,
) -> HolderEstimate:
    """Sampled ``sup ||fn(t,a) - fn(t,b)|| / ||a - b||^exponent`` over point pairs.

    Pairs ``(a, a + s d)`` with ``a`` from :func:`sample_points`, ``d`` a random unit vector and
    ``s`` each distance of :data:`HOLDER_SCALES`, and pairs ``(0, s d)`` through the origin (where
    the 1/2-Hoelder ratio of square-root terms peaks). Pairs where ``fn`` is NaN are skipped.
    """
    rng = np.random.default_rng(seed + 1)
    A = sample_points(n, seed=seed)
    radii = np.linalg.norm(A, axis=1)
    top = np.isclose(radii, SAMPLE_RADII[-1])
    prev = np.isclose(radii, SAMPLE_RADII[-2])
    best, best_top, best_prev = 0.0, 0.0, 0.0
    by_scale = []
    n_bad = None
    with np.errstate(all="ignore"):
        for scale in HOLDER_SCALES:
            d = _directions(n, len(A), rng)
            s_best = 0.0
            for k, (P, Q) in enumerate(((A, A + scale * d), (np.zeros_like(A), scale * d))):
                dist = np.linalg.norm(P - Q, axis=1)
                for tt in times:
                    fP = np.asarray(fn(float(tt), P), dtype=float).reshape(len(P), -1)
                    if n_bad is None:
                        n_bad = _n_nonfinite(fP, len(P))
                    fQ = np.asarray(fn(float(tt), Q), dtype=float).reshape(len(Q), -1)
                    num = np.linalg.norm(fP - fQ, axis=1)
                    ratio = np.where(dist > 0, num / dist**exponent, np.nan)
                    if np.any(np.isfinite(ratio)):
                        s_best = _nan_max(ratio, s_best)
                    if k == 0:
                        best_top = _nan_max(ratio[top], best_top)
                        best_prev = _nan_max(ratio[prev], best_prev)
            by_scale.append(s_best)
            best = max(best, s_best)
    return HolderEstimate(
        value=best,
        exponent=float(exponent),
        by_scale=tuple(by_scale),
        top_radius=best_top,
        below_top_radius=best_prev,
        n_nonfinite=n_bad or 0,
        n_points=len(A),
    )
