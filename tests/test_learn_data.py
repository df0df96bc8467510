"""Expert demonstrations: the RK4 integrator against closed forms and solve_ivp, the sampling of
initial states, the Demonstrations value object and its file formats."""

from __future__ import annotations

import math
from pathlib import Path

import numpy as np
import pytest
from scipy.integrate import solve_ivp

from drip_cert._jax import jax, jnp
from drip_cert.errors import SpecError
from drip_cert.learn.data import (
    Demonstrations,
    generate_demonstrations,
    load_demonstrations,
    sample_initial_states,
    save_demonstrations,
    simulate_closed_loop,
)
from tests.helpers import MC_FIVE_SIGMA, ROUNDING_ATOL
from tests.helpers import PAPER_LIKE_BOX as BOX
from tests.helpers import PAPER_LIKE_H_MLP as H_MLP
from tests.helpers import paper_like_expert as expert
from tests.helpers import paper_like_field as field

IVP_TOL = 1e-12  # rtol = atol of the DOP853 reference solution (near double precision)
RK4_VS_IVP_ATOL = 1e-10  # h = 0.0125 RK4 on rates <= ~1: error ~ h^4 / 100 ~ 1e-10 at most
CLOSED_FORM_ATOL = 1e-12  # linear decay at rate 0.1, h = 0.0125: RK4 error ~ 1e-13
ORDER_TOL = 0.15  # observed convergence order of RK4 must be 4 +- 0.15 on a smooth problem
RICHARDSON_RATIO = (0.5, 2.0)  # Richardson estimate within a factor 2 of the true error


def weak_policy(x):
    """u = -0.2 x: leaves h in the loop, closed loop x' = -0.1 x - 0.25 h(x) (nonlinear)."""
    return -0.2 * x


def _forced_field(t, x, u):
    """Time-varying nonlinear field (Duffing-like with forcing), to exercise the t argument."""
    return jnp.array([x[1], -x[0] - 0.3 * x[1] - x[0] ** 3 + 0.5 * jnp.cos(1.3 * t) + u[0]])


def _forced_policy(x):
    return jnp.array([-0.2 * jnp.tanh(x[0])])


def _ivp(fun_np, x0, times):
    sol = solve_ivp(
        fun_np, (times[0], times[-1]), x0, method="DOP853", t_eval=times, rtol=IVP_TOL,
        atol=IVP_TOL,
    )  # fmt: skip
    assert sol.success
    return sol.y.T


def test_expert_closed_loop_matches_closed_form():
    x0 = sample_initial_states(BOX, 5, np.random.default_rng(1))
    T, k = 10.0, 100
    xs = simulate_closed_loop(field, expert, x0, T, k, substeps=8)
    times = np.linspace(0.0, T, k + 1)
    exact = x0[:, None, :] * np.exp(-0.1 * times)[None, :, None]
    np.testing.assert_allclose(xs, exact, rtol=0, atol=CLOSED_FORM_ATOL)


def test_nonlinear_closed_loop_matches_solve_ivp():
    x0 = sample_initial_states(BOX, 3, np.random.default_rng(2))
    T, k = 10.0, 100
    xs = simulate_closed_loop(field, weak_policy, x0, T, k, substeps=8)
    rhs = jax.jit(lambda x: field(0.0, x, weak_policy(x)))
    times = np.linspace(0.0, T, k + 1)
    for i in range(3):
        ref = _ivp(lambda t, y: np.asarray(rhs(jnp.asarray(y))), x0[i], times)
        np.testing.assert_allclose(xs[i], ref, rtol=0, atol=RK4_VS_IVP_ATOL)


def test_time_varying_field_matches_solve_ivp():
    x0 = np.array([[0.5, -0.3], [-1.0, 0.8]])
    T, k = 6.0, 60
    # the cubic, forced field has large high derivatives: at h = 0.1/16 RK4 errs by ~1e-9
    # (measured); h = 0.1/64 brings it to ~4e-12. A wrong time argument in the substeps would
    # err by O(h) ~ 1e-3, so this still tests that t is threaded through correctly.
    xs = simulate_closed_loop(_forced_field, _forced_policy, x0, T, k, substeps=64)
    rhs = jax.jit(lambda t, x: _forced_field(t, x, _forced_policy(x)))
    times = np.linspace(0.0, T, k + 1)
    for i in range(2):
        ref = _ivp(lambda t, y: np.asarray(rhs(t, jnp.asarray(y))), x0[i], times)
        np.testing.assert_allclose(xs[i], ref, rtol=0, atol=RK4_VS_IVP_ATOL)


