"""Tests of the chunked gap statistics (drip_cert.numerics.stats)."""

from __future__ import annotations

import math

import mpmath
import numpy as np
import pytest
import scipy.stats

from drip_cert.errors import SpecError
from drip_cert.numerics.stats import (
    accumulate,
    bonferroni_level,
    clopper_pearson_lower,
    clopper_pearson_upper,
    finalize,
    new_sums,
    norms_sequential,
    t_interval,
    t_one_sided,
    upper_quantile_bounds,
    w2_empirical,
)
from tests.helpers import MC_Z

SUM_RTOL = 1e-12
"""Sequential vs numpy's pairwise summation of <= 10^4 O(1) terms: both within ~1e-13 relative."""

CP_ATOL = 1e-10
"""scipy's beta quantile and binomial CDF are accurate to ~1e-12; the defining equation of the
Clopper-Pearson bound is checked to this absolute tolerance."""

W2_ATOL = 1e-9
"""The network-simplex optimum is exact up to rounding in the cost matrix (~1e-15 per entry);
1e-9 leaves room for the sqrt near small values."""

T_COVERAGE_ERROR = 0.02
"""The t interval is not exact for non-normal data: at n = 15 with the mild skew of sqrt(Exp(1))
its coverage error is below 0.02 (a property of the CLT approximation, not a tolerance knob)."""

CP_QUANTILE_RTOL = 1e-11
"""scipy's beta quantile against the closed form of the Clopper-Pearson bound at k = 0 or k = n:
accurate to ~1e-12 relative."""

BONFERRONI_ATOL = 1e-15
"""1 - (1 - 0.95) / 10 in float64 against the literal 0.995: an ulp or two."""


def _data(seed=0, n_paths=257, n_times=6):
    rng = np.random.default_rng(seed)
    return np.abs(rng.normal(size=(n_paths, n_times))) * np.linspace(0.5, 2.0, n_times)


def test_chunked_accumulation_is_split_invariant_and_correct():
    r = _data()
    valid = np.ones(len(r), dtype=bool)
    valid[[3, 100, 200]] = False
    whole = accumulate(new_sums(6, 3, (0.5, 1.5)), r, valid)
    for sizes in ([1] * 20 + [237], [100, 100, 57], [7] * 36 + [5]):
        s = new_sums(6, 3, (0.5, 1.5))
        start = 0
        for size in sizes:
            s = accumulate(s, r[start : start + size], valid[start : start + size])
            start += size
        assert start == len(r)
        assert np.array_equal(s.power_sums, whole.power_sums)
        assert np.array_equal(s.tail_counts, whole.tail_counts)
        assert np.array_equal(s.max, whole.max)
        assert np.array_equal(s.path_max, whole.path_max)
        assert s.count == whole.count == len(r) - 3
    rv = r[valid]
    for q_i, q in enumerate(whole.powers):
        np.testing.assert_allclose(whole.power_sums[q_i], np.sum(rv**q, axis=0), rtol=SUM_RTOL)
    np.testing.assert_array_equal(whole.tail_counts[1], np.sum(rv >= 1.5, axis=0))
    np.testing.assert_array_equal(whole.max, rv.max(axis=0))
    np.testing.assert_array_equal(whole.path_max, rv.max(axis=1))


def test_finalize_matches_direct_computation():
    r = _data(1)
    s = accumulate(new_sums(6, 3, (1.0,)), r, np.ones(len(r), dtype=bool))
    times = np.linspace(0.0, 1.0, 6)
    st = finalize("g", s, times, 0.9)
    np.testing.assert_allclose(st.mean, r.mean(axis=0), rtol=SUM_RTOL)
    for p in (1, 2, 3):
        np.testing.assert_allclose(st.moments[p - 1], np.mean(r ** (2 * p), axis=0), rtol=SUM_RTOL)
        np.testing.assert_allclose(
            st.lp_norms[p - 1], np.mean(r ** (2 * p), axis=0) ** (1 / (2 * p)), rtol=SUM_RTOL
        )
    # Student-t interval: scipy's own interval from the raw data
    for k in range(6):
        lo, hi = scipy.stats.t.interval(
            0.9, len(r) - 1, loc=r[:, k].mean(), scale=scipy.stats.sem(r[:, k])
        )
        assert st.ci_low[k] == pytest.approx(lo, rel=SUM_RTOL)
        assert st.ci_high[k] == pytest.approx(hi, rel=SUM_RTOL)
    k = int(np.argmax(r.mean(axis=0)))
    assert st.argmax_time == times[k]
    assert st.max_mean == st.mean[k] and st.max_ci_low == st.ci_low[k]
    np.testing.assert_array_equal(st.tail_freq[0], np.mean(r >= 1.0, axis=0))
    d = st.to_dict()
    assert d["n_valid"] == len(r) and d["max_mean"] == st.max_mean


