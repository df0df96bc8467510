"""The command line: exit statuses, JSON keys other tools read, and error messages."""

from __future__ import annotations

import json

import pytest

from drip_cert.cli import main
from tests.helpers import (
    CLOSED_FORM_TOL,
    DOUBLE_INTEGRATOR_CONSTANTS,
    PAPER_4D_SPEC,
    example_spec,
    run_cli,
    write_spec,
)

PAPER = str(PAPER_4D_SPEC)
# sound interval bounds are rounded outward by a few ulps per operation (observed 1.6e-15 on the
# A7 margin below; 1e-9 is generous)
SOUND_ROUNDING_TOL = 1e-9


def test_check_spec_ok(capsys):
    code, out, _ = run_cli(capsys, "check-spec", PAPER)
    assert code == 0
    assert "paper-4d" in out and "n = 4" in out


def test_check_spec_bad_input_exit_2_no_traceback(tmp_path, capsys):
    p = write_spec(
        tmp_path,
        '[system]\nname = "x"\nstates = ["x1"]\nhorizon = 1.0\n[dynamics]\n'
        'f = ["__import__(\'os\')"]\ng = [["1"]]\n[policy]\nexpert = ["-x1"]\n'
        "[initial]\nsupport = [[0.0, 1.0]]\n",
        "bad.toml",
    )
    code, out, err = run_cli(capsys, "check-spec", str(p))
    assert code == 2
    assert "dynamics.f[0]" in err and str(p) in err
    assert "Traceback" not in err and out == ""


def test_certify_paper_example_json(capsys):
    code, out, _ = run_cli(capsys, "certify", PAPER, "--json")
    assert code == 0
    d = json.loads(out)
    assert d["certified"] is True
    # expert closed loop -(0.05 + 0.25 * 0.2) I = -0.1 I: rate 0.1 exactly, on all of R^4
    assert abs(d["contraction"]["rate"] - 0.1) < CLOSED_FORM_TOL
    assert d["contraction"]["method"] == "exact-linear"
    assert d["contraction"]["how"] == "exact"
    # comparison-lemma gain ||g||_2 / lambda = 0.25 / 0.1; the paper's Delta_g / lambda = 0.5/0.1
    assert abs(d["delta_iss"]["gain"] - 2.5) < CLOSED_FORM_TOL
    assert abs(d["delta_iss"]["gain_paper"] - 5.0) < CLOSED_FORM_TOL
    ids = {a["id"] for a in d["assumptions"]}
    assert {"DRIP-A1", "DRIP-A2", "L1DRAC-A7"} <= ids
    assert all({"id", "holds", "detail"} <= set(a) for a in d["assumptions"])
    assert "metric_rate" in d["contraction"]


def test_certify_infeasible_example_says_why(capsys):
    code, out, _ = run_cli(capsys, "certify", str(example_spec("infeasible_2d")), "--json")
    assert code == 1
    d = json.loads(out)
    assert d["certified"] is False
    a7 = next(a for a in d["assumptions"] if a["id"] == "L1DRAC-A7")
    assert a7["holds"] is False
    # lambda = 1 (exact), Delta_g_perp = 1, L_mu_perp = Lip(1.5 sin(x2)) = 1.5 (sound, tight):
    # the margin is 1 - 1.5 = -0.5 up to the outward rounding of the bound
    assert abs(a7["margin"] + 0.5) < SOUND_ROUNDING_TOL


def test_certify_nonlinear_example_is_sound_on_box(capsys):
    code, out, _ = run_cli(capsys, "certify", str(example_spec("nonlinear_2d")), "--json")
    assert code == 0
    c = json.loads(out)["contraction"]
    assert c["how"] == "sound" and c["method"] == "interval-bnb"
    assert c["region"].startswith("box")
    e = c["expert"]
    # the sound bound on max mu_2 is never below the sampled maximum
    assert e["max_mu_upper"] >= e["max_mu_sampled"]
    assert 0 < c["rate"] < 1


def test_certify_markdown(capsys):
    code, out, _ = run_cli(capsys, "certify", str(example_spec("unmatched_2d")))
    assert code == 0
    assert out.startswith("# drip-cert certificate: unmatched-2d")
    assert "| DRIP-A2 | holds |" in out


def test_design_l1_calculator(capsys):
    code, out, _ = run_cli(capsys, "design-l1", str(DOUBLE_INTEGRATOR_CONSTANTS), "--json")
    assert code == 0
    d = json.loads(out)
    assert d["feasible"] is True
    assert [c["eq"] for c in d["conditions"]] == ["16a", "16b", "21a", "21b", "24"]
    assert all(c["holds"] and c["margin"] >= 0 for c in d["conditions"])
    assert d["rho"] == pytest.approx(d["rho_r"] + d["rho_a"], rel=CLOSED_FORM_TOL)


def test_design_l1_bad_key_exit_2(tmp_path, capsys):
    text = DOUBLE_INTEGRATOR_CONSTANTS.read_text()
    p = tmp_path / "c.toml"
    p.write_text(text.replace("[constants]", "[constants]\nlambdaa = 3.0", 1))
    code, _, err = run_cli(capsys, "design-l1", str(p))
    assert code == 2
    assert "lambdaa" in err


def test_usage_error_exit_2(capsys):
    with pytest.raises(SystemExit) as info:
        main(["no-such-command"])
    assert info.value.code == 2
