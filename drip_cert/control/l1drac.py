"""The L1-DRAC feedback of L1-DRAC (15a)-(15c) as a pure, vectorisable time step.

The controller is the composition of a process predictor (15c), a piecewise-constant adaptation
law with sampling period ``T_s`` (15b) and a low-pass filter of bandwidth ``omega`` (15a) (Gahlawat,
Karumanchi, Hovakimyan, arXiv:2509.04619, Sec. 3.1; DRIP paper, Sec. "Bounding the Uncertainty
Induced Imitation Gap"). In DRIP the known drift seen by the predictor INCLUDES the mid-level
policy: ``f_known(t, x) = f(t, x) + g(t) pi_IL(x)``; the caller evaluates it once per step and
passes it in, so the plant and the predictor share it.

Discretisation (docs/math/l1drac.md section 10), on the simulation grid ``t_j = j dt`` with
``T_s = k dt`` (``k`` a positive integer):

1. if ``j > 0`` and ``j mod k == 0``: ``Lambda_hat <- lambda_s (1 - e^{lambda_s T_s})^{-1}
   (x_hat - x)`` and ``Theta <- Theta_ad(t_j)`` (15b); ``Lambda_hat = 0`` on ``[0, T_s)``;
2. ``u = -eta`` (15a);
3. ``eta <- e^{-omega dt} eta + (1 - e^{-omega dt}) Theta Lambda_hat``: the exact zero-order-hold
   solution of ``eta' = -omega eta + omega Theta Lambda_hat`` (Lambda_hat is constant on each
   ``dt`` step because ``dt`` divides ``T_s``);
4. ``x_hat <- x_hat + dt (-lambda_s (x_hat - x) + f_known + g u + Lambda_hat)``: Euler step of
   (15c), with ``x_hat(0) = x_0``.

A property of the law worth knowing [derived]: for a constant uncertainty ``sigma`` the estimate
converges to ``e^{-lambda_s T_s} sigma``, not to ``sigma`` (the prediction error sampled at
``iT_s`` is the integral of ``sigma`` over the previous period). The control therefore converges
to ``-e^{-lambda_s T_s} Theta_ad sigma``; the relative residual ``1 - e^{-lambda_s T_s}`` vanishes
as ``T_s -> 0``. This holds for the Euler predictor as well as for the exact one.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Generic, NamedTuple, TypeVar

from drip_cert._jax import jnp
from drip_cert.errors import SpecError

__all__ = ["L1Params", "L1State", "l1_init", "l1_step"]

_RATIO_RTOL = 1e-9

_Leaf = TypeVar("_Leaf")
"""Relative tolerance on ``T_s / dt`` being an integer: floating-point inputs such as
``T_s = 0.01, dt = 0.001`` give ratios within a few ulps of an integer; anything farther is a
genuine mismatch between the sampling period and the grid."""


@dataclass(frozen=True)
class L1Params:
    """Control parameters of L1-DRAC (15) and the simulation step.

    Parameters
    ----------
    omega
        Low-pass filter bandwidth of (15a), ``> 0``.
    lambda_s
        Process-predictor pole of (15c) (``A_s = -lambda_s I``), ``> 0``.
    Ts
        Sampling period of the adaptation law (15b), ``> 0``.
    dt
        Simulation step; must divide ``Ts`` exactly (``Ts = k dt``, ``k`` integer).
    """

    omega: float
    lambda_s: float
    Ts: float
    dt: float

    def __post_init__(self) -> None:
        for fld in ("omega", "lambda_s", "Ts", "dt"):
            v = getattr(self, fld)
            try:
                fv = float(v)
            except (TypeError, ValueError):
                raise SpecError(f"must be a number, got {v!r}", field=f"L1Params.{fld}") from None
            if not (math.isfinite(fv) and fv > 0.0):
                raise SpecError(
                    f"must be a finite positive number, got {v!r}", field=f"L1Params.{fld}"
                )
            object.__setattr__(self, fld, fv)
        ratio = self.Ts / self.dt
        k = round(ratio)
        if k < 1 or abs(ratio - k) > _RATIO_RTOL * max(1.0, ratio):
            raise SpecError(
                f"the sampling period Ts={self.Ts!r} is not an integer multiple of dt={self.dt!r} "
                f"(Ts/dt = {ratio!r}); choose dt = Ts/k for an integer k >= 1, e.g. "
                f"dt={self.Ts / max(1, math.ceil(ratio))!r}",
                field="L1Params.Ts",
            )

    @property
    def k(self) -> int:
        """Steps per sampling period, ``Ts / dt``."""
        return int(round(self.Ts / self.dt))

    @property
    def adaptation_gain(self) -> float:
        """``lambda_s (1 - e^{lambda_s T_s})^{-1} = -lambda_s / expm1(lambda_s T_s)`` of (15b).

        Equals the Hovakimyan-Cao piecewise-constant gain ``-Phi^{-1}(T_s) e^{A_s T_s}`` with
        ``A_s = -lambda_s I`` and ``Phi(T) = A_s^{-1}(e^{A_s T} - I)``
        (docs/math/l1drac.md section 4).
        """
        return -self.lambda_s / math.expm1(self.lambda_s * self.Ts)

    @property
    def filter_decay(self) -> float:
        """``e^{-omega dt}``: zero-order-hold transition of the filter (15a) over one step."""
        return math.exp(-self.omega * self.dt)

    @property
    def filter_input_gain(self) -> float:
        """``1 - e^{-omega dt} = -expm1(-omega dt)``: zero-order-hold input gain of (15a)."""
        return -math.expm1(-self.omega * self.dt)

    @property
    def estimate_bias(self) -> float:
        """``e^{-lambda_s T_s}``: steady-state ratio of the estimate to a constant uncertainty."""
        return math.exp(-self.lambda_s * self.Ts)


class L1State(NamedTuple, Generic[_Leaf]):
    """Controller state of one path at ``t_j`` (a jax pytree; add a leading axis to batch).

    The leaves are arrays, ``L1State[jnp.ndarray]``; the same structure with an axis (int) or
    ``None`` per leaf, ``L1State[int | None]``, is a ``jax.vmap`` ``in_axes``/``out_axes`` spec.

    Attributes
    ----------
    x_hat
        Predictor state ``(n,)`` of (15c).
    eta
        Filter state ``(m,)`` of (15a); the control is ``u = -eta``.
    lam_hat
        Held estimate ``Lambda_hat`` ``(n,)`` of (15b), full (matched + unmatched).
    theta
        ``Theta_ad`` ``(m, n)`` held from the last sampling instant.
    step
        The step counter ``j``.
    """

    x_hat: _Leaf
    eta: _Leaf
    lam_hat: _Leaf
    theta: _Leaf
    step: _Leaf


def l1_init(x0, theta0) -> L1State[jnp.ndarray]:
    """Initial state: ``x_hat(0) = x_0``, ``eta(0) = 0``, ``Lambda_hat = 0`` on ``[0, T_s)``.

    Parameters
    ----------
    x0
        Initial plant state ``(n,)`` (the predictor starts there, L1-DRAC (15c)).
    theta0
        ``Theta_ad(0)``, shape ``(m, n)``.
    """
    x0 = jnp.asarray(x0, dtype=jnp.float64)
    theta0 = jnp.asarray(theta0, dtype=jnp.float64)
    m = theta0.shape[0]
    return L1State(
        x_hat=x0,
        eta=jnp.zeros((m,), dtype=jnp.float64),
        lam_hat=jnp.zeros_like(x0),
        theta=theta0,
        step=jnp.zeros((), dtype=jnp.int64),
    )


def l1_step(params: L1Params, state: L1State[jnp.ndarray], x, f_known, g_t, theta_t):
    """One step of L1-DRAC (15a)-(15c) from ``t_j`` to ``t_{j+1} = t_j + dt``.

    Pure and shape-polymorphic over one path; use ``jax.vmap`` (with ``g_t``, ``theta_t``
    unbatched) for an ensemble and call it inside ``lax.scan``.

    Parameters
    ----------
    params
        :class:`L1Params` (static Python floats).
    state
        :class:`L1State` at ``t_j``.
    x
        Measured plant state ``X_{t_j}``, shape ``(n,)``.
    f_known
        Known drift at the measured state, ``f(t_j, x) + g(t_j) pi_IL(x)``, shape ``(n,)``.
    g_t
        ``g(t_j)``, shape ``(n, m)``.
    theta_t
        ``Theta_ad(t_j)``, shape ``(m, n)``; latched only at sampling instants (15b).

    Returns
    -------
    u : jnp.ndarray
        The L1 control ``U_{L1}(t_j) = -eta_j`` of (15a), shape ``(m,)``, held on the step.
    state : L1State
        The state at ``t_{j+1}``.
    """
    j = state.step
    sample = jnp.logical_and(j > 0, j % params.k == 0)
    tilde = state.x_hat - x
    lam_hat = jnp.where(sample, params.adaptation_gain * tilde, state.lam_hat)
    theta = jnp.where(sample, theta_t, state.theta)
    u = -state.eta
    eta = params.filter_decay * state.eta + params.filter_input_gain * _matvec(theta, lam_hat)
    gu = _matvec(g_t, u)
    x_hat = state.x_hat + params.dt * (-params.lambda_s * tilde + f_known + gu + lam_hat)
    return u, L1State(x_hat=x_hat, eta=eta, lam_hat=lam_hat, theta=theta, step=j + 1)


def _matvec(a, v):
    """``a @ v`` for one path: ``a`` ``(m, n)``, ``v`` ``(n,)``.

    float64: ``a @ v``. float32 (the float32 engine): the ``n`` column products summed in order
    ``k = 0 .. n-1``; vmapped over the paths, XLA's CPU batched product of small blocks costs as
    much in float32 as in float64 (~6 CPU ns per path-step for 4x4), the column form ~1 ns. Path
    by path either way, so no number depends on the batch.
    """
    if v.dtype != jnp.float32:
        return a @ v
    acc = a[:, 0] * v[0]
    for k in range(1, v.shape[0]):
        acc = acc + a[:, k] * v[k]
    return acc
