"""The validation checks (drip_cert.validate) on synthetic gap samples, and one CLI run.

Each test builds per-path gap norms ``r`` (paths x recorded times) with a seeded generator, turns
them into the engine's statistics with :mod:`drip_cert.numerics.stats`, and calls the check
functions directly: no simulation, except the last test, which runs ``drip-cert validate --quick``
(the quick suite's one end-to-end run of that command).
"""

from __future__ import annotations

import json
import math
from dataclasses import dataclass, field
from types import SimpleNamespace

import numpy as np
import pytest

from drip_cert.numerics.stats import (
    accumulate,
    clopper_pearson_lower,
    finalize,
    new_sums,
    t_one_sided,
)
from drip_cert.validate.checks import (
    HOLDS,
    NOT_CHECKED,
    NOTHING_CHECKED,
    VIOLATED,
    EmpiricalCheck,
    check_mean,
    check_radius,
    check_tail,
    checks_from_result,
    overall_status,
    total_tail_claim,
)
from tests.helpers import by_name, example_spec, run_cli

LEVEL = 0.95
"""The engine's default confidence level (SimConfig.ci_level)."""

N_PATHS = 400
"""Paths per synthetic sample: enough for the Clopper-Pearson and t bounds to resolve the
margins used below (0.3 vs 0.1, 0.5 vs 0.3), small enough to stay instant."""

N_TIMES = 21
"""Recorded times of a synthetic sample (Bonferroni divides 1 - LEVEL by this)."""

TIMES = np.linspace(0.0, 2.0, N_TIMES)

NOISE_EXCESS = 1e-3
"""Relative excess of a point estimate over its bound that is pure sampling noise: far below the
standard error of an L_2 norm from N_PATHS exponential draws (~5% relative)."""

RHO_TASIL, DELTA_TASIL = 1.0, 0.1
RHO_L1, P, KAPPA, DELTA_L1 = 0.5, 1, 2.0, 0.2
"""Certified numbers of the synthetic certificate (any positive values; kappa >= rho_L1 as in
L1-DRAC (130a), kappa = rho_L1 delta^(-1/(2p)) = 0.5 * 0.2^(-1/2) ~ 1.1, rounded up)."""

COUNT_TOL = 0.5 / N_PATHS
"""A frequency is (count of paths) / N_PATHS: less than half a path's share means the count is
exact."""

FLOAT_ATOL = 1e-15
"""The same few float64 operations on numbers in [0, 1], in another order: an ulp or two."""


def _stats(name: str, r: np.ndarray, valid: np.ndarray | None = None, p_max: int = 4):
    """The engine's GapStats of the per-path norms ``r`` (paths x times)."""
    kappas = (KAPPA, RHO_TASIL + KAPPA)
    valid = np.ones(len(r), dtype=bool) if valid is None else valid
    sums = accumulate(new_sums(r.shape[1], p_max, kappas), r, valid)
    return finalize(name, sums, TIMES, LEVEL)


@dataclass
class _FakeResult:
    """What checks_from_result reads from a SimResult."""

    gaps: dict
    n_paths_done: int
    config: SimpleNamespace = field(default_factory=lambda: SimpleNamespace(ci_level=LEVEL))

    def gap(self, name):
        return self.gaps[name]


def _result(policy: np.ndarray, unc: np.ndarray, total: np.ndarray, **valid) -> _FakeResult:
    gaps = {
        "policy": _stats("policy", policy, valid.get("policy")),
        "uncertainty_l1": _stats("uncertainty_l1", unc, valid.get("unc")),
        "total_l1": _stats("total_l1", total, valid.get("total")),
    }
    return _FakeResult(gaps, len(policy))


def _small(seed: int, scale: float) -> np.ndarray:
    """Norms well inside every bound: exponential with mean ``scale``, zero at t = 0."""
    r = np.random.default_rng(seed).exponential(scale, size=(N_PATHS, N_TIMES))
    r[:, 0] = 0.0
    return r


def _certified(**kw):
    args = {
        "rho_tasil": RHO_TASIL,
        "delta_tasil": DELTA_TASIL,
        "rho_l1": RHO_L1,
        "p": P,
        "kappa": KAPPA,
        "delta_l1": DELTA_L1,
    }
    return {**args, **kw}


