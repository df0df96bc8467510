"""The versioned output layouts (drip_cert/schema), checked on real outputs of certify and
validate with the reference JSON Schema validator; the loader's messages on bad files; and the
files validate writes beside validation.json (Markdown report and figure)."""

from __future__ import annotations

import copy
import dataclasses
import json

import pytest

from drip_cert.errors import SpecError
from drip_cert.schema import KINDS, check_output, load_output, problems, schema, schema_version
from tests.helpers import ROOT, run_cli

PLANT = ROOT / "examples" / "regression_ci" / "plant.toml"
"""The worked example's plant: certified in seconds, simulable at the certified parameters."""

PNG_MAGIC = b"\x89PNG\r\n\x1a\n"


@pytest.fixture(scope="module")
def outputs(tmp_path_factory):
    """A real certificate (certify --json) and a real validation run of the plant (--out)."""
    from drip_cert.workflows import validate_spec

    out = tmp_path_factory.mktemp("validate")
    rep = validate_spec(PLANT, trajectories=100, seed=0, out=out)
    cert = json.loads(json.dumps(rep.certificate.to_dict()))
    return {"cert": cert, "validation": json.loads((out / "validation.json").read_text())}, rep, out


def _reference_errors(obj, kind):
    jsonschema = pytest.importorskip("jsonschema")
    from referencing import Registry, Resource

    registry = Registry().with_resources(
        [(schema(k)["$id"], Resource.from_contents(schema(k))) for k in KINDS]
    )
    v = jsonschema.Draft202012Validator(schema(kind), registry=registry)
    return sorted(".".join(map(str, e.absolute_path)) for e in v.iter_errors(obj))


def test_schema_files_are_valid_json_schema_and_state_the_versions_the_code_writes():
    jsonschema = pytest.importorskip("jsonschema")
    from drip_cert.bounds.certificate import SCHEMA_VERSION
    from drip_cert.validate.run import VALIDATION_SCHEMA_VERSION

    for k in KINDS:
        jsonschema.Draft202012Validator.check_schema(schema(k))
    assert schema_version("certificate") == SCHEMA_VERSION
    assert schema_version("validation") == VALIDATION_SCHEMA_VERSION


def test_real_outputs_follow_their_layouts(outputs):
    d, _, _ = outputs
    assert d["cert"]["schema_version"] == schema_version("certificate")
    assert d["validation"]["schema_version"] == schema_version("validation")
    for obj, kind in ((d["cert"], "certificate"), (d["validation"], "validation")):
        assert _reference_errors(obj, kind) == []
        assert problems(obj, kind) == []
        assert check_output(obj).kind == kind


def test_certify_json_output_follows_the_layout(capsys):
    code, out, _ = run_cli(capsys, "certify", str(PLANT), "--json", "--quiet")
    assert code == 0
    obj = json.loads(out)
    assert _reference_errors(obj, "certificate") == [] and problems(obj, "certificate") == []


@pytest.mark.parametrize(
    "path, value, key",
    [
        (("rho", "rho_total"), [1.0], "rho.rho_total"),
        (("verdict",), "maybe", "verdict"),
        (("assumptions", 0, "how"), "guessed", "assumptions[0].how"),
        (("certified",), "yes", "certified"),
        (("constants", "Delta_g", "value"), "big", "constants.Delta_g.value"),
    ],
)
def test_a_corrupted_certificate_is_caught_by_both_validators(outputs, path, value, key):
    cert = copy.deepcopy(outputs[0]["cert"])
    node = cert
    for p in path[:-1]:
        node = node[p]
    node[path[-1]] = value
    assert _reference_errors(cert, "certificate")  # the reference validator agrees it is bad
    found = problems(cert, "certificate")
    assert found and found[0].startswith(key + ":"), found


def test_a_missing_required_key_is_named(outputs):
    cert = copy.deepcopy(outputs[0]["cert"])
    del cert["rho"]["rho_tasil"]
    assert _reference_errors(cert, "certificate")
    assert problems(cert, "certificate") == ["rho: required key 'rho_tasil' is missing"]


# ---------------------------------------------------------------------- the loader's errors
def _load_error(tmp_path, text):
    p = tmp_path / "old.json"
    p.write_text(text)
    with pytest.raises(SpecError) as exc:
        load_output(p)
    return str(exc.value), str(p)


def test_loader_messages_name_the_file_the_key_and_the_fix(tmp_path, outputs):
    msg, p = _load_error(tmp_path, "{not json")
    assert msg.startswith(p) and "not valid JSON (line 1" in msg and "drip-cert certify" in msg
    msg, p = _load_error(tmp_path, json.dumps({"hello": 1}))
    assert msg.startswith(p) and "not a drip-cert certificate" in msg and "['hello']" in msg
    old = dict(outputs[0]["cert"], schema_version=2)
    msg, p = _load_error(tmp_path, json.dumps(old))
    assert f"{p}: schema_version: certificate layout version 2" in msg and "regenerate" in msg
    old.pop("schema_version")
    msg, p = _load_error(tmp_path, json.dumps(old))
    assert f"{p}: schema_version:" in msg and "without 'schema_version'" in msg
    bad = dict(outputs[0]["cert"], verdict="fine")
    msg, p = _load_error(tmp_path, json.dumps(bad))
    assert f"{p}: verdict: " in msg and "'fine' is not one of" in msg
    with pytest.raises(SpecError, match="no such file"):
        load_output(tmp_path / "absent.json")


# ------------------------------------------------------------- validate's report + figure
def test_validate_writes_markdown_and_figure_beside_the_json(outputs):
    d, rep, out = outputs
    assert sorted(p.name for p in out.iterdir() if p.is_file()) == [
        "validation.json",
        "validation.md",
        "validation.png",
    ]
    assert (out / "validation.png").read_bytes()[:8] == PNG_MAGIC
    md = (out / "validation.md").read_text()
    assert md.startswith("# drip-cert validation: regression-ci-plant")
    assert f"**{rep.status.upper()}**" in md
    assert "L1-DRAC at the certified parameters" in md and rep.at_certified_parameters
    assert "![empirical gaps against the certified bounds](validation.png)" in md
    for c in d["validation"]["checks"]:  # every check is in the table
        assert f"| {c['name']} |" in md


def test_report_and_figure_say_when_not_at_certified_parameters(outputs, tmp_path):
    from drip_cert.report import validation_markdown, write_validation_outputs

    _, rep, _ = outputs
    off = dataclasses.replace(rep, at_certified_parameters=False)
    md = validation_markdown(off.to_dict())
    assert "L1-DRAC NOT at the certified parameters" in md
    assert "do not validate the certificate's L1-DRAC part" in md
    paths = write_validation_outputs(off, tmp_path)
    assert [p.name for p in paths] == ["validation.md", "validation.png"]
    assert paths[1].read_bytes()[:8] == PNG_MAGIC
    assert not list(tmp_path.glob(".*tmp*"))  # nothing half-written is left
