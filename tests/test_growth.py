"""Sound global growth / Lipschitz / 1/2-Hoelder constants (L1-DRAC Assumptions 4 and 6).

Closed-form cases (the DRIP paper's 4-D uncertainty, bounded and constant fields), references
computed independently with scipy, a sampled property test that no bound is below an observed
ratio, and the fallback to a labelled estimate for a field no sound route covers.
"""

from __future__ import annotations

import math

import numpy as np
import pytest
import sympy as sp
from hypothesis import given, settings
from hypothesis import strategies as st
from scipy.optimize import minimize_scalar

from drip_cert.analysis.growth.regularity import (
    BNB_RTOL,
    growth_bound,
    holder_half_bound,
    lipschitz_bound,
)
from drip_cert.model.expr import parse_expression
from drip_cert.numerics.sampling import (
    SAMPLE_RADII,
    growth_ratio_estimate,
    holder_estimate,
)
from drip_cert.provenance import How

#: a sound bound may exceed the supremum by the branch-and-bound stopping rule (relative
#: BNB_RTOL) plus outward rounding; 10x that is still far below any modelling error
BNB_SLACK = 10 * BNB_RTOL
#: closed-form bounds (constant derivative enclosures) are off only by a few ulps of rounding
ULPS = 1e-14
#: numpy's own rounding of a sampled ratio (relative), so that "bound >= sample" is exact math
SAMPLE_SLACK = 1e-12
#: scipy's bounded Brent search to xatol 1e-12 finds the 1-D maximiser; the value is then exact
#: to ~1e-16 relative (the maximum is flat), far inside BNB_SLACK
SCIPY_XATOL = 1e-12
#: the Collatz-Wielandt bound of ||A||_2 with its vector from an SVD: within a few ulps of
#: LAPACK's value in practice; 1e-9 relative is a generous ceiling
COLLATZ_REL = 1e-9
#: 2 r / sqrt(1 + r^2) at the largest sampled radius r = 1e6 is 2 (1 - 5e-13)
LARGEST_RADIUS_DEFICIT = 1e-12
#: a Lipschitz ratio |F(a) - F(b)| / |a - b| sampled at distances down to 1e-6: cancellation
#: costs up to ~eps |a| / 1e-6 relative (observed exact for this linear field)
CANCELLATION_REL = 1e-6

X = sp.symbols("x1:5", real=True)
T = sp.Symbol("t", real=True)
NO_TIME = (0.0, 0.0)
SCALARS = {str(s): s for s in X}


def _parse(text: str) -> sp.Expr:
    return parse_expression(text, field="test", scalars=SCALARS, vector_name="x", vector=X)


# the DRIP paper's example (drip_cert/data/paper_4d/paper_4d.toml, [uncertainty])
LAMBDA_MU = sp.Matrix([_parse("0.1 + 0.05*norm(x)")] * 4)
LAMBDA_SIGMA = sp.diag(*[_parse("0.1 + 0.05*norm(x)**0.5")] * 4)


def _max_1d(fun, hi: float) -> float:
    res = minimize_scalar(
        lambda r: -fun(r), bounds=(0.0, hi), method="bounded", options={"xatol": SCIPY_XATOL}
    )
    return float(-res.fun)


# ----------------------------------------------------------------------------- the paper
def test_paper_lambda_mu_growth_is_sqrt_005():
    # ||Lambda_mu(a)|| = ||1_4|| (0.1 + 0.05 r) = 0.2 + 0.1 r with r = ||a||.
    # d/dr (0.2 + 0.1 r)/sqrt(1 + r^2) = [0.1 (1 + r^2) - (0.2 + 0.1 r) r] / (1 + r^2)^{3/2}
    #                                = (0.1 - 0.2 r) / (1 + r^2)^{3/2} = 0  at r = 1/2,
    # value 0.25 / sqrt(1.25) = sqrt(0.0625 / 1.25) = sqrt(0.05) = 0.22360679...
    # (Cauchy-Schwarz gives the same: 0.2 + 0.1 r <= sqrt(0.2^2 + 0.1^2) sqrt(1 + r^2), equality
    # at r = 0.1 / 0.2; so the Lipschitz route and the radial branch and bound both reach it)
    q = growth_bound(LAMBDA_MU, X, None, NO_TIME, 1, "Delta_mu")
    exact = math.sqrt(0.05)
    assert q.how is How.SOUND
    assert exact <= q.value <= exact * (1 + BNB_SLACK)


