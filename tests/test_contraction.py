"""Contraction rates (DRIP Assumption 2): exact, interval branch and bound, sampled, LMI metric."""

from __future__ import annotations

import json

import numpy as np
import pytest
import sympy as sp

from drip_cert.analysis.contraction.lmi import (
    DEFAULT_BISECTION_TOL,
    contraction_metric,
    interval_vertices,
    metric_rate_lmi,
    verify_metric,
)
from drip_cert.analysis.contraction.lognorm import mu_2, mu_2_weighted, spectral_abscissa
from drip_cert.analysis.contraction.rate import (
    DEFAULT_TOL,
    SamplingOptions,
    contraction_rate,
    jacobian_function,
)
from drip_cert.errors import SpecError
from drip_cert.numerics.interval import UnsupportedExpression
from drip_cert.provenance import How
from drip_cert.spec import load_spec
from tests.helpers import CLOSED_FORM_TOL, write_spec

#: the branch-and-bound default: the sound rate is within this of the sampled one
BNB_TOL = DEFAULT_TOL
#: numpy re-evaluation of a verified metric at sampled points (rounding of eigvalsh)
RECHECK_TOL = 1e-9
#: metric rate vs -spectral abscissa: bisection tolerance plus the margin of the strict LMI
METRIC_TOL = 10 * DEFAULT_BISECTION_TOL
#: the witness is the centre of a final branch-and-bound box next to x1 = 0 (observed exactly 0)
WITNESS_TOL = 1e-3
#: cond(P) from eigvalsh may exceed the solver's cap kappa by the SDP solver's tolerance
SOLVER_CAP_REL = 1e-6
#: a rate this far beyond -(spectral abscissa) no metric can certify (far above METRIC_TOL)
BEYOND_ABSCISSA = 0.01

x1, x2, t = sp.symbols("x1 x2 t")


def _mu2_2x2(a, b, c, d):
    return 0.5 * (a + d) + np.sqrt((0.5 * (a - d)) ** 2 + (0.5 * (b + c)) ** 2)


def test_linear_and_affine_loops_are_exact():
    A = sp.Matrix([[-2, 3], [-1, -4]])
    r = contraction_rate(A, [x1, x2])
    assert r.how == How.EXACT and r.method == "exact-linear" and r.region == "all x, all t"
    assert r.rate == pytest.approx(-_mu2_2x2(-2, 3, -1, -4), abs=CLOSED_FORM_TOL)
    f = A * sp.Matrix([x1, x2]) + sp.Matrix([1, sp.Rational(5, 2)])  # affine: same Jacobian
    r2 = contraction_rate(f.jacobian([x1, x2]), [x1, x2], np.array([[-1, 1], [-1, 1]]))
    assert r2.how == How.EXACT and r2.rate == r.rate
    json.dumps(r.to_dict())


def test_time_varying_jacobian_is_sound_over_the_time_range_for_all_x():
    J = sp.Matrix([[-2 + sp.sin(t), 1], [0, -3]])
    r = contraction_rate(J, [x1, x2], None, t, (0.0, 10.0))
    ts = np.linspace(0, 10, 200001)
    truth = -np.max(_mu2_2x2(-2 + np.sin(ts), 1.0, 0.0, -3.0))
    assert r.how == How.SOUND and r.region.startswith("all x")
    assert truth - BNB_TOL <= r.rate <= truth
    with pytest.raises(SpecError, match="t_range"):
        contraction_rate(J, [x1, x2], None, t, None)


def test_cubic_scalar_rate_is_one_over_a_box_containing_zero():
    J = sp.Matrix([[sp.diff(-x1 - x1**3, x1)]])
    r = contraction_rate(J, [x1], np.array([[-2.0, 3.0]]))
    assert r.how == How.SOUND and r.method == "interval-bnb"
    assert 1.0 - BNB_TOL <= r.rate <= 1.0  # never above the true rate 1
    assert r.max_mu_sampled == pytest.approx(-1.0, abs=CLOSED_FORM_TOL)
    assert "box" in r.region and "paper asks for all x" in r.note
    # a box away from 0 contracts faster, a larger box never faster (monotonicity)
    far = contraction_rate(J, [x1], np.array([[1.0, 2.0]]))
    wider = contraction_rate(J, [x1], np.array([[0.5, 2.0]]))
    assert 4.0 - BNB_TOL <= far.rate <= 4.0
    assert wider.rate <= far.rate and 1.75 - BNB_TOL <= wider.rate <= 1.75


