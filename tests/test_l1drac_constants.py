"""Appendix A of L1-DRAC (arXiv:2509.04619): constants, maps, their limits and the TOML reader.

Ties to the paper: Proposition A.1 (A.20) monotonicity in xi, (A.21) limits as Ts -> 0,
Remark 3.1 (Gamma_r orders), Remark 3.2 (bandwidth orders), Sec. 4.3 (rate in Ts), and the
expm1 accuracy of (A.13)-(A.15) at Ts = 1e-14 against mpmath.
"""

from __future__ import annotations

import dataclasses
import math
import re
from pathlib import Path

import mpmath
import numpy as np
import pytest

from drip_cert.bounds.l1drac import appendix as A
from drip_cert.bounds.l1drac import sides as S
from drip_cert.bounds.l1drac.constants import CONSTANT_NAMES, L1Constants
from drip_cert.bounds.l1drac.toml import design_l1_report, load_l1_constants
from drip_cert.errors import AssumptionViolation, SpecError
from tests.helpers import (
    DOUBLE_INTEGRATOR_CONSTANTS,
    REL_CLOSED_FORM,
    di_constants,
    random_constants,
)

#: expm1-based float64 vs 50-digit mpmath at Ts = 1e-14: a handful of roundings, no cancellation
REL_MPMATH = 1e-12
#: a non-decreasing map may round down by a few ulps between neighbouring grid points
MONO_SLACK = 1e-12
#: log-log slope fits over four decades: the next-order terms shift the slope by < 0.02
SLOPE_TOL = 0.02
#: a map in O(Ts^{1/4}) falls by 1e-2 per 1e-8 step in Ts (observed 0.99999e-2); the 1e-4
#: relative slack is for the higher-order terms, far below a slower rate (1e-8 -> 1e-1 at O(Ts^1/8))
QUARTER_RATE_FALL = 1.0001e-2
#: from Ts = 1e-4 to 1e-28 a map in O(Ts^{1/4}) falls by 1e-6 (observed 8.9e-7): 1e-5 leaves
#: a factor 10
VANISH_RATIO = 1e-5
#: lets a map that is exactly 0 at both ends pass the strict "<" (no real value is this small)
ZERO_GUARD = 1e-300
#: (A.22c) at Ts = 1e-28: gamma_2 - 1 = O(omega Ts) = 1e-25 (it rounds to exactly 1), plus rounding
GAMMA2_LIMIT_REL = 1e-20 + REL_CLOSED_FORM
#: (A.22a) at Ts = 1e-28: Ts gamma_1 ~ sqrt(2 Ts) = 1.4e-14
TS_GAMMA1_LIMIT = 1e-13
#: Remark 3.1 at rho_r = 1e12: Gamma_r / rho^{3/2} is within O(rho^{-1/2}) of its limit
#: (observed 1.5e-5)
RHO_LIMIT_REL = 1e-4
#: Remark 3.1 at omega = 1e12: omega / |2 lambda - omega| - 1 = 2 lambda / omega ~ 4e-11
OMEGA_LIMIT_REL = 1e-10


# ------------------------------------------------------------------ validation


def test_example_file_loads_with_all_names() -> None:
    c, req = load_l1_constants(DOUBLE_INTEGRATOR_CONSTANTS)
    assert set(c.to_dict()) == set(CONSTANT_NAMES)
    assert c.lam == 10.0 and c.to_dict()["lambda"] == 10.0
    assert req.p == 1 and req.lambda_s == 100.0 and req.omega == 1000.0


@pytest.mark.parametrize(
    ("key", "value", "words"),
    [
        ("Delta_g", -1.0, "negative"),
        ("Delta_g", float("nan"), "not finite"),
        ("Delta_g", float("inf"), "not finite"),
        ("Delta_g", True, "not a real number"),
        ("Delta_g", "1.0", "not a real number"),
        ("lambda", 0.0, "> 0"),
        ("eps_r", 0.0, "> 0"),
        ("p_star", 0, ">= 1"),
        ("p_star", 1.5, "not an integer"),
        ("m", 0, ">= 1"),
        ("lip_f", 1, "not a boolean"),
    ],
)
def test_bad_constant_names_field_and_value(key: str, value: object, words: str) -> None:
    d = di_constants().to_dict()
    d[key] = value
    with pytest.raises(SpecError) as e:
        L1Constants.from_mapping(d)
    assert key in str(e.value) and words in str(e.value)
    assert e.value.field is not None and key in e.value.field


