"""``drip-cert diff``: each rule fires on a constructed change and not on an identical pair; exit
status 1 on a regression, 0 otherwise, 2 on bad input (a message, never a traceback)."""

from __future__ import annotations

import copy
import json

import pytest

from drip_cert.diff import (
    ATOL,
    DEFAULT_RTOL,
    IMPROVEMENT,
    REGRESSION,
    diff_outputs,
)
from drip_cert.schema import check_output
from tests.helpers import ROOT, run_cli

PLANT = ROOT / "examples" / "regression_ci" / "plant.toml"


@pytest.fixture(scope="module")
def cert():
    """The plant's real certificate (certified: every part, exact or sound constants)."""
    from drip_cert.bounds.certificate import certify
    from drip_cert.numerics.atomic_io import jsonable
    from drip_cert.spec import load_spec

    out = jsonable(certify(load_spec(PLANT)).to_dict())
    assert out["verdict"] == "certified"
    return out


@pytest.fixture(scope="module")
def validation(tmp_path_factory, cert):
    """A real validation report of the plant (100 paths, at the certified parameters)."""
    from drip_cert.workflows import validate_spec

    rep = validate_spec(PLANT, trajectories=100, seed=0)
    out = json.loads(json.dumps(rep.to_dict()))
    assert out["status"] == "holds" and out["at_certified_parameters"]
    return out


def _diff(old, new, rtol=DEFAULT_RTOL):
    return diff_outputs(check_output(old, where="old"), check_output(new, where="new"), rtol=rtol)


def _only(res, rule, effect):
    """The one change of ``res``; it has ``rule`` and ``effect``."""
    assert len(res.changes) == 1, [c.text for c in res.changes]
    c = res.changes[0]
    assert (c.rule, c.effect) == (rule, effect), c
    assert res.exit_status == (1 if effect == REGRESSION else 0)
    return c


def test_identical_outputs_have_no_change(cert, validation):
    for obj in (cert, validation):
        res = _diff(obj, copy.deepcopy(obj))
        assert res.changes == () and res.exit_status == 0


def test_verdict_rule(cert):
    new = copy.deepcopy(cert)
    new["verdict"] = "conditional"
    c = _only(_diff(cert, new), "verdict", REGRESSION)
    assert c.key == "verdict" and c.text == "verdict: certified -> conditional"
    _only(_diff(new, cert), "verdict", IMPROVEMENT)
    new = copy.deepcopy(cert)
    new["parts"]["l1drac"]["verdict"] = "not_certified"
    assert _only(_diff(cert, new), "verdict", REGRESSION).key == "parts.l1drac.verdict"
    del new["parts"]["l1drac"]  # a part no longer computed
    assert "no longer computed" in _only(_diff(cert, new), "verdict", REGRESSION).text


@pytest.mark.parametrize(
    "key, upper", [("rho.rho_total", True), ("delta_iss.gain", True), ("contraction.rate", False)]
)
def test_bound_rule_loosened_tightened_and_within_tolerance(cert, key, upper):
    def scaled(factor):
        new = copy.deepcopy(cert)
        node = new
        *parents, last = key.split(".")
        for p in parents:
            node = node[p]
        node[last] = node[last] * factor
        return new

    step = 10 * DEFAULT_RTOL
    looser, tighter = (1 + step, 1 - step) if upper else (1 - step, 1 + step)
    c = _only(_diff(cert, scaled(looser)), "bound", REGRESSION)
    assert c.key == key and "loosened" in c.text
    assert "tightened" in _only(_diff(cert, scaled(tighter)), "bound", IMPROVEMENT).text
    assert _diff(cert, scaled(1 + DEFAULT_RTOL / 10)).changes == ()  # within the tolerance
    assert _diff(cert, scaled(looser), rtol=2 * step).changes == ()  # --rtol widens it


def test_bound_rule_on_infinite_and_lost_bounds(cert):
    new = copy.deepcopy(cert)
    new["rho"]["rho_tasil"] = "inf"
    assert "loosened" in _only(_diff(cert, new), "bound", REGRESSION).text
    _only(_diff(new, cert), "bound", IMPROVEMENT)
    new["rho"]["rho_tasil"] = None
    assert "no longer computed" in _only(_diff(cert, new), "bound", REGRESSION).text
    zero = copy.deepcopy(cert)
    zero["rho"]["rho_tasil"], new["rho"]["rho_tasil"] = 0.0, ATOL / 10  # rounding, not a change
    assert _diff(zero, new).changes == ()


