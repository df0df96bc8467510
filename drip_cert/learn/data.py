"""Expert demonstrations: the training data of the DRIP paper's Definition "Training Data".

The training set (DRIP, Definition "Training Data", eq. (partition)) is the collection of
nominal expert states ``x*_t(xi_i)`` at the times of the uniform partition
``{0, T/k, 2T/k, ..., T}`` of the horizon, for ``n`` initial states ``xi_i`` drawn i.i.d. from
the initial law ``D``. Here ``D`` is the uniform law on a support box, the nominal closed loop is
``x' = f(t, x) + g(t) pi*(x)``, given as a jax-traceable ``field(t, x, u)`` and ``expert(x)``,
and it is integrated with the classical fixed-step Runge-Kutta method of order 4 (RK4).

Integration error
-----------------
Every sample interval ``T/k`` is split into ``substeps`` RK4 steps of size
``h = T / (k * substeps)``. RK4 has global error ``O(h^4)``: on ``[0, T]`` the error is at most
``C h^4 (e^{L T} - 1) / L`` with ``L`` the Lipschitz constant of the closed loop and ``C`` a bound
on its fifth derivatives. :func:`generate_demonstrations` does not rely on this bound: it also
integrates with ``2 * substeps`` and records the Richardson estimate
``max |x_h - x_{h/2}| * 16/15`` of the error of the stored (coarser) solution in
``Demonstrations.integration_error``. Measured on the paper-like 4-D example (T = 10, k = 100,
substeps = 8, h = 0.0125): the expert closed loop ``x' = -0.1 x`` matches its closed form to
7e-15, and the nonlinear closed loop with ``u = -0.2 x`` matches ``scipy.integrate.solve_ivp``
(DOP853, rtol = atol = 1e-12) to 1.3e-11, the accuracy of the reference solver itself
(tests/test_learn_data.py also checks the observed order 4).
"""

from __future__ import annotations

import math
import os
from collections.abc import Callable
from dataclasses import dataclass
from functools import partial
from pathlib import Path

import numpy as np

from drip_cert._jax import jax, jnp
from drip_cert.errors import SpecError
from drip_cert.numerics.user_files import read_npz

DEFAULT_SUBSTEPS = 8
"""RK4 steps per sample interval (T/k); with T/k = 0.1 this gives h = 0.0125."""

_RICHARDSON_FACTOR = 16.0 / 15.0
"""|x_h - x*| ~ 16/15 |x_h - x_{h/2}| for a method of order 4."""

Field = Callable  # field(t, x, u) -> xdot, jax-traceable
Policy = Callable  # policy(x) -> u, jax-traceable


@dataclass(frozen=True)
class Demonstrations:
    """Expert trajectories sampled on a time grid (DRIP Definition "Training Data").

    Parameters
    ----------
    times
        ``(k+1,)`` strictly increasing sample times; for generated data the uniform partition
        ``{0, T/k, ..., T}`` of eq. (partition).
    states
        ``(N, k+1, n)`` expert states ``x*_t(xi_i)``.
    actions
        ``(N, k+1, m)`` expert inputs ``pi*(x*_t(xi_i))``.
    x0
        ``(N, n)`` initial states ``xi_i``; must equal ``states[:, 0]``.
    source
        Free text saying where the data came from (generator settings or a file name).
    integration_error
        Richardson estimate of the largest integration error in ``states`` (``nan`` when
        unknown, e.g. for user-provided trajectories).
    """

    times: np.ndarray
    states: np.ndarray
    actions: np.ndarray
    x0: np.ndarray
    source: str = ""
    integration_error: float = math.nan

    def __post_init__(self) -> None:
        arrays = _validated(self.times, self.states, self.actions, self.x0, where=None)
        for name, arr in zip(("times", "states", "actions", "x0"), arrays):
            object.__setattr__(self, name, arr)
        object.__setattr__(self, "source", str(self.source))
        object.__setattr__(self, "integration_error", float(self.integration_error))

    @property
    def n_traj(self) -> int:
        """Number of trajectories ``N``."""
        return int(self.states.shape[0])

    @property
    def state_dim(self) -> int:
        return int(self.states.shape[2])

    @property
    def input_dim(self) -> int:
        return int(self.actions.shape[2])

    @property
    def k(self) -> int:
        """Number of sample intervals (``k`` of eq. (partition))."""
        return int(self.times.shape[0] - 1)

    @property
    def horizon(self) -> float:
        """``T = times[-1] - times[0]``."""
        return float(self.times[-1] - self.times[0])

    def subset(self, index: np.ndarray) -> Demonstrations:
        """The demonstrations of the trajectories ``index`` (e.g. a train/validation split)."""
        index = np.asarray(index, dtype=np.int64)
        return Demonstrations(
            self.times,
            self.states[index],
            self.actions[index],
            self.x0[index],
            self.source,
            self.integration_error,
        )

    def save(self, path: str | Path) -> None:
        """Write an ``.npz`` file atomically (readable with ``allow_pickle=False``)."""
        save_demonstrations(self, path)

    @classmethod
    def load(cls, path: str | Path, expert: Policy | None = None) -> Demonstrations:
        """Read a file written by :meth:`save` or a user file; see :func:`load_demonstrations`."""
        return load_demonstrations(path, expert)