# ---------------------------------------------------------------------------------- statuses


def test_within_bounds_holds():
    res = _result(_small(0, 0.05), _small(1, 0.05), _small(2, 0.1))
    checks = by_name(checks_from_result(res, **_certified()))
    for name in (
        "policy_radius",
        "uncertainty_gap",
        "uncertainty_L2_norm",
        "tail_frequency",
        "total_tail",
    ):
        assert checks[name].status == HOLDS, (name, checks[name].reason)
        assert checks[name].holds is True
        assert checks[name].confidence_low <= checks[name].bound
        assert checks[name].ratio > 1.0
    # the expectation numbers next to radii are information only, never "holds"
    for name in ("policy_gap", "total_gap"):
        assert checks[name].status == NOT_CHECKED
        assert checks[name].reason.startswith("information only")
    assert overall_status(list(checks.values())) == HOLDS


def test_nothing_finite_checked_is_nothing_checked():
    res = _result(_small(0, 0.05), _small(1, 0.05), _small(2, 0.1))
    checks = checks_from_result(
        res, rho_tasil=math.inf, delta_tasil=0.1, rho_l1=None, p=1, kappa=None, delta_l1=None
    )
    assert all(c.status == NOT_CHECKED and c.holds is False for c in checks)
    assert all(c.reason for c in checks)
    assert overall_status(checks) == NOTHING_CHECKED
    assert overall_status([]) == NOTHING_CHECKED


def test_vacuous_tasil_radius_is_not_checked():
    res = _result(_small(0, 0.05), _small(1, 0.05), _small(2, 0.1))
    checks = by_name(checks_from_result(res, **_certified(rho_tasil=math.inf)))
    assert checks["policy_radius"].status == NOT_CHECKED
    assert "vacuous" in checks["policy_radius"].reason
    # the total needs rho_TaSIL too; the L1 checks do not
    assert checks["total_tail"].status == NOT_CHECKED
    assert checks["tail_frequency"].status == HOLDS


def test_nan_empirical_is_not_checked_never_holds():
    nan = np.full(N_TIMES, np.nan)
    c = check_mean("m", nan, nan, N_PATHS, 1.0, LEVEL, times=TIMES)
    assert c.status == NOT_CHECKED and not c.holds
    # NaN at one time only, the others far inside the bound: the sup over t is unknown
    s1 = np.full(N_TIMES, 0.1 * N_PATHS)
    s2 = np.full(N_TIMES, 0.02 * N_PATHS)
    s1[5] = np.nan
    c = check_mean("m", s1, s2, N_PATHS, 1.0, LEVEL, times=TIMES)
    assert c.status == NOT_CHECKED and "non-finite" in c.reason
    # a per-path sample of NaNs: nothing is known
    c = check_radius("r", np.full(50, np.nan), 1.0, 0.1, LEVEL)
    assert c.status == NOT_CHECKED and not c.holds
    # no valid path for a tail check
    c = check_tail("t", np.zeros(N_TIMES), 0, 1.0, 0.1, LEVEL, n_total=N_PATHS)
    assert c.status == NOT_CHECKED and "no valid paths" in c.reason


def test_not_at_certified_parameters_never_counts_but_the_policy_radius_does():
    res = _result(_small(0, 0.05), _small(1, 0.05), _small(2, 0.1))
    checks = by_name(
        checks_from_result(
            res, **_certified(), at_certified_l1=False, not_certified_why="practical T_s"
        )
    )
    for name in ("uncertainty_gap", "uncertainty_L2_norm", "tail_frequency", "total_tail"):
        assert checks[name].status == NOT_CHECKED
        assert "not at certified parameters" in checks[name].reason
        assert "not at certified parameters" in checks[name].note
    # the two nominal processes do not involve the L1-DRAC parameters
    assert checks["policy_radius"].status == HOLDS


# ------------------------------------------------------------------------ like with like