def test_t_interval_coverage():
    rng = np.random.default_rng(4)
    reps, n, level = 4000, 15, 0.9
    x = rng.exponential(size=(reps, n)) ** 0.5  # skewed but light-tailed
    true_mean = math.gamma(1.5)
    _, lo, hi = t_interval(x.sum(1), (x * x).sum(1), n, level)
    cover = np.mean((lo <= true_mean) & (true_mean <= hi))
    assert abs(cover - level) <= T_COVERAGE_ERROR + MC_Z * math.sqrt(level * (1 - level) / reps)


def test_clopper_pearson_upper():
    n, level = 50, 0.95
    assert clopper_pearson_upper(0, n, level) == pytest.approx(
        1 - (1 - level) ** (1 / n), rel=CP_QUANTILE_RTOL
    )
    assert clopper_pearson_upper(n, n, level) == 1.0
    ks = np.arange(n)
    up = clopper_pearson_upper(ks, n, level)
    assert np.all(np.diff(up) > 0)
    assert np.all(up > ks / n)
    # defining equation: P(Bin(n, upper) <= k) = 1 - level
    np.testing.assert_allclose(scipy.stats.binom.cdf(ks, n, up), 1 - level, atol=CP_ATOL)


# Values of the two Clopper-Pearson functions drip-cert had before they became one (recorded from
# the code of commit 30a5c84): the TaSIL held-out form's clopper_pearson_upper(k, n, delta) of
# drip_cert/bounds/tasil.py (Arb-verified, called with the failure probability delta) and
# clopper_pearson_upper / clopper_pearson_lower(k, n, level) of this module (scipy's quantile).
# The one implementation reproduces both to the last bit.
FORMER_TASIL_CP = [  # (k, n, delta, bound)
    (1, 7, 0.1, 0.45256494335779973),
    (0, 40, 0.05, 0.07215752450551459),
    (2, 40, 0.025, 0.16919686395941766),
    (13, 40, 0.05, 0.4662950987058696),
    (20, 40, 0.001, 0.7396332798521307),
    (39, 40, 0.05, 0.9987184894771248),
    (40, 40, 0.05, 1.0),
    (0, 200, 0.05, 0.014867039231272059),
    (66, 200, 0.3, 0.3503764987550536),
    (999, 1000, 0.5, 0.9993070929904526),
    (0, 12345, 1e-06, 0.001118491927771959),
    (4115, 12345, 1e-06, 0.3537406898005782),
]
FORMER_STATS_CP_UPPER = [  # (k, n, level, bound)
    (1, 7, 0.9, 0.4525649433577997),
    (0, 40, 0.95, 0.07215752450551455),
    (2, 40, 0.975, 0.16919686395941763),
    (13, 40, 0.99, 0.5203113754560791),
    (39, 40, 0.95, 0.9987184894771247),
    (40, 40, 0.95, 1.0),
    (66, 200, 0.999, 0.43970020291016665),
    (333, 1000, 0.3, 0.32576998166356375),
    (4115, 12345, 0.9999875, 0.3514146256082909),
]
FORMER_STATS_CP_LOWER = [  # (k, n, level, bound)
    (1, 7, 0.9, 0.014938794558884472),
    (0, 40, 0.95, 0.0),
    (13, 40, 0.99, 0.1655404651856619),
    (40, 40, 0.95, 0.9278424754944854),
    (4115, 12345, 0.9999875, 0.31558174754595836),
]

