"""The TaSIL sure bound on a finite horizon along the expert's tube (tasil.md 3.7, 3.10)."""

from __future__ import annotations

import math

import numpy as np
import pytest
from scipy.integrate import solve_ivp

from drip_cert.analysis.learned_loop import sup_policy_difference
from drip_cert.bounds.tasil.tube import (
    horizon_factor_up,
    time_resolved_gap_up,
    tube_bound,
    tube_radii_up,
)
from drip_cert.learn.imitation import learned_system
from drip_cert.model.mlp import MLP
from drip_cert.spec import load_spec
from tests.helpers import write_spec

#: closed forms rounded up from Arb balls: within a few ulps above the float64 closed form
ROUNDING_TOL = 1e-12
#: DOP853 at rtol 1e-10: the simulated gaps are accurate far below the bounds' slack
ODE_RTOL = 1e-10

SPEC = """
[system]
name = "two"
states = ["x1", "x2"]
horizon = 3.0

[dynamics]
f = ["-x1", "-x2"]
g = [["0.5", "0"], ["0", "0.5"]]

[policy]
expert = ["-x1", "-x2"]

[initial]
support = [[-1.0, 1.0], [-1.0, 1.0]]
"""
#: ||F*(0)|| enclosed in outward-rounded intervals: a few subnormals above the exact 0
PHI_TINY = 1e-300
#: absolute slack on the simulated gaps (DOP853 at ODE_RTOL on states of size 1)
GAP_ATOL = 1e-9
#: a coarse grid keeps the test fast (each interval is one branch and bound)
INTERVALS = 5
#: the learned rate is taken this much below its float closed form (rounding of the norms)
RATE_SLACK = 1e-9
#: the expert loop is x' = -1.5 x: rate 1.5 on all x; the learned loop adds 0.5 (K x + N(x))
LAM_STAR = 1.5


def test_closed_forms_are_rounded_up_and_exact_to_rounding():
    lam, T = 0.7, 2.5
    f = horizon_factor_up(lam, T)
    assert f >= -math.expm1(-lam * T) / lam
    assert f == pytest.approx(-math.expm1(-lam * T) / lam, rel=ROUNDING_TOL)
    assert f < min(T, 1.0 / lam)
    ts = np.linspace(0.0, T, 6)
    r = tube_radii_up(2.0, 0.3, lam, ts)
    exact = np.exp(-lam * ts) * 2.0 + 0.3 * -np.expm1(-lam * ts) / lam
    assert np.all(r >= exact) and np.allclose(r, exact, rtol=ROUNDING_TOL)
    # a constant H: the recursion is the finite-horizon comparison bound at every grid time
    b = time_resolved_gap_up(ts, [0.2] * 5, lam, 0.5)
    exact_b = 0.5 * 0.2 * -np.expm1(-lam * ts) / lam
    assert np.all(b >= exact_b) and np.allclose(b, exact_b, rtol=ROUNDING_TOL)


def test_a_decaying_H_gives_a_smaller_bound_than_the_constant_one():
    ts = np.linspace(0.0, 10.0, 11)
    H = np.exp(-0.1 * ts[:-1])
    b = time_resolved_gap_up(ts, H, 0.1, 1.0)
    assert b.max() < horizon_factor_up(0.1, 10.0) * H[0]


@pytest.fixture(scope="module")
def system(tmp_path_factory):
    base = load_spec(write_spec(tmp_path_factory.mktemp("tube"), SPEC)).system
    rng = np.random.default_rng(5)
    w1, w2 = 0.5 * rng.standard_normal((8, 2)), 0.2 * rng.standard_normal((2, 8))
    net = MLP(weights=(w1, w2), biases=(np.zeros(8), np.zeros(2)))
    K = -np.eye(2) - 0.9 * w2 @ w1
    return learned_system(base, net, linear=K), net, K


def test_tube_bound_holds_on_simulated_gaps_and_beats_the_uniform_form(system):
    s, net, K = system
    S = np.asarray(s.support, dtype=float)
    full = sup_policy_difference(s, S)
    assert full is not None
    # the learned loop -x + 0.5 (K x + N(x)) has Jacobian -1.5 I + 0.5 (K + I + DN): by the
    # subadditivity of mu_2 its rate is >= 1.5 - 0.5 (||K + I|| + ||w2|| ||w1||) on all x
    w1, w2 = net.weights
    lip = np.linalg.norm(K + np.eye(2), 2) + np.linalg.norm(w1, 2) * np.linalg.norm(w2, 2)
    g_norm, lam_il = 0.5, 1.5 - 0.5 * float(lip) - RATE_SLACK
    assert lam_il > 0
    tb = tube_bound(
        s, S, LAM_STAR, lam_il, g_norm, lambda b, ball: sup_policy_difference(s, b, ball),
        H_full=full.value, intervals=INTERVALS,
    )  # fmt: skip
    assert tb is not None and np.allclose(tb.centre, 0.0) and tb.phi <= PHI_TINY
    uniform = g_norm * full.value * horizon_factor_up(lam_il, s.horizon)
    assert tb.rho <= uniform
    assert list(tb.H) == sorted(tb.H, reverse=True)  # the tube shrinks, so does the sup

    def F_hat(x):  # the learned loop in numpy: -x + 0.5 (K x + N(x))
        return -x + 0.5 * (K @ x + net.apply_np(x[None, :])[0])

    starts = np.array([[a, b] for a in (-1.0, 1.0) for b in (-1.0, 1.0)] + [[0.3, -0.8]])
    for x0 in starts:
        sol = solve_ivp(
            lambda _t, y: np.concatenate([-LAM_STAR * y[:2], F_hat(y[2:])]),
            (0.0, s.horizon), np.concatenate([x0, x0]), rtol=ODE_RTOL, atol=1e-12,
            t_eval=np.asarray(tb.times),
        )  # fmt: skip
        gap = np.linalg.norm(sol.y[2:] - sol.y[:2], axis=0)
        assert np.all(gap <= np.asarray(tb.rho_t) + GAP_ATOL)
