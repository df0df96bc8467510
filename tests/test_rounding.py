"""drip_cert.numerics.rounding: every outward-rounded result encloses the exact one.

References are exact (``fractions.Fraction`` for the correctly rounded operations: every float is a
rational) or mpmath at 50 digits (library functions, eigenvalues, singular values). The library
error budgets are measured here, so that a platform whose numpy / scipy is less accurate than
documented fails this file instead of producing unsound enclosures.
"""

from __future__ import annotations

import math
from fractions import Fraction

import mpmath as mp
import numpy as np
import pytest
from flint import arb
from hypothesis import given, settings
from hypothesis import strategies as st
from scipy.special import ndtr

from drip_cert.numerics.rounding import (
    LIBM_REL,
    NEXTAFTER_INT_MIN,
    add_down,
    add_up,
    arb_hi,
    arb_lo,
    arb_norm2_up,
    arb_sqrt_up,
    div_down,
    div_up,
    down,
    down_np,
    enclose_down,
    enclose_up,
    gamma,
    matmul_bounds,
    mul_down,
    mul_up,
    ndtr_rel_budget,
    nonneg_spectral_norm_upper,
    norm2_up,
    norm2_up_np,
    spectral_norm_upper,
    sqrt_down,
    sqrt_up,
    sub_down,
    sub_up,
    sum_down,
    sum_sq_up,
    sum_up,
    sum_up_np,
    sym_lambda_max_upper,
    up,
    up_np,
    widen_np,
)
from tests.helpers import MP_DPS

mp.mp.dps = MP_DPS  # reference precision (set globally for this module's mpmath references)

#: a measured library error must stay below this fraction of its budget (the budgets carry a
#: safety factor of 4 over the documented accuracy; half of it must remain on this platform)
BUDGET_USE = 0.5
#: rigorous eigenvalue / singular-value bounds may exceed the true value by O(n eps ||S||); for
#: the O(1) matrices of these tests 1e-12 relative is far above that and far below any real error
RIGOROUS_EXCESS = 1e-12

# finite floats over the whole exponent range (no NaN / inf), the inputs of the property tests
_floats = st.floats(allow_nan=False, allow_infinity=False, width=64)
_moderate = st.floats(min_value=-1e150, max_value=1e150, allow_nan=False, width=64)


def _q(x: float) -> Fraction:
    return Fraction(x)


def _brackets(lo: float, exact: Fraction, hi: float) -> bool:
    """``lo <= exact <= hi`` with float ends that may be infinite (overflow)."""
    below = lo == -math.inf or (lo != math.inf and Fraction(lo) <= exact)
    above = hi == math.inf or (hi != -math.inf and Fraction(hi) >= exact)
    return below and above


# ------------------------------------------------------------------- correctly rounded ops


@settings(max_examples=400)
@given(a=_moderate, b=_moderate)
def test_directed_arithmetic_brackets_the_exact_rational_result(a, b):
    qa, qb = _q(a), _q(b)
    assert _brackets(add_down(a, b), qa + qb, add_up(a, b))
    assert _brackets(sub_down(a, b), qa - qb, sub_up(a, b))
    assert _brackets(mul_down(a, b), qa * qb, mul_up(a, b))
    if b != 0.0:
        assert _brackets(div_down(a, b), qa / qb, div_up(a, b))
    s = abs(a)
    assert _q(sqrt_down(s)) ** 2 <= _q(s) <= _q(sqrt_up(s)) ** 2


@settings(max_examples=200)
@given(a=_floats)
def test_up_down_move_outward_and_propagate_nan(a):
    assert down(a) < a < up(a) or (math.isinf(a))
    assert up(a, 3) > up(a) or up(a) == math.inf
    assert math.isnan(up(math.nan)) and math.isnan(down(math.nan))
    assert enclose_down(math.nan) == -math.inf and enclose_up(math.nan) == math.inf


def _same_bits(a: np.ndarray, b: np.ndarray) -> np.ndarray:
    """Entrywise: the same float64 bits, or both NaN (NaN payloads and signs are not a value)."""
    return (a.view(np.int64) == b.view(np.int64)) | (np.isnan(a) & np.isnan(b))