CP_SOUND_RTOL = 1e-11
"""The sound bound is scipy's quantile moved up until Arb proves it: at most a few 1e-12 steps
(scipy's quantile is accurate to ~1e-12 relative) above the plain one."""

CP_CLOSED_RTOL = 4 * np.finfo(np.float64).eps
"""The sound k = 0 bound is the Arb enclosure of the closed form, its upper end moved one ulp:
within a few ulps of the exact value."""


@pytest.mark.parametrize("k, n, delta, want", FORMER_TASIL_CP)
def test_clopper_pearson_reproduces_the_former_tasil_bound(k, n, delta, want):
    got = clopper_pearson_upper(k, n, alpha=delta, sound=True)
    assert float(got) == want and np.shape(got) == ()


@pytest.mark.parametrize("k, n, level, want", FORMER_STATS_CP_UPPER)
def test_clopper_pearson_reproduces_the_former_upper_bound(k, n, level, want):
    assert float(clopper_pearson_upper(k, n, level)) == want


@pytest.mark.parametrize("k, n, level, want", FORMER_STATS_CP_LOWER)
def test_clopper_pearson_reproduces_the_former_lower_bound(k, n, level, want):
    assert float(clopper_pearson_lower(k, n, level)) == want


def test_clopper_pearson_closed_forms_and_log_bound():
    """k = 0: upper = 1 - (1 - level)^(1/n) <= log(1/(1 - level)) / n; k = n: upper = 1."""
    for n in (1, 10, 100, 1000, 10_000):
        for alpha in (0.5, 0.05, 1e-3, 1e-6):
            with mpmath.workdps(50):
                exact = 1 - mpmath.mpf(alpha) ** (mpmath.mpf(1) / n)
            sound = float(clopper_pearson_upper(0, n, alpha=alpha, sound=True))
            assert exact <= sound <= exact * (1 + CP_CLOSED_RTOL)
            assert sound <= math.log(1 / alpha) / n
            plain = float(clopper_pearson_upper(0, n, 1 - alpha))
            assert plain == pytest.approx(float(exact), rel=CP_SOUND_RTOL)
            for kw in ({"alpha": alpha, "sound": True}, {"alpha": alpha}):
                assert float(clopper_pearson_upper(n, n, **kw)) == 1.0


def test_clopper_pearson_sound_bound_is_the_plain_one_rounded_up():
    n, level = 40, 0.95
    ks = np.arange(n + 1).reshape(1, n + 1)
    plain = clopper_pearson_upper(ks, n, level)
    sound = clopper_pearson_upper(ks, n, level, sound=True)
    assert sound.shape == ks.shape
    assert np.all(sound >= plain) and np.all(sound <= plain * (1 + CP_SOUND_RTOL))
    assert np.all(np.diff(sound) > 0) and sound[0, -1] == 1.0
    # a level and its miss probability name the same confidence (1 - level is exact in floats
    # for level >= 1/2, Sterbenz); the float 0.05 is not 1 - 0.95
    by_miss = clopper_pearson_upper(ks, n, alpha=1 - level, sound=True)
    np.testing.assert_array_equal(sound, by_miss)


def test_clopper_pearson_sound_exact_coverage():
    """P_p[p > CP(K)] computed exactly from the binomial pmf stays below delta for every p."""
    n, delta = 30, 0.1
    cps = clopper_pearson_upper(np.arange(n + 1), n, alpha=delta, sound=True)
    for p in np.linspace(0.001, 0.999, 300):
        miss = scipy.stats.binom.pmf(np.arange(n + 1), n, p)[cps < p].sum()
        assert miss <= delta + CP_ATOL


def test_clopper_pearson_argument_errors():
    with pytest.raises(TypeError, match="exactly one"):
        clopper_pearson_upper(1, 10, 0.95, alpha=0.05)
    with pytest.raises(TypeError, match="exactly one"):
        clopper_pearson_upper(1, 10)
    with pytest.raises(SpecError, match="integers"):
        clopper_pearson_upper(1.5, 10, 0.95, sound=True)
    with pytest.raises(SpecError, match="confidence"):
        clopper_pearson_upper(1, 10, alpha=1.5, sound=True)