def test_unknown_and_missing_keys() -> None:
    d = di_constants().to_dict()
    with pytest.raises(SpecError, match="unknown"):
        L1Constants.from_mapping({**d, "Delta_gg": 1.0})
    del d["L_f"]
    with pytest.raises(SpecError, match="missing.*L_f"):
        L1Constants.from_mapping(d)


def test_assumption_7_violation_gives_the_numbers() -> None:
    d = di_constants().to_dict()
    d.update(Delta_g_perp=2.0, Delta_mu_perp=3.0, L_mu_perp=6.0)  # 2 * 6 = 12 > lambda = 10
    with pytest.raises(AssumptionViolation) as e:
        L1Constants.from_mapping(d)
    assert "Assumption 7" in str(e.value) and "12.0" in str(e.value) and "10.0" in str(e.value)


def test_toml_errors_name_file_and_field(tmp_path: Path) -> None:
    text = DOUBLE_INTEGRATOR_CONSTANTS.read_text()
    cases = {
        "Delta_g = 1.0": ("Delta_g = -1.0", "Delta_g"),
        "lambda = 10.0": ("lambda = nan", "lambda"),
        "lip_f = true": ("lip_f = 1", "lip_f"),
        "p = 1": ("p = 9", "p_star"),
        "lambda_s = 100.0": ("", "lambda_s"),
        "omega = 1000.0": ("omega = 20.0", "2*lambda"),
        "[design]": ("[design]\nfoo = 1", "foo"),
        "delta = 0.1353352832366127": ("delta = 1.5", "delta"),
    }
    for i, (old, (new, word)) in enumerate(cases.items()):
        f = tmp_path / f"c{i}.toml"
        f.write_text(re.sub("^" + re.escape(old), new, text, count=1, flags=re.M))
        with pytest.raises(SpecError) as e:
            load_l1_constants(f)
        assert str(f) in str(e.value) and word in str(e.value), (old, str(e.value))
    with pytest.raises(SpecError, match="cannot read"):
        load_l1_constants(tmp_path / "absent.toml")


def test_report_is_json_ready() -> None:
    import json

    r = design_l1_report(DOUBLE_INTEGRATOR_CONSTANTS)
    s = json.dumps(r)
    back = json.loads(s)
    for k in ("feasible", "p", "omega", "lambda_s", "Ts", "rho_r", "rho_a", "rho", "kappa"):
        assert k in back
    assert [c["eq"] for c in back["conditions"]] == ["16a", "16b", "21a", "21b", "24"]
    assert back["feasible"] is True
    assert back["verified"] is True and all(c["verified"] for c in back["conditions"])
    assert back["verification"]["min_margin_lo"] > 0.0


# ------------------------------------------------------------------ closed forms


def test_frak_p_closed_forms() -> None:
    # (A.1a): p(1) = 0, p'(1)^2 = 1/2, p''(1)^2 = 3; p(2)^2 = 1, p'(2)^2 = 3, p''(2)^2 = 14
    assert A.frak_p(1) == 0.0
    assert A.frak_p_prime(1) ** 2 == pytest.approx(0.5, rel=REL_CLOSED_FORM)
    assert A.frak_p_dprime(1) ** 2 == pytest.approx(3.0, rel=REL_CLOSED_FORM)
    assert A.frak_p(2) ** 2 == pytest.approx(1.0, rel=REL_CLOSED_FORM)
    assert A.frak_p_prime(2) ** 2 == pytest.approx(3.0, rel=REL_CLOSED_FORM)
    assert A.frak_p_dprime(2) ** 2 == pytest.approx(14.0, rel=REL_CLOSED_FORM)


