"""Tests of the L1-DRAC controller step, L1-DRAC (15a)-(15c)."""

from __future__ import annotations

import math

import numpy as np
import pytest
import scipy.linalg

from drip_cert._jax import jax, jnp
from drip_cert.control.l1drac import L1Params, L1State, l1_init, l1_step
from drip_cert.errors import SpecError

GAIN_RTOL = 1e-12
"""expm-based and expm1-based gains agree to a few ulps times the condition of Phi (~1 here)."""

ROUNDING_ATOL = 1e-13
"""Quantities that are zero in exact arithmetic; absolute errors are a few ulps of O(1) states."""

SAME_FORMULA_REL = 1e-15
"""The adaptation gain against -lambda_s / expm1(lambda_s Ts) written out: one formula, an ulp."""

STEADY_RTOL = 1e-9
"""Relative error of the steady state after many filter time constants and adaptation periods:
the transients decay like e^{-omega t} and q^i with |q| < 1e-2 per period, far below this."""

# a stable 3-state, 2-input linear test plant with a time-invariant g
_A = np.array([[-1.0, 0.5, 0.0], [0.0, -2.0, 0.3], [0.2, 0.0, -1.5]])
_G = np.array([[1.0, 0.0], [0.0, 1.0], [1.0, 1.0]])
_G_PERP = np.array([1.0, 1.0, -1.0])  # spans ker G^T
_THETA = np.linalg.solve(_G.T @ _G, _G.T)  # [I 0] [G G_perp]^{-1}


def _simulate(params: L1Params, sigma: np.ndarray, n_steps: int, x0=(0.3, -0.2, 0.1)):
    """Deterministic closed loop x' = A x + G u + sigma (Euler) under L1-DRAC; returns histories."""
    g = jnp.asarray(_G)
    theta = jnp.asarray(_THETA)
    a = jnp.asarray(_A)
    sig = jnp.asarray(sigma)

    def body(carry, _):
        x, st = carry
        f_known = a @ x
        u, st = l1_step(params, st, x, f_known, g, theta)
        x = x + params.dt * (f_known + g @ u + sig)
        return (x, st), (u, st.lam_hat, st.x_hat - x)

    x0 = jnp.asarray(x0, dtype=jnp.float64)
    (_, st), (us, lams, tildes) = jax.lax.scan(body, (x0, l1_init(x0, theta)), None, n_steps)
    return np.asarray(us), np.asarray(lams), np.asarray(tildes), st


def test_gain_equals_hovakimyan_cao_law():
    # -Phi^{-1}(T) e^{A_s T}, Phi(T) = A_s^{-1}(e^{A_s T} - I), A_s = -lambda_s I, via expm
    for lam_s, ts in [(10.0, 0.01), (100.0, 1e-3), (0.5, 2.0), (1e3, 1e-6)]:
        a_s = -lam_s * np.eye(3)
        e = scipy.linalg.expm(a_s * ts)
        phi = np.linalg.solve(a_s, e - np.eye(3))
        hc = -np.linalg.solve(phi, e)
        params = L1Params(omega=50.0, lambda_s=lam_s, Ts=ts, dt=ts / 10)
        np.testing.assert_allclose(hc, params.adaptation_gain * np.eye(3), rtol=GAIN_RTOL, atol=0.0)


