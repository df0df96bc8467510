"""Per-time statistics of imitation gaps, accumulated over chunks of Monte-Carlo paths.

The DRIP paper decomposes the total imitation gap (TIG, Definition "ImitationGap") into the
policy-induced gap ``E||x'_t - x*_t||`` and the uncertainty-induced gap ``E||X_t - x'_t||``
(eq. Decomposition:IG:Components). For each gap and each recorded time this module accumulates,
over paths, the power sums ``sum r^q`` (``q = 1, 2, 4, ..., 2 p_max``), the tail counts
``#{r >= kappa}``, the sample maximum and, per path, the maximum over the recorded times
``max_t r_t`` (what a high-probability radius such as ``rho_TaSIL`` bounds), and turns them into

* the mean with a CLT Student-t interval at a named level (two-sided);
* the moments ``E r^{2p}`` and the ``L_{2p}`` norms ``E[r^{2p}]^{1/(2p)}`` that L1-DRAC
  Theorem 4.1 bounds by ``rho_L1(p)``;
* tail frequencies with one-sided Clopper-Pearson upper bounds (distribution-free, exact
  binomial). No distribution-free bound on the MEAN is offered: without a known bound on the
  support of the gap there is none (Hoeffding/Bernstein need one; the divergence cap is far too
  loose to be useful);
* the maximum over time of the mean gap with the interval at the argmax.

For the validation (:mod:`drip_cert.validate`) it also offers one-sided bounds: Student-t bounds
for a mean (:func:`t_one_sided`), Clopper-Pearson bounds for a proportion
(:func:`clopper_pearson_upper`, :func:`clopper_pearson_lower`), distribution-free order-statistic
bounds for an upper quantile (:func:`upper_quantile_bounds`) and the Bonferroni level for a
family of tests (:func:`bonferroni_level`). :func:`clopper_pearson_upper` is drip-cert's one
Clopper-Pearson implementation: with ``sound=True`` it proves its bound in Arb (the held-out form
of the TaSIL certificate, docs/math/tasil.md 3.3 c, labels it sound).

Determinism: sums are added path by path in global path order (:func:`accumulate`), so the
result does not depend on how paths were grouped into chunks, bit for bit.

Also here: the empirical Wasserstein-2 distance between two sample clouds with POT's exact solver,
and a same-law baseline (W2 between two independent samples of ONE law), because the empirical W2
is biased upward in dimension >= 3 (math notes: a true 0.2 measured 0.5 at 4000 samples in 4-D).
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Any

import numpy as np
from flint import arb, ctx

from drip_cert.errors import SpecError
from drip_cert.numerics.rounding import arb_hi, up
from drip_cert.provenance import json_float

__all__ = [
    "GapSums",
    "GapStats",
    "W2Estimate",
    "accumulate",
    "bonferroni_level",
    "clopper_pearson_lower",
    "clopper_pearson_upper",
    "finalize",
    "map_sequential",
    "min_trials_zero_failures",
    "new_sums",
    "norms_sequential",
    "t_interval",
    "t_one_sided",
    "upper_quantile_bounds",
    "w2_empirical",
]


@dataclass(frozen=True)
class GapSums:
    """Running sums of one gap ``r_t = ||a_t - b_t||`` over paths (one value per recorded time).

    Attributes
    ----------
    count
        Number of valid paths added.
    powers
        The exponents ``q`` of ``power_sums``: ``(1, 2, 4, ..., 2 p_max)``.
    power_sums
        ``(len(powers), n_times)``: ``sum_paths r_t^q``.
    kappas
        Tail thresholds.
    tail_counts
        ``(len(kappas), n_times)`` int64: ``#{paths: r_t >= kappa}``.
    max
        ``(n_times,)``: sample maximum of ``r_t`` (``-inf`` when empty).
    path_max
        ``(count,)``: ``max_t r_t`` of every valid path over the recorded times, in global path
        order (8 bytes per path).
    """

    count: int
    powers: tuple[int, ...]
    power_sums: np.ndarray
    kappas: tuple[float, ...]
    tail_counts: np.ndarray
    max: np.ndarray
    path_max: np.ndarray


def new_sums(n_times: int, p_max: int, kappas: tuple[float, ...] = ()) -> GapSums:
    """Empty :class:`GapSums` for ``n_times`` recorded times and moments up to ``2 p_max``."""
    if int(p_max) < 1:
        raise SpecError(f"p_max must be an integer >= 1, got {p_max!r}", field="p_max")
    powers = (1, *(2 * p for p in range(1, int(p_max) + 1)))
    kappas = tuple(float(k) for k in kappas)
    if any(not (np.isfinite(k) and k > 0) for k in kappas):
        raise SpecError(f"tail thresholds must be finite and > 0, got {kappas}", field="kappas")
    return GapSums(
        count=0,
        powers=powers,
        power_sums=np.zeros((len(powers), n_times)),
        kappas=kappas,
        tail_counts=np.zeros((len(kappas), n_times), dtype=np.int64),
        max=np.full(n_times, -np.inf),
        path_max=np.zeros(0),
    )


def map_sequential(diff: np.ndarray, M: np.ndarray) -> np.ndarray:
    """``diff @ M.T`` over the last axis, each entry summed left to right.

    Like :func:`norms_sequential`, each output row depends on its own input row only (a BLAS
    product may change its summation order with the array's shape), which the chunk-size
    invariance of the Monte-Carlo accumulators needs.
    """
    diff = np.asarray(diff, dtype=np.float64)
    M = np.asarray(M, dtype=np.float64)
    out = np.empty(diff.shape[:-1] + (M.shape[0],), dtype=np.float64)
    for i in range(M.shape[0]):
        acc = diff[..., 0] * M[i, 0]
        for c in range(1, diff.shape[-1]):
            acc = acc + diff[..., c] * M[i, c]
        out[..., i] = acc
    return out


def norms_sequential(diff: np.ndarray) -> np.ndarray:
    """Euclidean norms over the last axis, summing squares left to right.

    The fixed left-to-right order makes each norm depend on its own row only (not on the array
    shape or the vectorisation numpy picks), which the chunk-size invariance needs.
    """
    diff = np.asarray(diff, dtype=np.float64)
    acc = diff[..., 0] * diff[..., 0]
    for c in range(1, diff.shape[-1]):
        acc = acc + diff[..., c] * diff[..., c]
    return np.sqrt(acc)


def accumulate(sums: GapSums, r: np.ndarray, valid: np.ndarray) -> GapSums:
    """Add the paths of one chunk, in order, to ``sums`` (pure: returns a new object).

    Parameters
    ----------
    sums
        The running sums.
    r
        ``(n_paths_chunk, n_times)``: gap norms of the chunk's paths, in global path order.
    valid
        ``(n_paths_chunk,)`` bool: paths to include (diverged and padding paths excluded).

    Notes
    -----
    The power sums are updated one path at a time (a sequential left fold), so the result for
    a set of paths is the same floating-point number however the paths were split into chunks.
    The per-path maxima are appended in path order (a maximum is exact), so they do not depend
    on the split either.
    """
    r = np.asarray(r, dtype=np.float64)
    valid = np.asarray(valid, dtype=bool)
    if r.ndim != 2 or r.shape[1] != sums.power_sums.shape[1] or valid.shape != (r.shape[0],):
        raise ValueError(f"r must be (paths, {sums.power_sums.shape[1]}), got {r.shape}")
    rv = r[valid]
    ps = sums.power_sums.copy()
    if rv.shape[0]:
        vals = np.stack([rv**q for q in sums.powers], axis=1)  # (paths, powers, times)
        # sequential left fold in path order: (((acc + v0) + v1) + ...)
        folded = np.add.accumulate(np.concatenate([ps[None], vals], axis=0), axis=0)
        ps = folded[-1].copy()
    tails = sums.tail_counts.copy()
    for i, kappa in enumerate(sums.kappas):
        tails[i] += np.count_nonzero(rv >= kappa, axis=0)
    mx = np.maximum(sums.max, rv.max(axis=0)) if rv.shape[0] else sums.max.copy()
    pm = np.concatenate([sums.path_max, rv.max(axis=1, initial=-np.inf)])
    return GapSums(
        count=sums.count + int(rv.shape[0]),
        powers=sums.powers,
        power_sums=ps,
        kappas=sums.kappas,
        tail_counts=tails,
        max=mx,
        path_max=pm,
    )


def t_interval(s1, s2, n: int, level: float):
    """Two-sided Student-t confidence interval for a mean from power sums.

    Parameters
    ----------
    s1, s2
        ``sum x`` and ``sum x^2`` (arrays of equal shape).
    n
        Number of samples (>= 2 for a finite interval).
    level
        Confidence level in (0, 1), e.g. 0.95.

    Returns
    -------
    mean, low, high : np.ndarray
        Sample mean and the interval ``mean -+ t_{(1+level)/2, n-1} s / sqrt(n)``.
    """
    s1 = np.asarray(s1, dtype=np.float64)
    s2 = np.asarray(s2, dtype=np.float64)
    if n < 1:
        nan = np.full(s1.shape, np.nan)
        return nan, nan.copy(), nan.copy()
    mean = s1 / n
    if n < 2:
        return mean, np.full(s1.shape, -np.inf), np.full(s1.shape, np.inf)
    var = np.maximum(s2 - s1 * s1 / n, 0.0) / (n - 1)
    import scipy.stats  # scipy.stats: 0.5 CPU-s to import, only where a quantile is needed

    half = scipy.stats.t.ppf(0.5 + 0.5 * level, n - 1) * np.sqrt(var / n)
    return mean, mean - half, mean + half


def t_one_sided(s1, s2, n: int, level: float):
    """One-sided Student-t confidence bounds for a mean from power sums.

    Parameters
    ----------
    s1, s2
        ``sum x`` and ``sum x^2`` (arrays of equal shape).
    n
        Number of samples (>= 2 for finite bounds).
    level
        Confidence level of EACH bound, in (0.5, 1).

    Returns
    -------
    mean, lower, upper : np.ndarray
        ``mean -+ t_{level, n-1} s / sqrt(n)``: ``P(mu >= lower) ~ level`` and
        ``P(mu <= upper) ~ level`` (CLT; not distribution-free). For right-skewed data the t
        statistic is left-skewed, so the LOWER bound errs on the conservative side and the
        upper bound on the liberal side.

    Notes
    -----
    The two-sided interval of :func:`t_interval` at level ``2 level - 1`` has exactly these
    end points; this function is that identity, so there is one t quantile in the module.
    """
    if not 0.5 < float(level) < 1.0:
        raise SpecError(f"one-sided level must be in (0.5, 1), got {level!r}", field="ci_level")
    return t_interval(s1, s2, n, 2.0 * float(level) - 1.0)


def bonferroni_level(level: float, m: int) -> float:
    """Per-test level of ``m`` one-sided tests whose union holds at ``level``: ``1 - (1-level)/m``.

    By the union bound the probability that ANY of the ``m`` bounds fails is at most
    ``m (1 - level) / m = 1 - level``, whatever the dependence between the tests.
    """
    if not 0.0 < float(level) < 1.0:
        raise SpecError(f"confidence level must be in (0, 1), got {level!r}", field="ci_level")
    return 1.0 - (1.0 - float(level)) / max(1, int(m))


# Clopper-Pearson, sound mode: first relative step above scipy's inverse, and how many tenfold
# steps to try before falling back to the trivial bound 1 (scipy's ppf is accurate to ~1e-12
# relative); bits of the Arb evaluation (balls far narrower than the 1e-12 steps)
_CP_STEP0 = 1e-12
_CP_TRIES = 12
_CP_PREC = 128


def _miss_probability(level: float | None, alpha: float | None) -> tuple[float, float, bool]:
    """``(level, miss, exact_miss)``: the float confidence of the scipy candidate, and the miss
    probability ``1 - level``, which is the given ``alpha`` itself when ``exact_miss``."""
    if level is None and alpha is not None:
        return 1.0 - float(alpha), float(alpha), True
    if level is not None and alpha is None:
        return float(level), 1.0 - float(level), False
    raise TypeError("give the confidence as exactly one of level and alpha = 1 - level")


def _proved_upper(k: int, n: int, candidate: float, tail: arb) -> float:
    """The smallest float ``p`` of the upward sequence from ``candidate`` at which Arb proves
    ``I_p(k + 1, n - k) >= 1 - tail``; ``1`` when none is found (``0 <= k < n``)."""
    if k == 0:  # closed form 1 - tail^(1/n), enclosed in Arb
        return min(1.0, arb_hi(1 - tail ** (arb(1) / n)))
    target = 1 - tail
    p = up(candidate)
    step = _CP_STEP0
    for _ in range(_CP_TRIES):
        if p >= 1.0:
            return 1.0
        if arb(p).beta_lower(k + 1, n - k, regularized=True) >= target:
            return p
        p = up(p * (1.0 + step))
        step *= 10.0
    return 1.0


def min_trials_zero_failures(target: float, alpha: float) -> int:
    """The smallest ``n`` at which ``k = 0`` failures in ``n`` trials give the sound one-sided
    Clopper-Pearson bound ``clopper_pearson_upper(0, n, alpha=alpha, sound=True) <= target``.

    With fewer trials no outcome at all can bring the bound to ``target`` (the bound is smallest
    at ``k = 0`` and decreases in ``n``): a check that needs it is impossible. The closed form
    ``1 - alpha^{1/n} <= target`` gives ``n >= log(alpha) / log(1 - target)``; the count is then
    confirmed (and raised where rounding needs it) with the sound bound itself.

    Examples
    --------
    >>> min_trials_zero_failures(0.05, 0.05)  # the held-out form at delta = 0.1
    59
    """
    if not (0.0 < target < 1.0 and 0.0 < alpha < 1.0):
        raise SpecError(f"target and alpha must lie in (0, 1), got {target!r}, {alpha!r}")
    n = max(1, math.floor(math.log(alpha) / math.log1p(-target)))
    while float(clopper_pearson_upper(0, n, alpha=alpha, sound=True)) > target:
        n += 1
    while n > 1 and float(clopper_pearson_upper(0, n - 1, alpha=alpha, sound=True)) <= target:
        n -= 1
    return n


def _beta_ppf() -> Any:
    """The ufunc ``scipy.stats.beta.ppf`` evaluates for valid arguments (``beta_gen._ppf``:
    ``scipy.special._ufuncs._beta_ppf``; ``ppf`` returns ``_ppf(q, a, b) * scale + loc``), or
    ``None`` where this scipy has none by that name (the caller then uses scipy.stats)."""
    import scipy.special  # scipy: 0.13 CPU-s to import, only where a quantile is needed

    return getattr(getattr(scipy.special, "_ufuncs", None), "_beta_ppf", None)


def clopper_pearson_upper(
    k, n: int, level: float | None = None, *, alpha: float | None = None, sound: bool = False
):
    """One-sided Clopper-Pearson upper confidence bound on a binomial proportion.

    ``P(p <= upper) >= level`` for ``k`` successes in ``n`` trials, with no distributional
    assumption beyond independence: ``upper = Beta^{-1}(level; k + 1, n - k)`` and 1 when
    ``k >= n`` or ``n < 1`` (for ``k = 0`` this is ``1 - (1 - level)^{1/n} <= log(1/(1 -
    level))/n``; docs/math/tasil.md 3.3 c).

    Parameters
    ----------
    k
        Success counts (scalar or array).
    n
        Number of trials.
    level
        Confidence level in (0, 1), e.g. 0.95.
    alpha
        The same confidence given as ``alpha = 1 - level`` (keyword only; exactly one of
        ``level`` and ``alpha``). With ``sound``, the bound is proved at the confidence exactly
        as given, and ``1 - alpha`` for a failure probability ``alpha`` is in general not a
        float: give ``alpha`` then.
    sound
        Prove the bound: each entry is the smallest float, searched upward from scipy's quantile,
        at which Arb (ball arithmetic) proves ``I_p(k + 1, n - k) >= level``; the regularized
        incomplete beta is the ``Beta(k + 1, n - k)`` CDF, increasing in ``p``, so the result is
        ``>=`` the exact bound. ``k = 0`` is enclosed in Arb from the closed form. Counts must
        then be integers ``>= 0``. Default: scipy's quantile as it is (accurate to ~1e-12).

    Returns
    -------
    np.ndarray
        Upper bounds, of the shape of ``k``.
    """
    lv, miss, exact_miss = _miss_probability(level, alpha)
    k = np.asarray(k, dtype=np.float64)
    if sound and not (0.0 < lv < 1.0 and 0.0 < miss < 1.0):
        raise SpecError(
            f"Clopper-Pearson confidence must lie in (0, 1), got level={level!r}, alpha={alpha!r}",
            field="delta" if exact_miss else "ci_level",
        )
    if n < 1:
        return np.ones(k.shape)
    if sound and (np.any(k < 0) or np.any(k != np.floor(k))):
        raise SpecError(f"counts k must be integers >= 0, got {k!r}", field="k")
    b = np.maximum(n - k, 1e-300)
    if sound and np.all((k == 0.0) | (k >= n)):
        # every entry is the closed form (k = 0) or 1 (k >= n): no quantile is used
        upper = np.where(k >= n, 1.0, np.nan)
    elif sound and (beta_ppf := _beta_ppf()) is not None:
        # the function scipy.stats.beta.ppf evaluates (its arguments are valid here: 0 < lv < 1,
        # a = k + 1 > 0, b > 0), without importing scipy.stats (0.5 CPU-s)
        with np.errstate(invalid="ignore"):
            upper = np.where(k >= n, 1.0, beta_ppf(lv, k + 1.0, b) * 1.0 + 0.0)
    else:
        import scipy.stats  # scipy.stats: 0.5 CPU-s to import, only where the quantile is used

        with np.errstate(invalid="ignore"):
            upper = np.where(k >= n, 1.0, scipy.stats.beta.ppf(lv, k + 1.0, b))
    if not sound:
        return upper
    old_prec = ctx.prec
    ctx.prec = _CP_PREC
    try:
        # the exact miss probability: alpha as given, or 1 - level (exact in 128 bits)
        tail = arb(miss) if exact_miss else 1 - arb(lv)
        flat = [
            1.0 if ki >= n else _proved_upper(int(ki), int(n), float(ci), tail)
            for ki, ci in zip(k.flat, upper.flat)
        ]
    finally:
        ctx.prec = old_prec
    return np.reshape(np.asarray(flat, dtype=np.float64), k.shape)


def clopper_pearson_lower(k, n: int, level: float):
    """One-sided Clopper-Pearson lower confidence bound on a binomial proportion.

    ``P(p >= lower) >= level`` for ``k`` successes in ``n`` trials (exact, distribution-free):
    ``lower = Beta^{-1}(1 - level; k, n - k + 1)``, and 0 when ``k = 0``.

    Computed as ``1 - clopper_pearson_upper(n - k, n, level)`` (the failures' upper bound), which
    is the same number by the symmetry ``Beta(a, b) = 1 - Beta(b, a)``: one implementation of the
    beta quantile serves both sides.
    """
    k = np.asarray(k, dtype=np.float64)
    if n < 1:
        return np.zeros(k.shape)
    low = 1.0 - np.asarray(clopper_pearson_upper(n - k, n, level), dtype=np.float64)
    return np.where(k <= 0, 0.0, np.clip(low, 0.0, 1.0))


def _first_true(pred, lo: int, hi: int) -> int | None:
    """Smallest ``k`` in ``[lo, hi]`` with ``pred(k)``, ``pred`` monotone (False.., True..)."""
    if lo > hi or not pred(hi):
        return None
    while lo < hi:
        mid = (lo + hi) // 2
        if pred(mid):
            hi = mid
        else:
            lo = mid + 1
    return lo


def upper_quantile_bounds(x, delta: float, level: float, n_total: int | None = None):
    """Empirical ``(1 - delta)``-quantile of a sample and distribution-free confidence bounds.

    The population quantile is ``q = inf{y : P(X > y) <= delta}``: a radius ``rho`` with
    ``P(X > rho) <= delta`` is exactly a number ``>= q``.

    Parameters
    ----------
    x
        1-D sample (finite values or ``+inf``; NaN entries count as unknown, like the missing
        ones below).
    delta
        Tail probability in (0, 1).
    level
        Confidence level of each one-sided bound.
    n_total
        Size of the whole i.i.d. sample when some draws are missing from ``x`` (e.g. diverged
        paths; default ``len(x)``): the missing and the NaN draws are taken as ``-inf`` for the
        lower bound and ``+inf`` for the upper one, so both stay valid whatever they were.

    Returns
    -------
    q_hat, q_low, q_high : float
        ``q_hat``: the ``ceil(n (1 - delta))``-th smallest known value (numpy's
        ``inverted_cdf``); ``q_low``: the ``k``-th largest value, ``k`` the smallest count with
        ``clopper_pearson_lower(k, n) > delta`` (``-inf`` when no such ``k``), so
        ``P(q >= q_low) >= level``; ``q_high``: the ``k'``-th largest value, ``k'`` the largest
        count with ``clopper_pearson_upper(k' - 1, n) <= delta`` (``+inf`` when none), so
        ``P(q <= q_high) >= level``.

    Notes
    -----
    ``q_low > rho`` holds exactly when ``#{x_i > rho} >= k``, i.e. when the Clopper-Pearson lower
    bound of the exceedance frequency of ``rho`` is ``> delta``: the quantile bound and the
    frequency test are the same test in two units. Proof of coverage: ``q_low > q`` needs at
    least ``k`` draws above ``q``, and ``P(X > q) <= delta`` (right continuity), so its
    probability is at most ``P(Bin(n, delta) >= k) < 1 - level``. Symmetrically
    ``P(X >= q) >= delta``, and ``q_high < q`` needs at most ``k' - 1`` draws ``>= q``.
    """
    a = np.asarray(x, dtype=np.float64).reshape(-1)
    known = a[~np.isnan(a)]
    if np.any(known == -np.inf):
        raise ValueError("sample values must be finite, +inf or NaN (unknown)")
    n = int(a.size if n_total is None else n_total)
    if n < a.size:
        raise ValueError(f"n_total={n} is smaller than the sample size {a.size}")
    delta = float(delta)
    if not 0.0 < delta < 1.0:
        raise SpecError(f"delta must lie in (0, 1), got {delta!r}", field="delta")
    if n == 0:
        return math.nan, -math.inf, math.inf
    desc = np.sort(known)[::-1]
    unknown = n - known.size
    q_hat = (
        float(np.quantile(known, 1.0 - delta, method="inverted_cdf")) if known.size else math.nan
    )
    k_low = _first_true(lambda k: float(clopper_pearson_lower(k, n, level)) > delta, 1, n)
    q_low = float(desc[k_low - 1]) if k_low is not None and k_low <= desc.size else -math.inf
    # largest k' with upper(k' - 1) <= delta  <=>  (smallest j with upper(j) > delta) = k'
    j = _first_true(lambda j: float(clopper_pearson_upper(j, n, level)) > delta, 0, n - 1)
    k_high = n if j is None else j
    padded = np.concatenate([np.full(unknown, np.inf), desc])
    q_high = float(padded[k_high - 1]) if k_high >= 1 else math.inf
    return q_hat, q_low, q_high


@dataclass(frozen=True)
class GapStats:
    """Statistics of one gap over the recorded times (see the module docstring).

    Attributes
    ----------
    name
        E.g. ``"policy"``, ``"total_l1"``, ``"uncertainty_l1"``.
    times
        ``(n_times,)`` recorded times.
    n
        Number of valid paths.
    level
        Confidence level of ``ci_low``/``ci_high`` and of the Clopper-Pearson bounds.
    mean, ci_low, ci_high
        ``(n_times,)``: mean of ``r_t`` and its two-sided t interval (CLT; not distribution-free).
    moments
        ``(p_max, n_times)``: ``E r_t^{2p}``, ``p = 1..p_max``.
    lp_norms
        ``(p_max, n_times)``: ``(E r_t^{2p})^{1/(2p)}`` (compare with ``rho_L1(p)``).
    kappas, tail_freq, tail_upper
        Thresholds, ``P(r_t >= kappa)`` estimates ``(n_kappa, n_times)`` and their one-sided
        Clopper-Pearson upper bounds at ``level`` (distribution-free).
    sample_max
        ``(n_times,)`` largest observed ``r_t``.
    max_mean, argmax_time, max_ci_low, max_ci_high
        ``max_t mean`` (a finite-grid estimate of the gap's ``Upsilon_T``), the time where it is
        attained, and the t interval there.
    powers, power_sums, tail_counts
        The raw sums behind the above (one-sided bounds and Bonferroni levels are computed from
        them in :mod:`drip_cert.validate`).
    path_max
        ``(n,)``: ``max_t r_t`` over the recorded times of every valid path, in path order.
    """

    name: str
    times: np.ndarray
    n: int
    level: float
    mean: np.ndarray
    ci_low: np.ndarray
    ci_high: np.ndarray
    moments: np.ndarray
    lp_norms: np.ndarray
    kappas: tuple[float, ...]
    tail_freq: np.ndarray
    tail_upper: np.ndarray
    sample_max: np.ndarray
    max_mean: float
    argmax_time: float
    max_ci_low: float
    max_ci_high: float
    powers: tuple[int, ...]
    power_sums: np.ndarray
    tail_counts: np.ndarray
    path_max: np.ndarray

    def to_dict(self) -> dict:
        """JSON-ready summary (maximum over time, final-time values, tails at the final time)."""
        return {
            "name": self.name,
            "n_valid": int(self.n),
            "level": float(self.level),
            "max_mean": json_float(self.max_mean),
            "argmax_time": json_float(self.argmax_time),
            "max_ci": [json_float(self.max_ci_low), json_float(self.max_ci_high)],
            "max_over_t_lp_norms": [json_float(v) for v in np.max(self.lp_norms, axis=1)],
            "final_mean": json_float(self.mean[-1]),
            "final_ci": [json_float(self.ci_low[-1]), json_float(self.ci_high[-1])],
            "kappas": list(self.kappas),
            "max_over_t_tail_freq": [json_float(v) for v in np.max(self.tail_freq, axis=1)]
            if self.kappas
            else [],
            "max_over_t_tail_upper": [json_float(v) for v in np.max(self.tail_upper, axis=1)]
            if self.kappas
            else [],
        }


def finalize(name: str, sums: GapSums, times: np.ndarray, level: float) -> GapStats:
    """Turn :class:`GapSums` into :class:`GapStats` at confidence ``level``."""
    if not 0.0 < level < 1.0:
        raise SpecError(f"confidence level must be in (0, 1), got {level!r}", field="ci_level")
    n = sums.count
    times = np.asarray(times, dtype=np.float64)
    mean, lo, hi = t_interval(sums.power_sums[0], sums.power_sums[1], n, level)
    with np.errstate(invalid="ignore", divide="ignore"):
        moments = sums.power_sums[1:] / n if n else np.full(sums.power_sums[1:].shape, np.nan)
        orders = np.array([2.0 * p for p in range(1, len(sums.powers))])[:, None]
        lp = moments ** (1.0 / orders)
        tail_freq = (sums.tail_counts / n if n else np.full(sums.tail_counts.shape, np.nan)).astype(
            np.float64
        )
    tail_up = clopper_pearson_upper(sums.tail_counts, n, level)
    if n and np.any(np.isfinite(mean)):
        i = int(np.nanargmax(mean))
        mmax, tmax, mlo, mhi = float(mean[i]), float(times[i]), float(lo[i]), float(hi[i])
    else:
        mmax = tmax = mlo = mhi = float("nan")
    return GapStats(
        name=name,
        times=times,
        n=n,
        level=float(level),
        mean=mean,
        ci_low=lo,
        ci_high=hi,
        moments=moments,
        lp_norms=lp,
        kappas=sums.kappas,
        tail_freq=tail_freq,
        tail_upper=np.asarray(tail_up, dtype=np.float64),
        sample_max=sums.max,
        max_mean=mmax,
        argmax_time=tmax,
        max_ci_low=mlo,
        max_ci_high=mhi,
        powers=sums.powers,
        power_sums=sums.power_sums,
        tail_counts=sums.tail_counts,
        path_max=sums.path_max,
    )


def w2_empirical(a: np.ndarray, b: np.ndarray) -> float:
    """Exact W2 between the empirical measures of two clouds (uniform weights), POT ``emd2``.

    Parameters
    ----------
    a, b
        ``(N_a, n)`` and ``(N_b, n)`` samples; rows with non-finite entries must be removed first.

    Returns
    -------
    float
        ``W2 = (min_coupling sum pi_ij ||a_i - b_j||^2)^{1/2}``.
    """
    import ot  # ot: keep off the API's import path

    a = np.asarray(a, dtype=np.float64)
    b = np.asarray(b, dtype=np.float64)
    if a.ndim != 2 or b.ndim != 2 or a.shape[1] != b.shape[1] or not len(a) or not len(b):
        raise ValueError(f"need two non-empty clouds of equal dimension, got {a.shape}, {b.shape}")
    cost = ot.dist(a, b, metric="sqeuclidean")
    wa = np.full(len(a), 1.0 / len(a))
    wb = np.full(len(b), 1.0 / len(b))
    val = float(ot.emd2(wa, wb, cost, numItermax=10_000_000))
    return float(np.sqrt(max(val, 0.0)))


@dataclass(frozen=True)
class W2Estimate:
    """Empirical W2 between two laws at one time, with same-law baselines.

    Attributes
    ----------
    pair
        E.g. ``("learned_l1_true", "expert_nominal")``.
    time
        The recorded time used.
    n_points
        Sample size of each cloud.
    w2
        W2 between INDEPENDENT samples of the two laws (disjoint path sets).
    baseline_a, baseline_b
        W2 between two independent samples of the same size of law ``a`` (resp. ``b``): the
        finite-sample bias of the estimator; a ``w2`` not clearly above them says nothing.
    """

    pair: tuple[str, str]
    time: float
    n_points: int
    w2: float
    baseline_a: float
    baseline_b: float

    def to_dict(self) -> dict:
        """JSON-ready dictionary."""
        return {
            "pair": list(self.pair),
            "time": self.time,
            "n_points": self.n_points,
            "w2": self.w2,
            "same_law_baseline": [self.baseline_a, self.baseline_b],
        }