def test_gamma_r_double_integrator_by_hand() -> None:
    """(18b) at p = 1 on the example constants, written out by hand from (A.3)-(A.7).

    Delta_p = 0, Delta_sigma = Delta_sigma_par = 1, Delta_g = m = 1, lambda = 10, p'^2 = 1/2,
    p(1) = 0, no unmatched mu: circ1 = 1, circ4 = 0.15, ocirc1 = 2, ocirc4 = 0.3, odot1 = 1,
    odot8 = 0.15, and every other coefficient of (18b) is 0.
    """
    c = di_constants()
    rc = A.reference_constants(c, 1)
    for omega in (50.0, 1e3, 1e6):
        w = omega / abs(20.0 - omega)
        for rho in (0.5, 2.0, 7.0):
            r = rho + 5.0
            by_hand = 0.05 + 0.15 * w + (0.1 + 0.3 * w) * math.sqrt(r) + (0.05 + 0.15 * w) * r
            assert S.gamma_r(rho, omega, rc) == pytest.approx(by_hand, rel=REL_CLOSED_FORM)


def test_odot4_uses_hat_delta_5() -> None:
    """(A.10b) typo: the undefined hat-Delta_6 is hat-Delta_5 = sqrt(m) Delta_g (L_p + L_sigma)."""
    c = di_constants()
    tc = A.true_constants(c, 2)
    lpar = c.L_p_par + c.L_sigma_par
    expect = lpar * (math.sqrt(c.m) * c.Delta_g * (c.L_p + c.L_sigma) + 3.0 * lpar) / c.lam
    assert tc.odot_4 == pytest.approx(expect, rel=REL_CLOSED_FORM)


# ------------------------------------------------------------------ expm1 accuracy


def _mp_sampling(c: L1Constants, p: int, omega: float, Ts: float, ls: float) -> dict:
    """(A.13), (A.15a) in 50-digit arithmetic, straight from the printed formulas."""
    mp = mpmath.mp
    with mpmath.workdps(50):
        w, T, s, lam = mp.mpf(omega), mp.mpf(Ts), mp.mpf(ls), mp.mpf(c.lam)
        e = mp.e
        g1 = mp.sqrt(s * (e ** (s * T) + 1) / (e ** (s * T) - 1))
        g1p = (1 - e ** (-2 * lam * T)) * (1 - e ** (-w * T))
        R = s / w * (e ** (w * T) - 1) / (e ** (s * T) - 1)
        g2 = max(e ** ((w - s) * T), 1) * R
        g2p = max(abs(1 - e ** ((w - s) * T) * R), abs(1 - R))
        fp1 = mp.sqrt(mp.mpf(p) * (2 * p - 1) / 2)
        fp2 = mp.sqrt(mp.mpf(p) * (4 * p - 1))
        gpp = fp1 * g2p + fp2 * mp.sqrt(1 - e ** (-2 * w * T)) * (2 + g2)
        gt = c.Delta_g * c.Delta_Theta * e ** (-s * T)
        ps = c.Delta_p + c.Delta_sigma
        b1 = (
            2 * T * (c.Delta_f + (1 + gt) * c.Delta_mu + fp1 * gt * g1 * ps)
            + 2 * mp.sqrt(2) * mp.sqrt(T) * fp1 * ps
        )
        return {
            "gamma_1": g1,
            "gamma_1p": g1p,
            "gamma_2": g2,
            "gamma_2p": g2p,
            "gamma_pp": gpp,
            "bar_1": b1,
            "expm1_omega_Ts": e ** (w * T) - 1,
        }


@pytest.mark.parametrize("Ts", [1e-14, 1e-9, 1e-4])
@pytest.mark.parametrize(("omega", "ls"), [(1e3, 100.0), (50.0, 300.0)])
def test_expm1_accuracy_against_mpmath(Ts: float, omega: float, ls: float) -> None:
    c = di_constants()
    s = A.sampling_constants(c, 2, omega, Ts, ls)
    ref = _mp_sampling(c, 2, omega, Ts, ls)
    for k, v in ref.items():
        assert getattr(s, k) == pytest.approx(float(v), rel=REL_MPMATH), k


def test_naive_exp_minus_one_would_fail_at_1e_14() -> None:
    """Why expm1: exp(x) - 1 at x = 1e-12 has relative error ~1e-4, far above REL_MPMATH."""
    x = 1e3 * 1e-15
    naive = (math.exp(x) - 1.0) / x
    assert abs(naive - 1.0) > 1e3 * REL_MPMATH
    assert abs(math.expm1(x) / x - 1.0) < REL_MPMATH


