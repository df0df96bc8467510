"""The trajectory quantities of the TaSIL lemma: ``h_0 = sup_t ||Delta(x*_t)||`` and
``h_1 = sup_t ||d Delta(x*_t)||_op`` along one expert trajectory, ``Delta = pi_hat - pi_star``
(docs/math/tasil.md (A3) of section 3.1; section 4 in continuous time).

In discrete time they are grid maxima of rounded-up norms (:func:`h_discrete`); in continuous time
a grid under-estimates a sup, and :func:`h_continuous` adds the Lipschitz-in-time correction of
the two-cone bound (docs/math/tasil.md Proposition 4.2).
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass

import numpy as np

from drip_cert.bounds.tasil._common import REL_PAD, positive
from drip_cert.errors import SpecError
from drip_cert.numerics.rounding import norm2_up_np, spectral_norm_upper
from drip_cert.provenance import How

__all__ = ["TrajectoryH", "h0_lipschitz", "h_continuous", "h_discrete", "h_from_functions"]

# relative allowance when checking grid values against the claimed Lipschitz-in-time rate
_CONSISTENCY_RTOL = 1e-9


@dataclass(frozen=True)
class TrajectoryH:
    """``h_0`` and ``h_1`` of one expert trajectory (docs/math/tasil.md A3; section 4 if
    continuous).

    Attributes
    ----------
    h0, h1
        The sups used by the lemma: grid maxima of rounded-up norms in discrete time, sound sups
        over the continuous time interval otherwise (both :attr:`How.SOUND`).
    h0_grid, h1_grid
        The maxima over the grid points.
    t_h0, t_h1
        Times (or grid indices in discrete time) of the grid maxima.
    continuous
        Whether ``h0``/``h1`` are continuous-time sups.
    how
        :class:`~drip_cert.provenance.How` of ``h0`` and ``h1``.
    """

    h0: float
    h1: float
    h0_grid: float
    h1_grid: float
    t_h0: float
    t_h1: float
    continuous: bool
    how: How


def _norms(delta, jac) -> tuple[np.ndarray, np.ndarray]:
    """Euclidean norms of ``delta`` ((N,) norms or (N, m) vectors) and operator norms of ``jac``
    ((N,) norms or (N, m, n) matrices, the spectral norm rounded up)."""
    d = np.asarray(delta, dtype=np.float64)
    j = np.asarray(jac, dtype=np.float64)
    if d.ndim == 2:
        d = norm2_up_np(d, axis=1)  # rigorous upper bounds (drip_cert.numerics.rounding)
    if j.ndim == 3:
        j = np.asarray(spectral_norm_upper(j), dtype=np.float64).reshape(j.shape[0])
    if d.ndim != 1 or j.ndim != 1 or d.shape != j.shape or d.size == 0:
        raise SpecError(
            "delta must be (N,) norms or (N, m) vectors and jac (N,) norms or (N, m, n) matrices "
            f"on the same N >= 1 grid points; got shapes {np.shape(delta)} and {np.shape(jac)}",
            field="delta",
        )
    if not (np.all(np.isfinite(d)) and np.all(np.isfinite(j))) or np.any(d < 0) or np.any(j < 0):
        raise SpecError("delta/jac norms must be finite and >= 0", field="delta")
    return d, j


def h_discrete(delta, jac) -> TrajectoryH:
    """``h_0 = max_t ||Delta(x*_t)||`` and ``h_1 = max_t ||d Delta(x*_t)||_op`` over the time steps
    ``t = 0..T-1`` of a discrete-time expert trajectory (docs/math/tasil.md section 3.1, A3).

    Parameters
    ----------
    delta
        ``(N,)`` norms or ``(N, m)`` values of ``Delta = pi_hat - pi_star`` at ``x*_0..x*_{T-1}``.
    jac
        ``(N,)`` operator norms or ``(N, m, n)`` Jacobians of ``Delta`` there. (Frobenius norms
        are a valid, conservative substitute for operator norms.)

    Returns
    -------
    TrajectoryH
        ``how = SOUND``; ``h0 = h0_grid``, ``h1 = h1_grid``; the times are grid indices.
    """
    d, j = _norms(delta, jac)
    i0, i1 = int(np.argmax(d)), int(np.argmax(j))
    return TrajectoryH(
        float(d[i0]), float(j[i1]), float(d[i0]), float(j[i1]), i0, i1, False, How.SOUND
    )


def _sound_sup(t: np.ndarray, v: np.ndarray, rate: np.ndarray, what: str) -> np.ndarray:
    """Per-interval sound sup of a function with grid values ``v`` and time-Lipschitz constant
    ``rate[i]`` on ``[t_i, t_{i+1}]``: ``max(v_i, v_{i+1}, (v_i + v_{i+1} + rate_i dt_i) / 2)``
    (docs/math/tasil.md Proposition 4.2).

    The function lies below both cones ``v_i + rate (s - t_i)`` and
    ``v_{i+1} + rate (t_{i+1} - s)``; the lower envelope peaks at
    ``(v_i + v_{i+1} + rate dt) / 2``. Grid values that jump by more than ``rate * dt``
    contradict the constants and raise :class:`SpecError`.
    """
    dt = np.diff(t)
    slack = rate * dt
    jump = np.abs(np.diff(v))
    bad = jump > slack * (1.0 + _CONSISTENCY_RTOL) + _CONSISTENCY_RTOL * np.maximum(v[1:], v[:-1])
    if np.any(bad):
        i = int(np.argmax(bad))
        raise SpecError(
            f"{what}: the grid values jump by {jump[i]:.6g} on [{t[i]:.6g}, {t[i + 1]:.6g}] "
            f"but the given constants allow only {slack[i]:.6g}; the speed bound or L_Delta "
            "is too small",
            field="speed",
        )
    peak = 0.5 * (v[:-1] + v[1:] + slack)
    peak = np.maximum(peak, np.maximum(v[:-1], v[1:]))
    return peak * (1.0 + REL_PAD) + 1e-300


def h_continuous(t, delta, jac, speed, L_Delta: float) -> TrajectoryH:
    """Sound continuous-time ``h_0``, ``h_1`` along an expert trajectory (docs/math/tasil.md
    section 4).

    Between grid points, ``|d/dt ||d Delta(x*_t)||| <= L_Delta ||x*_dot||`` gives the sound ``h_1``;
    then ``|d/dt ||Delta(x*_t)||| <= ||d Delta(x*_t)|| ||x*_dot||``, with ``||d Delta||`` bounded on
    each interval by that interval's sound sup, gives the sound ``h_0``. Only ``d Delta`` *along the
    trajectory* enters, so no global Lipschitz constant of ``Delta`` is needed.

    Parameters
    ----------
    t
        Increasing time grid ``(N,)`` covering the interval ``[t_0, t_{N-1}]`` of the sup.
    delta, jac
        As in :func:`h_discrete`, at the grid times.
    speed
        ``sup ||x*_dot||``: a scalar, or ``(N-1,)`` per-interval sups.
    L_Delta
        Lipschitz constant of ``d Delta`` (operator norm) along the trajectory.

    Returns
    -------
    TrajectoryH
        ``how = SOUND``; ``h0 >= h0_grid``, ``h1 >= h1_grid``.
    """
    d, j = _norms(delta, jac)
    t = np.asarray(t, dtype=np.float64)
    if t.shape != d.shape or t.size < 2 or np.any(np.diff(t) <= 0) or not np.all(np.isfinite(t)):
        raise SpecError(
            f"t must be a strictly increasing finite grid with one time per value "
            f"(>= 2 points), got shape {t.shape} for {d.size} values",
            field="t",
        )
    L = positive("L_Delta", L_Delta, allow_zero=True)
    v = np.broadcast_to(np.asarray(speed, dtype=np.float64), (t.size - 1,))
    if not np.all(np.isfinite(v)) or np.any(v < 0):
        raise SpecError(f"speed must be finite and >= 0, got {speed!r}", field="speed")
    sup1 = _sound_sup(t, j, L * v, "h1 (Jacobian norm)")
    sup0 = _sound_sup(t, d, sup1 * v, "h0 (policy error norm)")
    i0, i1 = int(np.argmax(d)), int(np.argmax(j))
    return TrajectoryH(
        float(sup0.max()),
        float(sup1.max()),
        float(d[i0]),
        float(j[i1]),
        float(t[i0]),
        float(t[i1]),
        True,
        How.SOUND,
    )


def h0_lipschitz(t, delta, speed, lip: float) -> float:
    """Sound continuous-time ``h_0 = sup_t ||Delta(x*_t)||`` along an expert trajectory from a
    Lipschitz constant ``lip`` of ``Delta`` alone (docs/math/tasil.md section 4 with
    ``|d/dt ||Delta(x*_t)||| <= lip ||x*_dot||``): no Jacobian-Lipschitz constant, so it serves a
    piecewise-linear (relu) policy, whose Clarke Jacobians are bounded by ``lip``.

    ``t``: increasing grid ``(N,)``; ``delta``: ``Delta`` at the grid points ``(N, m)``;
    ``speed``: ``sup ||x*_dot||`` per interval ``(N-1,)`` (or a scalar).
    """
    d = np.linalg.norm(np.asarray(delta, dtype=np.float64).reshape(len(t), -1), axis=1)
    t = np.asarray(t, dtype=np.float64)
    if t.size < 2 or np.any(np.diff(t) <= 0) or not np.all(np.isfinite(t)):
        raise SpecError("t must be a strictly increasing finite grid of >= 2 points", field="t")
    L = positive("lip", lip, allow_zero=True)
    v = np.broadcast_to(np.asarray(speed, dtype=np.float64), (t.size - 1,))
    if not np.all(np.isfinite(v)) or np.any(v < 0):
        raise SpecError(f"speed must be finite and >= 0, got {speed!r}", field="speed")
    return float(np.max(_sound_sup(t, d, L * v, "h0 (policy error norm)")))


def h_from_functions(
    states,
    delta_fn: Callable[[np.ndarray], np.ndarray],
    jac_fn: Callable[[np.ndarray], np.ndarray],
    *,
    t=None,
    speed=None,
    L_Delta: float | None = None,
) -> TrajectoryH:
    """:func:`h_discrete` (``t is None``) or :func:`h_continuous` with ``Delta`` and its Jacobian
    evaluated by callables on the expert states (docs/math/tasil.md A3, section 4).

    Parameters
    ----------
    states
        ``(N, n)`` expert states.
    delta_fn, jac_fn
        ``delta_fn(states) -> (N, m)`` values and ``jac_fn(states) -> (N, m, n)`` Jacobians of
        ``Delta``; any policy pair.
    t, speed, L_Delta
        As in :func:`h_continuous`; ``t=None`` gives the discrete-time maxima.

    Returns
    -------
    TrajectoryH
    """
    states = np.asarray(states, dtype=np.float64)
    d = np.asarray(delta_fn(states), dtype=np.float64)
    j = np.asarray(jac_fn(states), dtype=np.float64)
    if t is None:
        return h_discrete(d, j)
    if speed is None or L_Delta is None:
        raise SpecError(
            "continuous-time h needs speed and L_Delta (or pass t=None for the discrete max)",
            field="speed",
        )
    return h_continuous(t, d, j, speed, L_Delta)
