"""The proof checks: the quick suite passes (or reports documented errata), and checks can fail."""

from __future__ import annotations

import json
import re

import pytest

from proofs_check import Verdict, run_checks
from proofs_check.__main__ import main
from proofs_check._core import Context, make_rng
from tests.helpers import ROOT, by_name

ERRATA = ROOT / "proofs_check" / "ERRATA.md"


@pytest.fixture(scope="module")
def quick_results():
    return run_checks(quick=True, seed=0)


def _ctx(name: str) -> Context:
    return Context(rng=make_rng(0, name), quick=True, seed=0)


def test_quick_suite_passes_or_documents_errata(quick_results):
    assert len(quick_results) >= 25
    failed = [(r.name, r.detail) for r in quick_results if r.verdict is Verdict.FAIL]
    assert not failed, failed
    headings = set(re.findall(r"^## (E\d+):", ERRATA.read_text(), flags=re.M))
    for r in quick_results:
        if r.verdict is Verdict.ERRATUM:
            assert r.erratum in headings, (r.name, r.erratum)


def test_expected_errata_are_found(quick_results):
    results = by_name(quick_results)
    for name in (
        "iss.perturbed_ode_statement",
        "tasil.rho_rate_delta",
        "l1drac.Ts_rate",
        "example.uncertainty_constants",
        "example.expert_contraction",
    ):
        assert results[name].verdict is Verdict.ERRATUM, name
    for name in (
        "iss.young_step",
        "iss.bound_random_systems",
        "iss.tight_never_looser",
        "decomposition.tig",
        "l1drac.markov_step",
        "l1drac.propA1_monotone",
    ):
        assert results[name].verdict is Verdict.PASS, name


def test_wrong_young_constant_fails():
    from proofs_check.delta_iss import check_young

    assert check_young(_ctx("iss.young_step")).verdict is Verdict.PASS
    assert check_young(_ctx("iss.young_step"), young_factor=0.9).verdict is Verdict.FAIL


def test_best_order_holds_and_fails_on_a_smaller_bound_or_another_controller():
    from proofs_check.l1drac_probability import check_best_order

    name = "l1drac.best_order"
    assert check_best_order(_ctx(name)).verdict is Verdict.PASS
    assert check_best_order(_ctx(name), bound_factor=0.99).verdict is Verdict.FAIL
    assert check_best_order(_ctx(name), same_controller=False).verdict is Verdict.FAIL


def test_wrong_markov_exponent_fails():
    from proofs_check.l1drac_probability import check_markov

    assert check_markov(_ctx("l1drac.markov_step"), p_factor=0.5).verdict is Verdict.FAIL


def test_overclaimed_contraction_rate_fails():
    from proofs_check.delta_iss import check_bound_random

    res = check_bound_random(_ctx("iss.bound_random_systems"), rate_factor=1.3)
    assert res.verdict is Verdict.FAIL and res.residual > 0


def test_wrong_gap_constant_fails():
    from proofs_check.tasil_gap import check_gap_adversarial

    res = check_gap_adversarial(_ctx("tasil.gap_lemma_adversarial"), sharp_factor=0.95)
    assert res.verdict is Verdict.FAIL


def test_cli_json_and_filter(capsys):
    assert main(["--quick", "--json", "--only", "iss.theta"]) == 0
    out = json.loads(capsys.readouterr().out)
    assert [o["name"] for o in out] == ["iss.theta_range_and_optimum"]
    assert set(out[0]) >= {"name", "label", "verdict", "residual", "detail"}
    assert main(["--quick", "--only", "no-such-check"]) == 2


def test_same_seed_same_numbers():
    a = run_checks(quick=True, seed=3, only="decomposition")
    b = run_checks(quick=True, seed=3, only="decomposition")
    assert [r.residual for r in a] == [r.residual for r in b]


def test_invariant_set_check_fails_on_a_too_small_set():
    from proofs_check.invariance import check_invariant_sets

    ctx = _ctx("invariance.sets_random_systems")
    assert check_invariant_sets(ctx).verdict is Verdict.PASS
    ctx = _ctx("invariance.sets_random_systems")
    res = check_invariant_sets(ctx, radius_factor=0.5)
    assert res.verdict is Verdict.FAIL and res.residual > 0


def test_paper_text_checks_skip_without_the_source(monkeypatch):
    """Without the paper's LaTeX source the textual errata are SKIP (not ERRATUM with NaN)."""
    monkeypatch.setenv("DRIP_PAPER_TEX", "/nonexistent/drip_paper.tex")
    res = run_checks(quick=True, seed=0, only="text.")
    assert res and all(r.verdict is Verdict.SKIP for r in res)
    assert main(["--quick", "--only", "text."]) == 0