def test_clopper_pearson_lower():
    n, level = 50, 0.95
    assert clopper_pearson_lower(0, n, level) == 0.0
    assert clopper_pearson_lower(n, n, level) == pytest.approx(
        (1 - level) ** (1 / n), rel=CP_QUANTILE_RTOL
    )
    ks = np.arange(1, n + 1)
    low = clopper_pearson_lower(ks, n, level)
    assert np.all(np.diff(low) > 0)
    assert np.all(low < ks / n)
    # defining equation: P(Bin(n, lower) >= k) = 1 - level, i.e. beta quantile (1-level; k, n-k+1)
    np.testing.assert_allclose(scipy.stats.binom.sf(ks - 1, n, low), 1 - level, atol=CP_ATOL)
    np.testing.assert_allclose(low, scipy.stats.beta.ppf(1 - level, ks, n - ks + 1), atol=CP_ATOL)


def test_t_one_sided_and_bonferroni():
    rng = np.random.default_rng(6)
    x = rng.normal(size=40)
    mean, lo, hi = t_one_sided(x.sum(), (x * x).sum(), len(x), 0.9)
    half = scipy.stats.t.ppf(0.9, len(x) - 1) * scipy.stats.sem(x)
    assert float(lo) == pytest.approx(x.mean() - half, rel=SUM_RTOL)
    assert float(hi) == pytest.approx(x.mean() + half, rel=SUM_RTOL)
    assert float(mean) == pytest.approx(x.mean(), rel=SUM_RTOL)
    with pytest.raises(SpecError, match="ci_level"):
        t_one_sided(x.sum(), (x * x).sum(), len(x), 0.5)
    assert bonferroni_level(0.95, 10) == pytest.approx(0.995, abs=BONFERRONI_ATOL)
    assert bonferroni_level(0.95, 1) == 0.95


def test_upper_quantile_bounds_match_the_frequency_test_and_cover():
    rng = np.random.default_rng(7)
    delta, level, n = 0.1, 0.95, 300
    x = rng.exponential(size=n)
    q_hat, q_low, q_high = upper_quantile_bounds(x, delta, level)
    assert q_low <= q_hat <= q_high
    assert q_hat == np.quantile(x, 1 - delta, method="inverted_cdf")
    # q_low > rho  <=>  Clopper-Pearson lower bound of #{x > rho} / n exceeds delta
    for rho in np.concatenate([np.sort(x), np.linspace(0.0, 5.0, 51)]):
        k = int(np.sum(x > rho))
        assert (q_low > rho) == bool(clopper_pearson_lower(k, n, level) > delta)
    # coverage of the true quantile of Exp(1), log(1/delta), by each one-sided bound
    reps, true_q = 2000, math.log(1 / delta)
    lows, highs = [], []
    for _ in range(reps):
        _, lo, hi = upper_quantile_bounds(rng.exponential(size=60), delta, level)
        lows.append(lo)
        highs.append(hi)
    se = math.sqrt(level * (1 - level) / reps)
    assert np.mean(np.array(lows) <= true_q) >= level - MC_Z * se
    assert np.mean(np.array(highs) >= true_q) >= level - MC_Z * se
    # unknown draws (NaN, or missing up to n_total) weaken both bounds, never strengthen them
    _, lo2, hi2 = upper_quantile_bounds(np.concatenate([x, [np.nan] * 20]), delta, level)
    _, lo3, hi3 = upper_quantile_bounds(x, delta, level, n_total=n + 20)
    assert (lo2, hi2) == (lo3, hi3)
    assert lo2 <= q_low and hi2 >= q_high
    # too few draws for a bound at this level: it is infinite, not made up. One draw bounds
    # nothing; five bound the quantile from below (3 of 5 above rho already contradict delta =
    # 0.1) but not from above (P(no draw above q) can be 0.9^5 = 0.59 > 0.05)
    assert upper_quantile_bounds(np.ones(1), delta, level) == (1.0, -math.inf, math.inf)
    assert upper_quantile_bounds(np.ones(5), delta, level) == (1.0, 1.0, math.inf)


