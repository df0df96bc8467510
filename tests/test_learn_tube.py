"""Value and Jacobian matching on the tube (certificate-aware training of plain MLPs, issue
24): the drawn points, the term on closed-form cases, its parameter gradient against finite
differences, determinism, and that the default leaves training unchanged."""

from __future__ import annotations

import math

import numpy as np
import pytest

from drip_cert._jax import jax, jnp
from drip_cert.errors import SpecError
from drip_cert.learn.data import Demonstrations, generate_demonstrations
from drip_cert.learn.losses import SAFE_NORM_FLOOR, tube_loss, tube_points
from drip_cert.learn.tasil import train_policy
from drip_cert.model.mlp import apply_params, init_mlp, jax_params
from drip_cert.spec.settings import TasilSettings

FD_STEP = 1e-5  # central differences: truncation ~ h^2 |f'''| ~ 1e-10, rounding ~ eps/h ~ 1e-11
FD_GRAD_RTOL = 1e-6  # directional derivative of a mean of norms of O(1) numbers
CLOSED_FORM_RTOL = 1e-12  # a Frobenius norm computed by numpy and by jax: rounding only

N_STATE = 2
BOX = np.array([[-0.5, 0.5], [-0.5, 0.5]])
EXPERT_K = np.array([[-4.0, -4.0]])


def expert(x):
    """The inverted pendulum's feedback-linearising PD expert ``-9.81 sin q - 4 q - 4 q_dot``."""
    return jnp.array([-9.81 * jnp.sin(x[0])]) + x @ jnp.asarray(EXPERT_K).T


def field(t, x, u):
    return jnp.array([x[1], 9.81 * jnp.sin(x[0]) - 0.5 * x[1] + u[0]])


@pytest.fixture(scope="module")
def demos() -> Demonstrations:
    return generate_demonstrations(field, expert, BOX, 10, 5.0, 50, np.random.default_rng(0))


def _policy(params):
    return lambda x: apply_params(params, x, "tanh", None, xp=jnp)


# --- the points --------------------------------------------------------------------------------


def test_tube_points_fill_the_box_and_depend_on_the_key_only():
    lo, hi = jnp.array([-1.0, 0.0, 2.0]), jnp.array([1.0, 0.5, 2.0])
    key = jax.random.PRNGKey(11)
    pts = np.asarray(tube_points(key, lo, hi, 2000))
    np.testing.assert_array_equal(pts, np.asarray(tube_points(key, lo, hi, 2000)))
    assert not np.array_equal(pts, np.asarray(tube_points(jax.random.PRNGKey(12), lo, hi, 2000)))
    assert np.all(pts >= np.asarray(lo)) and np.all(pts <= np.asarray(hi))
    # 2000 uniform draws come within 1 % of the box's faces (a flat side stays flat)
    width = np.asarray(hi - lo)
    assert np.all(pts.min(axis=0) - np.asarray(lo) <= 0.01 * width)
    assert np.all(np.asarray(hi) - pts.max(axis=0) <= 0.01 * width)


# --- the term ----------------------------------------------------------------------------------


def test_term_is_minimal_exactly_when_values_and_jacobians_agree():
    """The expert itself: both norms at their floor. A constant offset ``c``: ``|c|`` + floor. A
    linear error ``D x``: ``mean_j |D y_j| + ||D||_F`` (the closed form)."""
    lo, hi = -jnp.ones(N_STATE), jnp.ones(N_STATE)
    pts = tube_points(jax.random.PRNGKey(0), lo, hi, 64)
    jac = jax.jacrev(expert)
    same = float(tube_loss(expert, expert, jac, pts, SAFE_NORM_FLOOR))
    assert math.isclose(same, 2 * SAFE_NORM_FLOOR, rel_tol=CLOSED_FORM_RTOL)
    shifted = float(tube_loss(lambda x: expert(x) + 0.3, expert, jac, pts, SAFE_NORM_FLOOR))
    assert math.isclose(shifted, 0.3 + SAFE_NORM_FLOOR, rel_tol=CLOSED_FORM_RTOL)
    D = np.array([[0.3, -0.4]])
    off = float(
        tube_loss(lambda x: expert(x) + x @ jnp.asarray(D).T, expert, jac, pts, SAFE_NORM_FLOOR)
    )
    closed = np.mean(np.abs(np.asarray(pts) @ D.T)) + np.linalg.norm(D)
    assert math.isclose(off, float(closed), rel_tol=CLOSED_FORM_RTOL)


