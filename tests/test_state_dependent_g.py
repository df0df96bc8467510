"""A state-dependent input operator g(t, x) (issue 23): model, numeric view, engine, constants,
certificate parts and validation.

The reference system: ``x1' = -x1 + c``, ``x2' = (2 + sin x1) u``. With the expert
``u = -x2 / (2 + sin x1)`` the closed loop is ``x2' = -x2``; with ``u = -x2`` it is
``x2' = -(2 + sin x1) x2``, whose Jacobian has the entry ``-cos(x1) x2`` that only the product rule
through ``g(x)`` produces.
"""

from __future__ import annotations

import math

import numpy as np
import pytest
import sympy as sp

from drip_cert import System, certify
from drip_cert._jax import jnp
from drip_cert.analysis.growth.constants import input_constants
from drip_cert.errors import SpecError
from drip_cert.model.numeric import closed_loop_jacobian
from drip_cert.sim.config import SimConfig
from drip_cert.sim.engine import simulate

JAC_RTOL = 1e-12
"""The lowered symbolic Jacobian and jax forward-mode autodiff are two float64 evaluations of one
O(1) expression: a few ulps apart."""

JAC_ATOL = 1e-15
"""Autodiff of ``(2 + sin x1) * (-x2 / (2 + sin x1))`` leaves a residue of a few ulps of its O(1)
cancelling terms where the exact entry is 0."""

FD_ATOL = 1e-6
"""Central differences with step 1e-5 on O(1) smooth entries: truncation O(h^2) = 1e-10 plus
rounding eps / h ~ 2e-11, far below 1e-6."""

ENGINE_RTOL = 1e-12
"""The engine's Euler recursion and the same recursion in numpy: the same float64 operations up
to the order of a 1-term product and a 2-term sum, a few ulps per step over 100 steps."""

SUP_RTOL = 1e-3
"""The branch and bound of a sup of ||g|| stops within G_RTOL = 1e-3 of a sampled value
(analysis/growth/constants.py); the bound can exceed the true sup by at most that much."""

X1, X2 = sp.symbols("x1 x2", real=True)


def _system(c: float = 0.0, learned=None, support=0.5, region=None) -> System:
    return System(
        name="g-of-x",
        states=(X1, X2),
        f=[-X1 + c, 0],
        g=[[0], [2 + sp.sin(X1)]],
        expert=[-X2 / (2 + sp.sin(X1))],
        learned=learned,
        support=[(-support, support), (-support, support)],
        horizon=1.0,
        Delta_mu=0.01,
        Delta_sigma=0.01,
    )


def test_state_dependent_g_is_accepted_and_the_jacobian_has_the_product_rule_term():
    s = _system(learned=[-X2])
    assert s.g_depends_on_x
    J = s.closed_loop_jacobian("learned")
    # d/dx1 [(2 + sin x1)(-x2)] = -cos(x1) x2: present only through g(x)
    assert sp.simplify(J[1, 0] + sp.cos(X1) * X2) == 0
    assert sp.simplify(s.closed_loop_jacobian("expert") - sp.diag(-1, -1)) == sp.zeros(2, 2)
    num = s.numeric
    assert num.g_state
    x = jnp.array([0.7, -0.4])
    for jac, pol in ((num.jac_expert, num.expert), (num.jac_learned, num.learned)):
        auto = closed_loop_jacobian(num.f, num.g, pol)(0.0, x)
        np.testing.assert_allclose(
            np.asarray(jac(0.0, x)), np.asarray(auto), rtol=JAC_RTOL, atol=JAC_ATOL
        )
    # and against central differences of the closed loop itself
    h = 1e-5

    def F(z):
        z = jnp.asarray(z)
        return np.asarray(num.f(0.0, z) + num.g(0.0, z) @ num.learned(z))

    fd = np.stack(
        [(F(np.array(x) + h * e) - F(np.array(x) - h * e)) / (2 * h) for e in np.eye(2)], axis=1
    )
    np.testing.assert_allclose(np.asarray(num.jac_learned(0.0, x)), fd, rtol=0, atol=FD_ATOL)


def test_rank_of_a_state_dependent_g_is_checked_on_the_support():
    with pytest.raises(SpecError, match="rank 0"):
        System(
            name="bad",
            states=(X1, X2),
            f=[-X1, -X2],
            g=[[0], [X1]],  # zero at the support's centre
            expert=[0],
            support=[(-1, 1), (-1, 1)],
            horizon=1.0,
        )


