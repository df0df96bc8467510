"""TaSIL / BC training: autodiff derivatives against finite differences, the losses on closed-form
cases, the NaN-safe norm, determinism, early stopping, the imitation gap, and TaSIL vs BC on a
paper-like 4-D system."""

from __future__ import annotations

import math
import re
from pathlib import Path

import numpy as np
import pytest

from drip_cert._jax import jax, jnp
from drip_cert.errors import SpecError
from drip_cert.learn.data import Demonstrations, generate_demonstrations, sample_initial_states
from drip_cert.learn.losses import (
    SAFE_NORM_FLOOR,
    LossSpec,
    error_table,
    expert_targets,
    imitation_loss,
    safe_norm,
)
from drip_cert.learn.tasil import evaluate_gap, train_policy
from drip_cert.model.mlp import apply_params, init_mlp, jax_params, load_mlp, mlp_from_params
from tests.helpers import PAPER_LIKE_BOX as BOX
from tests.helpers import ROUNDING_ATOL
from tests.helpers import paper_like_expert as expert
from tests.helpers import paper_like_field as field
from tests.helpers import paper_like_h as h

FD_STEP = 1e-5  # central differences: truncation ~ h^2 |f'''| ~ 1e-10, rounding ~ eps/h ~ 1e-11
FD_ATOL = 1e-8  # both error sources above, with two orders of margin
FD_GRAD_RTOL = 1e-6  # directional derivative of a loss built from norms of O(1) numbers
CLOSED_FORM_RTOL = 1e-12  # the same formula evaluated by numpy and by jax: rounding only
PERTURBATION = 1e-3  # weight perturbation: makes e_0, e_1 ~ 1e-3, far above the 1e-8 floor
ABOVE_FLOOR = 100.0  # "positive" means at least 100x the floor value (expected ~1e5x)
LOSS_DROP = 0.5  # 200 Adam steps must at least halve the loss of the random network
GAP_ATOL = 1e-10  # RK4 with h = 0.0125 on a linear system: error ~ 1e-13

T_HORIZON, K_SAMPLES, N_TRAJ = 10.0, 100, 20


@pytest.fixture(scope="module")
def demos() -> Demonstrations:
    return generate_demonstrations(
        field, expert, BOX, N_TRAJ, T_HORIZON, K_SAMPLES, np.random.default_rng(0)
    )


@pytest.fixture(scope="module")
def heldout_x0() -> np.ndarray:
    """Held-out initial states, drawn from D independently of the training data."""
    return sample_initial_states(BOX, 50, np.random.default_rng(99))


def _policy(mlp):
    params = jax_params(mlp)
    return lambda x: apply_params(params, x, mlp.activation, mlp.output_activation, xp=jnp)


# --- derivatives -------------------------------------------------------------------------------


@pytest.mark.parametrize("activation", ["tanh", "gelu"])
def test_policy_jacobian_and_hessian_match_finite_differences(activation):
    rng = np.random.default_rng(1)
    mlp = init_mlp((4, 8, 8, 3), rng, activation)
    pol = _policy(mlp)
    x = rng.normal(size=4)
    jac_fun = jax.jit(jax.jacrev(pol))
    jac = np.asarray(jac_fun(jnp.asarray(x)))
    hess = np.asarray(jax.jit(jax.jacfwd(jax.jacrev(pol)))(jnp.asarray(x)))
    eye = np.eye(4)
    fd_jac = np.stack(
        [
            (mlp.apply_np(x + FD_STEP * e) - mlp.apply_np(x - FD_STEP * e)) / (2 * FD_STEP)
            for e in eye
        ],
        axis=-1,
    )
    fd_hess = np.stack(
        [
            (
                np.asarray(jac_fun(jnp.asarray(x + FD_STEP * e)))
                - np.asarray(jac_fun(jnp.asarray(x - FD_STEP * e)))
            )
            / (2 * FD_STEP)
            for e in eye
        ],
        axis=-1,
    )
    np.testing.assert_allclose(jac, fd_jac, rtol=0, atol=FD_ATOL)
    np.testing.assert_allclose(hess, fd_hess, rtol=0, atol=FD_ATOL)
    np.testing.assert_allclose(
        hess, np.swapaxes(hess, 1, 2), rtol=0, atol=ROUNDING_ATOL
    )  # symmetric