def test_term_gradient_matches_finite_differences():
    """jax.grad of the term (through jacrev: second-order autodiff) vs central differences."""
    rng = np.random.default_rng(2)
    params = jax_params(init_mlp((N_STATE, 8, 1), rng, "tanh"))
    pts = tube_points(jax.random.PRNGKey(3), -0.5 * jnp.ones(N_STATE), 0.5 * jnp.ones(N_STATE), 16)
    jac = jax.jacrev(expert)

    @jax.jit
    def loss(p):
        return tube_loss(_policy(p), expert, jac, pts, SAFE_NORM_FLOOR)

    grads = jax.grad(loss)(params)
    direction = [(rng.normal(size=w.shape), rng.normal(size=b.shape)) for w, b in params]
    analytic = sum(
        float(jnp.sum(gw * dw) + jnp.sum(gb * db)) for (gw, gb), (dw, db) in zip(grads, direction)
    )

    def shifted(sign):
        return [(w + sign * FD_STEP * dw, b + sign * FD_STEP * db)
                for (w, b), (dw, db) in zip(params, direction)]  # fmt: skip

    fd = (float(loss(shifted(+1))) - float(loss(shifted(-1)))) / (2 * FD_STEP)
    assert math.isclose(analytic, fd, rel_tol=FD_GRAD_RTOL), (analytic, fd)


# --- training ----------------------------------------------------------------------------------

SMALL = dict(hidden=(8, 8), steps=40, eval_every=20, batch=32, progress=False)


def _weights(res):
    return [np.asarray(a) for a in (*res.mlp.weights, *res.mlp.biases)]


def test_weight_zero_leaves_training_unchanged(demos):
    """With weight 0 no point is drawn and the objective is the imitation loss: the tube's
    count and radius change nothing; a positive weight changes the weights."""
    base = train_policy(demos, expert, seed=1, **SMALL)
    zero = train_policy(demos, expert, seed=1, tube_points=7, tube_radius=0.3, **SMALL)
    for a, b in zip(_weights(base), _weights(zero)):
        np.testing.assert_array_equal(a, b)
    assert base.history == zero.history
    on = train_policy(demos, expert, seed=1, tube_weight=1.0, **SMALL)
    assert not np.array_equal(_weights(base)[0], _weights(on)[0])
    # the recorded losses (early stopping, the restored step) carry the term: same initial
    # network, a larger loss by the term at the fixed evaluation points
    assert on.history.train_loss[0] > base.history.train_loss[0]
    assert on.history.val_loss[0] > base.history.val_loss[0]


def test_training_with_the_term_is_deterministic(demos):
    kw = dict(tube_weight=1.0, tube_points=16, tube_radius=0.2, **SMALL)
    a = train_policy(demos, expert, seed=3, **kw)
    b = train_policy(demos, expert, seed=3, **kw)
    c = train_policy(demos, expert, seed=4, **kw)
    for wa, wb in zip(_weights(a), _weights(b)):
        np.testing.assert_array_equal(wa, wb)
    assert a.history == b.history
    assert not np.array_equal(_weights(a)[0], _weights(c)[0])


def test_behaviour_cloning_ignores_the_term(demos):
    a = train_policy(demos, expert, method="bc", seed=2, **SMALL)
    b = train_policy(demos, expert, method="bc", seed=2, tube_weight=5.0, **SMALL)
    for wa, wb in zip(_weights(a), _weights(b)):
        np.testing.assert_array_equal(wa, wb)


def test_the_term_lowers_the_error_on_the_tube(demos):
    """Trained with the term, the first-order error at fresh points of the tube's box is smaller
    than without it (same seed, data and steps)."""
    kw = {**SMALL, "steps": 200, "lr": 1e-2}
    plain = train_policy(demos, expert, seed=0, **kw)
    tube = train_policy(demos, expert, seed=0, tube_weight=1.0, tube_radius=0.5, **kw)
    states = demos.states.reshape(-1, N_STATE)
    lo, hi = jnp.asarray(states.min(axis=0) - 0.5), jnp.asarray(states.max(axis=0) + 0.5)
    pts = tube_points(jax.random.PRNGKey(99), lo, hi, 2000)
    jac = jax.jacrev(expert)
    err_plain = float(tube_loss(plain.mlp.apply_jax, expert, jac, pts, SAFE_NORM_FLOOR))
    err_tube = float(tube_loss(tube.mlp.apply_jax, expert, jac, pts, SAFE_NORM_FLOOR))
    assert err_tube < err_plain, (err_tube, err_plain)


@pytest.mark.parametrize(
    "kwargs, field_name",
    [
        (dict(tube_weight=-1.0), "tube_weight"),
        (dict(tube_weight=math.nan), "tube_weight"),
        (dict(tube_points=0), "tube_points"),
        (dict(tube_radius=-0.1), "tube_radius"),
        (dict(tube_radius=math.inf), "tube_radius"),
    ],
)
def test_bad_tube_settings_are_spec_errors(demos, kwargs, field_name):
    with pytest.raises(SpecError) as info:
        train_policy(demos, expert, progress=False, **kwargs)
    assert info.value.field == field_name


def test_tasil_table_reads_and_checks_the_tube_keys():
    st = TasilSettings.from_table({"tube_weight": 2.5, "tube_points": 64})
    assert (st.tube_weight, st.tube_points) == (2.5, 64)
    default = TasilSettings.from_table({})
    assert (default.tube_weight, default.tube_points) == (0.0, 128)
    with pytest.raises(SpecError, match="tube_weight"):
        TasilSettings.from_table({"tube_weight": -1.0})
    with pytest.raises(SpecError, match="tube_points"):
        TasilSettings.from_table({"tube_points": 0})
