"""delta-ISS gains: DRIP Proposition 1, its corollary, and the tighter comparison-lemma bound."""

from __future__ import annotations

import json
import math
from fractions import Fraction

import mpmath as mp
import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st
from scipy.integrate import solve_ivp

from drip_cert.analysis.iss import delta_iss, discrete_bound
from drip_cert.errors import AssumptionViolation, SpecError
from drip_cert.provenance import How, Quantity
from tests.helpers import CLOSED_FORM_TOL, MP_DPS

#: solve_ivp's tolerances for the simulated trajectories (near double precision)
IVP_RTOL, IVP_ATOL = 1e-10, 1e-12
#: solve_ivp with IVP_RTOL / IVP_ATOL over t <= 6: global error well below this
SIM_TOL = 1e-7
#: the finite-time optimum theta(T) approaches theta* exponentially in T: at T = 60 it is theta*
#: to rounding (observed 2e-16); 1e-4 is a generous ceiling
THETA_LIMIT_REL = 1e-4
#: relative accuracy of the optimum found on a 20001-point theta grid
GRID_REL = 1e-6

LAM = 1.5  # rate of the test system, proved by Gershgorin below
G = np.diag([1.0, 0.5])  # ||G||_2 = 1, ||G||_F = sqrt(1.25)
G2, GF = 1.0, float(np.sqrt(1.25))


def _f(x):
    # J = [[-2, cos(x2)/2], [cos(x1)/2, -2 - 3 x2^2]]: diagonal <= -2, |sym off-diagonal| <= 1/2,
    # so by Gershgorin mu_2(J) <= -1.5 for all x (DRIP Assumption 2 with lambda = 1.5)
    return np.array([-2 * x[0] + 0.5 * np.sin(x[1]), -2 * x[1] - x[1] ** 3 + 0.5 * np.sin(x[0])])


def _perturbation(rng):
    amp = rng.normal(size=(2, 3))
    om = rng.uniform(0.2, 4.0, size=(2, 3))
    ph = rng.uniform(0, 2 * np.pi, size=(2, 3))

    def s(tt):
        return np.sum(amp * np.sin(om * tt + ph), axis=1)

    sup = float(np.linalg.norm(np.abs(amp).sum(axis=1)))  # rigorous sup of ||s||
    return s, sup


def test_closed_forms_and_best_asymptotic_theta():
    r = delta_iss(LAM, GF, G2)
    assert r.theta_star == pytest.approx(LAM / GF**2, rel=CLOSED_FORM_TOL)
    assert r.paper_gain_asymptotic == pytest.approx(GF / LAM, rel=CLOSED_FORM_TOL)
    assert r.tight_gain_asymptotic == pytest.approx(G2 / LAM, rel=CLOSED_FORM_TOL)
    # the paper's gain at theta* tends to Delta_g / lambda
    assert r.paper_gain(1e3) == pytest.approx(GF / LAM, rel=CLOSED_FORM_TOL)
    assert r.lambda_theta() == pytest.approx(LAM, rel=CLOSED_FORM_TOL)  # 2 lam - lam
    # theta* is the minimiser of the asymptotic gain on a fine grid
    thetas = np.linspace(1e-4, 1 - 1e-4, 20001) * 2 * LAM / GF**2
    asym = 1 / np.sqrt(thetas * (2 * LAM - thetas * GF**2))
    assert abs(thetas[np.argmin(asym)] - r.theta_star) <= 2 * (thetas[1] - thetas[0])
    assert r.paper_gain_quantity().value == pytest.approx(asym.min(), rel=GRID_REL)


@pytest.mark.parametrize(("t", "e0"), [(0.1, 0.0), (1.0, 0.0), (3.0, 2.0), (0.5, 1.0)])
def test_best_theta_at_finite_time_beats_a_fine_grid(t, e0):
    r = delta_iss(LAM, GF, G2)
    th = r.best_theta(t, e0=e0, sup_s=1.0)
    thetas = np.linspace(1e-5, 1 - 1e-5, 20001) * 2 * LAM / GF**2
    grid = np.array([r.paper_bound(t, e0, 1.0, x) for x in thetas])
    assert r.paper_bound(t, e0, 1.0, th) <= grid.min() * (1 + GRID_REL)