def _validated(times, states, actions, x0, where: str | None):
    """Validated read-only float64 copies of the four arrays of :class:`Demonstrations`."""
    times = _finite_array(times, "times", where)
    states = _finite_array(states, "states", where)
    actions = _finite_array(actions, "actions", where)
    x0 = _finite_array(x0, "x0", where)
    _check_times(times, where)
    if states.ndim != 3 or states.shape[1] != times.shape[0]:
        raise SpecError(
            f"array 'states' must have shape (N, {times.shape[0]}, n) to match 'times' "
            f"of length {times.shape[0]}, got {states.shape}",
            field="states",
            path=where,
        )
    if states.shape[0] < 1 or states.shape[2] < 1:
        raise SpecError(
            f"array 'states' must hold at least one trajectory of a state of dimension "
            f">= 1, got shape {states.shape}",
            field="states",
            path=where,
        )
    if actions.ndim != 3 or actions.shape[:2] != states.shape[:2] or actions.shape[2] < 1:
        raise SpecError(
            f"array 'actions' must have shape ({states.shape[0]}, {states.shape[1]}, m) "
            f"to match 'states', got {actions.shape}",
            field="actions",
            path=where,
        )
    if x0.shape != (states.shape[0], states.shape[2]):
        raise SpecError(
            f"array 'x0' must have shape {(states.shape[0], states.shape[2])}, got {x0.shape}",
            field="x0",
            path=where,
        )
    if not np.array_equal(x0, states[:, 0]):
        raise SpecError(
            "array 'x0' must equal states[:, 0] (the first sample of every trajectory); "
            f"largest difference {np.max(np.abs(x0 - states[:, 0])):.3g}",
            field="x0",
            path=where,
        )
    for arr in (times, states, actions, x0):
        arr.setflags(write=False)
    return times, states, actions, x0


def _finite_array(value, name: str, where: str | None) -> np.ndarray:
    try:
        arr = np.array(value, dtype=np.float64)
    except (TypeError, ValueError) as exc:
        raise SpecError(f"array {name!r} is not numeric: {exc}", field=name, path=where) from None
    bad = ~np.isfinite(arr)
    if np.any(bad):
        first = tuple(int(i) for i in np.argwhere(bad)[0])
        raise SpecError(
            f"array {name!r} contains {int(bad.sum())} NaN/inf entries (first at index {first}); "
            "remove or re-simulate the affected trajectories",
            field=name,
            path=where,
        )
    return arr


def _check_times(times: np.ndarray, where: str | None) -> None:
    if times.ndim != 1 or times.shape[0] < 2:
        raise SpecError(
            f"array 'times' must be 1-D with at least 2 samples, got shape {times.shape}",
            field="times",
            path=where,
        )
    steps = np.diff(times)
    if np.any(steps <= 0):
        i = int(np.argmax(steps <= 0))
        raise SpecError(
            f"array 'times' must be strictly increasing, but times[{i + 1}] = {times[i + 1]!r} "
            f"<= times[{i}] = {times[i]!r}",
            field="times",
            path=where,
        )


def check_support(support) -> np.ndarray:
    """Validate a support box ``(n, 2)`` of ``[low, high]`` rows and return it as float64."""
    box = np.array(support, dtype=np.float64)
    if box.ndim != 2 or box.shape[1] != 2 or box.shape[0] < 1:
        raise SpecError(
            f"the support box must have shape (n, 2) with rows [low, high], got {box.shape}",
            field="support",
        )
    if not np.all(np.isfinite(box)):
        raise SpecError("the support box must be finite (uniform law on a box)", field="support")
    if np.any(box[:, 0] > box[:, 1]):
        i = int(np.argmax(box[:, 0] > box[:, 1]))
        raise SpecError(
            f"support row {i} has low {box[i, 0]!r} > high {box[i, 1]!r}; swap them",
            field=f"support[{i}]",
        )
    return box


