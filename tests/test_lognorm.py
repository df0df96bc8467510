"""Matrix measures: closed forms, the limit definition, and the rigorous eigenvalue bounds."""

from __future__ import annotations

import mpmath as mp
import numpy as np
import pytest
import scipy.linalg as sl

from drip_cert.analysis.contraction.lognorm import (
    lambda_max_upper,
    mu2_constant_bounds,
    mu2_interval_upper,
    mu_1,
    mu_2,
    mu_2_weighted,
    mu_inf,
    perron_upper,
    spectral_abscissa,
)
from drip_cert.errors import SpecError
from tests.helpers import CLOSED_FORM_TOL, MP_DPS

#: step of the one-sided difference in the definition mu(A) = lim (||I + hA|| - 1)/h
H_DEF = 1e-7
#: the difference quotient has error O(h ||A||^2) ~ 1e-6 for ||A|| ~ 3, plus rounding eps/h ~ 2e-9
DEF_TOL = 2e-5
#: rigorous bounds may exceed the float eigenvalue by O(n eps ||S||) only
RIGOROUS_EXCESS = 1e-11
#: sqrtm and a generalised eigenproblem of a P with condition number ~10: rounding amplified by
#: the conditioning (observed 3e-15)
CHANGE_OF_COORDINATES_TOL = 1e-10
#: a bound rounded up by a few ulps against an exact max row sum of the same numbers
ROUNDED_UP_REL = 1e-12
#: eigvalsh of 3x3 O(1) matrices and the outward rounding of the Rohn bound
EIGVALSH_SLACK = 1e-9


def _batch(seed: int, shape=(50, 3, 3)) -> np.ndarray:
    return np.random.default_rng(seed).normal(size=shape)


def test_mu2_2x2_closed_form():
    A = _batch(0, (200, 2, 2))
    a, b, c, d = A[:, 0, 0], A[:, 0, 1], A[:, 1, 0], A[:, 1, 1]
    expected = 0.5 * (a + d) + np.sqrt((0.5 * (a - d)) ** 2 + (0.5 * (b + c)) ** 2)
    np.testing.assert_allclose(mu_2(A), expected, atol=CLOSED_FORM_TOL)


def test_mu2_of_symmetric_is_lambda_max():
    A = _batch(1)
    S = A + np.swapaxes(A, 1, 2)
    expected = np.array([sl.eigh(s, eigvals_only=True)[-1] for s in S])
    np.testing.assert_allclose(mu_2(S), expected, atol=CLOSED_FORM_TOL)


def test_mu1_muinf_hand_computed():
    A = np.array([[-3.0, 1.0, 2.0], [0.5, -4.0, 1.0], [-1.0, 2.0, -5.0]])
    # columns: -3+0.5+1, -4+1+2, -5+2+1 ; rows: -3+1+2, 0.5-4+1, -1+2-5
    assert mu_1(A) == pytest.approx(-1.0, abs=CLOSED_FORM_TOL)
    assert mu_inf(A) == pytest.approx(0.0, abs=CLOSED_FORM_TOL)


@pytest.mark.parametrize(("fn", "ord_"), [(mu_1, 1), (mu_2, 2), (mu_inf, np.inf)])
def test_log_norms_match_the_limit_definition(fn, ord_):
    A = _batch(2, (20, 3, 3))
    eye = np.eye(3)
    by_def = np.array([(np.linalg.norm(eye + H_DEF * a, ord_) - 1.0) / H_DEF for a in A])
    np.testing.assert_allclose(fn(A), by_def, atol=DEF_TOL)


@pytest.mark.parametrize("fn", [mu_1, mu_2, mu_inf])
def test_log_norm_properties(fn):
    A, B = _batch(3), _batch(4)
    # lower bound by the spectral abscissa, subadditivity, translation by c I
    assert np.all(fn(A) >= spectral_abscissa(A) - CLOSED_FORM_TOL)
    assert np.all(fn(A + B) <= fn(A) + fn(B) + CLOSED_FORM_TOL)
    np.testing.assert_allclose(fn(A + 2.5 * np.eye(3)), fn(A) + 2.5, atol=CLOSED_FORM_TOL)


