"""Imitation losses: behaviour cloning and TaSIL of order 1 and 2.

TaSIL (Pfrommer et al. 2022; DRIP eq. (LossTaSIL)) matches the policy error
``Delta = pi_hat - pi*`` and its derivatives along expert states. Per expert state ``x``:

    e_0(x) = ||pi_hat(x) - pi*(x)||_2
    e_1(x) = ||d_x pi_hat(x) - d_x pi*(x)||_F          (order >= 1)
    e_2(x) = ||d_x^2 pi_hat(x) - d_x^2 pi*(x)||_F      (order 2)

with NON-squared norms, as the reference implementation (unstable-zeros/TaSIL,
``imitation_learning/__init__.py``) and as eq. (LossTaSIL). Jacobians come from
``jax.jacrev`` under ``vmap``, Hessians from ``jax.jacfwd(jax.jacrev(.))``; the outer
``jax.grad`` over the parameters differentiates through them.

Two reductions over the training states:

* ``"mean"`` (the reference code): ``mean_{i,t} [e_0 + lambda_J e_1 + lambda_H e_2]``;
* ``"max"`` (DRIP eq. (LossTaSIL)): ``mean_i [max_t e_0 + lambda_J max_t e_1 +
  lambda_H max_t e_2]``, the empirical mean over trajectories of per-trajectory maxima over the
  partition without its last point. DRIP writes a factor 1/2 in front (with lambda_J = 1); a
  constant factor changes neither the minimiser nor Adam's steps (up to Adam's epsilon), so it is
  left out and the two reductions agree on a single state.

Behaviour cloning (BC) is order 0: ``e_0`` only.

**Matching on the tube** (:func:`tube_points`, :func:`tube_loss`): the certificate needs
``||Delta||`` and ``||d_x Delta||`` small along the expert trajectories of NEW initial states
(their sups ``h_0, h_1``, whose held-out thresholds are 1.25 x the training maxima) and the
curvature of ``Delta`` small on the whole box ``B`` around the demonstrations (its ``L_Delta``,
docs/math/tasil.md 3.12), not only at the demonstrated states, which crowd near the equilibrium.
An optional term adds, with weight ``w``, the first-order error at points ``y_j`` drawn uniformly
on the box of the training states enlarged by the tube radius ``r``:

    L_tube = w * mean_j (||pi_hat(y_j) - pi*(y_j)|| + ||d_x pi_hat(y_j) - d_x pi*(y_j)||_F)

(docs/math/tasil.md section 5.1). It is minimal (every norm at its floor) exactly when the values
and the Jacobians agree at every drawn point.
"""

from __future__ import annotations

import math
from collections.abc import Callable
from dataclasses import dataclass
from functools import partial

from drip_cert._jax import jax, jnp
from drip_cert.errors import SpecError

SAFE_NORM_FLOOR = 1e-8
"""Lower bound of :func:`safe_norm`, as ``safe_norm(x, 1e-8)`` of the reference code."""

REDUCTIONS = ("mean", "max")


def safe_norm(x, floor: float = SAFE_NORM_FLOOR):
    """Euclidean (Frobenius) norm of all entries of ``x``, floored at ``floor``, NaN-safe.

    Returns ``max(||x||, floor)``, i.e. ``sqrt(max(sum x^2, floor^2))``. The gradient of
    ``||x||`` at ``x = 0`` is NaN in jax (0/0); here, below the floor the inner ``where``
    replaces ``x`` by ones before the square root (the "double where" trick of the reference
    implementation), so the gradient is exactly 0 there and finite everywhere.
    """
    sq = jnp.sum(jnp.square(x))
    small = sq < floor * floor
    safe_sq = jnp.where(small, 1.0, sq)
    return jnp.where(small, floor, jnp.sqrt(safe_sq))


@dataclass(frozen=True)
class LossSpec:
    """Which imitation loss to minimise.

    Parameters
    ----------
    order
        0 = behaviour cloning, 1 = TaSIL-1 (value + Jacobian), 2 = TaSIL-2 (+ Hessian).
    lambda_j
        Weight of the Jacobian term (reference code: 1 for orders 1 and 2).
    lambda_h
        Weight of the Hessian term (reference code: 10 for order 2).
    reduction
        ``"mean"`` over states (reference code) or ``"max"`` over each trajectory's partition
        then mean over trajectories (DRIP eq. (LossTaSIL)).
    floor
        Floor of :func:`safe_norm`.
    """

    order: int = 1
    lambda_j: float = 1.0
    lambda_h: float = 10.0
    reduction: str = "mean"
    floor: float = SAFE_NORM_FLOOR

    def __post_init__(self) -> None:
        if self.order not in (0, 1, 2):
            raise SpecError(
                f"TaSIL order must be 0 (BC), 1 or 2, got {self.order!r}", field="order"
            )
        if self.reduction not in REDUCTIONS:
            raise SpecError(
                f"reduction must be one of {REDUCTIONS}, got {self.reduction!r}",
                field="reduction",
            )
        for name in ("lambda_j", "lambda_h"):
            value = getattr(self, name)
            if not (math.isfinite(value) and value >= 0):
                raise SpecError(f"{name} must be finite and >= 0, got {value!r}", field=name)
        if not (self.floor > 0):
            raise SpecError(f"floor must be > 0, got {self.floor!r}", field="floor")


