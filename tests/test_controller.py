"""The L1-DRAC controller object in a user's loop reproduces the engine, path for path.

A hand-written numpy Euler-Maruyama loop of the true system (drift and diffusion written in
numpy, not taken from the model) calls :class:`~drip_cert.control.controller.L1DRACController`
once per step and applies its input; the Monte-Carlo engine simulates the same system with the
same initial states and Brownian increments (its counter-based normals). The two trajectories of
the ``learned_l1_true`` scenario agree to :data:`PATH_TOL` at every step.
"""

from __future__ import annotations

import math

import numpy as np
import pytest

from drip_cert._jax import jax, jnp
from drip_cert.control.controller import L1DRACController, PolicyFunction
from drip_cert.control.l1drac import L1Params
from drip_cert.errors import SpecError
from drip_cert.model.numeric import make_model
from drip_cert.sim.config import SimConfig
from drip_cert.sim.engine import simulate
from drip_cert.sim.noise import normals

PATH_TOL = 1e-13
"""Controller loop vs engine, max over paths, steps and components (states O(1)); measured
2.8e-16. The controller runs the engine's jax step itself (same operations, same order, same
grid times j dt), so the only differences are the user's plant written in numpy (numpy's
``sin``/``tanh`` vs XLA's, ``g (pi + u)`` vs the engine's ``g pi + g u``): an ulp or so per step,
not amplified by the contracting closed loop over 400 steps."""

COORD_TOL = 1e-13
"""The same comparison through the coordinate change (measured 8.6e-16): the engine simulates
the system in z = Theta x (Theta a Cholesky factor, cond ~ 3), the user's loop the pendulum in x;
the maps x -> z -> x and the transformed vector field add a few ulps per step."""

SEED = 7
N, M, D = 3, 2, 2
B = 6  # paths
DT = 2.5e-3
K = 4  # Ts = K dt
T = 1.0


# the true system, once in jax (for the engine) and once in numpy (the user's simulator)
def _g_jax(t):
    return jnp.array([[1.0, 0.0], [0.0, 1.0], [0.1 * jnp.cos(t), 0.2]])


def _g_np(t):
    return np.array([[1.0, 0.0], [0.0, 1.0], [0.1 * math.cos(t), 0.2]])


def _f_jax(t, x):
    return jnp.array(
        [-x[0] + 0.5 * jnp.sin(x[1]), -x[1] + 0.2 * x[0] * x[2], -2.0 * x[2] + 0.1 * t]
    )


def _f_np(t, x):
    return np.stack(
        [
            -x[:, 0] + 0.5 * np.sin(x[:, 1]),
            -x[:, 1] + 0.2 * x[:, 0] * x[:, 2],
            -2.0 * x[:, 2] + 0.1 * t,
        ],
        axis=1,
    )


def _lam_mu_jax(t, x):
    return jnp.array([0.3 * jnp.sin(x[1]), 0.2 + 0.1 * jnp.tanh(x[0]), 0.1 * jnp.cos(x[2])])


def _lam_mu_np(t, x):
    return np.stack(
        [0.3 * np.sin(x[:, 1]), 0.2 + 0.1 * np.tanh(x[:, 0]), 0.1 * np.cos(x[:, 2])], axis=1
    )


_SIG = np.array([[0.05, 0.0], [0.0, 0.08], [0.02, 0.0]])


def _lam_sigma_jax(t, x):
    return jnp.asarray(_SIG) * (1.0 + 0.1 * jnp.tanh(x[0]))


def _lam_sigma_np(t, x):
    return _SIG[None] * (1.0 + 0.1 * np.tanh(x[:, 0]))[:, None, None]


def _expert(x):
    return jnp.array([-x[0] - 0.5 * x[1], -x[1]])


def _learned(x):
    return jnp.array([-1.02 * x[0] - 0.5 * x[1] + 0.05 * jnp.tanh(x[2]), -0.98 * x[1]])


def _sampler(key):
    return jax.random.uniform(key, (N,), minval=-1.0, maxval=1.0, dtype=jnp.float64)