# ------------------------------------------------------------------ Proposition A.1


def _maps(s: A.SamplingConstants, c: L1Constants):
    return {
        "Upsilon'_1": lambda x: A.upsilon1_prime(x, s),
        "Upsilon'_2": lambda x: A.upsilon2_prime(x, s),
        "Upsilon'_3": lambda x: A.upsilon3_prime(x, s),
        "tilde Upsilon^-": lambda x: A.upsilon_minus_tilde(x, s),
        "Upsilon^-": lambda x: A.upsilon_minus(x, s),
        "ring Upsilon": lambda x: A.upsilon_ring(x, c, s.p, s.omega),
    }


@pytest.mark.parametrize("seed", [0, 1, 2])
def test_prop_A1_maps_non_decreasing_in_xi(seed: int) -> None:
    """(A.20): every map xi -> Upsilon(xi) is non-decreasing, on a grid and at random xi."""
    rng = np.random.default_rng(seed)
    c = random_constants(rng)
    for _ in range(4):
        p = int(rng.integers(1, 9))
        omega = float(10 ** rng.uniform(-1, 6))
        Ts = float(10 ** rng.uniform(-12, -1))
        ls = float(10 ** rng.uniform(-1, 4))
        if max(omega, ls) * Ts > 300:
            continue
        s = A.sampling_constants(c, p, omega, Ts, ls)
        grid = np.concatenate([[0.0], np.logspace(-6, 6, 61), np.sort(rng.uniform(0, 50, 40))])
        grid.sort()
        for name, f in _maps(s, c).items():
            v = np.array([f(float(x)) for x in grid])
            assert np.all(np.diff(v) >= -MONO_SLACK * np.abs(v[1:])), name
            assert np.all(v >= 0.0), name


# ------------------------------------------------------------------ (A.21)


@pytest.mark.parametrize("seed", [3, 4])
def test_A21_maps_vanish_as_Ts_to_zero(seed: int) -> None:
    rng = np.random.default_rng(seed)
    c = random_constants(rng)
    xi = 7.0
    vals = []
    for Ts in (1e-4, 1e-12, 1e-20, 1e-28):
        s = A.sampling_constants(c, 3, 1e3, Ts, 50.0)
        m = _maps(s, c)
        vals.append([m[k](xi) for k in m if k != "ring Upsilon"])
    vals = np.array(vals)
    # each map falls by at least the T^{1/4} rate: 1e-8 in Ts -> >= 1e-2 in value
    assert np.all(vals[1:] <= vals[:-1] * QUARTER_RATE_FALL)
    assert np.all(vals[-1] < VANISH_RATIO * np.maximum(vals[0], ZERO_GUARD) + ZERO_GUARD)
    # (A.22c): gamma_2 -> 1 and (A.22a): Ts gamma_1 -> 0
    s = A.sampling_constants(c, 3, 1e3, 1e-28, 50.0)
    assert s.gamma_2 == pytest.approx(1.0, rel=GAMMA2_LIMIT_REL)
    assert 1e-28 * s.gamma_1 < TS_GAMMA1_LIMIT


# ------------------------------------------------------------------ Remarks 3.1 and 3.2