def test_radius_violated_although_the_mean_is_below_rho():
    rng = np.random.default_rng(3)
    policy = rng.uniform(0.0, 0.1 * RHO_TASIL, size=(N_PATHS, N_TIMES))
    out = rng.permutation(N_PATHS)[: int(0.3 * N_PATHS)]  # 30% of the paths leave the radius...
    when = rng.integers(1, N_TIMES, size=out.size)  # ...each at one (random) time
    policy[out, when] = 2.0 * RHO_TASIL
    res = _result(policy, _small(1, 0.05), _small(2, 0.1))
    checks = by_name(checks_from_result(res, **_certified()))
    rad = checks["policy_radius"]
    assert rad.status == VIOLATED and rad.holds is False
    assert rad.extra["exceed_frequency"] == pytest.approx(0.3, abs=COUNT_TOL)
    assert rad.extra["exceed_confidence_low"] > DELTA_TASIL
    # the same test in radius units: the lower confidence bound of the 0.9-quantile exceeds rho
    assert rad.confidence_low > RHO_TASIL and rad.empirical == 2.0 * RHO_TASIL
    # the old comparison, max_t E||x' - x*|| against rho_TaSIL, would have said "holds"
    pol = res.gap("policy")
    assert pol.max_mean < RHO_TASIL
    _, mean_low, _ = t_one_sided(pol.power_sums[0], pol.power_sums[1], pol.n, LEVEL)
    assert np.max(mean_low) < RHO_TASIL
    assert checks["policy_gap"].empirical < checks["policy_gap"].bound
    assert checks["policy_gap"].status == NOT_CHECKED  # reported, not checked
    assert overall_status(list(checks.values())) == VIOLATED


def test_radius_frequency_test_and_quantile_bound_agree():
    rng = np.random.default_rng(4)
    for frac in (0.0, 0.08, 0.12, 0.16, 0.3):
        x = rng.uniform(0.0, 0.5, size=N_PATHS)
        x[: int(frac * N_PATHS)] = 1.5
        c = check_radius("r", x, 1.0, 0.1, LEVEL)
        assert (c.confidence_low > 1.0) == (c.extra["exceed_confidence_low"] > 0.1)
        assert c.status == (VIOLATED if c.extra["exceed_confidence_low"] > 0.1 else HOLDS)