@pytest.mark.parametrize("order", [0, 1, 2])
def test_loss_gradient_matches_finite_differences(demos, order):
    """jax.grad through jacrev / jacfwd(jacrev) (second- and third-order autodiff) vs FD."""
    rng = np.random.default_rng(2)
    mlp = init_mlp((4, 8, 4), rng, "tanh")
    params = jax_params(mlp)
    spec = LossSpec(order=order)
    targets = expert_targets(expert, demos.states[:3, :10], demos.actions[:3, :10], order)

    @jax.jit
    def loss(p):
        return imitation_loss(lambda x: apply_params(p, x, "tanh", None, xp=jnp), targets, spec)

    grads = jax.jit(jax.grad(loss))(params)
    direction = [(rng.normal(size=w.shape), rng.normal(size=b.shape)) for w, b in params]
    analytic = sum(
        float(jnp.sum(gw * dw) + jnp.sum(gb * db)) for (gw, gb), (dw, db) in zip(grads, direction)
    )

    def shifted(sign):
        return [(w + sign * FD_STEP * dw, b + sign * FD_STEP * db)
                for (w, b), (dw, db) in zip(params, direction)]  # fmt: skip

    fd = (float(loss(shifted(+1))) - float(loss(shifted(-1)))) / (2 * FD_STEP)
    assert math.isclose(analytic, fd, rel_tol=FD_GRAD_RTOL), (analytic, fd)


# --- the NaN-safe norm -------------------------------------------------------------------------


def test_safe_norm_value_and_gradient():
    x = jnp.array([3.0, -4.0])
    assert float(safe_norm(x)) == 5.0
    np.testing.assert_allclose(
        jax.grad(safe_norm)(x), np.array([0.6, -0.8]), rtol=0, atol=ROUNDING_ATOL
    )
    zero = jnp.zeros(3)
    assert float(safe_norm(zero)) == SAFE_NORM_FLOOR
    g = jax.grad(safe_norm)(zero)
    assert np.all(np.isfinite(g)) and np.all(g == 0.0)
    # the plain norm is what the floor protects against: its gradient at 0 is NaN
    assert np.all(np.isnan(jax.grad(jnp.linalg.norm)(zero)))


# --- losses on closed-form cases ---------------------------------------------------------------


@pytest.mark.parametrize("reduction", ["mean", "max"])
def test_linear_policy_loss_closed_form(reduction):
    """pi(x) = K x + c vs pi*(x) = K* x: e0 = ||(K - K*) x + c||, e1 = ||K - K*||_F, e2 = 0."""
    rng = np.random.default_rng(3)
    n, m = 3, 2
    k_star = rng.normal(size=(m, n))
    k_hat = k_star + 0.1 * rng.normal(size=(m, n))
    c = 0.05 * rng.normal(size=m)
    states = rng.normal(size=(4, 7, n))
    actions = states @ k_star.T

    def expert_lin(x):
        return jnp.asarray(k_star) @ x

    def policy(x):
        return jnp.asarray(k_hat) @ x + jnp.asarray(c)

    lam_j, lam_h = 0.7, 3.0
    spec = LossSpec(order=2, lambda_j=lam_j, lambda_h=lam_h, reduction=reduction)
    targets = expert_targets(expert_lin, states, actions, 2)
    value = float(jax.jit(lambda t: imitation_loss(policy, t, spec))(targets))
    e0 = np.linalg.norm(states @ (k_hat - k_star).T + c, axis=-1)  # (4, 7)
    e1 = np.linalg.norm(k_hat - k_star)
    e2 = SAFE_NORM_FLOOR  # Hessians of both are exactly zero
    if reduction == "mean":
        expected = np.mean(e0) + lam_j * e1 + lam_h * e2
    else:  # DRIP eq. (LossTaSIL): per-trajectory max over the partition, mean over trajectories
        expected = np.mean(np.max(e0, axis=1)) + lam_j * e1 + lam_h * e2
    assert math.isclose(value, expected, rel_tol=CLOSED_FORM_RTOL)