def test_estimate_latched_with_gain_at_sampling_instants_only():
    params = L1Params(omega=20.0, lambda_s=10.0, Ts=0.01, dt=0.002)
    sigma = np.array([0.4, -0.7, 0.2])
    _, lams, tildes, _ = _simulate(params, sigma, 40)
    k = params.k
    # step j returns the state at t_{j+1}; the estimate held on [t_j, t_{j+1}) is lams[j]
    np.testing.assert_array_equal(lams[:k], 0.0)  # Lambda_hat = 0 on [0, T_s)
    for j in range(k, 40):
        i = (j // k) * k  # last sampling instant <= t_j
        tilde_i = tildes[i - 1]  # x_hat - x at t_i
        np.testing.assert_allclose(
            lams[j], params.adaptation_gain * tilde_i, rtol=GAIN_RTOL, atol=ROUNDING_ATOL
        )


def test_no_uncertainty_estimate_stays_zero():
    params = L1Params(omega=50.0, lambda_s=10.0, Ts=0.01, dt=0.001)
    us, lams, tildes, _ = _simulate(params, np.zeros(3), 500)
    assert np.max(np.abs(lams)) <= ROUNDING_ATOL
    assert np.max(np.abs(us)) <= ROUNDING_ATOL
    assert np.max(np.abs(tildes)) <= ROUNDING_ATOL


def test_constant_matched_disturbance_is_cancelled():
    # sigma = G c is matched. The PWC law converges to e^{-lambda_s T_s} sigma (module docstring),
    # so u -> -e^{-lambda_s T_s} c; the residual |u + c| is (1 - e^{-lambda_s T_s}) |c|.
    params = L1Params(omega=50.0, lambda_s=10.0, Ts=0.005, dt=0.001)
    c = np.array([0.8, -0.5])
    n_steps = 2000  # T = 2 s: e^{-omega T} = e^{-100}
    us, lams, _, _ = _simulate(params, _G @ c, n_steps)
    u_end = us[-1]
    bias = params.estimate_bias
    residual_tol = (1.0 - bias) * np.linalg.norm(c) + math.exp(-params.omega * n_steps * params.dt)
    assert np.linalg.norm(u_end + c) <= residual_tol
    np.testing.assert_allclose(u_end, -bias * c, rtol=STEADY_RTOL)
    np.testing.assert_allclose(lams[-1], bias * (_G @ c), rtol=STEADY_RTOL)
    # and the residual is real, not a test artefact: it is at least half the predicted one
    assert np.linalg.norm(u_end + c) >= 0.5 * (1.0 - bias) * np.linalg.norm(c)


def test_unmatched_disturbance_is_not_fed_back():
    params = L1Params(omega=50.0, lambda_s=10.0, Ts=0.005, dt=0.001)
    sigma = 0.9 * _G_PERP
    us, lams, _, _ = _simulate(params, sigma, 2000)
    # the estimate sees the unmatched uncertainty in full...
    np.testing.assert_allclose(lams[-1], params.estimate_bias * sigma, rtol=STEADY_RTOL)
    # ...but Theta_ad kills it: Theta_ad g_perp = 0
    assert np.max(np.abs(us)) <= ROUNDING_ATOL


def test_theta_latched_at_sampling_instants():
    # time-varying g(t): Theta_ad must be the one at the last sampling instant i T_s
    params = L1Params(omega=10.0, lambda_s=5.0, Ts=0.004, dt=0.001)

    def theta_of(t):
        return jnp.array([[1.0 + t, 2.0 * t, -t]])

    g = jnp.array([[1.0], [0.0], [0.0]])
    x = jnp.zeros(3)
    st = l1_init(x, theta_of(0.0))
    for j in range(11):
        t = j * params.dt
        _, st = l1_step(params, st, x, jnp.zeros(3), g, theta_of(t))
        i = (j // params.k) * params.k
        np.testing.assert_array_equal(np.asarray(st.theta), np.asarray(theta_of(i * params.dt)))


def test_vmap_and_jit_match_single_path():
    params = L1Params(omega=30.0, lambda_s=8.0, Ts=0.003, dt=0.001)
    rng = np.random.default_rng(3)
    b = 5
    xs = jnp.asarray(rng.normal(size=(b, 3)))
    fk = jnp.asarray(rng.normal(size=(b, 3)))
    g = jnp.asarray(_G)
    theta = jnp.asarray(_THETA)
    st = jax.vmap(l1_init, in_axes=(0, None))(xs + 0.1, theta)
    st = st._replace(step=jnp.full((b,), 3), lam_hat=jnp.asarray(rng.normal(size=(b, 3))))
    step = jax.jit(jax.vmap(lambda s, x, f: l1_step(params, s, x, f, g, theta)))
    u_b, st_b = step(st, xs, fk)
    for i in range(b):
        st_i = L1State(*(leaf[i] for leaf in st))
        u_i, s_i = l1_step(params, st_i, xs[i], fk[i], g, theta)
        np.testing.assert_allclose(np.asarray(u_b[i]), np.asarray(u_i), rtol=0, atol=ROUNDING_ATOL)
        np.testing.assert_allclose(
            np.asarray(st_b.x_hat[i]), np.asarray(s_i.x_hat), rtol=0, atol=ROUNDING_ATOL
        )


def test_params_validation():
    p = L1Params(omega=50.0, lambda_s=10.0, Ts=0.01, dt=0.001)
    assert p.k == 10
    assert p.adaptation_gain == pytest.approx(-10.0 / math.expm1(0.1), rel=SAME_FORMULA_REL)
    with pytest.raises(SpecError, match="not an integer multiple of dt"):
        L1Params(omega=50.0, lambda_s=10.0, Ts=0.01, dt=0.003)
    with pytest.raises(SpecError, match="L1Params.omega"):
        L1Params(omega=0.0, lambda_s=10.0, Ts=0.01, dt=0.001)
    with pytest.raises(SpecError, match="L1Params.dt"):
        L1Params(omega=1.0, lambda_s=10.0, Ts=0.01, dt=float("nan"))
    with pytest.raises(SpecError, match="not an integer multiple"):
        L1Params(omega=1.0, lambda_s=10.0, Ts=0.001, dt=0.01)  # dt > Ts