def sample_initial_states(support, n: int, key) -> np.ndarray:
    """Draw ``n`` initial states i.i.d. from ``D`` = the uniform law on the support box.

    Parameters
    ----------
    support
        ``(n_x, 2)`` array of ``[low, high]`` per coordinate.
    n
        Number of draws.
    key
        A ``numpy.random.Generator`` or a jax PRNG key (explicit randomness: the same key
        gives the same states).

    Returns
    -------
    numpy.ndarray
        ``(n, n_x)`` float64 initial states.
    """
    box = check_support(support)
    if int(n) != n or n < 1:
        raise SpecError(f"the number of initial states must be a positive integer, got {n!r}")
    n = int(n)
    lo, hi = box[:, 0], box[:, 1]
    if isinstance(key, np.random.Generator):
        return lo + (hi - lo) * key.random((n, box.shape[0]))
    try:
        u = jax.random.uniform(key, (n, box.shape[0]), dtype=jnp.float64)
    except (TypeError, ValueError) as exc:
        raise SpecError(
            f"key must be a numpy.random.Generator or a jax PRNG key, got {type(key).__name__}: "
            f"{exc}",
            field="key",
        ) from None
    return lo + (hi - lo) * np.asarray(u)


def _rk4_step(field: Field, policy: Policy, t, x, h):
    """One classical RK4 step of the closed loop ``x' = field(t, x, policy(x))``."""

    def rhs(s, y):
        return field(s, y, policy(y))

    k1 = rhs(t, x)
    k2 = rhs(t + 0.5 * h, x + 0.5 * h * k1)
    k3 = rhs(t + 0.5 * h, x + 0.5 * h * k2)
    k4 = rhs(t + h, x + h * k3)
    return x + (h / 6.0) * (k1 + 2.0 * k2 + 2.0 * k3 + k4)


@partial(jax.jit, static_argnames=("field", "policy", "k", "substeps"))
def _rollout(field: Field, policy: Policy, x0s, t0, T, k: int, substeps: int):
    """States ``(N, k+1, n)`` of the closed loop on the uniform grid, RK4 under ``lax.scan``."""
    dt = T / k
    h = dt / substeps

    def one(x0):
        def interval(x, j):
            def sub(y, i):
                return _rk4_step(field, policy, t0 + j * dt + i * h, y, h), None

            x_next, _ = jax.lax.scan(sub, x, jnp.arange(substeps))
            return x_next, x_next

        _, xs = jax.lax.scan(interval, x0, jnp.arange(k))
        return jnp.concatenate([x0[None, :], xs], axis=0)

    return jax.vmap(one)(x0s)


def _check_grid(T: float, k: int, substeps: int) -> None:
    if not (np.isfinite(T) and T > 0):
        raise SpecError(f"the horizon T must be a positive number, got {T!r}", field="T")
    if int(k) != k or k < 1:
        raise SpecError(f"the number of sample intervals k must be >= 1, got {k!r}", field="k")
    if int(substeps) != substeps or substeps < 1:
        raise SpecError(
            f"substeps must be a positive integer (RK4 steps per sample), got {substeps!r}",
            field="substeps",
        )


def simulate_closed_loop(
    field: Field,
    policy: Policy,
    x0s: np.ndarray,
    T: float,
    k: int,
    substeps: int = DEFAULT_SUBSTEPS,
    t0: float = 0.0,
) -> np.ndarray:
    """Integrate ``x' = field(t, x, policy(x))`` from each row of ``x0s`` and sample it.

    Fixed-step RK4 with ``substeps`` steps per sample interval ``T/k`` (see the module
    docstring for the error), jit-compiled under ``jax.lax.scan`` and vmapped over the initial
    states. The result is sampled on ``{t0, t0 + T/k, ..., t0 + T}``, the uniform partition of
    DRIP eq. (partition). A trajectory that diverges contains inf/NaN; nothing is raised.

    Returns
    -------
    numpy.ndarray
        ``(N, k+1, n)`` states.
    """
    _check_grid(T, k, substeps)
    x0s = np.asarray(x0s, dtype=np.float64)
    if x0s.ndim != 2:
        raise SpecError(f"initial states must have shape (N, n), got {x0s.shape}", field="x0s")
    out = _rollout(field, policy, jnp.asarray(x0s), float(t0), float(T), int(k), int(substeps))
    return np.asarray(out)


def expert_actions(expert: Policy, states: np.ndarray) -> np.ndarray:
    """``expert`` applied to every state of ``states`` ``(..., n)``; returns ``(..., m)``."""
    states = np.asarray(states, dtype=np.float64)
    flat = states.reshape(-1, states.shape[-1])
    u = np.asarray(jax.jit(jax.vmap(expert))(jnp.asarray(flat)))
    if u.ndim != 2:
        raise SpecError(
            f"the expert must map a state (n,) to an input (m,), got output shape {u.shape[1:]}",
            field="expert",
        )
    return u.reshape(*states.shape[:-1], u.shape[-1])