def test_weighted_mu2_is_mu2_after_change_of_coordinates():
    rng = np.random.default_rng(5)
    A = rng.normal(size=(30, 3, 3))
    M = rng.normal(size=(3, 3))
    P = M @ M.T + 0.5 * np.eye(3)
    R = sl.sqrtm(P).real
    changed = mu_2(R @ A @ np.linalg.inv(R))
    np.testing.assert_allclose(mu_2_weighted(A, P), changed, atol=CHANGE_OF_COORDINATES_TOL)
    gen = [sl.eigh(0.5 * (a.T @ P + P @ a), P, eigvals_only=True)[-1] for a in A]
    np.testing.assert_allclose(mu_2_weighted(A, P), gen, atol=CHANGE_OF_COORDINATES_TOL)
    np.testing.assert_allclose(mu_2_weighted(A, np.eye(3)), mu_2(A), atol=CLOSED_FORM_TOL)


def test_weighted_rejects_indefinite_P():
    with pytest.raises(SpecError):
        mu_2_weighted(np.eye(2), np.diag([1.0, -1.0]))
    with pytest.raises(SpecError):
        mu_2(np.ones((2, 3)))


def test_lambda_max_upper_is_rigorous_and_tight():
    for S in _batch(6, (40, 4, 4)):
        S = S + S.T
        exact = np.linalg.eigvalsh(S)[-1]
        ub = lambda_max_upper(S)
        assert exact <= ub <= exact + RIGOROUS_EXCESS * (1 + np.abs(S).max())


def test_lambda_max_upper_of_an_exact_diagonal():
    # eigenvalues known exactly: the bound must not be below them
    S = np.diag([-3.0, 0.25, 1e-3])
    assert 0.25 <= lambda_max_upper(S) <= 0.25 + RIGOROUS_EXCESS
    assert -3.0 >= -lambda_max_upper(-S) >= -3.0 - RIGOROUS_EXCESS  # lambda_min from below


def test_perron_upper_bounds_spectral_radius():
    N = np.abs(_batch(7, (30, 4, 4)))
    for n in N:
        rho = np.max(np.abs(np.linalg.eigvals(n)))
        ub = perron_upper(n)
        assert rho <= ub
        # Collatz-Wielandt with a near-Perron vector of the symmetric part: not tight for
        # non-symmetric N, but never worse than the max row sum
        assert ub <= np.abs(n).sum(axis=1).max() * (1 + ROUNDED_UP_REL)


def test_interval_mu2_bound_contains_sampled_members():
    rng = np.random.default_rng(8)
    for _ in range(20):
        C = rng.normal(size=(3, 3))
        R = 0.2 * rng.random((3, 3))
        ub = mu2_interval_upper(C - R, C + R)
        members = C + R * rng.uniform(-1, 1, size=(500, 3, 3))
        assert mu_2(members).max() <= ub
        # and the Rohn bound is within rho(sym R) of the centre's mu_2
        assert ub <= mu_2(C) + np.max(np.abs(np.linalg.eigvalsh(R + R.T))) + EIGVALSH_SLACK
    A = rng.normal(size=(3, 3))
    assert mu_2(A) <= mu2_interval_upper(A, A) <= mu_2(A) + RIGOROUS_EXCESS * 10


# --------------------------------------------------------------- mu_2 of a constant matrix

#: mu2_constant_bounds is accurate to a few ulps RELATIVE to mu_2 (roots isolated to 53 bits)
CONSTANT_REL_WIDTH = 1e-14
#: Arb enclosures of irrational entries widen the bounds by their radius only (observed 1.8e-15
#: for a mu_2 of -0.68)
ARB_ENTRY_WIDTH = 1e-14
#: far below the float64 rounding of O(1) entries (~1e-16): a sign no float eigenvalue resolves
BELOW_ROUNDING = 1e-20
#: the exact mu_2 of TINY_2X2 is 6.46e-27: the lower bound keeps at least two digits of it
TINY_2X2_LOWER = 6.4e-27


def _mp_mu2(A) -> mp.mpf:
    with mp.workdps(MP_DPS):
        M = mp.matrix([[mp.mpf(v) if isinstance(v, float) else v for v in row] for row in A])
        return max(mp.eigsy((M + M.T) / 2)[0])


