"""DAgger and DART: the two interactive imitation baselines beside TaSIL and BC.

Both start from the same expert demonstrations as BC and TaSIL and spend the same label budget:
``n`` trajectories of ``k + 1`` samples, each sample labelled by the expert (the last sample of a
trajectory is not used by the loss, as in DRIP eq. (LossTaSIL)). The ``n`` trajectories are split
over ``I`` iterations (:func:`split_budget`); iteration 0 is the first ``n_0`` trajectories of the
expert training set, so every method sees the same first data.

* **DAgger** (Ross, Gordon and Bagnell 2011, Algorithm 3.1 with ``beta_i = 1[i = 0]``): after
  iteration ``i`` the learner ``pi_i`` is trained on the aggregate ``D_0 u ... u D_i`` and rolled
  out (noise-free, on the nominal model) from ``n_{i+1}`` fresh initial states ``xi ~ D``; every
  visited state ``x`` is labelled with the expert's action ``pi*(x)`` exactly (the expert is
  known analytically, so DAgger's interactive expert is available in simulation) and added.
* **DART** (Laskey, Lee, Fox, Dragan and Goldberg 2017, Algorithm 1): after iteration ``i`` the
  learner is trained on the aggregate, the noise covariance is fitted to its error on the
  aggregate, ``Sigma = mean_x (pi_i(x) - pi*(x)) (pi_i(x) - pi*(x))^T`` (DART eq. (5), the
  maximum-likelihood Gaussian of the learner's error, without the optional ``alpha`` prior), and
  ``n_{i+1}`` fresh expert trajectories are collected with ``u = pi*(x) + eta_j``,
  ``eta_j ~ N(0, Sigma)`` i.i.d. and held over each sample interval ``[t_j, t_{j+1})``; the
  labels are the clean expert actions ``pi*(x)``. A fixed ``noise_cov`` replaces the fit.

Both use the behaviour-cloning loss (value matching, as the original algorithms); the final
learner is trained on the whole aggregate with the full step budget, intermediate learners with
``steps // I`` steps (so the gradient-step budget is at most twice BC's).
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass
from typing import Any

import numpy as np

from drip_cert._jax import jax, jnp
from drip_cert.errors import SpecError
from drip_cert.learn.data import (
    DEFAULT_SUBSTEPS,
    Demonstrations,
    expert_actions,
    sample_initial_states,
    simulate_closed_loop,
)

BASELINES = ("dagger", "dart")  #: the interactive methods of this module
DEFAULT_ITERATIONS = 4
"""Data-collection iterations ``I`` of DAgger and DART (Ross et al. and Laskey et al. use 4-20;
with n = 20 trajectories, 4 gives 5 trajectories per iteration)."""

DIVERGENCE_FACTOR = 10.0
"""A learner rollout whose state norm exceeds this many times the largest expert training state
is treated as diverged: its states are far outside the region the expert's data describe, and a
few of them would dominate the mean-square loss."""

_STREAM_BASE = 16
"""Key streams ``16 + i`` of the seed draw iteration ``i``'s initial states and noise (streams 0
and 1 are the training and held-out expert demonstrations)."""

Fit = Callable[[Demonstrations, int], tuple[Any, Callable]]
"""``fit(data, steps) -> (train_result, policy)``: trains on ``data`` (BC loss), returns the
result and the whole learned policy ``x -> u`` (jax-traceable)."""


@dataclass(frozen=True)
class BaselineRound:
    """One data-collection iteration of DAgger or DART.

    ``source``: ``"expert"`` (iteration 0), ``"learner"`` (DAgger) or ``"noisy expert"`` (DART);
    ``replaced``: learner rollouts that diverged and were replaced by the expert's rollout from
    the same initial state (DAgger); ``noise_cov``: the DART covariance used to collect this
    iteration's data (``None`` otherwise); ``steps``: training steps of the learner that
    collected it (0 for iteration 0).
    """

    iteration: int
    trajectories: int
    source: str
    replaced: int = 0
    noise_cov: tuple[tuple[float, ...], ...] | None = None
    steps: int = 0

    def as_dict(self) -> dict[str, object]:
        return {
            "iteration": self.iteration,
            "trajectories": self.trajectories,
            "source": self.source,
            "replaced": self.replaced,
            "noise_cov": None if self.noise_cov is None else [list(r) for r in self.noise_cov],
            "steps": self.steps,
        }


@dataclass(frozen=True)
class BaselineRun:
    """What :func:`train_baseline` produced: the final learner trained on ``data``, the
    aggregate of every iteration, and the rounds."""

    method: str
    result: Any  #: drip_cert.learn.tasil.TrainResult of the final learner
    policy: Callable
    data: Demonstrations
    rounds: tuple[BaselineRound, ...]

    @property
    def labels(self) -> int:
        """Expert-labelled states the loss uses: ``N k`` (the last sample is not used)."""
        return int(self.data.n_traj * self.data.k)


def split_budget(n: int, iterations: int) -> tuple[int, ...]:
    """``n`` trajectories over ``min(iterations, n)`` iterations, as equal as possible, the
    larger shares first: ``sum == n`` and each share is ``>= 1``."""
    if int(n) != n or n < 1:
        raise SpecError(f"the number of trajectories must be >= 1, got {n!r}", field="trajectories")
    if int(iterations) != iterations or iterations < 1:
        raise SpecError(
            f"the number of iterations must be >= 1, got {iterations!r}", field="iterations"
        )
    it = min(int(iterations), int(n))
    q, r = divmod(int(n), it)
    return tuple(q + (1 if i < r else 0) for i in range(it))


def learner_rollouts(
    field: Callable,
    expert: Callable,
    policy: Callable,
    x0s: np.ndarray,
    T: float,
    k: int,
    bound: float,
    substeps: int = DEFAULT_SUBSTEPS,
) -> tuple[Demonstrations, int]:
    """DAgger's data: the learner's closed loop ``x' = field(t, x, policy(x))`` from each
    initial state, sampled on ``{0, T/k, ..., T}``, every state labelled by ``expert(x)``.

    A rollout that is not finite or leaves the ball of radius ``bound`` is replaced by the
    expert's rollout from the same initial state (the label budget stays the same).

    Returns
    -------
    (Demonstrations, int)
        The labelled rollouts and the number of replaced ones.
    """
    x0s = np.asarray(x0s, dtype=np.float64)
    states = simulate_closed_loop(field, policy, x0s, T, k, substeps)
    with np.errstate(invalid="ignore", over="ignore"):
        norms = np.linalg.norm(states, axis=-1)
    bad = ~np.all(np.isfinite(states), axis=(1, 2)) | ~np.all(norms <= bound, axis=1)
    if np.any(bad):
        states = states.copy()
        states[bad] = simulate_closed_loop(field, expert, x0s[bad], T, k, substeps)
    times = np.linspace(0.0, T, k + 1)
    demos = Demonstrations(
        times,
        states,
        expert_actions(expert, states),
        x0s,
        source=f"learner rollouts labelled by the expert ({int(bad.sum())} replaced)",
    )
    return demos, int(bad.sum())


def dart_noise(key, cov: np.ndarray, n: int, k: int) -> np.ndarray:
    """``(n, k, m)`` i.i.d. draws ``eta = L z``, ``z ~ N(0, I)``, with ``L L^T = cov`` (the
    symmetric square root, so a singular ``cov`` is allowed)."""
    cov = np.asarray(cov, dtype=np.float64)
    if cov.ndim != 2 or cov.shape[0] != cov.shape[1] or not np.all(np.isfinite(cov)):
        raise SpecError(
            f"the DART noise covariance must be a finite square matrix, got shape {cov.shape}",
            field="noise_cov",
        )
    sym = 0.5 * (cov + cov.T)
    w, V = np.linalg.eigh(sym)
    if w.min() < -1e-12 * max(1.0, float(np.abs(w).max())):
        raise SpecError(
            f"the DART noise covariance must be positive semidefinite (smallest eigenvalue "
            f"{w.min():.3g})",
            field="noise_cov",
        )
    L = V @ np.diag(np.sqrt(np.clip(w, 0.0, None))) @ V.T
    z = np.asarray(jax.random.normal(key, (int(n), int(k), cov.shape[0]), dtype=jnp.float64))
    return z @ L.T


def noisy_expert_rollouts(
    field: Callable,
    expert: Callable,
    x0s: np.ndarray,
    T: float,
    k: int,
    noise: np.ndarray,
    substeps: int = DEFAULT_SUBSTEPS,
) -> Demonstrations:
    """DART's data: ``x' = field(t, x, expert(x) + noise[i, j])`` on ``[t_j, t_{j+1})`` (RK4,
    ``substeps`` steps per interval), sampled on ``{0, T/k, ..., T}``; the actions are the
    clean expert labels ``expert(x)``."""
    x0s = np.asarray(x0s, dtype=np.float64)
    noise = np.asarray(noise, dtype=np.float64)
    if noise.ndim != 3 or noise.shape[:2] != (x0s.shape[0], int(k)):
        raise SpecError(
            f"the DART noise must have shape ({x0s.shape[0]}, {k}, m), got {noise.shape}",
            field="noise",
        )
    dt = float(T) / int(k)
    h = dt / int(substeps)

    def one(x0, eta):
        def interval(x, j):
            e = eta[j]

            def rhs(s, y):
                return field(s, y, expert(y) + e)

            def sub(y, i):
                t = j * dt + i * h
                k1 = rhs(t, y)
                k2 = rhs(t + 0.5 * h, y + 0.5 * h * k1)
                k3 = rhs(t + 0.5 * h, y + 0.5 * h * k2)
                k4 = rhs(t + h, y + h * k3)
                return y + (h / 6.0) * (k1 + 2.0 * k2 + 2.0 * k3 + k4), None

            x_next, _ = jax.lax.scan(sub, x, jnp.arange(int(substeps)))
            return x_next, x_next

        _, xs = jax.lax.scan(interval, x0, jnp.arange(int(k)))
        return jnp.concatenate([x0[None, :], xs], axis=0)

    states = np.asarray(jax.jit(jax.vmap(one))(jnp.asarray(x0s), jnp.asarray(noise)))
    if not np.all(np.isfinite(states)):
        raise SpecError(
            "the noisy expert closed loop produced NaN/inf states: the DART noise is too large "
            "for the expert to stabilise the nominal model",
            field="noise_cov",
        )
    return Demonstrations(
        np.linspace(0.0, T, k + 1),
        states,
        expert_actions(expert, states),
        x0s,
        source="expert rollouts with DART noise, labelled by the clean expert",
    )


def error_covariance(policy: Callable, expert: Callable, states: np.ndarray) -> np.ndarray:
    """``mean_x (policy(x) - expert(x)) (policy(x) - expert(x))^T`` over ``states (..., n)``:
    DART's fitted noise covariance (Laskey et al. 2017, eq. (5))."""
    err = expert_actions(policy, states) - expert_actions(expert, states)
    e = err.reshape(-1, err.shape[-1])
    return (e.T @ e) / e.shape[0]


