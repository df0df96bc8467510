"""The best moment order at one controller (docs/math/l1drac.md section 5.6): the mean-gap bound
min_q rho(q) and kappa* = min_q rho(q) delta^{-1/(2q)}, every rho(q) a design verified at the
design's own omega, lambda_s, T_s."""

from __future__ import annotations

import dataclasses
import math

import pytest

from drip_cert.bounds.l1drac import DesignRequest, design, kappa_markov, mean_gap_bound
from drip_cert.bounds.l1drac.toml import design_l1_report, load_l1_constants
from drip_cert.report import l1_design_text
from tests.helpers import ROOT

LEARNED = ROOT / "examples" / "l1drac_constants" / "paper_4d_learned.toml"
DOUBLE_INTEGRATOR = ROOT / "examples" / "l1drac_constants" / "double_integrator.toml"
#: the bound at p = 1 against p = 2 on the paper-4d constants (measured 517.6 vs 2312): a gain of
#: at least 4x, the order's factors frak_p(1) = 0, frak_p'(1) < frak_p'(2) removing terms
MEAN_GAIN_MIN = 4.0
#: the same numbers computed twice by the same float64 code: identical up to rounding
SAME_RTOL = 1e-12
#: the designer backs radii off their roots by at most 1e-3 (backoff.py): a re-design at the same
#: controller can differ from a returned design by that much
BACKOFF_RTOL = 1e-3


@pytest.fixture(scope="module")
def paper():
    c, req = load_l1_constants(LEARNED)
    d = design(c, dataclasses.replace(req, Ts=1e-3, objective=None, front=False))
    assert d.feasible and d.p == 2
    return c, d, mean_gap_bound(c, d)


def test_mean_bound_is_rho1_at_the_same_controller(paper):
    c, d, m = paper
    assert (m.omega, m.lambda_s, m.Ts) == (d.omega, d.lambda_s, d.Ts)
    d1 = design(c, DesignRequest(p=1, omega=d.omega, lambda_s=d.lambda_s, Ts=d.Ts, front=False))
    assert d1.feasible and d1.verified and (d1.omega, d1.Ts) == (d.omega, d.Ts)
    assert math.isclose(m.by_p[0], d1.rho, rel_tol=SAME_RTOL)
    assert m.by_p[1] == d.rho and m.p == 1 and m.value == m.by_p[0]
    assert d.rho / m.value >= MEAN_GAIN_MIN


def test_best_order_kappa_is_the_smallest_markov_radius(paper):
    _, d, m = paper
    cands = [kappa_markov(r, q, d.delta) for q, r in enumerate(m.by_p, start=1)]
    assert m.kappa == min(cands) and m.kappa_p == 1
    assert m.kappa < d.kappa  # the design's own kappa is the q = p candidate
    assert math.isclose(cands[-1], d.kappa, rel_tol=SAME_RTOL)


def test_user_fixed_radii_are_replaced_by_the_smallest_at_the_controller(paper):
    c, d, _ = paper
    big = design(
        c,
        DesignRequest(p=2, omega=d.omega, lambda_s=d.lambda_s, Ts=d.Ts, rho_a=5000.0, front=False),
    )
    assert big.feasible and big.rho > 5000.0
    m = mean_gap_bound(c, big)
    assert m is not None and m.by_p[1] < big.rho
    assert math.isclose(m.by_p[1], d.rho, rel_tol=SAME_RTOL)


def test_order_one_design_gains_nothing():
    c, req = load_l1_constants(DOUBLE_INTEGRATOR)
    d = design(c, dataclasses.replace(req, front=False))
    m = mean_gap_bound(c, d)
    assert d.p == 1 and m is not None and len(m.by_p) == 1
    assert m.value <= d.rho and m.kappa <= d.kappa
    assert math.isclose(m.value, d.rho, rel_tol=BACKOFF_RTOL)


def test_infeasible_design_has_no_bound():
    c, req = load_l1_constants(LEARNED)
    d = design(c, dataclasses.replace(req, Ts=1.0, objective=None, front=False))
    assert not d.feasible and mean_gap_bound(c, d) is None


def test_bound_reaches_json_and_text():
    rep = design_l1_report(LEARNED, Ts=1e-3)
    m = rep["decomposition"]["rho_mean"]
    assert m["p"] == 1 and m["value"] < rep["rho"] and m["kappa"] < rep["kappa"]
    text = l1_design_text(rep)
    assert "mean gap max_t E||X_t - X*_t|| <" in text and "best-order kappa(0.05)" in text