def test_total_uses_rho_tasil_plus_kappa_and_delta_sum():
    rng = np.random.default_rng(5)
    thr = RHO_TASIL + KAPPA
    total = _small(2, 0.1)
    # 28% of the paths beyond rho_TaSIL + kappa at every t > 0: more than delta_L1 = 0.2 alone
    # allows (even at the Bonferroni level), less than delta_TaSIL + delta_L1 = 0.3
    hit = rng.permutation(N_PATHS)[: int(0.28 * N_PATHS)]
    total[hit, 1:] = 1.01 * thr
    res = _result(_small(0, 0.05), _small(1, 0.05), total)
    tot = by_name(checks_from_result(res, **_certified()))["total_tail"]
    assert tot.extra["threshold"] == thr
    assert tot.bound == pytest.approx(DELTA_TASIL + DELTA_L1, abs=FLOAT_ATOL)
    assert tot.empirical == pytest.approx(0.28, abs=COUNT_TOL)
    assert tot.status == HOLDS
    # the lower bound exceeds delta_L1 alone: the union bound is what makes it hold
    assert tot.confidence_low > DELTA_L1
    # at 50% beyond the threshold even delta_TaSIL + delta_L1 is exceeded
    total[rng.permutation(N_PATHS)[: N_PATHS // 2], 1:] = 1.01 * thr
    res = _result(_small(0, 0.05), _small(1, 0.05), total)
    tot = by_name(checks_from_result(res, **_certified()))["total_tail"]
    assert tot.status == VIOLATED
    # the frequency just AT the threshold counts too: (130a) and the union bound are for ">="
    total = _small(2, 0.1)
    total[: N_PATHS // 2, 1:] = thr
    res = _result(_small(0, 0.05), _small(1, 0.05), total)
    assert by_name(checks_from_result(res, **_certified()))["total_tail"].status == VIOLATED


RHO_SDE = 0.3
"""``sup_t ||X*_t - x'_t||_{L_2p}`` of a synthetic certificate with a known diffusion."""

ULPS_TOL = 1e-14
"""The Markov radius is rounded up by a few ulps of numbers ~4: relative 1e-14 covers it."""


def test_total_tail_with_a_known_diffusion_passes_through_the_nominal_sde():
    # closed form: r = rho_sde delta_L1^(-1/(2p)) = 0.3 / sqrt(0.2); thr = rho_TaSIL + kappa + r
    thr, dsum, why = total_tail_claim(RHO_TASIL, KAPPA, DELTA_TASIL, DELTA_L1, RHO_SDE, P)
    exact = RHO_TASIL + KAPPA + RHO_SDE / math.sqrt(DELTA_L1)
    assert why is None
    assert exact <= thr <= exact * (1 + ULPS_TOL)
    assert dsum == pytest.approx(DELTA_TASIL + 2 * DELTA_L1, abs=FLOAT_ATOL)
    # without a known diffusion: the two-term claim, unchanged
    thr0, dsum0, _ = total_tail_claim(RHO_TASIL, KAPPA, DELTA_TASIL, DELTA_L1, None, P)
    assert (thr0, dsum0) == (RHO_TASIL + KAPPA, pytest.approx(DELTA_TASIL + DELTA_L1))
    # p = 2: the 4th moment, r = rho_sde delta^(-1/4)
    thr2, _, _ = total_tail_claim(RHO_TASIL, KAPPA, DELTA_TASIL, DELTA_L1, RHO_SDE, 2)
    assert thr2 == pytest.approx(RHO_TASIL + KAPPA + RHO_SDE * DELTA_L1**-0.25, rel=ULPS_TOL)
    # a vacuous rho_sde or a probability sum >= 1 forms no claim
    assert total_tail_claim(RHO_TASIL, KAPPA, DELTA_TASIL, DELTA_L1, math.inf, P)[2]
    assert total_tail_claim(RHO_TASIL, KAPPA, 0.3, 0.4, RHO_SDE, P)[2]


def test_the_markov_radius_is_the_smallest_that_holds_for_every_law():
    # Y = r w.p. delta, else 0: ||Y||_{L_2p} = r delta^(1/(2p)) = rho_sde and P(Y >= r) = delta
    # exactly, so no smaller radius is valid for every law with that moment (Markov attained)
    for p in (1, 2, 3):
        thr, _, _ = total_tail_claim(0.0, KAPPA, DELTA_TASIL, DELTA_L1, RHO_SDE, p)
        r = thr - KAPPA
        r_tight = RHO_SDE * DELTA_L1 ** (-1.0 / (2 * p))
        assert r == pytest.approx(r_tight, rel=ULPS_TOL) and r >= r_tight * (1 - ULPS_TOL)
        moment = (DELTA_L1 * r_tight ** (2 * p)) ** (1.0 / (2 * p))
        assert moment == pytest.approx(RHO_SDE, rel=ULPS_TOL)


def test_total_tail_with_a_known_diffusion_checks_the_three_term_threshold():
    thr, dsum, _ = total_tail_claim(RHO_TASIL, KAPPA, DELTA_TASIL, DELTA_L1, RHO_SDE, P)
    assert thr is not None and dsum is not None
    rng = np.random.default_rng(9)
    # 40% of the paths between rho_TaSIL + kappa and the three-term threshold: the two-term
    # claim (at 0.3) would be violated; the three-term claim (at 0.5) holds
    total = _small(3, 0.1)
    total[rng.permutation(N_PATHS)[: int(0.4 * N_PATHS)], 1:] = 0.5 * (RHO_TASIL + KAPPA + thr)
    kappas = (KAPPA, RHO_TASIL + KAPPA, thr)
    sums = accumulate(new_sums(N_TIMES, 4, kappas), total, np.ones(N_PATHS, dtype=bool))
    res = _result(_small(0, 0.05), _small(1, 0.05), total)
    res.gaps["total_l1"] = finalize("total_l1", sums, TIMES, LEVEL)
    tot = by_name(checks_from_result(res, **_certified(rho_sde=RHO_SDE)))["total_tail"]
    assert tot.extra["threshold"] == thr
    assert tot.bound == pytest.approx(dsum, abs=FLOAT_ATOL)
    assert tot.empirical == 0.0 and tot.status == HOLDS
    two = by_name(checks_from_result(res, **_certified()))["total_tail"]
    assert two.status == VIOLATED  # the same paths against the claim without rho_sde
    # a run that simulated only the two-term threshold cannot check the three-term claim
    plain = _result(_small(0, 0.05), _small(1, 0.05), total)
    tot = by_name(checks_from_result(plain, **_certified(rho_sde=RHO_SDE)))["total_tail"]
    assert tot.status == NOT_CHECKED


def test_l2p_norm_uses_a_lower_confidence_bound():
    rng = np.random.default_rng(6)
    r = rng.exponential(size=(N_PATHS, N_TIMES))
    r[:, 0] = 0.0
    # rescale so that the point estimate of the L_2 norm at the worst time is the bound plus noise
    l2 = np.sqrt(np.mean(r**2, axis=0))
    r *= RHO_L1 * (1.0 + NOISE_EXCESS) / l2.max()
    res = _result(_small(0, 0.05), r, _small(2, 0.1))
    lp = by_name(checks_from_result(res, **_certified()))["uncertainty_L2_norm"]
    assert lp.empirical > RHO_L1  # the point estimate says "above the bound"...
    assert lp.confidence_low < RHO_L1  # ...the lower confidence bound does not
    assert lp.status == HOLDS
    # a clear excess is a violation
    res = _result(_small(0, 0.05), 1.5 * r, _small(2, 0.1))
    lp = by_name(checks_from_result(res, **_certified()))["uncertainty_L2_norm"]
    assert lp.status == VIOLATED and lp.confidence_low > RHO_L1
    # the mean gap against rho_L1 is the weaker (E|.| <= L_2p) comparison of the same sample
    mean = by_name(checks_from_result(res, **_certified()))["uncertainty_gap"]
    assert mean.empirical < lp.empirical


def test_tail_frequency_clopper_pearson_with_bonferroni():
    counts = np.zeros(N_TIMES)
    counts[7] = 0.3 * N_PATHS
    c = check_tail("t", counts, N_PATHS, KAPPA, DELTA_L1, LEVEL, times=TIMES)
    per_t = 1.0 - (1.0 - LEVEL) / N_TIMES
    assert c.extra["per_time_level"] == pytest.approx(per_t, abs=FLOAT_ATOL)
    assert c.confidence_low == pytest.approx(
        float(clopper_pearson_lower(counts[7], N_PATHS, per_t)), abs=FLOAT_ATOL
    )
    assert c.extra["time"] == TIMES[7] and c.status == VIOLATED


def test_diverged_paths_make_a_hold_inconclusive_but_not_a_violation():
    x = np.random.default_rng(7).uniform(0.0, 0.5, size=N_PATHS)
    # 5% above rho among the valid ones; 10% of the paths diverged (unknown)
    x[: N_PATHS // 20] = 2.0
    c = check_radius("r", x, 1.0, 0.1, LEVEL, n_total=N_PATHS + N_PATHS // 10)
    assert c.status == NOT_CHECKED and "inconclusive" in c.reason
    x[: N_PATHS // 3] = 2.0
    c = check_radius("r", x, 1.0, 0.1, LEVEL, n_total=N_PATHS + N_PATHS // 10)
    assert c.status == VIOLATED
    # moments: a diverged path's contribution is unbounded, so no "holds"
    s1, s2 = np.full(N_TIMES, 0.01 * N_PATHS), np.full(N_TIMES, 0.001 * N_PATHS)
    c = check_mean("m", s1, s2, N_PATHS, 1.0, LEVEL, n_total=N_PATHS + 1, times=TIMES)
    assert c.status == NOT_CHECKED and "inconclusive" in c.reason


# ---------------------------------------------------------------------------- end to end


def test_cli_validate_exit_status_matches_report_status(capsys, tmp_path):
    # the infeasible example with a policy under certification (the expert's gains 1 % off),
    # so that validate does not train one first (minutes): what is tested is the exit status
    text = example_spec("infeasible_2d").read_text()
    text = text.replace(
        'expert = ["-x1 - 2*x2"]', 'expert = ["-x1 - 2*x2"]\nlearned = ["-1.01*x1 - 2*x2"]'
    )
    text += "\n[tasil]\ntrajectories = 4\nsamples = 20\n"
    spec = tmp_path / "infeasible_learned.toml"
    spec.write_text(text)
    code, out, _ = run_cli(
        capsys,
        "validate",
        str(spec),
        "--quick",
        "--json",
        "--trajectories",
        "50",
        "--seed",
        "0",
    )
    rep = json.loads(out)
    assert rep["status"] in (HOLDS, VIOLATED, NOTHING_CHECKED)
    assert rep["holds"] is (rep["status"] == HOLDS)
    assert code == (0 if rep["status"] == HOLDS else 1)
    # infeasible L1-DRAC: no L1 check may count
    for c in rep["checks"]:
        if c["name"] in ("uncertainty_gap", "uncertainty_L2_norm", "tail_frequency", "total_tail"):
            assert c["status"] == NOT_CHECKED
    # the policy radius needs no L1-DRAC design: it is checked, against a finite radius
    radius = next(c for c in rep["checks"] if c["name"] == "policy_radius")
    assert radius["status"] in (HOLDS, VIOLATED) and radius["bound"] is not None


def test_every_check_reports_its_ratio_at_confidence():
    """Issue 25: next to bound / empirical, bound / (the statistic's upper confidence bound), the
    tightness one can claim at the check's level; None when either is missing."""
    c = EmpiricalCheck(
        name="x", kind="radius", what="", bound=8.0, empirical=2.0, confidence_low=1.5,
        confidence_high=4.0, level=0.95, status="holds", reason=None, note="",
    )  # fmt: skip
    d = c.to_dict()
    assert d["ratio"] == 4.0 and d["ratio_at_confidence"] == 2.0
    none = EmpiricalCheck(
        name="y", kind="radius", what="", bound=8.0, empirical=2.0, confidence_low=1.5,
        confidence_high=None, level=0.95, status="holds", reason=None, note="",
    )  # fmt: skip
    assert none.to_dict()["ratio_at_confidence"] is None


# ------------------------------------------------------------------- the mean bound (5.6.1)


def test_mean_gap_is_checked_against_rho_mean_like_with_like():
    """Issue 25: max_t E||X_t - x'_t|| against rho_mean = min_q rho(q) (docs/math/l1drac.md
    5.6.1), beside the L_2p check against rho_L1(p): same statistic as uncertainty_gap, the
    smaller bound, its own ratio; a rho_mean below the mean's lower confidence bound is
    violated while rho_L1 still holds."""
    unc = _small(1, 0.05)  # E r_t = 0.05 at every t > 0
    res = _result(_small(0, 0.05), unc, _small(2, 0.1))
    rho_mean = 0.2  # < RHO_L1 = 0.5, as min_q rho(q) <= rho(p)
    checks = by_name(checks_from_result(res, **_certified(rho_mean=rho_mean)))
    mean, gap = checks["uncertainty_gap_rho_mean"], checks["uncertainty_gap"]
    assert mean.kind == "expectation" and mean.status == HOLDS
    assert mean.bound == rho_mean and gap.bound == RHO_L1
    # the same statistic and confidence bounds, a different bound
    assert mean.empirical == gap.empirical
    assert (mean.confidence_low, mean.confidence_high) == (gap.confidence_low, gap.confidence_high)
    assert mean.ratio == pytest.approx(rho_mean / gap.empirical, rel=FLOAT_ATOL)
    assert mean.ratio_at_confidence == pytest.approx(rho_mean / gap.confidence_high, rel=FLOAT_ATOL)
    assert checks["uncertainty_L2_norm"].status == HOLDS  # the L_2p check is kept
    # a too-small bound: below the mean's one-sided lower confidence bound
    small = 0.5 * gap.confidence_low
    checks = by_name(checks_from_result(res, **_certified(rho_mean=small)))
    assert checks["uncertainty_gap_rho_mean"].status == VIOLATED
    assert checks["uncertainty_gap"].status == HOLDS  # rho_L1 itself is not violated
    assert overall_status(list(checks.values())) == VIOLATED
    # no rho_mean in the certificate: not checked, with the reason
    c = by_name(checks_from_result(res, **_certified()))["uncertainty_gap_rho_mean"]
    assert c.status == NOT_CHECKED and "no bound certified" in c.reason
    # away from the certified parameters it never counts
    c = by_name(
        checks_from_result(
            res, **_certified(rho_mean=small), at_certified_l1=False, not_certified_why="x"
        )
    )["uncertainty_gap_rho_mean"]
    assert c.status == NOT_CHECKED and "not at certified parameters" in c.reason


def test_certified_rho_mean_reads_the_decomposition_in_x():
    """rho_mean (``Certificate.claims().rho_mean``) from ``l1drac.decomposition.rho_mean.value``,
    mapped to x like rho_L1 (factor ||Theta^{-1}||_2, rounded up); None without a feasible design
    or a decomposition."""
    from drip_cert.bounds.certificate import Claims

    design = SimpleNamespace(kappa=None, p=1, delta=None, omega=1.0, lambda_s=1.0, Ts=1e-3)

    def stub(l1, coordinates=None):
        return SimpleNamespace(
            l1=l1,
            coordinates=coordinates,
            rho_tasil=None,
            tasil=None,
            rho_l1=None,
            rho_sde=None,
            rho=None,
        )

    def l1_with(decomposition, feasible=True):
        return SimpleNamespace(feasible=feasible, design=design, decomposition=decomposition)

    mean = SimpleNamespace(value=0.25)
    l1 = l1_with(SimpleNamespace(rho_mean=mean))
    assert Claims.of(stub(l1)).rho_mean == 0.25
    coords = SimpleNamespace(gap_in_x=lambda v: 3.0 * v)
    assert Claims.of(stub(l1, coords)).rho_mean == 0.75
    for cert in (
        stub(None),
        stub(l1_with(SimpleNamespace(rho_mean=mean), feasible=False)),
        stub(l1_with(None)),
        stub(l1_with(SimpleNamespace(rho_mean=None))),
    ):
        assert Claims.of(cert).rho_mean is None


def test_record_stride_divides_the_steps_and_bounds_the_records():
    """The recorded grid ends at T (the stride divides the steps), keeps about 200 records and
    never more than 1000: 285720 steps (2^3 3 5 2381) gave 28572 records (3.5 GiB of states at
    2000 paths, a SpecError) with the former "largest divisor below 200 records" search."""
    from drip_cert.validate.run import RECORDS_MOST, record_stride

    for n, want in ((285720, 2381), (10000, 50), (997, 1), (1, 1)):
        d = record_stride(n)
        assert n % d == 0 and n // d <= RECORDS_MOST and d == want, (n, d)


def test_a_prime_step_count_drops_a_few_periods_for_a_recording_grid():
    """1009 periods of one step each (a prime above 1000) recorded only t = T; 1008 periods
    (2^4 3^2 7) keep 252 records. Counts that already record enough are kept; at most 1 % of
    the periods is dropped."""
    from drip_cert.validate.run import (
        PERIODS_DROP_MOST,
        RECORDS_LEAST,
        record_stride,
        recorded_periods,
    )

    assert record_stride(1009) == 1009  # the old grid: one record
    for periods, k in ((1009, 1), (100003, 1), (1009, 3), (500, 1), (997, 1), (7, 1)):
        m = recorded_periods(periods, k)
        n = m * k
        assert periods * (1 - PERIODS_DROP_MOST) <= m <= periods
        assert n // record_stride(n) >= min(RECORDS_LEAST, periods * k), (periods, k, m)
    assert recorded_periods(1009, 1) == 1008
    assert recorded_periods(500, 1) == 500 and recorded_periods(1000, 3) == 1000
    assert recorded_periods(1009, 3) == 1008  # 3027 = 3 x 1009 records 3 times at most
