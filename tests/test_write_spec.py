"""``train --write-spec`` (issue 27): the spec written with the trained policy loads from where it
is written and means what the original meant; train's old ``use_in_spec`` could not be pasted
into the spec it came from (duplicate tables, a weights path relative to the output directory).
"""

from __future__ import annotations

from pathlib import Path

import pytest

from drip_cert.spec import load_spec
from drip_cert.spec.write import read_document, spec_with_policy, toml_document
from tests.helpers import EXAMPLES, run_cli

#: examples whose spec is rewritten and re-read (one with an ONNX block, with a relative path)
ROUND_TRIP = [
    EXAMPLES / "nonlinear_2d" / "nonlinear_2d.toml",
    EXAMPLES / "onnx_relu" / "spec.toml",
    EXAMPLES / "regression_ci" / "plant.toml",
    EXAMPLES / "pendulum" / "pendulum.toml",
]


@pytest.mark.parametrize("path", ROUND_TRIP, ids=lambda p: p.parent.name)
def test_written_document_means_the_same_spec(tmp_path, path):
    """Written elsewhere (a relative weights path re-based), read back: the same system and
    settings, literal for literal (floats keep their text, so the same exact rationals)."""
    doc = read_document(path)
    if "blocks" in doc:  # re-base the user's blocks as spec_with_policy does
        learned = doc["policy"]["learned"]
        name, table = next(iter(doc["blocks"].items()))
        table = dict(table, weights=str((path.parent / table["weights"]).resolve()))
        doc = spec_with_policy(
            doc,
            source=path,
            target=tmp_path / "sub" / "spec.toml",
            block=name,
            block_table=table,
            learned=learned,
            tasil={},
        )
    (tmp_path / "sub").mkdir()
    out = tmp_path / "sub" / "spec.toml"
    out.write_text(toml_document(doc, header="rewritten"))
    a, b = load_spec(path), load_spec(out)
    da, db = a.system.to_dict(), b.system.to_dict()
    for d in (da, db):  # the weights file is the same one, named from another directory
        for blk in d.get("blocks", []):
            blk["source"] = str(Path(blk["source"]).resolve())
    assert db == da
    assert b.settings == a.settings


def test_policy_replaces_the_learned_policy_and_keeps_other_blocks(tmp_path):
    src = EXAMPLES / "onnx_relu" / "spec.toml"
    target = tmp_path / "out" / "trained.toml"
    doc = spec_with_policy(
        read_document(src),
        source=src,
        target=target,
        block="pi_il",
        block_table={"kind": "mlp", "weights": str(src.parent / "policy.onnx")},
        learned=["pi_il(x)[0]"],
        tasil={"seed": 3},
    )
    assert doc["policy"]["learned"] == ["pi_il(x)[0]"]
    assert doc["tasil"]["seed"] == 3
    assert set(doc["blocks"]) == {"pi_il"} | set(read_document(src)["blocks"])
    assert list(doc)[:2] == ["system", "blocks"]  # blocks before the expressions using them
    target.parent.mkdir()
    target.write_text(toml_document(doc))
    assert load_spec(target).system.learned is not None


@pytest.mark.slow  # trains a small policy (jax compile and 50 steps: ~5 s CPU, more when busy)
def test_train_write_spec_passes_check_spec(tmp_path, capsys):
    src = EXAMPLES / "regression_ci" / "plant.toml"
    out_spec = tmp_path / "specs" / "trained.toml"
    out_spec.parent.mkdir()
    argv = ["train", str(src), "--out", str(tmp_path / "run"), "--steps", "50"]
    argv += ["--trajectories", "5", "--no-compare", "--no-certify", "--quiet"]
    code, _, err = run_cli(capsys, *argv, "--write-spec", str(out_spec))
    assert code == 0, err
    code, out, err = run_cli(capsys, "check-spec", str(out_spec))
    assert code == 0, err
    assert "blocks: pi_il, learned policy: yes" in out
    text = out_spec.read_text()
    assert 'weights = "../run/policy.npz"' in text  # relative to the written spec
    assert text.count("[policy]") == 1 and text.count("[tasil]") == 1  # no duplicate tables
