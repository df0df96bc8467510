"""examples/relu_unmatched_2d: a ReLU network (ONNX, written by make_policy.py as torch.onnx.export
writes it) in the policy of the gallery system unmatched_2d, certified end to end: the learned
loop contracts on all of R^2 through the network's Clarke Jacobians (route
perturbation-of-expert), TaSIL through the sure (uniform) form while the lemma route is not
applicable (the network's Jacobian is not Lipschitz)."""

from __future__ import annotations

import importlib.util
import json
import math
import shutil
from pathlib import Path

import numpy as np
import pytest

pytest.importorskip("onnx")  # a declared dependency; the skip only names a broken venv

from drip_cert.analysis.networks.mlp import lipschitz_bound  # noqa: E402
from drip_cert.cli import main  # noqa: E402
from drip_cert.spec.load import load_spec  # noqa: E402

EXAMPLE = Path(__file__).resolve().parents[1] / "examples" / "relu_unmatched_2d"
FIT_ERROR = 0.01  # the fitted residual cancels -(0.2 + 0.1 tanh x1) to ~5e-3 on the support
MAX_LIPSCHITZ = 0.5  # ridge keeps Lip(r) ~ 0.31 < 1 = the expert's rate: a global learned rate


def _make(tmp_path: Path) -> Path:
    spec = importlib.util.spec_from_file_location("make_policy", EXAMPLE / "make_policy.py")
    assert spec is not None and spec.loader is not None
    mod = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(mod)
    shutil.copy(EXAMPLE / "spec.toml", tmp_path / "spec.toml")
    mod.make(tmp_path / "policy.onnx")
    return tmp_path / "spec.toml"


def test_the_committed_policy_is_what_the_script_writes_and_a_relu_network(tmp_path):
    spec = _make(tmp_path)
    assert (tmp_path / "policy.onnx").read_bytes() == (EXAMPLE / "policy.onnx").read_bytes()
    mlp = load_spec(spec).system.blocks["pi_il"].mlp
    assert mlp is not None and mlp.sizes == (2, 16, 16, 1)
    assert mlp.activation_specs == ("relu", "relu", "identity") and not mlp.smooth
    x = np.random.default_rng(0).uniform([-1.0, -0.75], [1.0, 0.75], (500, 2))
    err = mlp.apply_np(x)[:, 0] + 0.2 + 0.1 * np.tanh(x[:, 0])
    assert np.max(np.abs(err)) < FIT_ERROR
    assert lipschitz_bound(mlp).value < MAX_LIPSCHITZ


@pytest.mark.slow  # certify: ~25 s on two shared cores
def test_the_example_is_certified_end_to_end(tmp_path, capsys):
    spec = _make(tmp_path)
    assert main(["certify", str(spec), "--json"]) == 0
    cert = json.loads(capsys.readouterr().out)
    assert cert["verdict"] == "certified"
    assert cert["parts"]["contraction"]["verdict"] == "certified"
    assert cert["parts"]["tasil"]["verdict"] == "certified"
    assert cert["parts"]["l1drac"]["verdict"] == "not_requested"
    learned = cert["contraction"]["learned"]
    assert learned["scope"]["box"] is None and learned["method"] == "perturbation-of-expert"
    assert learned["holds"] and learned["rate"] > 0
    t = cert["tasil"]
    assert t["rho_form"] == "uniform" and math.isfinite(float(t["rho"]))
    notes = {f["name"]: f["note"] for f in t["forms"]}
    # the held-out form from data through the comparison bound (no lemma, no h1)
    assert (
        "comparison bound" in notes["held_out"]
        and "lemma route is not applicable" in (notes["held_out"])
    )
    assert notes["threshold"].startswith("not applicable: the policy's Jacobian is not Lipschitz")
