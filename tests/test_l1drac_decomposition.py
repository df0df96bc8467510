"""rho_L1 term by term (docs/math/l1drac.md section 5.5): the terms add up to the binding
condition's left side, match the designer's own sides, and reach the JSON, text and figure."""

from __future__ import annotations

import math

import pytest

from drip_cert.bounds.l1drac.appendix import reference_constants, sampling_constants
from drip_cert.bounds.l1drac.decomposition import decompose
from drip_cert.bounds.l1drac.designer import design
from drip_cert.bounds.l1drac.sides import gamma_r, upsilon_sum
from drip_cert.bounds.l1drac.toml import design_l1_report, load_l1_constants
from drip_cert.figures_l1 import l1_terms_figure
from drip_cert.report import l1_design_text
from tests.helpers import ROOT

CONSTANTS = ROOT / "examples" / "l1drac_constants" / "paper_4d_expert.toml"
#: float64 sums of ~10 terms of magnitudes up to 1e9: a few ulps of the largest, relative
SUM_RTOL = 1e-9
#: the designer backs radii off their roots by at most 1e-3 (backoff.py): the room left in a
#: binding condition is at most ~2e-3 of (1 - k) rho^2 (twice: rho^2)
ROOM_MAX = 2.1e-3


@pytest.fixture(scope="module")
def designed():
    c, req = load_l1_constants(CONSTANTS)
    d = design(c, req)
    assert d.feasible
    return c, d, decompose(c, d)


def test_terms_add_up_to_the_binding_left_side(designed):
    _, d, dec = designed
    assert dec is not None and dec.rho == d.rho
    for part in (dec.rho_r, dec.rho_a):
        assert -SUM_RTOL * part.lhs <= part.room <= ROOM_MAX * part.lhs
        assert math.isclose(sum(t.share for t in part.terms), 1.0, abs_tol=ROOM_MAX)
    assert dec.rho_Ts0 is not None and dec.rho_Ts0 < d.rho  # the T_s -> 0 end of the front


def test_terms_are_the_designers_own_sides(designed):
    c, d, dec = designed
    rc = reference_constants(c, d.p)
    gam = sum(t.value for t in dec.rho_r.terms if t.condition == "16a") - c.alpha**2 - c.eps_r
    assert math.isclose(gam, gamma_r(d.rho_r, d.omega, rc), rel_tol=SUM_RTOL)
    s = sampling_constants(c, d.p, d.omega, d.Ts, d.lambda_s)
    ups = upsilon_sum(d.rho_a + d.rho_r + c.Delta_star, d.rho_a, s)
    assert math.isclose(dec.sampling_share * dec.rho_a.lhs, ups, rel_tol=SUM_RTOL)
    # the binding term is the largest of the larger radius's terms
    b = dec.binding()
    assert b.value == max(t.value for t in dec.rho_a.terms)


def test_decomposition_reaches_json_text_and_figure(tmp_path):
    rep = design_l1_report(CONSTANTS)
    dec = rep["decomposition"]
    assert (
        dec["binding"]["name"]
        and dec["rho_a"]["terms"][0]["value"] >= dec["rho_a"]["terms"][-1]["value"]
    )
    text = l1_design_text(rep)
    assert "rho_L1 term by term" in text and dec["binding"]["name"] in text
    out = l1_terms_figure(rep, tmp_path / "terms.png")
    assert out.stat().st_size > 0
    # no design: the figure says so instead of failing
    assert l1_terms_figure({"feasible": False}, tmp_path / "none.png").stat().st_size > 0