def test_paper_lambda_mu_lipschitz_is_0_1():
    # dF/da = 0.05 * 1_4 (a / r)^T, rank one with norm 0.05 * ||1_4|| = 0.1, attained on rays
    q = lipschitz_bound(LAMBDA_MU, X, None, NO_TIME, "L_mu")
    assert q.how is How.SOUND
    assert 0.1 <= q.value <= 0.1 * (1 + ULPS)


def test_paper_lambda_sigma_growth_matches_scipy():
    # ||Lambda_sigma||_F = ||I_4||_F (0.1 + 0.05 sqrt(r)) = 2 (0.1 + 0.05 sqrt(r)), power 1/2
    ref = _max_1d(lambda r: 2 * (0.1 + 0.05 * math.sqrt(r)) / (1 + r * r) ** 0.25, 10.0)
    q = growth_bound(LAMBDA_SIGMA, X, None, NO_TIME, 0.5, "Delta_sigma")
    assert q.how is How.SOUND
    assert ref <= q.value <= ref * (1 + BNB_SLACK)


def test_paper_lambda_sigma_holder_is_0_1():
    # |sqrt(r1) - sqrt(r2)| <= sqrt(|r1 - r2|) <= ||a - b||^{1/2}, equality at b = 0:
    # constant 0.05 * ||I_4||_F = 0.1
    q = holder_half_bound(LAMBDA_SIGMA, X, None, NO_TIME, "L_sigma")
    assert q.how is How.SOUND
    assert 0.1 <= q.value <= 0.1 * (1 + ULPS)


def test_paper_lambda_sigma_is_not_lipschitz_and_says_so():
    # 0.05 sqrt(r) has an infinite slope at r = 0: no sound Lipschitz bound exists
    q = lipschitz_bound(LAMBDA_SIGMA, X, None, NO_TIME, "L")
    assert q.how is How.ESTIMATE
    assert "estimate, not a bound" in q.note and "likely infinite" in q.note


def test_paper_lambda_mu_is_not_holder_half():
    # linear growth in r: ||F(a) - F(0)|| / ||a||^{1/2} = 0.1 sqrt(r) is unbounded
    q = holder_half_bound(LAMBDA_MU, X, None, NO_TIME, "H")
    assert q.how is How.ESTIMATE
    assert "estimate, not a bound" in q.note


# ------------------------------------------------------------------------- bounded fields
def test_bounded_sin_field():
    F = sp.Matrix([sp.Rational(3, 10) * sp.sin(X[1]), 0, 0, 0])
    # Lipschitz: sup |0.3 cos| = 0.3, attained
    L = lipschitz_bound(F, X, None, NO_TIME, "L")
    assert L.how is How.SOUND and 0.3 <= L.value <= 0.3 * (1 + ULPS)
    # growth: only x2 matters (||a|| >= |x2|, equality when the rest is 0): sup 0.3|sin s| /
    # sqrt(1 + s^2), reference by scipy on [0, pi] (beyond pi the ratio is below 0.3 / pi < value)
    ref = _max_1d(lambda s: 0.3 * abs(math.sin(s)) / math.sqrt(1 + s * s), math.pi)
    D = growth_bound(F, X, None, NO_TIME, 1, "D")
    assert D.how is How.SOUND
    assert ref <= D.value <= ref * (1 + BNB_SLACK)
    # 1/2-Hoelder: sqrt(L * diameter) = sqrt(0.3 * 0.6), a sound (not tight) bound
    H = holder_half_bound(F, X, None, NO_TIME, "H")
    assert H.how is How.SOUND
    assert math.sqrt(0.18) <= H.value <= math.sqrt(0.18) * (1 + ULPS)


def test_constant_field_is_exact():
    F = sp.Matrix([[1, 2], [3, sp.Rational(1, 2)]])
    D = growth_bound(F, X, None, NO_TIME, 0.5, "D")
    assert D.how is How.EXACT
    assert math.sqrt(14.25) <= D.value <= math.sqrt(14.25) * (1 + ULPS)
    for fn in (lipschitz_bound, holder_half_bound):
        q = fn(F, X, None, NO_TIME, "L")
        assert q.how is How.EXACT and q.value == 0.0
    Z = growth_bound(sp.zeros(4, 1), X, None, NO_TIME, 1, "D")
    assert Z.how is How.EXACT and Z.value == 0.0