#: 2x2 with exact mu_2 = 2**-87 * (1 + O(2**-43)) ~ +6.46e-27: y = 1 + 2**-43, z = -(1 + 2**-42),
#: det(S) = z(-1) - y^2 = -2**-86, trace ~ -2, so lambda_max ~ 2**-86 / 2 > 0
_Y = 1.0 + 2.0**-43
TINY_2X2 = np.array([[-1.0, _Y], [_Y, -(1.0 + 2.0**-42)]])
#: 3x3 found by search (seed 0): exact mu_2 = +7.17e-21, float eigvalsh = -1.37e-16
TINY_3X3 = np.array(
    [
        [-1.6075585623211075, -0.025284768316649872, 0.36672057749061926],
        [-0.025284768316649872, -0.05504554059253014, 0.23489560260193748],
        [0.36672057749061926, 0.23489560260193748, -1.0443437511493108],
    ]
)


@pytest.mark.parametrize("A", [TINY_2X2, TINY_3X3], ids=["2x2", "3x3"])
def test_tiny_positive_mu2_keeps_its_sign(A):
    exact = _mp_mu2(A.tolist())
    assert 0 < exact < BELOW_ROUNDING  # within rounding of 0, but positive: NOT contracting
    # the old route: float eigvalsh says <= 0, i.e. "contracting with rate >= 0"
    assert mu_2(A) <= 0.0
    lo, hi = mu2_constant_bounds(A)
    assert 0.0 < lo <= exact <= hi
    assert mp.mpf(hi - lo) <= CONSTANT_REL_WIDTH * exact


def test_tiny_2x2_has_the_closed_form_value():
    lo, hi = mu2_constant_bounds(TINY_2X2)
    with mp.workdps(MP_DPS):
        y, z = mp.mpf(_Y), -(1 + mp.mpf(2) ** -42)
        tr, det = -1 + z, -z - y * y
        lam = (tr + mp.sqrt(tr * tr - 4 * det)) / 2
    assert lo <= lam <= hi and mp.mpf(lo) > TINY_2X2_LOWER


def test_constant_bounds_contain_mpmath_eigenvalues_of_random_matrices():
    rng = np.random.default_rng(21)
    for n in (1, 2, 3, 5, 8):
        for scale in (1e-6, 1.0, 1e6):
            A = rng.normal(size=(n, n)) * scale
            lo, hi = mu2_constant_bounds(A)
            exact = _mp_mu2(A.tolist())
            assert lo <= exact <= hi
            assert hi - lo <= CONSTANT_REL_WIDTH * abs(float(exact))


def test_constant_bounds_of_sympy_matrices():
    import sympy as sp

    # exact rationals go through the exact route (1/3 is not a float)
    A = sp.Matrix([[sp.Rational(-1, 3), 1], [0, -3]])
    lo, hi = mu2_constant_bounds(A)
    with mp.workdps(MP_DPS):
        exact = _mp_mu2([[mp.mpf(-1) / 3, 1], [0, -3]])
    assert lo <= exact <= hi and hi - lo <= CONSTANT_REL_WIDTH
    # irrational entries are enclosed in Arb and widen the bounds by their radius only
    B = sp.Matrix([[-1, sp.sqrt(2)], [sp.pi / 10, -3]])
    lo, hi = mu2_constant_bounds(B)
    with mp.workdps(MP_DPS):
        exact = _mp_mu2([[-1, mp.sqrt(2)], [mp.pi / 10, -3]])
    assert lo <= exact <= hi and hi - lo <= ARB_ENTRY_WIDTH
    with pytest.raises(SpecError, match="not constant"):
        mu2_constant_bounds(sp.Matrix([[sp.Symbol("x")]]))


def test_constant_bounds_fallback_above_the_exact_size(monkeypatch):
    import drip_cert.analysis.contraction.lognorm as ln

    monkeypatch.setattr(ln, "EXACT_MAX_DIM", 2)
    A = np.random.default_rng(22).normal(size=(6, 6))
    lo, hi = ln.mu2_constant_bounds(A)
    exact = _mp_mu2(A.tolist())
    assert lo <= exact <= hi and hi - lo <= RIGOROUS_EXCESS
    assert ln.mu2_constant_bounds(np.array([[np.inf, 0.0], [0.0, 1.0]])) == (-np.inf, np.inf)