@pytest.mark.parametrize("ulps", [1, 3])
def test_up_np_down_np_equal_nextafter_bit_for_bit(ulps):
    """The integer form of up_np / down_np (arrays of NEXTAFTER_INT_MIN entries or more) gives
    np.nextafter's floats exactly: on every special value (signed zeros, subnormal ends, the
    largest float, infinities, NaN) and on a million random bit patterns (all exponents, both
    signs, NaN payloads among them)."""
    rng = np.random.default_rng(2026)
    tiny, big = np.finfo(np.float64).tiny, np.finfo(np.float64).max
    special = np.array(
        [0.0, -0.0, np.inf, -np.inf, np.nan, -np.nan, 2.0**-1074, -(2.0**-1074), tiny, -tiny]
        + [np.nextafter(tiny, 0.0), -np.nextafter(tiny, 0.0), big, -big, 1.0, -1.0, 0.5, -0.5]
    )
    special = np.resize(special, NEXTAFTER_INT_MIN)  # at the threshold: the integer form
    ints = rng.integers(np.iinfo(np.int64).min, np.iinfo(np.int64).max, 10**6, dtype=np.int64)
    for x in (special, ints.view(np.float64), special[:7], rng.normal(size=(40, 50))):
        with np.errstate(all="ignore"):
            want_up, want_down = x.copy(), x.copy()
            for _ in range(ulps):
                want_up = np.nextafter(want_up, np.inf)
                want_down = np.nextafter(want_down, -np.inf)
            got_up, got_down = up_np(x, ulps), down_np(x, ulps)  # (signalling NaNs warn)
        assert got_up.shape == x.shape and got_down.shape == x.shape
        assert _same_bits(got_up, want_up).all()
        assert _same_bits(got_down, want_down).all()
        assert not np.shares_memory(got_up, x) and not np.shares_memory(got_down, x)


def test_overflow_and_underflow_ends():
    big = np.finfo(np.float64).max
    # exact big + big overflows: the lower bound is the largest float, the upper bound inf
    assert add_down(big, big) == big and add_up(big, big) == math.inf
    # exact 2**-1074 / 4 rounds to 0: the bounds straddle it
    tiny = 2.0**-1074
    assert div_down(tiny, 4.0) < 0.0 < div_up(tiny, 4.0)


@settings(max_examples=200)
@given(xs=st.lists(_moderate, min_size=0, max_size=40))
def test_sums_bracket_the_exact_sum(xs):
    exact = sum((_q(x) for x in xs), Fraction(0))
    assert _q(sum_down(xs)) <= exact <= _q(sum_up(xs))
    assert _q(sum_sq_up(xs)) >= sum((_q(x) ** 2 for x in xs), Fraction(0))
    if xs:
        arr = np.array(xs)
        assert _q(float(sum_up_np(arr))) >= exact
        nrm = mp.sqrt(mp.fsum(mp.mpf(x) ** 2 for x in xs))
        assert mp.mpf(norm2_up(xs)) >= nrm
        assert mp.mpf(float(norm2_up_np(arr))) >= nrm


def test_sum_up_np_on_a_cancelling_sum():
    # 1e16 + 1 - 1e16 rounds to 0 or 2 in float; the bound must reach the exact 1
    x = np.array([1e16, 1.0, -1e16, 1.0, 1.0])
    assert float(sum_up_np(x)) >= 3.0
    assert sum_up(x.tolist()) >= 3.0


def test_gamma_is_an_upper_bound_of_higham_constant():
    u = Fraction(1, 2**53)
    for n in (1, 2, 10, 1000, 10**9):
        assert _q(gamma(n)) >= n * u / (1 - n * u)
    with pytest.raises(ValueError):
        gamma(2**52)