def test_engine_evaluates_g_at_each_paths_state():
    """Point-mass initial law: every path is the Euler recursion of the closed loop with g(x);
    a g read at x = 0 (g = 2) would give x2' = -2 x2 for the learned loop instead."""
    s = _system(learned=[-X2])
    x0 = np.array([0.9, 0.8])
    dt, steps = 0.01, 100
    cfg = SimConfig(
        T=dt * steps,
        dt=dt,
        n_paths=4,
        seed=0,
        record_every=steps,
        scenarios=("expert_nominal", "learned_nominal"),
    )
    res = simulate(s.numeric, cfg, lambda key: jnp.asarray(x0), progress=False)
    ref = {}
    for name, u in (
        ("expert_nominal", lambda x: -x[1] / (2 + math.sin(x[0]))),
        ("learned_nominal", lambda x: -x[1]),
    ):
        x = x0.copy()
        for _ in range(steps):
            x = x + dt * np.array([-x[0], (2 + math.sin(x[0])) * u(x)])
        ref[name] = x
    got = np.asarray(res.sample_paths)[:, 0, -1, :]
    np.testing.assert_allclose(got[0], ref["expert_nominal"], rtol=ENGINE_RTOL)
    np.testing.assert_allclose(got[1], ref["learned_nominal"], rtol=ENGINE_RTOL)


def test_sup_of_g_is_a_sound_bound_over_the_box():
    s = _system()
    box = np.array([[-1.5, 1.5], [-1.5, 1.5]])
    ic = input_constants(s, box)
    exact_sup = 2 + math.sin(1.5)  # ||g||_F = ||g||_2 = |2 + sin x1|, increasing on the box
    exact_inf = 2 - math.sin(1.5)
    for q in (ic.Delta_g, ic.Delta_g_spectral):
        assert exact_sup <= q.value <= exact_sup * (1 + SUP_RTOL)
        assert q.how.value == "sound" and q.scope.box == tuple(map(tuple, box))
    assert exact_inf * (1 - SUP_RTOL) <= ic.min_singular_value.value <= exact_inf
    assert ic.rank.value == 1
    with pytest.raises(ValueError, match="give the box"):
        input_constants(s)


def test_certificate_covers_drip_parts_and_l1drac_is_not_applicable():
    cert = certify(_system())
    parts = cert.part_verdicts()
    assert parts["contraction"]["verdict"] == "certified"
    assert parts["l1drac"]["verdict"] == "not_applicable"
    assert "g(t)" in parts["l1drac"]["reasons"][0]
    a1 = next(c for c in cert.assumptions if c.id == "DRIP-A1")
    assert a1.scope.box == ((-0.5, 0.5), (-0.5, 0.5)) and a1.scope_ok
    # gamma0 = sup ||g||_2 / lambda on the support (the rate is exactly 1)
    assert cert.delta_iss.g_norm2 == pytest.approx(2 + math.sin(0.5), rel=SUP_RTOL)
    assert cert.inputs.Delta_g.value >= 2 + math.sin(0.5)


def test_sup_over_an_unproved_set_makes_the_result_conditional():
    """The drift pushes the expert out of the support (equilibrium x1 = 2): no invariant set in
    the box where sup ||g|| is taken, so the parts resting on it are conditional, never global."""
    cert = certify(_system(c=2.0))
    assert cert.verdict.value == "conditional"
    a1 = next(c for c in cert.assumptions if c.id == "DRIP-A1")
    assert a1.holds and not a1.scope_ok
    assert "g depends on the state" in a1.scope_reason


@pytest.mark.slow  # certify + a Monte-Carlo run with its compile: ~16 s on a loaded 2-core machine
def test_validation_simulates_no_l1drac_process_and_says_why():
    from drip_cert.validate.run import validate

    s = _system(learned=[-X2 + sp.Rational(1, 50) * sp.tanh(X1)])
    report = validate(s, paths=64, seed=0)
    assert "learned_l1_true" not in report.result.config.scenarios
    by_name = {c["name"]: c for c in report.to_dict()["checks"]}
    for name in ("uncertainty_gap", "tail_frequency", "total_tail"):
        assert by_name[name]["status"] == "not_checked"
        assert "g depends on the state" in by_name[name]["reason"]
    # the DRIP processes are simulated with g(x) (the engine test above checks their values)
    assert report.result.gap("policy").n == 64
