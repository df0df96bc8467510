"""Reports that say what to change (issue 27): the coordinates (Theta, P, the factor to x) in the
text report, the other coordinate candidates with their reasons (closest first), the fix for a
number the certificate lacks, the training advice for a held-out gap, and a complete
``design-l1`` file exported from a certificate (``certify --export-l1-constants``)."""

from __future__ import annotations

import tomllib
from types import SimpleNamespace

import numpy as np
import pytest

from drip_cert.bounds.l1drac.toml import design_l1_report
from drip_cert.report import _coordinate_lines, l1_constants_toml
from drip_cert.spec.settings import L1Settings
from tests.helpers import EXAMPLES, run_cli

DOUBLE_INTEGRATOR = EXAMPLES / "l1drac_constants" / "double_integrator.toml"
RHO_RTOL = 1e-12  #: the same constants and inputs give the same design up to float printing


def _coordinates(alternatives: list[dict]) -> dict:
    theta = [[2.0, 0.0], [0.5, 1.0]]
    P = (np.array(theta).T @ np.array(theta)).tolist()
    return {
        "system": "z = Theta x",
        "theta": theta,
        "P": P,
        "factor_to_x": 0.75,
        "cond_theta_at_least": 2.5,
        "source": "the LMI contraction metric of the expert closed loop",
        "alternatives": alternatives,
    }


def test_text_report_prints_theta_p_and_the_factor():
    text = "\n".join(_coordinate_lines(_coordinates([]), "certified"))
    assert "## Coordinates" in text
    assert "Theta =\n  [2, 0]\n  [0.5, 1]" in text
    assert "P = Theta^T Theta =\n  [4.25, 0.5]\n  [0.5, 1]" in text  # Theta^T Theta
    assert "factor_to_x = 0.75" in text
    assert "region is in x" in text


def test_all_candidates_fail_the_closest_one_is_shown_first_with_its_reasons():
    """x fails DRIP-A2 (always, for (q, q') systems) and two z candidates fail something else:
    every candidate's own reasons are shown, the one with the fewest failing checks first."""
    alts = [
        {
            "coordinates": "z = Theta x",
            "verdict": "not_certified",
            "cond_theta": 100.0,
            "rho_tasil_x": None,
            "rho_l1_x": None,
            "failing": 2,
            "verdict_reasons": ["L1DRAC-A7 fails: far", "TaSIL fails: vacuous"],
        },
        {
            "coordinates": "z = Theta x",
            "verdict": "not_certified",
            "cond_theta": 10.0,
            "rho_tasil_x": 0.5,
            "rho_l1_x": 2.0,
            "failing": 1,
            "verdict_reasons": ["L1DRAC-A7 fails: by 0.01"],
        },
    ]
    text = "\n".join(_coordinate_lines({"system": "x", "alternatives": alts}, "not_certified"))
    assert "## Other coordinates tried (closest first)" in text
    assert text.index("cond Theta 10") < text.index("cond Theta 100")
    assert "L1DRAC-A7 fails: by 0.01" in text and "TaSIL fails: vacuous" in text
    # a certified certificate does not list the alternatives it beat
    assert _coordinate_lines({"system": "x", "alternatives": alts}, "certified") == []


def test_no_kappa_certified_says_set_l1drac_delta():
    from drip_cert.validate.checks import _bound_problem, _delta_problem

    assert "set [l1drac] delta" in _bound_problem(None, "kappa")
    assert "set [tasil] delta" in _delta_problem(None, "delta_TaSIL")
    assert _bound_problem(1.0, "kappa") is None  # only a missing number gets the advice


def test_held_out_gap_failure_says_more_demonstrations():
    from drip_cert.workflows import _training_failures

    tp = SimpleNamespace(
        result=SimpleNamespace(stop_reason="steps", best_step=10),
        settings=SimpleNamespace(trajectories=20, steps=500),
    )
    (why,) = _training_failures(tp, np.array([2.0, 3.0]), spec=None, given=1.0)
    assert "more demonstrations (n = 20 now: --trajectories 40)" in why


def _certificate_dict_of(path) -> tuple[dict, L1Settings]:
    """The L1-DRAC part of a certificate as ``to_dict`` writes it, from a design-l1 file."""
    doc = tomllib.loads(path.read_text())
    used = {
        k: (v if isinstance(v, bool) or k in ("p_star", "m") else {"value": v, "how": "given"})
        for k, v in doc["constants"].items()
    }
    for q in used.values():
        if isinstance(q, dict):
            q["source"] = "the example"
    cert = {
        "verdict": "certified",
        "coordinates": {"system": "x"},
        "l1drac": {"constants_used": used, "p": doc["design"]["p"], "lambda_s": None},
    }
    return cert, L1Settings(**doc["design"])


def test_exported_constants_give_the_same_design(tmp_path):
    """Round trip: the design-l1 example -> a certificate's l1drac dict -> the exported file ->
    design-l1 gives the same rho, omega and T_s."""
    cert, settings = _certificate_dict_of(DOUBLE_INTEGRATOR)
    out = tmp_path / "exported.toml"
    out.write_text(l1_constants_toml(cert, settings, source="double_integrator"))
    a = design_l1_report(DOUBLE_INTEGRATOR)
    b = design_l1_report(out)
    assert a["feasible"] == b["feasible"]
    for key in ("rho", "omega", "Ts"):
        assert b[key] == pytest.approx(a[key], rel=RHO_RTOL), key


def test_export_refuses_a_constant_without_a_value():
    from drip_cert.errors import SpecError

    cert, settings = _certificate_dict_of(DOUBLE_INTEGRATOR)
    cert["l1drac"]["constants_used"]["L_mu_hat"]["value"] = None  # NaN in JSON
    with pytest.raises(SpecError, match="L_mu_hat.*give them in the spec's"):
        l1_constants_toml(cert, settings)


@pytest.mark.slow  # certifies the regression_ci plant: 3 s of CPU, more on a busy machine
def test_certify_export_l1_constants_end_to_end(tmp_path, capsys):
    spec = EXAMPLES / "regression_ci" / "plant.toml"
    out = tmp_path / "plant_l1.toml"
    code, _, _ = run_cli(capsys, "certify", str(spec), "--quiet", "--export-l1-constants", str(out))
    assert code == 0
    doc = tomllib.loads(out.read_text())
    assert {"p_star", "m", "lip_f"} <= set(doc["constants"])
    code, cert_json, _ = run_cli(capsys, "certify", str(spec), "--json", "--quiet")
    import json

    l1 = json.loads(cert_json)["l1drac"]
    assert {"p_star", "m", "lip_f"} <= set(l1["constants_used"])
    rep = design_l1_report(out)
    assert rep["rho"] == pytest.approx(l1["rho"], rel=RHO_RTOL)
    assert rep["Ts"] == pytest.approx(l1["Ts"], rel=RHO_RTOL)


def test_candidates_with_an_infinite_radius_are_ranked_not_crashed():
    """A candidate's radius may be ``"inf"`` in the JSON (a TaSIL bound that does not exist):
    the ranking reads it as infinity (it crashed the text report with a TypeError)."""
    from drip_cert.report import _closeness

    finite = {"verdict": "not_certified", "failing": 1, "rho_tasil_x": 1.0, "rho_l1_x": 2.0}
    infinite = {"verdict": "not_certified", "failing": 1, "rho_tasil_x": "inf", "rho_l1_x": None}
    assert _closeness(infinite) == (2, 1, float("inf"))
    assert sorted([infinite, finite], key=_closeness) == [finite, infinite]