@settings(max_examples=60)
@given(
    seed=st.integers(0, 2**31),
    m=st.integers(1, 6),
    k=st.integers(1, 12),
    n=st.integers(1, 6),
    scale=st.sampled_from([1e-300, 1e-8, 1.0, 1e100]),
)
def test_matmul_bounds_enclose_the_exact_product(seed, m, k, n, scale):
    rng = np.random.default_rng(seed)
    A = rng.normal(size=(m, k)) * scale
    B = rng.normal(size=(k, n))
    if k > 1:  # make entry (0, 0) cancel: A[0] . B[:, 0] ~ 0 up to rounding
        B[-1, 0] = -float(A[0, :-1] @ B[:-1, 0]) / A[0, -1]
    lo, hi = matmul_bounds(A, B)
    for i in range(m):
        for j in range(n):
            exact = sum((_q(A[i, t]) * _q(B[t, j]) for t in range(k)), Fraction(0))
            assert _q(lo[i, j]) <= exact <= _q(hi[i, j])


def test_widen_np_contains_the_band():
    y = np.array([1.0, -3.0, 0.0, 1e-310])
    lo, hi = widen_np(y, 1e-3, 1e-300)
    for v, a, b in zip(y, lo, hi):
        band = abs(_q(v)) * Fraction(1, 1000) + _q(1e-300)
        assert _q(a) <= _q(v) - band and _q(v) + band <= _q(b)


def test_arb_ends_contain_the_ball():
    for v in (arb(1) / 3, arb.pi() * 1e300, -arb(2).sqrt() * 1e-300, arb(0), arb("1e-400")):
        assert arb_lo(v) <= v.lower() and arb_hi(v) >= v.upper()
    assert arb_hi(arb(1) / 0) == math.inf and arb_lo(arb(1) / 0) == -math.inf


# ------------------------------------------------------------------------ library budgets


def _rel_err(computed: np.ndarray, exact: list) -> np.ndarray:
    return np.array(
        [abs((mp.mpf(float(c)) - e) / e) if e != 0 else 0 for c, e in zip(computed, exact)],
        dtype=float,
    )


def test_numpy_exp_and_tanh_meet_the_libm_budget():
    rng = np.random.default_rng(11)
    x = np.concatenate([rng.uniform(-700, 700, 400), rng.uniform(-1, 1, 200), [0.0, 1e-300]])
    err = _rel_err(np.exp(x), [mp.exp(mp.mpf(float(v))) for v in x])
    assert err.max() <= BUDGET_USE * LIBM_REL
    t = np.concatenate([rng.uniform(-20, 20, 400), rng.uniform(-1e-3, 1e-3, 100)])
    err = _rel_err(np.tanh(t), [mp.tanh(mp.mpf(float(v))) for v in t])
    assert err.max() <= BUDGET_USE * LIBM_REL


def test_scipy_ndtr_meets_its_budget_in_both_tails():
    rng = np.random.default_rng(12)
    # the left tail down past the underflow of ndtr (z ~ -37.5 to subnormal, ~ -38.5 to 0), where
    # exp(-z^2/2) amplifies the rounding of z^2, the centre, and the right tail where ndtr -> 1
    z = np.concatenate([rng.uniform(-39.0, -5.0, 1500), rng.uniform(-5, 8, 500)])
    got = ndtr(z)
    exact = [mp.ncdf(mp.mpf(float(v))) for v in z]
    normal = got >= 2.0**-1022  # the relative budget applies to normal results
    err = _rel_err(got[normal], [e for e, ok in zip(exact, normal) if ok])
    assert np.all(err <= BUDGET_USE * ndtr_rel_budget(z[normal]))
    # and the widened value (relative budget plus the absolute floor) encloses every value
    lo, hi = widen_np(got, ndtr_rel_budget(z))
    assert all(mp.mpf(float(a)) <= e <= mp.mpf(float(b)) for a, b, e in zip(lo, hi, exact))


# ------------------------------------------------------------------------- linear algebra


def _mp_lambda_max(S: np.ndarray) -> mp.mpf:
    Sm = mp.matrix(S.tolist())
    Sm = (Sm + Sm.T) / 2
    return max(mp.eigsy(Sm)[0])


@settings(max_examples=40)
@given(seed=st.integers(0, 2**31), n=st.integers(1, 6), scale=st.sampled_from([1e-200, 1.0, 1e150]))
def test_sym_lambda_max_upper_is_rigorous_and_tight(seed, n, scale):
    S = np.random.default_rng(seed).normal(size=(n, n)) * scale
    ub = float(sym_lambda_max_upper(S))
    exact = _mp_lambda_max(S)
    assert mp.mpf(ub) >= exact
    assert mp.mpf(ub) - exact <= RIGOROUS_EXCESS * scale * (1 + np.abs(S / scale).sum())


