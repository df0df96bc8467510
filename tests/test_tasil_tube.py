"""The TaSIL sure bound on a finite horizon along the expert's tube (tasil.md 3.7, 3.10)."""

from __future__ import annotations

import math

import numpy as np
import pytest
from scipy.integrate import solve_ivp

from drip_cert.analysis.contraction.learned_loop import sup_policy_difference
from drip_cert.bounds.tasil.tube import (
    box_tubes,
    horizon_factor_up,
    time_resolved_gap_up,
    tube_bound,
    tube_radii_up,
    weighted_inf_rate,
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


# --------------------------------------------------------------- the box tubes (tasil.md 3.11)

NONLINEAR = """
[system]
name = "nl"
states = ["x1", "x2"]
horizon = 3.0

[dynamics]
f = ["-x1 + 0.3*tanh(x2)", "-2*x2 + 0.2*sin(x1)"]
g = [["1", "0"], ["0", "1"]]

[policy]
expert = ["-0.5*x1", "-0.5*x2"]

[initial]
support = [[-1.0, 1.0], [-0.5, 0.5]]
"""
#: the expert Jacobian [[-1.5, 0.3 sech^2 x2], [0.2 cos x1, -2.5]]: inf-norm rate
#: min(1.5 - 0.3, 2.5 - 0.2) = 1.2 (attained at x = 0); with w = (1, 2) (the support's
#: 1/half-widths) min(1.5 - 0.3/2, 2.5 - 0.2*2) = 1.35
RATE_PLAIN, RATE_WEIGHTED = 1.2, 1.35
#: the branch and bound of the rate stops within BOX_RATE_RTOL (5 %) of the sampled value
RATE_RTOL = 0.05
#: dense sampling of mu_inf for the soundness comparison (seeded)
RATE_SAMPLES = 4000


@pytest.fixture(scope="module")
def nonlinear(tmp_path_factory):
    return load_spec(write_spec(tmp_path_factory.mktemp("nl"), NONLINEAR)).system


def _mu_inf_w(J: np.ndarray, w: np.ndarray) -> float:
    M = J * (w[:, None] / w[None, :])
    d = np.diag(M)
    return float(np.max(d + np.sum(np.abs(M), axis=1) - np.abs(d)))


def test_weighted_inf_rate_is_sound_against_sampling_and_near_the_closed_form(nonlinear):
    s = nonlinear
    S = np.array([[-1.0, 1.0], [-1.0, 1.0]])
    jac = s.lower(s.closed_loop_jacobian("expert"))
    X = np.random.default_rng(11).uniform(-1.0, 1.0, (RATE_SAMPLES, 2))
    for w, exact in ((np.ones(2), RATE_PLAIN), (np.array([1.0, 2.0]), RATE_WEIGHTED)):
        lam = weighted_inf_rate(s, S, w)
        sampled = min(-_mu_inf_w(np.asarray(jac(0.0, x), dtype=float), w) for x in X)
        assert lam is not None and lam <= sampled  # proved never above any sampled rate
        assert lam <= exact and lam >= exact * (1.0 - RATE_RTOL)


def test_weighted_inf_rate_of_a_constant_jacobian_is_exact(system):
    s, _, _ = system  # the expert loop is -1.5 x
    lam = weighted_inf_rate(s, np.asarray(s.support, dtype=float), np.ones(2))
    assert lam is not None and lam <= LAM_STAR
    assert lam == pytest.approx(LAM_STAR, rel=ROUNDING_TOL)


def test_box_tubes_hold_the_simulated_expert_trajectories(nonlinear):
    s = nonlinear
    S = np.array([[-1.0, 1.0], [-1.0, 1.0]])
    times = np.linspace(0.0, s.horizon, 7)
    c, mags = np.zeros(2), np.zeros(2)
    tubes = box_tubes(s, S, c, mags, times)
    assert len(tubes) == 2  # the plain and the support-weighted inf-norm
    F = s.lower(s.closed_loop("expert"))
    starts = [np.array([a, b]) for a in (-1.0, 1.0) for b in (-0.5, 0.5)] + [np.array([0.7, -0.1])]
    for x0 in starts:
        sol = solve_ivp(
            lambda _t, x: np.asarray(F(0.0, x), dtype=float).reshape(-1), (0.0, s.horizon), x0,
            rtol=ODE_RTOL, atol=1e-12, t_eval=times,
        )  # fmt: skip
        for tb in tubes:
            w = np.asarray(tb.weights)
            r = np.asarray(tb.radius)
            assert np.all(np.max(np.abs(sol.y) * w[:, None], axis=0) <= r + GAP_ATOL)


def test_the_box_tubes_cut_the_sets_and_tighten_the_bound(system):
    s, net, K = system
    S = np.asarray(s.support, dtype=float)
    full = sup_policy_difference(s, S)
    assert full is not None
    w1, w2 = net.weights
    lip = np.linalg.norm(K + np.eye(2), 2) + np.linalg.norm(w1, 2) * np.linalg.norm(w2, 2)
    g_norm, lam_il = 0.5, 1.5 - 0.5 * float(lip) - RATE_SLACK

    def run(boxes: bool):
        return tube_bound(
            s, S, LAM_STAR, lam_il, g_norm, lambda b, ball: sup_policy_difference(s, b, ball),
            H_full=full.value, intervals=INTERVALS, boxes=boxes,
        )  # fmt: skip

    with_boxes, ball_only = run(True), run(False)
    assert with_boxes is not None and ball_only is not None
    # the expert loop is -1.5 x: the reachable set at t_k is exactly e^{-1.5 t_k} [-1, 1]^2
    for k, box in enumerate(with_boxes.sets):
        edge = math.exp(-LAM_STAR * with_boxes.times[k])
        assert np.allclose(np.asarray(box), [[-edge, edge]] * 2, rtol=ROUNDING_TOL)
    assert all(a <= b for a, b in zip(with_boxes.H, ball_only.H))
    # here the max is reached on the first interval (the set is S there); later times gain
    assert with_boxes.rho <= ball_only.rho and with_boxes.rho_t[-1] < ball_only.rho_t[-1]
    assert with_boxes.to_dict()["box_tubes"][0]["rate"] == pytest.approx(LAM_STAR)