def test_w2_translation_and_one_dimension():
    rng = np.random.default_rng(2)
    a = rng.normal(size=(300, 4))
    c = np.array([0.3, -0.1, 0.2, 0.05])
    assert w2_empirical(a, a + c) == pytest.approx(np.linalg.norm(c), abs=W2_ATOL)
    assert w2_empirical(a, a) == pytest.approx(0.0, abs=W2_ATOL)
    # 1-D with equal sizes: the optimal coupling matches order statistics
    x = rng.normal(size=400)
    y = 0.5 + 2.0 * rng.normal(size=400)
    direct = math.sqrt(np.mean((np.sort(x) - np.sort(y)) ** 2))
    assert w2_empirical(x[:, None], y[:, None]) == pytest.approx(direct, abs=W2_ATOL)


def test_w2_same_law_baseline_is_biased_upward_in_4d():
    # two independent samples of ONE law in 4-D: the true W2 is 0, the estimate is not
    rng = np.random.default_rng(3)
    a, b = rng.normal(size=(2, 500, 4))
    base = w2_empirical(a, b)
    assert base > 0.3  # the reason the engine reports a same-law baseline next to each W2


def test_norms_sequential_and_errors():
    rng = np.random.default_rng(5)
    d = rng.normal(size=(10, 7, 4))
    np.testing.assert_allclose(norms_sequential(d), np.linalg.norm(d, axis=-1), rtol=SUM_RTOL)
    with pytest.raises(SpecError, match="p_max"):
        new_sums(3, 0)
    with pytest.raises(SpecError, match="kappas"):
        new_sums(3, 1, (-1.0,))
    with pytest.raises(SpecError, match="ci_level"):
        finalize("g", new_sums(3, 1), np.zeros(3), 1.5)


def test_sound_clopper_pearson_of_closed_forms_and_certify_import_no_scipy_stats():
    """scipy.stats (and scipy.optimize, which it imports) cost ~0.5 CPU-s to import, a tenth of a
    small `certify`: the sound bound at ``k = 0`` (closed form) and ``k >= n`` (1) does not use
    scipy's quantile, so neither it nor importing the certificate loads them; same numbers."""
    import subprocess
    import sys
    from pathlib import Path

    code = (
        "import sys\n"
        "from drip_cert.numerics.stats import clopper_pearson_upper\n"
        "r = clopper_pearson_upper([0, 7, 9], 7, alpha=0.05, sound=True)\n"
        "import drip_cert.bounds.certificate\n"
        "print(repr(r.tolist()), 'scipy.stats' in sys.modules, 'scipy.optimize' in sys.modules)\n"
    )
    root = Path(__file__).resolve().parents[1]
    out = subprocess.run(
        [sys.executable, "-c", code], cwd=root, capture_output=True, text=True, check=False
    )
    assert out.returncode == 0, out.stderr
    want = [float(clopper_pearson_upper(0, 7, alpha=0.05, sound=True)), 1.0, 1.0]
    assert out.stdout.strip() == f"{want!r} False False"


def test_sound_clopper_pearson_candidate_is_scipys_beta_quantile_bit_for_bit(monkeypatch):
    """The sound bound starts its upward search at scipy's beta quantile; it is taken from the
    ufunc behind ``scipy.stats.beta.ppf`` (without importing scipy.stats): the same floats, so
    the same proved bounds as with scipy.stats itself (forced here by hiding the ufunc)."""
    import drip_cert.numerics.stats as st

    k = np.array([0, 1, 2, 3, 5, 8, 13, 40, 99, 100, 120])
    for n, alpha in ((100, 0.05), (100, 0.1), (59, 0.025), (1000, 1e-3)):
        q, a, b = 1.0 - alpha, k + 1.0, np.maximum(n - k, 1e-300)
        assert np.array_equal(st._beta_ppf()(q, a, b), scipy.stats.beta.ppf(q, a, b))
        fast = clopper_pearson_upper(k, n, alpha=alpha, sound=True)
        with monkeypatch.context() as m:
            m.setattr(st, "_beta_ppf", lambda: None)
            slow = clopper_pearson_upper(k, n, alpha=alpha, sound=True)
        assert np.array_equal(fast, slow)
