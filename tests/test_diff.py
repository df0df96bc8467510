"""``drip-cert diff``: each rule fires on a constructed change and not on an identical pair; exit
status 1 on a regression, 0 otherwise, 2 on bad input (a message, never a traceback)."""

from __future__ import annotations

import copy
import json

import pytest

from drip_cert.diff import (
    ATOL,
    CHANGE,
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
    new["parts"]["l1drac"]["verdict"] = "not_requested"  # a part no longer computed
    assert "no longer computed" in _only(_diff(cert, new), "verdict", REGRESSION).text
    assert "new" in _only(_diff(new, cert), "verdict", CHANGE).text


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


def test_a_looser_ratio_is_a_regression_even_when_the_check_holds(validation):
    """Issue 25: bound / empirical grown beyond rtol (the check still holds) is a regression,
    shrunk an improvement, and a change within rtol is no change."""
    new = copy.deepcopy(validation)
    held = next(c for c in new["checks"] if c["status"] == "holds" and c.get("ratio"))
    held["ratio"] = held["ratio"] * 2.0
    c = _only(_diff(validation, new), "tightness", REGRESSION)
    assert c.key == f"checks[{held['name']}].ratio" and "looser" in c.text
    _only(_diff(new, validation), "tightness", IMPROVEMENT)
    same = copy.deepcopy(validation)
    held = next(c for c in same["checks"] if c["name"] == held["name"])
    held["ratio"] = held["ratio"] * (1.0 + 1e-12)
    assert not _diff(validation, same).changes


# ------------------------------------------------------- claims, not headline numbers (issue 22)
# The names added with these rules (constant_direction, is_timing_key) are imported inside the
# tests that use them, so that every test below also runs, and fails, against the diff of 8844af7.

WEAKER_DELTA = 0.9
"""The TaSIL delta of finding 3 of issue 22 (the plant certifies at 0.1): confidence 10 %."""

LOOSENED = 100.0
"""A constant's value times 100 with the same label (finding 3 of issue 22)."""


def _kinds(res):
    """``[(rule, effect), ...]`` of the changes, in order."""
    return [(c.rule, c.effect) for c in res.changes]


def test_larger_tasil_delta_at_the_same_radius_is_a_regression(cert):
    new = copy.deepcopy(cert)
    new["tasil"]["delta"] = WEAKER_DELTA
    c = _only(_diff(cert, new), "claim", REGRESSION)
    assert c.key == "tasil.delta" and (c.old, c.new) == (cert["tasil"]["delta"], WEAKER_DELTA)
    assert "TaSIL claim weakened: delta 0.1 -> 0.9" in c.text and "the same radius" in c.text
    new["rho"]["rho_tasil"] *= 1.5  # a looser radius too: still one claim line, no bound line
    c = _only(_diff(cert, new), "claim", REGRESSION)
    assert "a looser radius rho_TaSIL" in c.text
    c = _only(_diff(new, cert), "claim", IMPROVEMENT)  # the other way round: stronger claim
    assert "strengthened" in c.text


def test_larger_tasil_delta_at_a_tighter_radius_is_a_trade_off_not_an_improvement(cert):
    new = copy.deepcopy(cert)
    new["tasil"]["delta"] = 2 * cert["tasil"]["delta"]
    new["rho"]["rho_tasil"] /= 2
    res = _diff(cert, new)
    assert _kinds(res) == [("claim", "change")] and res.exit_status == 0
    assert "neither claim implies the other" in res.changes[0].text


def test_smaller_moment_order_p_is_a_regression_not_an_improvement(cert):
    old = copy.deepcopy(cert)
    old["l1drac"]["p"] = 2
    new = copy.deepcopy(old)
    new["l1drac"]["p"] = 1
    c = _only(_diff(old, new), "claim", REGRESSION)
    assert c.key == "l1drac.p" and "p 2 -> 1 (an L_4 -> L_2 moment bound)" in c.text
    _only(_diff(new, old), "claim", IMPROVEMENT)
    # what 8844af7 read as an improvement: a smaller p with it a smaller rho_L1 (and rho) is
    # another claim, neither stronger nor weaker
    new["rho"]["rho_l1"] /= 2
    new["rho"]["rho_total"] = new["rho"]["rho_l1"] + new["rho"]["rho_tasil"]
    res = _diff(old, new)
    assert res.improvements == () and _kinds(res) == [("claim", "change")]


def test_larger_l1drac_delta_at_the_same_kappa_is_a_regression(cert):
    new = copy.deepcopy(cert)
    new["l1drac"]["delta"] = 2 * cert["l1drac"]["delta"]
    c = _only(_diff(cert, new), "claim", REGRESSION)
    assert c.key == "l1drac.delta" and "L1-DRAC tail claim weakened" in c.text


@pytest.mark.parametrize(
    "key, value, radius",
    [
        ("tasil.rho_form", "held_out", "rho.rho_tasil"),
        ("coordinates.system", "z = Theta x", "l1drac.kappa"),  # rho.* stay in x: compared
    ],
)
def test_changed_form_or_coordinates_is_a_regression(cert, key, value, radius):
    new = copy.deepcopy(cert)
    table, last = key.split(".")
    new[table][last] = value
    rt, rl = radius.split(".")
    new[rt][rl] /= 2  # the radius of another claim is not called tightened
    c = _only(_diff(cert, new), "claim", REGRESSION)
    assert c.key == key and f"({key}) {cert[table][last]} -> {value};" in c.text
    assert "another statement, not compared" in c.text


def test_removed_constant_is_a_regression(cert):
    new = copy.deepcopy(cert)
    gone = new["constants"].pop("L_mu")
    c = _only(_diff(cert, new), "constant", REGRESSION)
    assert c.key == "constants.L_mu" and c.old == gone["value"] and "removed" in c.text
    c = _only(_diff(new, cert), "constant", "change")  # a new constant is a change
    assert "new constant(s): L_mu" in c.text


def test_constant_value_times_100_with_the_same_label_is_a_regression(cert):
    new = copy.deepcopy(cert)
    q = new["constants"]["L_mu"]
    assert q["how"] == "sound" and q["value"] > 0
    q["value"] *= LOOSENED
    c = _only(_diff(cert, new), "constant", REGRESSION)
    assert c.key == "constants.L_mu.value" and "loosened" in c.text and "(+99 relative)" in c.text
    assert "tightened" in _only(_diff(new, cert), "constant", IMPROVEMENT).text
    rate = copy.deepcopy(cert)  # a rate: smaller is looser
    rate["constants"]["lambda_learned"]["value"] /= LOOSENED
    c = _only(_diff(cert, rate), "constant", REGRESSION)
    assert "smaller is looser" in c.text
    within = copy.deepcopy(cert)
    within["constants"]["L_mu"]["value"] *= 1 + DEFAULT_RTOL / 10
    assert _diff(cert, within).changes == ()


def test_constant_of_unknown_direction_is_flagged_on_any_move(cert):
    from drip_cert.diff import constant_direction

    name = "zeta_new"
    assert constant_direction(name)[0] == "direction unknown"
    old = copy.deepcopy(cert)
    old["constants"][name] = dict(cert["constants"]["L_mu"], name=name, value=1.0)
    for factor in (2.0, 0.5):
        new = copy.deepcopy(old)
        new["constants"][name]["value"] = factor
        c = _only(_diff(old, new), "constant", REGRESSION)
        assert "direction unknown" in c.text


def test_every_constant_of_the_certificate_has_a_direction(cert):
    from drip_cert.diff import constant_direction

    unknown = [n for n in cert["constants"] if constant_direction(n)[0] == "direction unknown"]
    assert unknown == []
    assert constant_direction("lambda")[0] == "smaller is looser"
    assert constant_direction("Delta_mu")[0] == "larger is looser"


def test_sound_lost_with_new_estimated_constants_is_a_regression(cert):
    new = copy.deepcopy(cert)
    name = "sup||D(pi_IL - pi*)||"
    new["constants"][name] = dict(cert["constants"]["L_mu"], name=name, how="estimate")
    new["sound"], new["estimated_constants"] = False, [name]
    res = _diff(cert, new)
    assert _kinds(res) == [
        ("soundness", REGRESSION),
        ("soundness", REGRESSION),
        ("constant", "change"),
    ]
    assert res.changes[0].text.startswith("sound: true -> false")
    assert res.changes[1].key == "estimated_constants" and f"new estimated constant: {name}" in (
        res.changes[1].text
    )
    assert _kinds(_diff(new, cert))[:2] == [("soundness", IMPROVEMENT)] * 2


def test_new_given_constant_is_a_regression(cert):
    new = copy.deepcopy(cert)
    new["constants"]["Delta_mu"]["how"] = "given"
    new["given_constants"] = ["Delta_mu"]
    res = _diff(cert, new)
    assert _kinds(res) == [("soundness", REGRESSION), ("provenance", REGRESSION)]
    assert "new given constant: Delta_mu" in res.changes[0].text


@pytest.mark.parametrize("where", ["assumptions", "tasil.gap_checks", "tasil.forms.checks"])
def test_scope_justified_lost_is_a_regression(cert, where):
    new = copy.deepcopy(cert)
    if where == "assumptions":
        check, path = new["assumptions"][1], f"assumptions[{cert['assumptions'][1]['id']}]"
    elif where == "tasil.gap_checks":
        check = new["tasil"]["gap_checks"][0]
        path = f"tasil.gap_checks[{check['id']}]"
    else:
        form = new["tasil"]["forms"][0]
        check = form["checks"][0]
        path = f"tasil.forms[{form['name']}].checks[{check['id']}]"
    assert check["scope_justified"] and check["status"] == "holds"
    check["scope_justified"], check["scope_reason"] = False, "proved on a box only"
    c = _only(_diff(cert, new), "scope", REGRESSION)
    assert c.key == path + ".scope_justified"
    assert "scope no longer justified (proved on a box only)" in c.text
    _only(_diff(new, cert), "scope", IMPROVEMENT)


def test_new_verdict_reason_is_a_regression(cert):
    def conditional(*reasons):
        out = copy.deepcopy(cert)
        out["verdict"], out["certified"] = "conditional", False
        out["verdict_reasons"] = list(reasons)
        out["parts"]["contraction"].update(verdict="conditional", reasons=list(reasons))
        return out

    first = "DRIP-A2 rests on an unproved region: the box [[-0.5, 0.5]] is short by 0.7"
    second = "DRIP-A1 rests on an estimate: Delta_g"
    old = conditional(first)
    c = _only(_diff(old, conditional(first, second)), "reason", REGRESSION)
    assert c.new == second and "new verdict reason (verdict, part contraction)" in c.text
    _only(_diff(conditional(first, second), old), "reason", IMPROVEMENT)
    moved = conditional(first.replace("0.7", "0.8"))  # a moved number is not a new reason
    assert _diff(old, moved).changes == ()


TIMED = ("time_s", "seconds", "compile_s", "run_s")
"""The wall-time keys of the certificate and validation JSON, all kept under ``timings``."""


def test_timings_are_ignored(cert, validation):
    from drip_cert.diff import is_timing_key

    assert all(is_timing_key(k) for k in ("timings", *TIMED, "setup_time_s"))
    assert not any(is_timing_key(k) for k in ("lambda_s", "Ts", "practical_Ts"))

    def retimed(obj):
        out = copy.deepcopy(obj)
        found = []

        def walk(node):
            if isinstance(node, dict):
                for k, v in node.items():
                    if k in TIMED and isinstance(v, float):
                        node[k] = 100 * v + 1
                        found.append(k)
                    else:
                        walk(v)
            elif isinstance(node, list):
                for v in node:
                    walk(v)

        walk(out)
        return out, found

    for obj in (cert, validation):
        # the outputs keep their wall times under "timings" (schema 4): none is left elsewhere
        assert obj["timings"] and all(k.rsplit(".", 1)[-1] in TIMED for k in obj["timings"])
        new, found = retimed(obj)
        assert found == []
        new["timings"] = {k: 100 * v + 1 for k, v in obj["timings"].items()}
        assert _diff(obj, new).changes == ()
        # whatever the key holds, even what other rules would read, is never compared
        old = copy.deepcopy(obj)
        old["timings"] = {"certify_s": 1.0, "rho.rho_total": 1.0, "sound": 1.0}
        new["timings"] = {"certify_s": 1e6, "rho.rho_total": 1e6, "sound": 0.0}
        assert _diff(old, new).changes == ()


def test_improvements_are_not_regressions(cert):
    new = copy.deepcopy(cert)
    new["tasil"]["delta"] = cert["tasil"]["delta"] / 2
    new["constants"]["L_mu"]["value"] /= 2
    new["constants"]["lambda"]["value"] *= 2
    new["l1drac"]["p"] = cert["l1drac"]["p"] + 1
    res = _diff(cert, new)
    assert res.exit_status == 0 and res.regressions == ()
    assert [c.rule for c in res.improvements] == ["claim", "claim", "constant", "constant"]


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