def test_sym_lambda_max_upper_batched_with_radius():
    rng = np.random.default_rng(13)
    S = rng.normal(size=(30, 4, 4))
    R = 0.05 * rng.random((30, 4, 4))
    ub = sym_lambda_max_upper(S, R)
    assert ub.shape == (30,)
    members = S[None] + R[None] * rng.uniform(-1, 1, size=(200, 30, 4, 4))
    sym = 0.5 * (members + np.swapaxes(members, -1, -2))
    assert np.all(np.linalg.eigvalsh(sym)[..., -1] <= ub)
    assert sym_lambda_max_upper(np.full((2, 2), np.nan)) == math.inf


@settings(max_examples=40)
@given(seed=st.integers(0, 2**31), m=st.integers(1, 6), n=st.integers(1, 6))
def test_spectral_norm_upper_is_rigorous_and_tight(seed, m, n):
    W = np.random.default_rng(seed).normal(size=(m, n))
    ub = float(spectral_norm_upper(W))
    exact = max(mp.svd_r(mp.matrix(W.tolist()), compute_uv=False))
    assert mp.mpf(ub) >= exact
    assert mp.mpf(ub) - exact <= RIGOROUS_EXCESS * (1 + exact)


def test_spectral_norm_upper_batched_and_degenerate():
    rng = np.random.default_rng(14)
    W = rng.normal(size=(25, 2, 5))
    ub = spectral_norm_upper(W)
    assert ub.shape == (25,) and np.all(ub >= np.linalg.norm(W, 2, axis=(1, 2)))
    assert spectral_norm_upper(np.zeros((3, 2))) == 0.0
    # rank one: ||u v^T|| = ||u|| ||v|| exactly
    u, v = np.array([3.0, 4.0]), np.array([1.0, 0.0, 0.0])
    assert 5.0 <= spectral_norm_upper(np.outer(u, v)) <= 5.0 * (1 + RIGOROUS_EXCESS)


# ------------------------------------------------------------------------- Arb twins
@settings(max_examples=200)
@given(xs=st.lists(_moderate, min_size=0, max_size=20))
def test_arb_norm2_and_sqrt_bound_the_exact_values(xs):
    exact_sq = sum((_q(x) ** 2 for x in xs), Fraction(0))
    ub = arb_norm2_up(xs)
    assert _q(ub) ** 2 >= exact_sq
    # never more than a few ulps above the correctly rounded float twin
    assert ub <= up(norm2_up(xs), 4)
    s = abs(xs[0]) if xs else 0.0
    r = arb_sqrt_up(s)
    assert _q(r) ** 2 >= _q(s) and r <= up(sqrt_up(s), 2)


def test_arb_sqrt_and_norm_ends():
    # a negative upper bound of a nonnegative quantity reads as 0 (one ulp up: Arb's outward step)
    assert arb_sqrt_up(-1e-300) == up(0.0)
    assert arb_sqrt_up(math.inf) == math.inf and arb_sqrt_up(math.nan) == math.inf
    assert arb_norm2_up([]) == up(0.0) and arb_norm2_up([3.0, 4.0]) == up(5.0)
    assert arb_norm2_up([1.0, math.inf]) == math.inf


@settings(max_examples=40)
@given(seed=st.integers(0, 2**31), m=st.integers(1, 7), n=st.integers(1, 5))
def test_nonneg_spectral_norm_upper_is_rigorous_and_tight(seed, m, n):
    M = np.abs(np.random.default_rng(seed).normal(size=(m, n)))
    ub = nonneg_spectral_norm_upper(M)
    exact = max(mp.svd_r(mp.matrix(M.tolist()), compute_uv=False))
    assert mp.mpf(ub) >= exact
    # Collatz-Wielandt with the float Perron vector: excess of order n eps ||M||
    assert mp.mpf(ub) - exact <= RIGOROUS_EXCESS * (1 + exact)
    assert nonneg_spectral_norm_upper(np.zeros((m, n))) == 0.0