def test_max_reduction_dominates_mean_and_agrees_on_one_sample(demos):
    mlp = init_mlp((4, 8, 4), np.random.default_rng(4), "tanh")
    pol = _policy(mlp)
    targets = expert_targets(expert, demos.states[:5, :-1], demos.actions[:5, :-1], 1)
    loss = jax.jit(lambda t, r: imitation_loss(pol, t, LossSpec(order=1, reduction=r)),
                   static_argnums=1)  # fmt: skip
    mean = float(loss(targets, "mean"))
    mx = float(loss(targets, "max"))
    assert mx > mean
    one = expert_targets(expert, demos.states[:5, :1], demos.actions[:5, :1], 1)
    assert float(loss(one, "mean")) == pytest.approx(float(loss(one, "max")), rel=CLOSED_FORM_RTOL)


@pytest.mark.parametrize("order", [0, 1, 2])
def test_tasil_loss_vanishes_for_the_expert_only(demos, order):
    """An expert that is itself an MLP: the learner with the expert's weights has loss equal to
    the floor, with finite (zero) gradients; any perturbation makes it positive."""
    expert_mlp = init_mlp((4, 16, 4), np.random.default_rng(5), "tanh")
    exp_params = jax_params(expert_mlp)

    def mlp_expert(x):
        return apply_params(exp_params, x, "tanh", None, xp=jnp)

    states = demos.states[:4, :-1]
    actions = np.asarray(jax.vmap(mlp_expert)(jnp.asarray(states.reshape(-1, 4)))).reshape(4, -1, 4)
    spec = LossSpec(order=order, lambda_j=1.0, lambda_h=10.0)
    targets = expert_targets(mlp_expert, states, actions, order)

    @jax.jit
    def loss(p):
        return imitation_loss(lambda x: apply_params(p, x, "tanh", None, xp=jnp), targets, spec)

    floor_value = SAFE_NORM_FLOOR * (1.0 + (order >= 1) * 1.0 + (order >= 2) * 10.0)
    assert float(loss(exp_params)) == pytest.approx(floor_value, rel=CLOSED_FORM_RTOL)
    grads = jax.jit(jax.grad(loss))(exp_params)
    for gw, gb in grads:
        assert np.all(np.isfinite(gw)) and np.all(np.isfinite(gb))
    rng = np.random.default_rng(6)
    perturbed = [(w + PERTURBATION * rng.normal(size=w.shape), b) for w, b in exp_params]
    assert float(loss(perturbed)) > ABOVE_FLOOR * floor_value


def test_jacobian_term_sees_what_behaviour_cloning_does_not():
    """A policy equal to the expert on the data but with a different slope: BC loss is at the
    floor, the TaSIL Jacobian term is the slope error."""
    # multiples of pi/2, where sin(2 x) vanishes up to ~1e-16, below the 1e-8 floor
    states = (np.pi / 2) * np.arange(-2.0, 3.0).reshape(1, 5, 1)

    def expert_1d(x):
        return 0.5 * x

    def policy(x):
        return 0.5 * x + 0.1 * jnp.sin(2.0 * x)

    actions = 0.5 * states
    targets = expert_targets(expert_1d, states, actions, 1)
    e0, e1, _ = jax.jit(lambda t: error_table(policy, t, LossSpec(order=1)))(targets)
    assert np.all(np.asarray(e0) == SAFE_NORM_FLOOR)
    np.testing.assert_allclose(
        np.asarray(e1), np.abs(0.2 * np.cos(2.0 * states[..., 0])), rtol=CLOSED_FORM_RTOL
    )


