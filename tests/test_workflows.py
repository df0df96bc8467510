"""End-to-end runs: reproduce paper-4d --quick, the gallery's quick runs, train and validate."""

from __future__ import annotations

import importlib.util
import json
from pathlib import Path

import pytest

from drip_cert.cli import main

ROOT = Path(__file__).resolve().parents[1]


def test_reproduce_paper_4d_quick(tmp_path, monkeypatch, capsys):
    """The paper's three qualitative claims hold on the quick run, the outputs exist, and nothing
    is written outside --out."""
    monkeypatch.chdir(tmp_path)
    out = tmp_path / "out"
    code = main(["reproduce", "paper-4d", "--quick", "--out", str(out), "--json"])
    rep = json.loads(capsys.readouterr().out)
    assert sorted(p.name for p in tmp_path.iterdir()) == ["out"]
    for name in (
        "report.md",
        "figure.png",
        "figure.svg",
        "certificate.json",
        "reproduce.json",
        "policy_tasil.npz",
        "policy_bc.npz",
    ):
        assert (out / name).is_file(), name
    claims = {c["case"]: c["holds"] for c in rep["claims"]}
    assert claims == {"(i)": True, "(ii)": True, "(iii)": True}
    assert rep["tasil_better_than_bc"] is True
    assert code == (0 if rep["holds"] else 1)
    cert = json.loads((out / "certificate.json").read_text())
    assert cert["contraction"]["rate"] == pytest.approx(0.1, abs=1e-12)
    # the certified T_s of the paper example is far below anything simulable: the report must say
    # the L1 runs are not at certified parameters
    val = rep["validation"]["ours"]
    if not val["at_certified_parameters"]:
        assert any("not at certified parameters" in c["note"] for c in val["checks"])


def _gallery():
    spec = importlib.util.spec_from_file_location("gallery", ROOT / "examples" / "gallery.py")
    mod = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(mod)
    return mod


@pytest.mark.parametrize("name", ["unmatched_2d", "nonlinear_2d", "infeasible_2d"])
def test_gallery_quick_run(name, tmp_path):
    summary = _gallery().run_one(name, tmp_path, quick=True)
    assert (tmp_path / f"{name}.png").is_file() and (tmp_path / f"{name}.md").is_file()
    if name == "infeasible_2d":
        assert summary["certified"] is False and "L1DRAC-A7" in summary["failing"]
    if name == "nonlinear_2d":
        assert "DRIP-A2" not in summary["failing"]


def test_train_command_writes_policy(tmp_path, capsys):
    out = tmp_path / "pol"
    code = main(
        [
            "train",
            "examples/unmatched_2d/unmatched_2d.toml",
            "--method",
            "bc",
            "--trajectories",
            "8",
            "--steps",
            "50",
            "--out",
            str(out),
            "--json",
        ]
    )
    assert code == 0
    summary = json.loads(capsys.readouterr().out)
    assert (out / "policy.npz").is_file() and (out / "train.json").is_file()
    assert summary["method"] == "bc" and summary["steps"] == 50
    assert not list(out.glob("*.tmp*"))