def test_margin_sign_rule(cert):
    new = copy.deepcopy(cert)
    a = new["assumptions"][1]
    a["margin"], a["status"], a["holds"] = -0.5, "fails", False
    c = _only(_diff(cert, new), "margin_sign", REGRESSION)
    assert c.key == f"assumptions[{a['id']}].margin" and "changed sign" in c.text
    _only(_diff(new, cert), "margin_sign", IMPROVEMENT)
    a["margin"] = None  # NaN: unknown is not satisfied
    _only(_diff(cert, new), "margin_sign", REGRESSION)
    smaller = copy.deepcopy(cert)  # a smaller positive margin is no sign change
    smaller["assumptions"][1]["margin"] = cert["assumptions"][1]["margin"] / 2
    assert _diff(cert, smaller).changes == ()


def test_provenance_rule_follows_the_how_order(cert):
    name = next(n for n, q in cert["constants"].items() if q["how"] == "exact")
    for weaker in ("sound", "given", "estimate"):
        new = copy.deepcopy(cert)
        new["constants"][name]["how"] = weaker
        c = _only(_diff(cert, new), "provenance", REGRESSION)
        assert c.key == f"constants.{name}.how" and "weakened" in c.text
        assert "strengthened" in _only(_diff(new, cert), "provenance", IMPROVEMENT).text
    new = copy.deepcopy(cert)
    new["assumptions"][0]["how"] = "estimate"
    assert _only(_diff(cert, new), "provenance", REGRESSION).key.startswith("assumptions[")


def test_removed_and_added_assumptions(cert):
    new = copy.deepcopy(cert)
    gone = new["assumptions"].pop()
    c = _only(_diff(cert, new), "removed", REGRESSION)
    assert gone["id"] in c.text and "no longer checked" in c.text
    assert _only(_diff(new, cert), "added", "change").effect == "change"  # added, and it holds


def test_validation_rules(validation):
    new = copy.deepcopy(validation)
    new["status"] = "violated"
    _only(_diff(validation, new), "status", REGRESSION)
    new = copy.deepcopy(validation)
    new["at_certified_parameters"] = False
    _only(_diff(validation, new), "parameters", REGRESSION)
    new = copy.deepcopy(validation)
    held = next(c for c in new["checks"] if c["status"] == "holds")
    held["status"] = "violated"
    c = _only(_diff(validation, new), "check", REGRESSION)
    assert c.key == f"checks[{held['name']}].status"
    _only(_diff(new, validation), "check", IMPROVEMENT)
    new = copy.deepcopy(validation)  # the embedded certificate is compared too
    new["certificate"]["verdict"] = "not_certified"
    assert _only(_diff(validation, new), "verdict", REGRESSION).key == "certificate.verdict"


# ------------------------------------------------------------------------------ the CLI
def _write(tmp_path, name, obj):
    p = tmp_path / name
    p.write_text(json.dumps(obj))
    return str(p)


def test_cli_exit_status_and_json(tmp_path, capsys, cert):
    old = _write(tmp_path, "old.json", cert)
    code, out, _ = run_cli(capsys, "diff", old, old)
    assert code == 0 and "no change" in out
    new = copy.deepcopy(cert)
    new["rho"]["rho_l1"] *= 1.5
    new["constants"]["Delta_g"]["how"] = "estimate"
    newp = _write(tmp_path, "new.json", new)
    code, out, _ = run_cli(capsys, "diff", old, newp)
    assert code == 1 and "REGRESSION" in out and "rho_L1 (rho.rho_l1) loosened" in out
    code, out, _ = run_cli(capsys, "diff", old, newp, "--json", "--rtol", "0.6")
    rep = json.loads(out)
    assert code == 1 and rep["rtol"] == 0.6 and rep["counts"]["regression"] == 1  # rho within
    assert [c["rule"] for c in rep["changes"]] == ["provenance"]
    code, out, _ = run_cli(capsys, "diff", newp, old)  # the other way: improvements only
    assert code == 0 and "no regression" in out and "Improvements:" in out


def test_cli_bad_input_exits_2_with_a_message(tmp_path, capsys, cert, validation):
    old = _write(tmp_path, "old.json", cert)
    bad = tmp_path / "bad.json"
    bad.write_text("[1, 2")
    code, out, err = run_cli(capsys, "diff", old, str(bad))
    assert code == 2 and out == "" and f"{bad}: not valid JSON" in err and "Traceback" not in err
    val = _write(tmp_path, "val.json", validation)
    code, _, err = run_cli(capsys, "diff", old, val)
    assert code == 2 and "is a certificate and" in err and "a validation" in err
    v2 = _write(tmp_path, "v2.json", dict(cert, schema_version=2))
    code, _, err = run_cli(capsys, "diff", v2, old)
    assert code == 2 and "v2.json: schema_version: certificate layout version 2" in err
    with pytest.raises(SystemExit) as exc:  # argparse: usage error
        run_cli(capsys, "diff", old, old, "--rtol", "-1")
    assert exc.value.code == 2