def test_nonlinear_2d_sampled_and_sound_bracket_the_truth():
    f = sp.Matrix([-x1 + sp.Rational(1, 2) * sp.sin(x2), -x2 - x2**3 + sp.Rational(3, 10) * x1])
    J = f.jacobian([x1, x2])
    box = np.array([[-2.0, 2.0], [-1.5, 1.5]])
    r = contraction_rate(J, [x1, x2], box)
    # independent truth: mu_2 depends on x2 only, closed form on a fine grid (x2 = 0 is on it)
    s = np.linspace(-1.5, 1.5, 300001)
    truth_max_mu = np.max(_mu2_2x2(-1.0, 0.5 * np.cos(s), 0.3, -1.0 - 3 * s**2))
    assert r.max_mu_sampled <= truth_max_mu + CLOSED_FORM_TOL
    assert r.max_mu_upper >= truth_max_mu
    assert r.gap <= BNB_TOL and r.how == How.SOUND
    est = contraction_rate(J, [x1, x2], box, method="sampled")
    assert est.how == How.ESTIMATE and np.isnan(est.max_mu_upper)
    assert r.rate <= -truth_max_mu <= est.rate + CLOSED_FORM_TOL


def test_failure_reports_a_witness():
    J = sp.Matrix([[1 - x1**2, 0], [0, -1]])
    r = contraction_rate(J, [x1, x2], np.array([[-0.5, 0.5], [-1.0, 1.0]]))
    assert not r.holds and r.rate <= -1.0 + BNB_TOL
    assert abs(r.witness[0]) < WITNESS_TOL  # mu_2 is largest at x1 = 0


def test_undefined_function_falls_back_to_an_estimate_or_uses_a_callback():
    h = sp.Function("h")
    J = sp.Matrix([[-2 + h(x1), 0], [0, -1]])
    box = np.array([[-1.0, 1.0], [-1.0, 1.0]])

    def J_num(tv, X):
        out = np.zeros((len(X), 2, 2))
        out[:, 0, 0] = -2 + 0.5 * np.tanh(X[:, 0])
        out[:, 1, 1] = -1
        return out

    est = contraction_rate(J, [x1, x2], box, J_num=J_num)
    assert est.how == How.ESTIMATE and est.method == "sampled" and "h" in est.note
    assert est.rate == pytest.approx(1.0, abs=CLOSED_FORM_TOL)
    sound = contraction_rate(J, [x1, x2], box, J_num=J_num, enclose=lambda n, a: (-0.5, 0.5))
    assert sound.how == How.SOUND and 1.0 - BNB_TOL <= sound.rate <= 1.0


def test_bad_inputs_name_the_field():
    J = sp.Matrix([[-1 - x1**2]])
    with pytest.raises(SpecError, match="box"):
        contraction_rate(J, [x1])
    with pytest.raises(SpecError, match="box"):
        contraction_rate(J, [x1], np.array([[1.0, -1.0]]))
    with pytest.raises(SpecError, match="a"):
        contraction_rate(sp.Matrix([[-sp.Symbol("a")]]), [x1])
    with pytest.raises(SpecError, match="method"):
        contraction_rate(J, [x1], np.array([[0.0, 1.0]]), method="magic")


def test_jacobian_function_matches_sympy():
    J = sp.Matrix([[-1, sp.cos(x2)], [x1 * t, 3]])
    fn = jacobian_function(J, [x1, x2], t)
    X = np.random.default_rng(0).normal(size=(5, 2))
    tv = np.arange(5.0)
    out = fn(tv, X)
    for k in range(5):
        ref = np.array(J.subs({x1: X[k, 0], x2: X[k, 1], t: tv[k]}).evalf(), dtype=float)
        np.testing.assert_allclose(out[k], ref, atol=CLOSED_FORM_TOL)


# ---------------------------------------------------------------------------------------------
# LMI contraction metric
# ---------------------------------------------------------------------------------------------


def test_interval_vertices_enumerate_the_hull_corners():
    lo = np.array([[0.0, 1.0], [2.0, 3.0]])
    hi = np.array([[0.0, 1.5], [2.5, 3.0]])
    V = interval_vertices(lo, hi)
    assert V.shape == (4, 2, 2)
    assert {tuple(v.ravel()) for v in V} == {
        (0.0, a, b, 3.0) for a in (1.0, 1.5) for b in (2.0, 2.5)
    }


def test_hurwitz_matrix_with_positive_mu2_gets_metric_rate_near_spectral_abscissa():
    A = np.array([[-1.0, 10.0], [0.0, -2.0]])
    assert mu_2(A) > 0  # Euclidean contraction fails
    rate, P, _ = metric_rate_lmi(A[None])
    alpha = spectral_abscissa(A)
    assert -alpha - METRIC_TOL <= rate <= -alpha
    assert mu_2_weighted(A, P) <= -rate + RECHECK_TOL
    assert verify_metric(A[None], P, rate)
    assert not verify_metric(A[None], P, -alpha + BEYOND_ABSCISSA)  # beyond the abscissa


def test_metric_for_the_nonlinear_2d_example_holds_at_sampled_states():
    f = sp.Matrix([-x1 + 2 * x2, -x2 - x2**3])  # mu_2 = 0 at x2 = 0: Euclidean rate 0
    J = f.jacobian([x1, x2])
    box = np.array([[-1.0, 1.0], [-1.0, 1.0]])
    m = contraction_metric(J, [x1, x2], box)
    assert m.how == How.SOUND and m.n_vertices >= 1
    assert m.euclidean_rate <= CLOSED_FORM_TOL and m.metric_rate > 0.9
    assert 1.0 <= m.cond_P <= m.kappa * (1 + SOLVER_CAP_REL)
    rng = np.random.default_rng(1)
    X = box[:, 0] + rng.random((2000, 2)) * 2.0
    Js = jacobian_function(J, [x1, x2], None)(np.zeros(len(X)), X)
    assert np.max(mu_2_weighted(Js, m.P)) <= -m.metric_rate + RECHECK_TOL
    json.dumps(m.to_dict())


