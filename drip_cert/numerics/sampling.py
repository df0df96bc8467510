"""Sampled estimates of growth and Hoelder constants (labelled ``estimate`` by their callers).

Points lie on spheres of fixed radii around the origin (and a centre), directions drawn from a
seeded generator, so every report is reproducible. A sampled supremum is a lower bound of the true
one: it can only make a verdict conditional, never certify.
"""

from __future__ import annotations

from collections.abc import Callable

import numpy as np

SAMPLE_RADII = (0.0, 0.1, 0.3, 1.0, 3.0, 10.0, 30.0, 100.0, 1e3, 1e4, 1e6)
#: radii at which growth ratios are sampled; 1e6 stands in for the limit r -> infinity
SAMPLES_PER_RADIUS = 256  #: random directions per radius for sampled estimates
SAMPLE_SEED = 20260101  #: fixed seed of the sampled estimates (reproducible reports)


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


def growth_ratio_estimate(
    fn: Callable[[np.ndarray], np.ndarray],
    n: int,
    power: float,
    times: np.ndarray,
    seed: int = SAMPLE_SEED,
) -> tuple[float, np.ndarray]:
    """Sampled ``sup ||fn(t, a)|| / (1 + ||a||^2)^{power/2}`` and the maximiser.

    ``power = 1`` is the drift form ``||F||^2 <= D^2 (1 + ||a||^2)``; ``power = 1/2`` is the
    diffusion form ``||F||_F^2 <= D^2 (1 + ||a||^2)^{1/2}`` of L1-DRAC Assumption 4.
    """
    X = sample_points(n, seed=seed)
    best, arg = 0.0, X[0]
    for tt in times:
        vals = fn(float(tt), X)
        norms = np.linalg.norm(vals.reshape(len(X), -1), axis=1)
        ratio = norms / (1.0 + np.sum(X**2, axis=1)) ** (power / 2.0)
        i = int(np.nanargmax(ratio))
        if ratio[i] > best:
            best, arg = float(ratio[i]), X[i]
    return best, arg


def holder_estimate(
    fn: Callable[[np.ndarray], np.ndarray],
    n: int,
    exponent: float,
    times: np.ndarray,
    seed: int = SAMPLE_SEED,
) -> float:
    """Sampled ``sup ||fn(t,a) - fn(t,b)|| / ||a - b||^exponent`` over pairs at many scales."""
    rng = np.random.default_rng(seed + 1)
    A = sample_points(n, seed=seed)
    best = 0.0
    for scale in (1e-4, 1e-2, 1e-1, 1.0, 10.0, 100.0):
        B = A + scale * _directions(n, len(A), rng)
        # pairs through the origin: the 1/2-Hoelder ratio of sqrt-type terms peaks there
        B0 = np.zeros_like(A)
        for P, Q in ((A, B), (B0, B)):
            dist = np.linalg.norm(P - Q, axis=1)
            ok = dist > 0
            for tt in times:
                diff = fn(float(tt), P) - fn(float(tt), Q)
                num = np.linalg.norm(diff.reshape(len(P), -1), axis=1)
                r = num[ok] / dist[ok] ** exponent
                if r.size:
                    best = max(best, float(np.nanmax(r)))
    return best