def test_rk4_converges_with_order_four():
    x0 = np.array([[0.5, -0.3]])
    T, k = 6.0, 12
    rhs = jax.jit(lambda t, x: _forced_field(t, x, _forced_policy(x)))
    times = np.linspace(0.0, T, k + 1)
    ref = _ivp(lambda t, y: np.asarray(rhs(t, jnp.asarray(y))), x0[0], times)
    errs = [
        np.max(np.abs(simulate_closed_loop(_forced_field, _forced_policy, x0, T, k, s)[0] - ref))
        for s in (2, 4, 8)
    ]
    orders = np.log2(np.array(errs[:-1]) / np.array(errs[1:]))
    assert np.all(np.abs(orders - 4.0) < ORDER_TOL), (errs, orders)


def test_richardson_estimate_tracks_true_error():
    # a coarse grid so that the integration error is far above rounding
    demos = generate_demonstrations(
        _forced_field, _forced_policy, np.array([[-1.0, 1.0]] * 2), 2, 6.0, 12,
        np.random.default_rng(3), substeps=2,
    )  # fmt: skip
    rhs = jax.jit(lambda t, x: _forced_field(t, x, _forced_policy(x)))
    true_err = max(
        np.max(
            np.abs(
                demos.states[i]
                - _ivp(lambda t, y: np.asarray(rhs(t, jnp.asarray(y))), demos.x0[i], demos.times)
            )
        )
        for i in range(2)
    )
    ratio = demos.integration_error / true_err
    assert RICHARDSON_RATIO[0] < ratio < RICHARDSON_RATIO[1], (demos.integration_error, true_err)


def test_generated_demonstrations_follow_the_definition():
    T, k, n = 10.0, 100, 6
    demos = generate_demonstrations(field, expert, BOX, n, T, k, np.random.default_rng(4))
    # uniform partition {0, T/k, ..., T} of DRIP eq. (HorizonPartition)
    np.testing.assert_array_equal(demos.times, np.linspace(0.0, T, k + 1))
    assert demos.states.shape == (n, k + 1, 4) and demos.actions.shape == (n, k + 1, 4)
    np.testing.assert_array_equal(demos.x0, demos.states[:, 0])
    # x0 drawn from the same generator stream as sample_initial_states
    np.testing.assert_array_equal(demos.x0, sample_initial_states(BOX, n, np.random.default_rng(4)))
    # actions are the expert at the states, computed here independently with numpy
    hx = H_MLP.apply_np(demos.states)
    np.testing.assert_allclose(demos.actions, -0.2 * demos.states + hx, rtol=0, atol=ROUNDING_ATOL)
    assert demos.integration_error < CLOSED_FORM_ATOL
    assert demos.k == k and demos.horizon == T and demos.n_traj == n


def test_initial_states_uniform_and_reproducible():
    box = np.array([[-1.0, 1.0], [2.0, 5.0], [0.0, 0.0]])
    n = 4000
    a = sample_initial_states(box, n, np.random.default_rng(7))
    b = sample_initial_states(box, n, np.random.default_rng(7))
    np.testing.assert_array_equal(a, b)
    c = sample_initial_states(box, n, jax.random.PRNGKey(7))
    d = sample_initial_states(box, n, jax.random.PRNGKey(7))
    np.testing.assert_array_equal(c, d)
    for draws in (a, c):
        assert np.all(draws >= box[:, 0]) and np.all(draws <= box[:, 1])
        width = box[:, 1] - box[:, 0]
        se = width / math.sqrt(12.0 * n)
        assert np.all(
            np.abs(draws.mean(axis=0) - box.mean(axis=1)) <= MC_FIVE_SIGMA * se + ROUNDING_ATOL
        )
    assert not np.array_equal(a, sample_initial_states(box, n, np.random.default_rng(8)))


@pytest.mark.parametrize(
    "box, field_name",
    [
        (np.array([[1.0, -1.0]]), "support[0]"),
        (np.array([-1.0, 1.0]), "support"),
        (np.array([[0.0, np.inf]]), "support"),
    ],
)
def test_bad_support_is_a_spec_error(box, field_name):
    with pytest.raises(SpecError) as info:
        sample_initial_states(box, 3, np.random.default_rng(0))
    assert info.value.field == field_name