@partial(
    jax.tree_util.register_dataclass,
    data_fields=["states", "actions", "jac", "hess"],
    meta_fields=[],
)
@dataclass(frozen=True)
class Targets:
    """Expert values and derivatives at the training states, arrays of shape ``(N, K, ...)``.

    ``states (N, K, n)``, ``actions (N, K, m)``, ``jac (N, K, m, n)`` (order >= 1, else
    ``None``), ``hess (N, K, m, n, n)`` (order 2, else ``None``); ``K`` = samples per trajectory
    used by the loss.
    """

    states: jax.Array
    actions: jax.Array
    jac: jax.Array | None = None
    hess: jax.Array | None = None

    def map_arrays(self, f: Callable[[jax.Array], jax.Array]) -> Targets:
        """``f`` applied to every array (an absent ``jac``/``hess`` stays ``None``)."""
        return Targets(
            f(self.states),
            f(self.actions),
            None if self.jac is None else f(self.jac),
            None if self.hess is None else f(self.hess),
        )

    def take(self, index) -> Targets:
        """The targets of the trajectories ``index``."""
        return self.map_arrays(lambda a: a[index])

    def flat(self) -> Targets:
        """The same targets with trajectories and times merged: shapes ``(1, N*K, ...)``."""
        return self.map_arrays(lambda a: a.reshape(1, -1, *a.shape[2:]))


def expert_targets(
    expert: Callable,
    states,
    actions,
    order: int,
    expert_jac: Callable | None = None,
) -> Targets:
    """Compute the expert Jacobians (and Hessians) at ``states`` ``(N, K, n)``.

    ``actions`` are the demonstrated expert inputs (``pi*(x)`` for generated data). The
    Jacobian is ``expert_jac(x)`` when given, else ``jax.jacrev(expert)(x)``; the Hessian is
    ``jax.jacfwd(jax.jacrev(expert))(x)``, both vmapped.
    """
    states = jnp.asarray(states)
    flat = states.reshape(-1, states.shape[-1])
    lead = states.shape[:-1]
    jac = hess = None
    if order >= 1:
        jfun = expert_jac if expert_jac is not None else jax.jacrev(expert)
        jac = jax.jit(jax.vmap(jfun))(flat)
        jac = jac.reshape(*lead, *jac.shape[1:])
    if order >= 2:
        hess = jax.jit(jax.vmap(jax.jacfwd(jax.jacrev(expert))))(flat)
        hess = hess.reshape(*lead, *hess.shape[1:])
    return Targets(states, jnp.asarray(actions), jac, hess)


def state_errors(policy: Callable, x, u_star, j_star, h_star, spec: LossSpec):
    """``(e_0, e_1, e_2)`` at one state ``x`` (zeros for orders above ``spec.order``).

    ``policy`` maps a state ``(n,)`` to an input ``(m,)``.
    """
    e0 = safe_norm(policy(x) - u_star, spec.floor)
    zero = jnp.zeros_like(e0)
    e1 = safe_norm(jax.jacrev(policy)(x) - j_star, spec.floor) if spec.order >= 1 else zero
    e2 = (
        safe_norm(jax.jacfwd(jax.jacrev(policy))(x) - h_star, spec.floor)
        if spec.order >= 2
        else zero
    )
    return e0, e1, e2


def error_table(policy: Callable, targets: Targets, spec: LossSpec):
    """Per-state errors ``e_0, e_1, e_2``, each of shape ``(N, K)``."""
    n_traj, n_time = targets.states.shape[:2]

    def flat_or_zeros(a, trailing):
        if a is None:
            return jnp.zeros((n_traj * n_time, *trailing))
        return a.reshape(n_traj * n_time, *a.shape[2:])

    n = targets.states.shape[-1]
    m = targets.actions.shape[-1]
    x = targets.states.reshape(-1, n)
    u = targets.actions.reshape(-1, m)
    j = flat_or_zeros(targets.jac, (m, n))
    h = flat_or_zeros(targets.hess, (m, n, n))
    e0, e1, e2 = jax.vmap(lambda a, b, c, d: state_errors(policy, a, b, c, d, spec))(x, u, j, h)
    return tuple(e.reshape(n_traj, n_time) for e in (e0, e1, e2))


def imitation_loss(policy: Callable, targets: Targets, spec: LossSpec):
    """The BC / TaSIL loss of ``policy`` on ``targets`` (see the module docstring)."""
    e0, e1, e2 = error_table(policy, targets, spec)
    if spec.reduction == "mean":
        per_state = e0 + spec.lambda_j * e1 + spec.lambda_h * e2
        return jnp.mean(per_state)
    per_traj = jnp.max(e0, axis=1)
    if spec.order >= 1:
        per_traj = per_traj + spec.lambda_j * jnp.max(e1, axis=1)
    if spec.order >= 2:
        per_traj = per_traj + spec.lambda_h * jnp.max(e2, axis=1)
    return jnp.mean(per_traj)


def tube_points(key, lo, hi, count: int):
    """``count`` points drawn uniformly on the box ``[lo, hi]`` (arrays ``(n,)``), from ``key``
    alone (same key, same points)."""
    u = jax.random.uniform(key, (count, lo.shape[-1]), dtype=lo.dtype)
    return lo + (hi - lo) * u


def tube_loss(policy: Callable, expert: Callable, expert_jac: Callable, points, floor: float):
    """``mean_j (||policy(y_j) - pi*(y_j)|| + ||d policy(y_j) - d pi*(y_j)||_F)`` over ``points``
    ``(M, n)``: TaSIL's first-order error at points off the demonstrations (module docstring),
    without its weight. Each norm is :func:`safe_norm` with ``floor``, so the value is ``2 floor``
    exactly where the values and the Jacobians agree at every point, and its gradient is finite
    everywhere.
    """

    def one(y):
        e0 = safe_norm(policy(y) - expert(y), floor)
        e1 = safe_norm(jax.jacrev(policy)(y) - expert_jac(y), floor)
        return e0 + e1

    return jnp.mean(jax.vmap(one)(points))