def generate_demonstrations(
    field: Field,
    expert: Policy,
    support,
    n: int,
    T: float,
    k: int,
    key,
    substeps: int = DEFAULT_SUBSTEPS,
) -> Demonstrations:
    """Roll out ``n`` nominal expert trajectories from ``xi_i ~ D`` (DRIP Def. "Training Data").

    Parameters
    ----------
    field
        ``field(t, x, u) -> xdot``: the nominal drift ``f(t, x) + g(t) u`` (jax-traceable).
    expert
        ``expert(x) -> u``, the expert policy ``pi*`` (jax-traceable).
    support
        ``(n_x, 2)`` support box of the uniform initial law ``D``.
    n
        Number of trajectories.
    T, k
        Horizon and number of intervals of the uniform partition ``{0, T/k, ..., T}``.
    key
        ``numpy.random.Generator`` or jax PRNG key for the initial states.
    substeps
        RK4 steps per sample interval.

    Returns
    -------
    Demonstrations
        States, expert actions and the Richardson estimate of the integration error.
    """
    _check_grid(T, k, substeps)
    x0 = sample_initial_states(support, n, key)
    states = simulate_closed_loop(field, expert, x0, T, k, substeps)
    fine = simulate_closed_loop(field, expert, x0, T, k, 2 * substeps)
    if not np.all(np.isfinite(states)):
        raise SpecError(
            "the expert closed loop produced NaN/inf states: the expert does not stabilise the "
            "nominal model on the support box, or T/(k*substeps) is too large",
            field="expert",
        )
    err = _RICHARDSON_FACTOR * float(np.max(np.abs(states - fine)))
    actions = expert_actions(expert, states)
    source = f"generated: n={n}, T={T!r}, k={k}, RK4 substeps={substeps}, D=uniform on box"
    times = np.linspace(0.0, float(T), int(k) + 1)
    return Demonstrations(times, states, actions, x0, source, err)


def save_demonstrations(demos: Demonstrations, path: str | Path) -> None:
    """Save ``demos`` to ``path`` (.npz, no pickles), written to a temporary file and renamed."""
    path = Path(path)
    path.parent.mkdir(parents=True, exist_ok=True)
    tmp = path.with_name(path.name + ".tmp")
    with open(tmp, "wb") as fh:
        np.savez(
            fh,
            times=demos.times,
            states=demos.states,
            actions=demos.actions,
            x0=demos.x0,
            source=np.array(demos.source),
            integration_error=np.array(demos.integration_error),
        )
    os.replace(tmp, path)


def load_demonstrations(path: str | Path, expert: Policy | None = None) -> Demonstrations:
    """Load demonstrations saved by :func:`save_demonstrations` or provided by a user.

    A user file is an ``.npz`` with arrays ``times`` ``(k+1,)`` and ``states`` ``(N, k+1, n)``
    (a single trajectory ``(k+1, n)`` is accepted) and optionally ``actions``
    ``(N, k+1, m)``. Missing actions are computed with ``expert``; missing ``x0`` is
    ``states[:, 0]``. Every problem raises :class:`~drip_cert.errors.SpecError` naming the file,
    the array and the problem.
    """
    path = Path(path)
    where = str(path)
    arrays = read_npz(path, "demonstrations file")
    for name in ("times", "states"):
        if name not in arrays:
            raise SpecError(
                f"array {name!r} is missing (found {sorted(arrays)}); a demonstrations file "
                "needs 'times' (k+1,) and 'states' (N, k+1, n), optionally 'actions'",
                field=name,
                path=where,
            )
    states = _finite_array(arrays["states"], "states", where)
    if states.ndim == 2:
        states = states[None]
    if "actions" in arrays:
        actions = _finite_array(arrays["actions"], "actions", where)
        if actions.ndim == 2 and states.shape[0] == 1:
            actions = actions[None]
    else:
        if expert is None:
            raise SpecError(
                "array 'actions' is missing and no expert was given to compute it; pass "
                "expert=... or add 'actions' (N, k+1, m)",
                field="actions",
                path=where,
            )
        if states.ndim != 3:
            raise SpecError(
                f"array 'states' must have shape (N, k+1, n), got {states.shape}",
                field="states",
                path=where,
            )
        actions = expert_actions(expert, states)
        if not np.all(np.isfinite(actions)):
            raise SpecError(
                "the expert returned NaN/inf on these states", field="actions", path=where
            )
    x0 = arrays["x0"] if "x0" in arrays else (states[:, 0] if states.ndim == 3 else states)
    source = str(arrays["source"]) if "source" in arrays else f"file: {where}"
    err = float(arrays["integration_error"]) if "integration_error" in arrays else math.nan
    times, states, actions, x0 = _validated(arrays["times"], states, actions, x0, where)
    return Demonstrations(times, states, actions, x0, source, err)