def test_metric_with_sampled_fallback_is_labelled_estimate():
    h = sp.Function("h")
    J = sp.Matrix([[-2 + h(x1), 0], [0, -1]])

    def J_num(tv, X):
        out = np.zeros((len(X), 2, 2))
        out[:, 0, 0] = -2 + 0.5 * np.tanh(X[:, 0])
        out[:, 1, 1] = -1
        return out

    m = contraction_metric(
        J,
        [x1, x2],
        np.array([[-1.0, 1.0], [-1.0, 1.0]]),
        J_num=J_num,
        sampling=SamplingOptions(n_grid=64, n_random=64),
    )
    assert m.how == How.ESTIMATE and "sampled" in m.note


class _Block(sp.Function):
    """A learned block as a sympy Function subclass; its derivative is another opaque class."""

    def fdiff(self, argindex=1):
        return _BlockD(*self.args)


class _BlockD(sp.Function):
    pass


def test_block_function_subclasses_are_sampled_or_enclosed():
    f = sp.Matrix([-2 * x1 + sp.Rational(1, 2) * _Block(x2), -x2])
    J = f.jacobian([x1, x2])  # [[-2, dB(x2)/2], [0, -1]]
    box = np.array([[-1.0, 1.0], [-1.0, 1.0]])

    def J_num(tv, X):  # B = tanh, B' = 1 - tanh^2 in [0.42, 1] on the box
        out = np.zeros((len(X), 2, 2))
        out[:, 0, 0], out[:, 1, 1] = -2.0, -1.0
        out[:, 0, 1] = 0.5 * (1 - np.tanh(X[:, 1]) ** 2)
        return out

    with pytest.raises(UnsupportedExpression):
        jacobian_function(J, [x1, x2], None)
    est = contraction_rate(J, [x1, x2], box, J_num=J_num)
    assert est.how == How.ESTIMATE

    def enclose(node, args):  # only B' is known (in [0, 1]); B'' is refused
        return (0.0, 1.0) if node.func is _BlockD else None

    sound = contraction_rate(J, [x1, x2], box, J_num=J_num, enclose=enclose)
    truth = -_mu2_2x2(-2.0, 0.5, 0.0, -1.0)  # largest coupling at x2 = 0
    assert sound.how == How.SOUND and sound.rate <= truth <= est.rate + CLOSED_FORM_TOL


# ------------------------------------------------------- literals read exactly (issue 22, 2)
#: 25 digits; its double is 0.65469604390304614..., whose shortest repr 0.6546960439030461 is
#: 8.5e-17 below the number written
DIGITS_25 = "0.6546960439030461848070769"
#: the loop's exact mu_2: the expert's gain is DIGITS_25 - 8.4e-27 (28 digits)
MU2_EXACT = sp.Rational(84, 10**28)
#: the exact route's rate is the float of an Arb-isolated root of a rational polynomial: ulps
EXACT_RATE_RTOL = 1e-14
_ONE_STATE = """
[system]
name = "digits"
states = ["x1"]
inputs = ["u"]
horizon = 1.0
[initial]
support = [[-0.2, 0.2]]
"""


@pytest.mark.parametrize(
    "model",
    [
        # expressions: the 25-digit literal in f, the gain as an exact integer ratio
        f'[dynamics]\nf = ["{DIGITS_25}*x1"]\ng = [["1"]]\n'
        '[policy]\nexpert = ["-6546960439030461848070768916/10**28*x1"]\n',
        # a linear model: both as TOML floats (the 28-digit gain rounds to the same double)
        f"[dynamics]\nA = [[{DIGITS_25}]]\nB = [[1]]\n"
        "[policy]\nexpert = { K = [[0.6546960439030461848070768916]] }\n",
    ],
    ids=["expressions", "toml-floats"],
)
def test_a_loop_with_exact_mu2_above_zero_is_not_contracting(tmp_path, model):
    """mu_2 = +8.4e-27 exactly: the exact route must say "not contracting" (rate -8.4e-27 < 0).
    Rounding the literals to doubles (or their repr) first gave the rate +8.5e-17 or 0."""
    system = load_spec(write_spec(tmp_path, _ONE_STATE + model)).system
    J = system.closed_loop_jacobian("expert")
    assert J == sp.Matrix([[MU2_EXACT]])
    r = contraction_rate(J, system.states)
    assert r.how == How.EXACT and r.method == "exact-linear"
    assert r.rate < 0
    assert r.rate == pytest.approx(-float(MU2_EXACT), rel=EXACT_RATE_RTOL)