def test_analytic_expert_jacobian_gives_the_same_targets(demos):
    def expert_jac(x):
        return -0.2 * jnp.eye(4) + jax.jacrev(h)(x)

    a = expert_targets(expert, demos.states[:2], demos.actions[:2], 1)
    b = expert_targets(expert, demos.states[:2], demos.actions[:2], 1, expert_jac=expert_jac)
    np.testing.assert_allclose(np.asarray(a.jac), np.asarray(b.jac), rtol=0, atol=ROUNDING_ATOL)


# --- training ----------------------------------------------------------------------------------

SMALL = dict(hidden=(16, 16), steps=60, eval_every=20, batch=64, progress=False)


def test_training_is_deterministic(demos):
    a = train_policy(demos, expert, seed=3, **SMALL)
    b = train_policy(demos, expert, seed=3, **SMALL)
    c = train_policy(demos, expert, seed=4, **SMALL)
    for wa, wb in zip(a.mlp.weights + a.mlp.biases, b.mlp.weights + b.mlp.biases):
        np.testing.assert_array_equal(wa, wb)
    assert a.history == b.history and a.train_index == b.train_index
    assert not np.array_equal(a.mlp.weights[0], c.mlp.weights[0])


def test_best_parameters_are_restored_and_the_split_is_held_out(demos):
    res = train_policy(demos, expert, seed=5, **SMALL)
    assert res.best_val_loss == min(res.history.val_loss)
    assert res.history.val_loss[res.history.steps.index(res.best_step)] == res.best_val_loss
    assert set(res.train_index).isdisjoint(res.val_index)
    assert sorted(res.train_index + res.val_index) == list(range(N_TRAJ))
    assert len(res.val_index) == round(0.2 * N_TRAJ)
    # recompute the held-out loss of the returned MLP independently of the training loop
    val = demos.subset(np.array(res.val_index))
    targets = expert_targets(expert, val.states[:, :-1], val.actions[:, :-1], 1)
    recomputed = float(jax.jit(lambda t: imitation_loss(res.mlp.apply_jax, t, LossSpec()))(targets))
    assert recomputed == pytest.approx(res.best_val_loss, rel=CLOSED_FORM_RTOL)


def test_patience_stops_training(demos):
    # an Adam step of 0.3 on a 16-16 tanh net overshoots: the held-out loss stops improving
    settings = {**SMALL, "steps": 2000, "lr": 0.3, "schedule": "constant", "patience": 100}
    res = train_policy(demos, expert, seed=0, **settings)
    assert res.stop_reason in ("patience", "non-finite loss")
    assert res.history.steps[-1] < 2000
    if res.stop_reason == "patience":
        assert res.history.steps[-1] - res.best_step >= 100


def test_max_reduction_trains_and_selects_on_training_loss_without_split(demos):
    """DRIP eq. (LossTaSIL) reduction, mini-batches of trajectories, no held-out split."""
    settings = {**SMALL, "reduction": "max", "batch": 8, "val_fraction": 0.0, "steps": 200}
    res = train_policy(demos, expert, seed=1, **settings)
    assert res.val_index == () and len(res.train_index) == N_TRAJ
    assert res.history.val_loss == res.history.train_loss
    assert res.best_val_loss < LOSS_DROP * res.history.train_loss[0]