def test_remark_3_1_gamma_r_orders() -> None:
    """Gamma_r in O(rho_r^{3/2}) (the limit of Gamma_r / rho^{3/2} is Delta_otimes1/(2 sqrt lambda))
    and O(1) in omega (the limit is (18b) with omega/|2 lambda - omega| -> 1)."""
    rng = np.random.default_rng(5)
    c = random_constants(rng)
    rc = A.reference_constants(c, 3)
    lim = rc.otimes_1 / (2 * math.sqrt(c.lam))
    assert lim > 0
    ratios = [S.gamma_r(r, 1e3, rc) / r**1.5 for r in (1e4, 1e8, 1e12)]
    assert abs(ratios[-1] / lim - 1) < RHO_LIMIT_REL
    assert abs(ratios[0] - lim) > abs(ratios[1] - lim) > abs(ratios[2] - lim)
    # O(1) in omega: bounded and convergent
    g = [S.gamma_r(2.0, w, rc) for w in (1e4, 1e8, 1e12)]
    r = 2.0 + rc.Delta_star  # (18b) at rho_r = 2 with omega / |2 lambda - omega| = 1:
    g_inf = (
        rc.circ_1 / (2 * c.lam)
        + rc.circ_4
        + (rc.ocirc_1 / (2 * c.lam) + rc.ocirc_4) * math.sqrt(r)
        + (rc.odot_1 / (2 * c.lam) + rc.odot_8) * r
        + (
            rc.odot_2 / (2 * c.lam)
            + rc.odot_3 / (2 * math.sqrt(c.lam))
            + rc.oast_1 * rc.Delta_star / (2 * c.lam)
        )
        * 2.0
        + rc.otimes_1 / (2 * math.sqrt(c.lam)) * r**1.5
    )
    assert abs(g[2] / g_inf - 1) < OMEGA_LIMIT_REL < abs(g[0] / g_inf - 1)


def _slope(xs, ys) -> float:
    return float(np.polyfit(np.log(xs), np.log(ys), 1)[0])


def test_remark_3_2_bandwidth_orders() -> None:
    """Theta_{r,a}/|2 lambda - omega| in O(1/sqrt(omega)); O(1/omega) without diffusion (4.3)."""
    c = di_constants()
    ws = np.logspace(8, 12, 5)
    rc, tc = A.reference_constants(c, 2), A.true_constants(c, 2)
    th_r = [S.theta_r(2.0, w, rc) / abs(2 * c.lam - w) for w in ws]
    th_a = [S.theta_a(1.0, 2.0, w, tc, c.Delta_star) / abs(2 * c.lam - w) for w in ws]
    assert _slope(ws, th_r) == pytest.approx(-0.5, abs=SLOPE_TOL)
    assert _slope(ws, th_a) == pytest.approx(-0.5, abs=SLOPE_TOL)
    nodiff = dataclasses.replace(
        c, Delta_sigma=0.0, Delta_sigma_par=0.0, L_sigma=0.0, L_sigma_par=0.0
    )
    rc0, tc0 = A.reference_constants(nodiff, 2), A.true_constants(nodiff, 2)
    th_r0 = [S.theta_r(2.0, w, rc0) / abs(2 * c.lam - w) for w in ws]
    th_a0 = [S.theta_a(1.0, 2.0, w, tc0, c.Delta_star) / abs(2 * c.lam - w) for w in ws]
    assert _slope(ws, th_r0) == pytest.approx(-1.0, abs=SLOPE_TOL)
    assert _slope(ws, th_a0) == pytest.approx(-1.0, abs=SLOPE_TOL)


# ------------------------------------------------------------------ Sec. 4.3: rate in Ts


def _upsilon_slope(c: L1Constants) -> float:
    Ts = np.logspace(-16, -12, 9)
    v = [
        S.upsilon_sum(1.0 + 2.0 + c.Delta_star, 1.0, A.sampling_constants(c, 1, 1e3, T, 100.0))
        for T in Ts
    ]
    return _slope(Ts, v)


def test_rate_in_Ts_quarter_with_hoelder_diffusion() -> None:
    """FINDING: with nonzero diffusion Hoelder constants sum Upsilon ~ Ts^{1/4}, not sqrt(Ts).

    Sec. 4.3 states O(sqrt(Ts)); Delta_sigma_{1,2} (A.17) carry bar-Delta_{1,2}^{1/2} ~ Ts^{1/4}.
    With those constants zero the rate is sqrt(Ts); without diffusion it is Ts (as stated).
    """
    c = di_constants()
    assert _upsilon_slope(c) == pytest.approx(0.25, abs=SLOPE_TOL)
    c0 = dataclasses.replace(c, L_sigma=0.0, L_sigma_par=0.0)
    assert _upsilon_slope(c0) == pytest.approx(0.5, abs=SLOPE_TOL)
    c1 = dataclasses.replace(c0, Delta_sigma=0.0, Delta_sigma_par=0.0)
    assert _upsilon_slope(c1) == pytest.approx(1.0, abs=SLOPE_TOL)