def test_best_theta_tends_to_theta_star():
    r = delta_iss(LAM, GF, G2)
    assert r.best_theta(60.0) == pytest.approx(r.theta_star, rel=THETA_LIMIT_REL)


def test_tight_bound_is_never_above_the_papers_for_any_theta():
    r = delta_iss(LAM, GF, G2)
    ts = np.linspace(0.0, 20.0, 401)
    for th in np.linspace(1e-3, 1 - 1e-3, 199) * 2 * LAM / GF**2:
        assert np.all(r.tight_gain(ts) <= r.paper_gain(ts, th) + CLOSED_FORM_TOL)
        assert np.all(r.tight_decay(ts) <= r.paper_decay(ts, th) + CLOSED_FORM_TOL)
    # even with Delta_g = ||g||_2 (the paper at its best) the tight bound stays below
    same = delta_iss(LAM, G2, G2)
    for th in np.linspace(1e-3, 1 - 1e-3, 199) * 2 * LAM / G2**2:
        assert np.all(same.tight_gain(ts) <= same.paper_gain(ts, th) + CLOSED_FORM_TOL)


def test_tight_bound_is_attained_by_the_scalar_linear_system():
    # e' = -lam e + g s with constant s: the comparison-lemma bound holds with equality
    lam, g, s, e0 = 0.7, 1.3, 0.4, 2.0
    r = delta_iss(lam, g)
    sol = solve_ivp(
        lambda tt, e: -lam * e + g * s,
        (0, 6),
        [e0],
        rtol=IVP_RTOL,
        atol=IVP_ATOL,
        dense_output=True,
    )
    ts = np.linspace(0, 6, 61)
    np.testing.assert_allclose(sol.sol(ts)[0], r.tight_bound(ts, e0, s), atol=SIM_TOL)


@pytest.mark.parametrize("seed", [0, 1, 2])
def test_both_bounds_hold_on_simulated_trajectory_pairs(seed):
    rng = np.random.default_rng(seed)
    s, sup = _perturbation(rng)
    xi1, xi2 = rng.normal(size=2) * 2, rng.normal(size=2) * 2

    def rhs(tt, z):
        y, x = z[:2], z[2:]
        return np.concatenate([_f(y) + G @ s(tt), _f(x)])

    ts = np.linspace(0, 6, 601)
    sol = solve_ivp(
        rhs, (0, 6), np.concatenate([xi1, xi2]), t_eval=ts, rtol=IVP_RTOL, atol=IVP_ATOL
    )
    err = np.linalg.norm(sol.y[:2] - sol.y[2:], axis=0)
    e0 = float(np.linalg.norm(xi1 - xi2))
    r = delta_iss(LAM, GF, G2)
    assert np.all(err <= r.tight_bound(ts, e0, sup) + SIM_TOL)
    for th in (0.2 * r.theta_star, r.theta_star, 1.8 * r.theta_star):
        assert np.all(err <= r.paper_bound(ts, e0, sup, th) + SIM_TOL)


def test_discrete_corollary_with_piecewise_constant_perturbation():
    rng = np.random.default_rng(7)
    tp = np.linspace(0, 4, 9)[:-1]  # partition points without T
    svals = rng.normal(size=(len(tp), 2))
    xi1, xi2 = np.array([1.0, -1.0]), np.array([-0.5, 0.3])
    z = np.concatenate([xi1, xi2])
    states = [z]
    edges = np.append(tp, 4.0)
    for i in range(len(tp) - 1):
        si = svals[i]
        sol = solve_ivp(
            lambda tt, zz, si=si: np.concatenate([_f(zz[:2]) + G @ si, _f(zz[2:])]),
            (edges[i], edges[i + 1]),
            z,
            rtol=IVP_RTOL,
            atol=IVP_ATOL,
        )
        z = sol.y[:, -1]
        states.append(z)
    err = np.array([np.linalg.norm(zz[:2] - zz[2:]) for zz in states])
    r = delta_iss(LAM, GF, G2)
    e0 = float(np.linalg.norm(xi1 - xi2))
    tight = discrete_bound(r, tp, e0, svals)
    paper = discrete_bound(r, tp, e0, svals, which="paper")
    assert np.all(err <= tight + SIM_TOL) and np.all(tight <= paper + CLOSED_FORM_TOL)