def test_final_sample_is_not_in_the_loss(demos):
    """DRIP eq. (LossTaSIL) runs over the partition without T: garbage at T changes nothing."""
    actions = demos.actions.copy()
    actions[:, -1] += 100.0
    other = Demonstrations(demos.times, demos.states, actions, demos.x0, "tampered")
    a = train_policy(demos, expert, method="bc", **SMALL)
    b = train_policy(other, expert, method="bc", **SMALL)
    assert a.history.train_loss[0] == b.history.train_loss[0]
    assert a.history.val_loss[0] == b.history.val_loss[0]


def test_result_round_trips_through_the_mlp_file_format(demos, tmp_path: Path):
    res = train_policy(demos, expert, method="bc", activation="gelu", **SMALL)
    assert res.order == 0 and res.method == "bc" and res.settings.order == 0
    path = tmp_path / "policy.npz"
    res.mlp.save(path)
    back = load_mlp(path)
    assert back.activation == "gelu"
    x = demos.states[0]
    np.testing.assert_array_equal(back.apply_np(x), res.mlp.apply_np(x))
    again = mlp_from_params(jax_params(back), back.activation)
    np.testing.assert_array_equal(again.weights[1], res.mlp.weights[1])


@pytest.mark.parametrize(
    "kwargs, field_name",
    [
        (dict(method="dagger"), "method"),
        (dict(activation="relu"), "activation"),
        (dict(order=3), "order"),
        (dict(val_fraction=1.0), "val_fraction"),
        (dict(steps=0), "steps"),
        (dict(reduction="median"), "reduction"),
        (dict(lambda_j=-1.0), "lambda_j"),
    ],
)
def test_bad_settings_are_spec_errors(demos, kwargs, field_name):
    with pytest.raises(SpecError) as info:
        train_policy(demos, expert, progress=False, **kwargs)
    assert info.value.field == field_name


def test_demos_must_be_demonstrations():
    with pytest.raises(SpecError, match="Demonstrations"):
        train_policy({"states": np.zeros((1, 2, 4))}, expert, progress=False)


# --- imitation gap -----------------------------------------------------------------------------


def test_gap_closed_form_for_a_constant_policy_error():
    """x' = -a x + u, expert u = 0, learner u = c: x_hat - x* = c (1 - e^{-a t}) / a, whose
    maximum over [0, T] is at T."""
    a, T, k = 0.3, 5.0, 50
    c = jnp.array([0.2, -0.1])

    def lin_field(t, x, u):
        return -a * x + u

    def zero_expert(x):
        return jnp.zeros_like(x)

    def const_policy(x):
        return c + 0.0 * x

    x0 = np.array([[1.0, 0.0], [-0.5, 0.5], [0.0, 0.0]])
    gaps = evaluate_gap(lin_field, zero_expert, const_policy, x0, T, k)
    expected = float(jnp.linalg.norm(c)) * (1.0 - math.exp(-a * T)) / a
    np.testing.assert_allclose(gaps, expected, rtol=0, atol=GAP_ATOL)
    assert np.all(evaluate_gap(lin_field, zero_expert, zero_expert, x0, T, k) == 0.0)


def test_diverging_learner_gives_infinite_gap():
    def lin_field(t, x, u):
        return -0.1 * x + u

    gaps = evaluate_gap(
        lin_field, lambda x: 0.0 * x, lambda x: 5.0 * x, np.array([[1.0], [0.0]]), 200.0, 20
    )
    assert gaps[0] == np.inf and gaps[1] == 0.0


def _gaps(demos, heldout_x0, seed, **kw):
    out = {}
    for method in ("bc", "tasil"):
        res = train_policy(demos, expert, method=method, seed=seed, **{"progress": False, **kw})
        gaps = evaluate_gap(field, expert, res.mlp.apply_jax, heldout_x0, T_HORIZON, K_SAMPLES)
        out[method] = (float(np.mean(gaps)), float(np.max(gaps)), res.wall_time_s)
    return out