@pytest.fixture(scope="module")
def model():
    return make_model(
        N,
        M,
        D,
        _f_jax,
        _g_jax,
        _expert,
        learned=_learned,
        lam_mu=_lam_mu_jax,
        lam_sigma=_lam_sigma_jax,
        name="controller-test",
    )


def _engine_paths(model, params):
    cfg = SimConfig(
        T=T,
        dt=DT,
        n_paths=B,
        seed=SEED,
        chunk_size=B,
        l1=params,
        record_every=1,
        n_sample_paths=B,
    )
    res = simulate(model, cfg, _sampler, workers=1)
    i = cfg.scenarios.index("learned_l1_true")
    assert np.all(res.sample_status[i] == 0)
    return res.sample_paths[i]  # (B, n_records, n)


def _user_loop(controller, params):
    """The user's loop: numpy plant, the controller called once per step, input held on it."""
    key = jax.random.PRNGKey(SEED)
    k_x0, k_bm = jax.random.fold_in(key, 0), jax.random.fold_in(key, 2)
    idx = jnp.arange(B, dtype=jnp.uint32)
    x = np.asarray(jax.vmap(lambda i: _sampler(jax.random.fold_in(k_x0, i)))(idx))
    n_steps = round(T / params.dt)
    out = np.empty((B, n_steps + 1, N))
    out[:, 0] = x
    controller.reset(x)
    t = 0.0
    for j in range(n_steps):
        u = controller.step(t, x)
        dw = math.sqrt(params.dt) * np.asarray(normals(k_bm, idx, jnp.uint32(j), D))
        drift = _f_np(t, x) + u @ _g_np(t).T + _lam_mu_np(t, x)
        x = x + params.dt * drift + np.einsum("bnd,bd->bn", _lam_sigma_np(t, x), dw)
        out[:, j + 1] = x
        t += params.dt  # a clock that accumulates: the controller keeps to j dt
    return out


def test_the_controller_in_a_numpy_loop_matches_the_engine_path_for_path(model):
    params = L1Params(omega=30.0, lambda_s=8.0, Ts=K * DT, dt=DT)
    ref = _engine_paths(model, params)
    ctrl = L1DRACController(model, params)
    got = _user_loop(ctrl, params)
    err = float(np.max(np.abs(got - ref)))
    print(f"controller vs engine: max |x_loop - x_engine| = {err:.3e}")
    assert err <= PATH_TOL
    # the comparison has teeth: the paths move, and L1-DRAC acts (a controller returning
    # pi_IL alone would not match)
    assert float(np.max(np.abs(ref[:, -1] - ref[:, 0]))) > 0.1
    assert ctrl.u_l1 is not None and float(np.max(np.abs(ctrl.u_l1))) > 1e-2
    np.testing.assert_array_equal(ctrl.u_policy, PolicyFunction(model)(got[:, -2]))


def test_the_controller_starts_at_zero_and_samples_every_k_steps(model):
    """L1-DRAC (15): U_L1 = 0 until the first sampling instant's estimate has passed the
    filter: eta(0) = 0 and Lambda_hat = 0 on [0, T_s), so u = pi_IL exactly for the first
    K + 1 steps (the estimate latched at step K enters eta at step K, u at step K + 1)."""
    params = L1Params(omega=30.0, lambda_s=8.0, Ts=K * DT, dt=DT)
    ctrl = L1DRACController(model, params)
    x = np.array([0.5, -0.3, 0.2])
    ctrl.reset(x)
    for j in range(K + 2):
        ctrl.step(j * DT, x)
        if j <= K:
            assert np.all(ctrl.u_l1 == 0.0), j
    assert np.any(ctrl.u_l1 != 0.0)
    assert ctrl.steps == K + 2