def test_time_dependent_field_takes_sup_over_horizon():
    # (1 + t) tanh(||a||) on t in [0, 2]: worst at t = 2; Lipschitz sup (1 + t) sech^2 = 3
    F = sp.Matrix([(1 + T) * sp.tanh(_parse("norm(x)"))])
    L = lipschitz_bound(F, X, T, (0.0, 2.0), "L")
    assert L.how is How.SOUND and 3.0 <= L.value <= 3.0 * (1 + BNB_SLACK)
    assert "[0, T] suffices" in L.note
    ref = _max_1d(lambda r: 3 * math.tanh(r) / math.sqrt(1 + r * r), 10.0)
    D = growth_bound(F, X, T, (0.0, 2.0), 1, "D")
    assert D.how is How.SOUND and ref <= D.value <= ref * (1 + BNB_SLACK)


def test_affine_field_uses_the_lipschitz_route():
    # F = A a + b: ||F|| <= ||b|| + ||A||_2 ||a|| <= sqrt(||b||^2 + ||A||_2^2) sqrt(1 + ||a||^2)
    A = np.array([[1.0, 2.0, 0.0, 0.0], [0.0, 0.0, 3.0, 0.0]])
    b = np.array([1.0, 0.0])
    F = sp.Matrix(A.astype(int).tolist()) * sp.Matrix(X) + sp.Matrix([1, 0])
    a2 = float(np.linalg.norm(A, 2))
    L = lipschitz_bound(F, X, None, NO_TIME, "L")
    assert L.how is How.SOUND and a2 <= L.value <= a2 * (1 + COLLATZ_REL)
    D = growth_bound(F, X, None, NO_TIME, 1, "D")
    assert D.how is How.SOUND and "Lipschitz route" in D.note
    assert D.value >= math.hypot(float(np.linalg.norm(b)), a2) * (1 - ULPS)


# --------------------------------------------------------------------------- estimates
def test_unbounded_non_radial_field_is_an_estimate():
    F = sp.Matrix([X[0] * X[1]])
    for q in (growth_bound(F, X, None, NO_TIME, 1, "D"), lipschitz_bound(F, X, None, NO_TIME, "L")):
        assert q.how is How.ESTIMATE
        assert "estimate, not a bound" in q.note and "likely infinite" in q.note


def test_undefined_function_without_evaluator_is_nan_estimate():
    h = sp.Function("h")
    q = growth_bound(sp.Matrix([h(X[0]) * X[1]]), X, None, NO_TIME, 1, "D")
    assert q.how is How.ESTIMATE and math.isnan(q.value)


def test_stray_symbol_is_rejected():
    with pytest.raises(ValueError, match="neither states nor time"):
        growth_bound(sp.Matrix([sp.Symbol("k") * X[0]]), X, None, NO_TIME, 1, "D")


# --------------------------------------------------------------------------- property
def _ratios(F, power, n_pts, rng):
    fn = sp.lambdify([X], list(F), "numpy")
    pts = rng.normal(size=(n_pts, 4)) * rng.choice([0.1, 1.0, 10.0, 1e3], size=(n_pts, 1))
    grow, lip, hold = [], [], []
    for a in pts:
        b = a + rng.normal(size=4) * rng.choice([1e-3, 1.0, 30.0])
        fa, fb = np.array(fn(a), float), np.array(fn(b), float)
        d = np.linalg.norm(a - b)
        grow.append(np.linalg.norm(fa) / (1 + a @ a) ** (power / 2))
        lip.append(np.linalg.norm(fa - fb) / d)
        hold.append(np.linalg.norm(fa - fb) / math.sqrt(d))
        f0 = np.array(fn(np.zeros(4)), float)
        hold.append(np.linalg.norm(fa - f0) / math.sqrt(np.linalg.norm(a)))
    return max(grow), max(lip), max(hold)


_coef = st.integers(min_value=-20, max_value=20).map(lambda k: sp.Rational(k, 10))