def concat(parts: list[Demonstrations]) -> Demonstrations:
    """The trajectories of ``parts`` (same time grid) as one set."""
    return Demonstrations(
        parts[0].times,
        np.concatenate([p.states for p in parts]),
        np.concatenate([p.actions for p in parts]),
        np.concatenate([p.x0 for p in parts]),
        source="; ".join(dict.fromkeys(p.source for p in parts)),
    )


def train_baseline(
    method: str,
    expert_demos: Demonstrations,
    field: Callable,
    expert: Callable,
    support,
    fit: Fit,
    steps: int,
    seed: int,
    *,
    iterations: int = DEFAULT_ITERATIONS,
    noise_cov: np.ndarray | None = None,
    substeps: int = DEFAULT_SUBSTEPS,
) -> BaselineRun:
    """Run DAgger or DART (module docstring) with the label budget of ``expert_demos``.

    Parameters
    ----------
    method
        ``"dagger"`` or ``"dart"``.
    expert_demos
        The expert training demonstrations of BC and TaSIL: their ``n`` and grid fix the budget,
        their first ``n_0`` trajectories are iteration 0.
    field, expert, support
        Nominal drift ``field(t, x, u)``, expert ``pi*`` and the support box of ``D``.
    fit
        Trains a learner on a data set (:data:`Fit`).
    steps, seed
        Steps of the final training (intermediate ones: ``steps // I``); the seed of the fresh
        initial states and of the DART noise (key streams ``16 + i``).
    iterations
        ``I``; at most ``n``.
    noise_cov
        DART: a fixed ``(m, m)`` covariance instead of the fitted one.
    """
    if method not in BASELINES:
        raise SpecError(f"method must be one of {BASELINES}, got {method!r}", field="method")
    shares = split_budget(expert_demos.n_traj, iterations)
    T, k = expert_demos.horizon, expert_demos.k
    data = [expert_demos.subset(np.arange(shares[0]))]
    rounds = [BaselineRound(0, shares[0], "expert")]
    bound = DIVERGENCE_FACTOR * float(np.max(np.linalg.norm(expert_demos.states, axis=-1)))
    inner = max(int(steps) // len(shares), 1)
    base = jax.random.PRNGKey(int(seed))
    for i, n_i in enumerate(shares[1:], start=1):
        agg = concat(data)
        _, policy = fit(agg, inner)
        key_x0, key_noise = jax.random.split(jax.random.fold_in(base, _STREAM_BASE + i))
        x0s = sample_initial_states(support, n_i, key_x0)
        if method == "dagger":
            part, replaced = learner_rollouts(field, expert, policy, x0s, T, k, bound, substeps)
            rounds.append(BaselineRound(i, n_i, "learner", replaced=replaced, steps=inner))
        else:
            cov = (
                error_covariance(policy, expert, agg.states[:, :-1])
                if noise_cov is None
                else np.asarray(noise_cov, dtype=np.float64)
            )
            eta = dart_noise(key_noise, cov, n_i, k)
            part = noisy_expert_rollouts(field, expert, x0s, T, k, eta, substeps)
            rounds.append(
                BaselineRound(
                    i,
                    n_i,
                    "noisy expert",
                    noise_cov=tuple(tuple(float(v) for v in row) for row in cov),
                    steps=inner,
                )
            )
        data.append(part)
    agg = concat(data)
    result, policy = fit(agg, int(steps))
    return BaselineRun(method, result, policy, agg, tuple(rounds))