def test_the_controller_refuses_a_wrong_clock_a_wrong_shape_and_no_reset(model):
    params = L1Params(omega=30.0, lambda_s=8.0, Ts=K * DT, dt=DT)
    ctrl = L1DRACController(model, params)
    with pytest.raises(SpecError, match="reset"):
        ctrl.step(0.0, np.zeros(N))
    ctrl.reset(np.zeros(N))
    with pytest.raises(SpecError, match="step 0 is at t = 0.0"):
        ctrl.step(DT, np.zeros(N))  # a skipped step
    with pytest.raises(SpecError, match="shape"):
        ctrl.step(0.0, np.zeros(N + 1))
    with pytest.raises(SpecError, match="not finite"):
        ctrl.step(0.0, np.array([np.nan, 0.0, 0.0]))
    ctrl.step(0.0, np.zeros(N))
    ctrl.step(DT * (1 + 1e-9), np.zeros(N))  # a clock a few ulps off is fine


def test_a_certificate_in_metric_coordinates_deploys_its_z_controller():
    """The pendulum is certified in z = Theta x (README): the deployed controller maps the
    measured x to z and runs the certified z-controller; the user's loop in x matches the
    engine's run of the z-system mapped back, path for path."""
    from drip_cert.deploy import l1drac_controller, learned_policy
    from drip_cert.validate.scenarios import x0_sampler
    from tests.helpers import example_spec

    spec = example_spec("pendulum")
    ctrl = l1drac_controller(spec)
    cert_theta = ctrl.theta
    assert cert_theta is not None and ctrl.verdict == "certified"
    params = ctrl.params
    assert params.Ts / params.dt == pytest.approx(round(params.Ts / params.dt), abs=1e-9)
    from drip_cert.spec import load_spec

    n_steps = 400
    zsys = ctrl.model
    box = np.array(load_spec(spec).system.support, dtype=float)
    cfg = SimConfig(
        T=n_steps * params.dt,
        dt=params.dt,
        n_paths=B,
        seed=SEED,
        chunk_size=B,
        l1=params,
        record_every=1,
        n_sample_paths=B,
    )
    res = simulate(zsys, cfg, x0_sampler(box, cert_theta), workers=1)
    i = cfg.scenarios.index("learned_l1_true")
    z_ref = res.sample_paths[i]
    x_ref = z_ref @ np.linalg.inv(cert_theta).T
    # the user's loop in x: the pendulum's true dynamics written in numpy
    key = jax.random.PRNGKey(SEED)
    k_x0, k_bm = jax.random.fold_in(key, 0), jax.random.fold_in(key, 2)
    idx = jnp.arange(B, dtype=jnp.uint32)
    lo, hi = jnp.asarray(box[:, 0]), jnp.asarray(box[:, 1])
    x = np.asarray(
        jax.vmap(
            lambda i: jax.random.uniform(
                jax.random.fold_in(k_x0, i), (2,), minval=lo, maxval=hi, dtype=jnp.float64
            )
        )(idx)
    )
    ctrl.reset(x)
    err = float(np.max(np.abs(x - x_ref[:, 0])))
    for j in range(n_steps):
        t = j * params.dt
        u = ctrl.step(t, x)[:, 0]
        q, qd = x[:, 0], x[:, 1]
        drift = np.stack(
            [qd, -9.81 * np.sin(q) - 0.5 * qd + u + 0.1 * np.sin(q) + 0.05 * np.tanh(qd)], 1
        )
        dw = math.sqrt(params.dt) * np.asarray(normals(k_bm, idx, jnp.uint32(j), 1))[:, 0]
        x = x + params.dt * drift + np.stack([np.zeros(B), 0.05 * dw], 1)
        err = max(err, float(np.max(np.abs(x - x_ref[:, j + 1]))))
    print(f"pendulum, controller in z vs engine in z: max |x_loop - Theta^-1 z_engine| = {err:.3e}")
    assert err <= COORD_TOL
    policy = learned_policy(spec)
    np.testing.assert_allclose(
        policy(np.array([0.1, 0.2])), [9.81 * math.sin(0.1) - 3.96 * 0.1 - 4.04 * 0.2], rtol=1e-14
    )