def test_provenance_and_errors():
    r = delta_iss(Quantity("lambda", LAM, How.SOUND), Quantity("Delta_g", GF, How.EXACT), G2)
    assert r.how == How.GIVEN  # a bare float is user-given
    q = r.gain()
    assert q.name == "gamma_0" and "comparison lemma" in q.source
    # rounded up: at or one ulp above the exact 2/3 (which is not a float)
    assert Fraction(q.value) >= Fraction(G2) / Fraction(LAM)
    assert q.value <= math.nextafter(G2 / LAM, math.inf)
    assert r.gain(T=2.0).value == pytest.approx(
        G2 / LAM * (1 - np.exp(-LAM * 2.0)), rel=CLOSED_FORM_TOL
    )
    est = delta_iss(Quantity("lambda", LAM, How.ESTIMATE), GF)
    assert est.how == How.ESTIMATE and est.g_norm2 == GF
    json.dumps(r.to_dict())
    with pytest.raises(AssumptionViolation, match="lambda"):
        delta_iss(-0.1, 1.0)
    with pytest.raises(SpecError, match="g_norm2"):
        delta_iss(1.0, 1.0, 2.0)
    with pytest.raises(SpecError, match="theta"):
        r.paper_gain(1.0, theta=2 * LAM / GF**2)


# ------------------------------------------------------------------------ rounding of the gains

#: an outward-rounded closed form exceeds the exact value by a few ulps at most
ROUNDED_REL_EXCESS = 1e-14

_pos = st.floats(min_value=1e-6, max_value=1e3, allow_nan=False)


@settings(max_examples=300)
@given(lam=_pos, dg=_pos, frac=st.floats(0.0, 1.0))
def test_asymptotic_gains_are_rounded_up(lam, dg, frac):
    g2 = dg * frac
    r = delta_iss(Quantity("lambda", lam, How.SOUND), Quantity("Delta_g", dg, How.SOUND), g2)
    assert Fraction(r.tight_gain_asymptotic) >= Fraction(r.g_norm2) / Fraction(lam)
    assert Fraction(r.paper_gain_asymptotic) >= Fraction(dg) / Fraction(lam)


def test_float_division_would_understate_the_gain():
    # 1/3 rounds DOWN in float: the old unrounded gain was below the true gain
    assert Fraction(1.0 / 3.0) < Fraction(1, 3)
    r = delta_iss(Quantity("lambda", 3.0, How.EXACT), Quantity("Delta_g", 1.0, How.EXACT))
    assert Fraction(r.tight_gain_asymptotic) > Fraction(1, 3)
    assert Fraction(r.gain().value) > Fraction(1, 3)


@settings(max_examples=100)
@given(lam=_pos, dg=_pos, T=st.floats(1e-6, 1e3), th=st.floats(1e-3, 1 - 1e-3))
def test_finite_time_gains_are_rounded_up(lam, dg, T, th):
    r = delta_iss(Quantity("lambda", lam, How.SOUND), Quantity("Delta_g", dg, How.SOUND))
    theta = th * 2 * lam / dg**2
    with mp.workdps(MP_DPS):
        L, D, TT, TH = (mp.mpf(v) for v in (lam, dg, T, theta))
        tight = D / L * (1 - mp.exp(-L * TT))
        lt = 2 * L - TH * D**2
        paper = mp.sqrt((1 - mp.exp(-lt * TT)) / (TH * lt))
        paper_inf = 1 / mp.sqrt(TH * lt)
    got = r.gain(T).value
    assert got >= tight and got - tight <= ROUNDED_REL_EXCESS * tight
    assert r.paper_gain_quantity(T, theta).value >= paper
    assert r.paper_gain_quantity(None, theta).value >= paper_inf


def test_labels_come_from_provenance_weakest():
    exact = Quantity("lambda", LAM, How.EXACT)
    # exact inputs: the rounded-up gain is a sound bound, not an exact value
    assert delta_iss(exact, Quantity("Delta_g", GF, How.EXACT)).how == How.SOUND
    assert delta_iss(exact, Quantity("Delta_g", GF, How.GIVEN)).how == How.GIVEN
    est = Quantity("Delta_g", GF, How.ESTIMATE)
    assert delta_iss(exact, est, Quantity("g", G2, How.GIVEN)).how == How.ESTIMATE