def test_tasil_beats_bc_on_the_paper_like_example(demos, heldout_x0):
    """Same data (20 trajectories, k = 100), same small budget (500 steps, 16-16 tanh,
    batch 64), seed 0, 50 held-out initial states."""
    out = _gaps(demos, heldout_x0, seed=0, **{**SMALL, "steps": 500})
    assert out["tasil"][0] < out["bc"][0], out


@pytest.mark.slow
@pytest.mark.parametrize("seed", [0, 1, 2])
def test_tasil_beats_bc_with_the_default_budget(demos, heldout_x0, seed):
    out = _gaps(demos, heldout_x0, seed=seed)
    print(f"seed {seed}: (mean gap, max gap, wall s) {out}")
    assert out["tasil"][0] < out["bc"][0], out


# --- cost of a step and of a recorded loss (issue 24: 4000 samples per trajectory) -------------


def test_a_step_on_a_large_pool_draws_its_batch_without_permuting_the_pool(demos):
    """Above ``PERMUTE_MAX`` entries mini-batches are drawn with replacement (``randint``,
    O(batch)): the compiled steps hold no sort, where ``choice(replace=False)``, kept for small
    pools (the batches of earlier versions), sorts a permutation of the whole pool every step."""
    from drip_cert.learn import tasil as T

    assert not T._draw_with_replacement(T.PERMUTE_MAX)
    assert T._draw_with_replacement(T.PERMUTE_MAX + 1)
    spec = LossSpec()
    pool = expert_targets(expert, demos.states[:, :-1], demos.actions[:, :-1], 1).flat()
    params = jax_params(init_mlp((4, 8, 1), np.random.default_rng(0), "tanh", None))
    lr_args = (jnp.asarray(1e-3), jnp.asarray(10.0))
    opt_state = T._adam(*lr_args, "cosine").init(params)
    net = T._Net("tanh", None)
    kw = dict(net=net, spec=spec, schedule="cosine", n_steps=3, batch_size=16, axis=1)
    args = (params, opt_state, jax.random.PRNGKey(0), jnp.asarray(0), pool, lr_args)
    box = jnp.zeros((2, 4))

    def program(replace: bool) -> str:
        return str(jax.make_jaxpr(lambda *a: T._run_chunk(*a, box, replace=replace, **kw))(*args))

    sort = re.compile(r"\bsort\[")  # the primitive, not a gather's keyword
    assert "random_bits" in program(True)  # the batches are drawn in the compiled steps
    assert sort.search(program(True)) is None
    assert sort.search(program(False)) is not None  # the small pools' draw: the test can fail


def test_recorded_losses_use_a_fixed_seeded_subset_of_a_large_split(demos, monkeypatch):
    """Above ``EVAL_STATES`` states a recorded loss is the mean over a fixed seeded subset: the
    restored held-out loss is the loss of the returned MLP on that subset (recomputed here), the
    same at every evaluation and in every run of the same seed."""
    from drip_cert.learn import tasil as T

    monkeypatch.setattr(T, "EVAL_STATES", 256)
    a = train_policy(demos, expert, seed=5, **SMALL)
    b = train_policy(demos, expert, seed=5, **SMALL)
    assert a.history == b.history
    val = demos.subset(np.array(a.val_index))
    targets = expert_targets(expert, val.states[:, :-1], val.actions[:, :-1], 1)
    n_states = targets.states.shape[0] * targets.states.shape[1]
    assert n_states > 256  # the subset is a strict one
    idx = np.sort(
        np.random.default_rng((5, T.EVAL_STREAM_VAL)).choice(n_states, 256, replace=False)
    )
    sub = targets.flat().map_arrays(lambda x: x[:, jnp.asarray(idx)])
    loss = jax.jit(lambda t: imitation_loss(a.mlp.apply_jax, t, LossSpec()))
    assert float(loss(sub)) == pytest.approx(a.best_val_loss, rel=CLOSED_FORM_RTOL)
    assert float(loss(targets)) != pytest.approx(a.best_val_loss, rel=CLOSED_FORM_RTOL)