def test_coordinate_mapping_check_fails_on_a_wrong_factor():
    """The mapped-back delta-ISS bound holds with drip-cert's factor and fails with 0.99 of it
    (a deliberately wrong mapping)."""
    from proofs_check.coordinates import check_delta_iss_maps_back

    ctx = _ctx("coordinates.delta_iss_maps_back")
    assert check_delta_iss_maps_back(ctx).verdict is Verdict.PASS
    ctx = _ctx("coordinates.delta_iss_maps_back")
    res = check_delta_iss_maps_back(ctx, factor=0.99)
    assert res.verdict is Verdict.FAIL and res.residual > 0


def test_comparison_bound_check_holds_and_fails_on_a_smaller_bound():
    """Proposition 3.7 (the TaSIL comparison route): holds, is attained on the tight instances,
    and fails when the bound is taken 0.99 times too small."""
    from proofs_check.tasil_comparison import check_comparison_bound

    ok = check_comparison_bound(_ctx("tasil.comparison_bound"))
    assert ok.verdict is Verdict.PASS and ok.residual > -1e-6  # attained: the ratio reaches 1
    res = check_comparison_bound(_ctx("tasil.comparison_bound"), factor=0.99)
    assert res.verdict is Verdict.FAIL and res.residual > 0


def test_sde_moment_bound_covers_ou_and_fails_when_smaller():
    """contraction.md Prop. 6.5: the bound covers the OU moments, is attained (q = 1), and fails
    when taken 1 % smaller or without the diffusion (the deterministic bound of 6.4)."""
    from proofs_check.sde_moments import check_ou

    ok = check_ou(_ctx("sde.ou_closed_form"))
    assert ok.verdict is Verdict.PASS and ok.residual > -1e-9  # attained
    for kw in ({"factor": 0.99}, {"ignore_diffusion": True}):
        res = check_ou(_ctx("sde.ou_closed_form"), **kw)
        assert res.verdict is Verdict.FAIL and res.residual > 0, kw


def test_sde_moment_bound_holds_on_a_simulated_nonlinear_sde():
    """Seeded Euler-Maruyama paths of a nonlinear contracting SDE stay below the bound; the bound
    of the ODE (diffusion ignored) is violated."""
    from proofs_check.sde_moments import check_simulated

    assert check_simulated(_ctx("sde.simulated_nonlinear")).verdict is Verdict.PASS
    res = check_simulated(_ctx("sde.simulated_nonlinear"), ignore_diffusion=True)
    assert res.verdict is Verdict.FAIL and res.residual > 0


#: a tight instance attains its bound to the ODE / grid accuracy (docs of proofs_check.tasil_tube)
ATTAINED = 1e-6


@pytest.mark.parametrize(
    "name, fn",
    [
        ("tasil.comparison_finite_horizon", "check_finite_horizon"),
        ("tasil.tube_radius", "check_tube_radius"),
        ("tasil.tube_gap", "check_tube_gap"),
        ("tasil.centred_form", "check_centred_form"),
        ("tasil.box_tube", "check_box_tube"),
    ],
)
def test_tube_checks_hold_attain_and_fail_on_a_smaller_bound(name, fn):
    """docs/math/tasil.md 3.7 (finite horizon), 3.9, 3.10, 3.11: each bound holds, is attained on
    the tight instances, and fails when taken 0.99 times too small."""
    import proofs_check.tasil_tube as tt

    check = getattr(tt, fn)
    ok = check(_ctx(name))
    assert ok.verdict is Verdict.PASS and ok.residual > -ATTAINED, ok.detail
    res = check(_ctx(name), factor=0.99)
    assert res.verdict is Verdict.FAIL and res.residual > 0


def test_difference_route_check_holds_attains_and_fails_on_a_smaller_bound():
    """docs/math/tasil.md 3.12: the local L_Delta of the difference bounds every sampled ratio,
    equals it on the tight quadratic instances, and fails when taken 0.99 times too small."""
    from proofs_check.tasil_difference import check_difference_local

    ok = check_difference_local(_ctx("tasil.difference_local"))
    assert ok.verdict is Verdict.PASS and ok.residual > -ATTAINED, ok.detail
    res = check_difference_local(_ctx("tasil.difference_local"), factor=0.99)
    assert res.verdict is Verdict.FAIL and res.residual > 0


def test_which_box_check_holds_and_fails_on_the_demonstrations_box():
    """docs/math/tasil.md 3.12, "Which box": the hull of the demonstrations and of a set holding
    every expert trajectory, enlarged by R, holds every new expert tube; the demonstrations' box
    alone does not."""
    from proofs_check.tasil_difference import check_which_box

    ok = check_which_box(_ctx("tasil.which_box"))
    assert ok.verdict is Verdict.PASS, ok.detail
    res = check_which_box(_ctx("tasil.which_box"), wrong=True)
    assert res.verdict is Verdict.FAIL and res.residual > 0, res.detail