@settings(max_examples=10)
@given(
    c0=_coef,
    c1=_coef,
    c2=_coef,
    kind=st.sampled_from(["linear", "sqrt", "bounded"]),
    seed=st.integers(0, 2**31 - 1),
)
def test_bounds_never_below_sampled_ratios(c0, c1, c2, kind, seed):
    r = _parse("norm(x)")
    if kind == "linear":
        F, power = sp.Matrix([c0 + c1 * r, c2 * r, 0, c0]), 1
    elif kind == "sqrt":
        F, power = sp.diag(c0 + c1 * sp.sqrt(r), c2 * sp.sqrt(r)), sp.Rational(1, 2)
    else:
        F, power = sp.Matrix([c0 * sp.sin(X[0] + X[2]), c1 * sp.tanh(c2 * X[3]), c2]), 1
    rng = np.random.default_rng(seed)
    g, lip, hol = _ratios(F, float(power), 200, rng)
    D = growth_bound(F, X, None, NO_TIME, power, "D")
    L = lipschitz_bound(F, X, None, NO_TIME, "L")
    H = holder_half_bound(F, X, None, NO_TIME, "H")
    for q, sampled in ((D, g), (L, lip), (H, hol)):
        if q.how in (How.SOUND, How.EXACT):
            assert q.value >= sampled * (1 - SAMPLE_SLACK), (q, sampled)
    assert D.how is not How.ESTIMATE  # every field here is radial, bounded or constant


# ------------------------------------------------------------- the sampled estimators
def _linear(tt, X):
    return 2.0 * X  # ||F(a)|| = 2 ||a||: growth sup 2 (as ||a|| -> inf), Lipschitz 2


def test_sampled_estimates_of_a_linear_field_approach_the_constants_from_below():
    g = growth_ratio_estimate(_linear, 3, 1.0, [0.0])
    # 2 r / sqrt(1 + r^2) at the largest radius r = 1e6 is 2 (1 - 5e-13)
    assert 2.0 * (1 - LARGEST_RADIUS_DEFICIT) <= g.value <= 2.0
    assert np.linalg.norm(g.argmax) == pytest.approx(SAMPLE_RADII[-1], rel=ULPS)
    assert not g.likely_infinite and g.n_nonfinite == 0 and g.diagnostics() == ""
    L = holder_estimate(_linear, 3, 1.0, [0.0])
    assert 2.0 * (1 - CANCELLATION_REL) <= L.value <= 2.0 * (1 + CANCELLATION_REL)
    assert not L.likely_infinite and "Lipschitz ratio" in L.diagnostics()


def test_sampled_estimates_flag_infinite_constants_and_undefined_points():
    def sqrt_norm(tt, X):
        r = np.linalg.norm(X, axis=1, keepdims=True)
        return np.sqrt(r)  # 1/2-Hoelder, not Lipschitz at 0

    L = holder_estimate(sqrt_norm, 2, 1.0, [0.0])
    assert L.likely_infinite and "likely infinite" in L.diagnostics()
    H = holder_estimate(sqrt_norm, 2, 0.5, [0.0])
    assert not H.likely_infinite and H.value <= 1.0 + SAMPLE_SLACK

    def cubic_with_hole(tt, X):
        out = X**3
        out[np.linalg.norm(X, axis=1) == 0.0] = np.nan  # undefined at the origin
        return out

    g = growth_ratio_estimate(cubic_with_hole, 2, 1.0, [0.0, 1.0])
    assert g.likely_infinite and g.n_nonfinite == 1
    assert "not finite (undefined) at 1 of" in g.diagnostics()
    assert math.isfinite(g.value) and g.value > 1e11


def test_a_field_is_built_once_and_shared_by_its_constants():
    """``GrowthField.make`` keeps the field of each (F, states, t, t_range): a growth bound and a
    Lipschitz bound of one constant share its lazily computed routes. The bounds are those of
    a field built afresh (the routes are deterministic functions of the field)."""
    from drip_cert.analysis.growth import field as fld

    x1, x2, t = sp.symbols("x1 x2 t", real=True)
    F = [sp.sin(x1) * x2 / (1 + x2**2), sp.Rational(1, 3) * sp.tanh(x1 + x2)]
    a = fld.GrowthField.make(F, (x1, x2), t, (0.0, 1.0))
    assert fld.GrowthField.make(sp.Matrix(F), [x1, x2], t, (0, 1)) is a
    assert fld.GrowthField.make(F, (x1, x2), t, (0.0, 2.0)) is not a
    g1, l1 = growth_bound(F, (x1, x2), None), lipschitz_bound(F, (x1, x2), None)
    fld._make_kept.cache_clear()
    fld._diff.cache_clear()
    fresh = fld.GrowthField._build(F, (x1, x2), None, (0.0, 0.0))
    assert fresh is not fld.GrowthField.make(F, (x1, x2), None, (0.0, 0.0))
    fld._make_kept.cache_clear()
    assert lipschitz_bound(F, (x1, x2), None).value == l1.value
    assert growth_bound(F, (x1, x2), None).value == g1.value