def _small_demos() -> Demonstrations:
    return generate_demonstrations(field, expert, BOX, 3, 1.0, 5, np.random.default_rng(5))


def test_save_load_round_trip(tmp_path: Path):
    demos = _small_demos()
    path = tmp_path / "sub" / "demos.npz"
    save_demonstrations(demos, path)
    back = Demonstrations.load(path)
    demos.save(path)  # the method, over an existing file
    assert Demonstrations.load(path).source == demos.source
    for name in ("times", "states", "actions", "x0"):
        np.testing.assert_array_equal(getattr(back, name), getattr(demos, name))
    assert back.source == demos.source
    assert back.integration_error == demos.integration_error
    assert sorted(p.name for p in path.parent.iterdir()) == ["demos.npz"]  # no temp file left
    with np.load(path, allow_pickle=False) as data:  # readable without pickles
        assert set(data.files) >= {"times", "states", "actions", "x0"}


def test_user_file_without_actions_uses_the_expert(tmp_path: Path):
    demos = _small_demos()
    path = tmp_path / "user.npz"
    np.savez(path, times=demos.times, states=demos.states)
    back = load_demonstrations(path, expert=expert)
    np.testing.assert_array_equal(back.states, demos.states)
    np.testing.assert_allclose(back.actions, demos.actions, rtol=0, atol=ROUNDING_ATOL)
    np.testing.assert_array_equal(back.x0, demos.states[:, 0])
    assert str(path) in back.source
    with pytest.raises(SpecError, match="actions") as info:
        load_demonstrations(path)
    assert info.value.path == str(path) and info.value.field == "actions"


def test_user_file_with_single_trajectory(tmp_path: Path):
    demos = _small_demos()
    path = tmp_path / "one.npz"
    np.savez(path, times=demos.times, states=demos.states[0], actions=demos.actions[0])
    back = load_demonstrations(path)
    assert back.n_traj == 1
    np.testing.assert_array_equal(back.actions[0], demos.actions[0])


def _corrupt(kind: str, demos: Demonstrations) -> dict:
    arrays = {"times": demos.times.copy(), "states": demos.states.copy()}
    arrays["actions"] = demos.actions.copy()
    if kind == "nan":
        arrays["states"][1, 2, 0] = np.nan
    elif kind == "inf_actions":
        arrays["actions"][0, 0, 0] = np.inf
    elif kind == "times_not_monotone":
        arrays["times"][3] = arrays["times"][2]
    elif kind == "shape":
        arrays["states"] = arrays["states"][:, :-1]
    elif kind == "actions_shape":
        arrays["actions"] = arrays["actions"][:2]
    elif kind == "no_states":
        del arrays["states"]
    return arrays


@pytest.mark.parametrize(
    "kind, array",
    [
        ("nan", "states"),
        ("inf_actions", "actions"),
        ("times_not_monotone", "times"),
        ("shape", "states"),
        ("actions_shape", "actions"),
        ("no_states", "states"),
    ],
)
def test_bad_user_files_name_file_array_and_problem(tmp_path: Path, kind: str, array: str):
    path = tmp_path / f"{kind}.npz"
    np.savez(path, **_corrupt(kind, _small_demos()))
    with pytest.raises(SpecError) as info:
        load_demonstrations(path, expert=expert)
    assert info.value.path == str(path)
    assert info.value.field == array
    assert str(path) in str(info.value) and array in str(info.value)


def test_missing_and_pickled_files_are_spec_errors(tmp_path: Path):
    with pytest.raises(SpecError, match="does not exist"):
        load_demonstrations(tmp_path / "nope.npz")
    path = tmp_path / "obj.npz"
    np.savez(path, times=np.array([0.0, 1.0]), states=np.array([{"a": 1}], dtype=object))
    with pytest.raises(SpecError, match="pickles"):
        load_demonstrations(path)


def test_demonstrations_are_frozen_and_validated():
    demos = _small_demos()
    with pytest.raises(ValueError):
        demos.states[0, 0, 0] = 1.0  # read-only arrays
    with pytest.raises(SpecError, match="x0"):
        Demonstrations(demos.times, demos.states, demos.actions, demos.x0 + 1.0)
    sub = demos.subset(np.array([2, 0]))
    np.testing.assert_array_equal(sub.states, demos.states[[2, 0]])
