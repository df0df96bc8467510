"""examples/onnx_relu: an ONNX ReLU policy written by make_policy.py (as torch.onnx.export writes
it) is read, checked against onnx.reference and certified end to end: contraction through the
Clarke Jacobian (global, by its LipSDP Lipschitz constant), TaSIL through the uniform form while
the lemma route is not applicable."""

from __future__ import annotations

import importlib.util
import json
import math
import shutil
from pathlib import Path

import numpy as np
import pytest

pytest.importorskip("onnx")  # a declared dependency; the skip only names a broken venv

from drip_cert.analysis.networks.policy_regularity import jacobian_lipschitz  # noqa: E402
from drip_cert.cli import main  # noqa: E402
from drip_cert.spec.load import load_spec  # noqa: E402

EXAMPLE = Path(__file__).resolve().parents[1] / "examples" / "onnx_relu"


def _make(tmp_path: Path) -> Path:
    spec = importlib.util.spec_from_file_location("make_policy", EXAMPLE / "make_policy.py")
    assert spec is not None and spec.loader is not None
    mod = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(mod)
    shutil.copy(EXAMPLE / "spec.toml", tmp_path / "spec.toml")
    mod.make(tmp_path / "policy.onnx")
    return tmp_path / "spec.toml"


def test_the_example_policy_loads_as_a_relu_network_and_its_jacobian_is_not_lipschitz(tmp_path):
    s = load_spec(_make(tmp_path)).system
    mlp = s.blocks["pi_il"].mlp
    assert mlp is not None and mlp.sizes == (2, 16, 16, 1)
    assert mlp.activation_specs == ("relu", "relu", "identity") and not mlp.smooth
    # close to the expert u = -x2 (the network writes -x2 with relus plus a small perturbation)
    x = np.random.default_rng(0).uniform(-1, 1, (200, 2))
    assert np.max(np.abs(mlp.apply_np(x)[:, 0] + x[:, 1])) < 0.2
    L = jacobian_lipschitz(s, "learned")
    assert L.value == math.inf and "not Lipschitz" in L.note


@pytest.mark.slow
def test_the_example_is_certified_end_to_end(tmp_path, capsys):
    spec = _make(tmp_path)
    assert main(["certify", str(spec), "--json"]) == 0
    cert = json.loads(capsys.readouterr().out)
    assert cert["verdict"] == "certified"
    learned = cert["contraction"]["learned"]
    # proved on all of R^2: relu's Clarke slopes in [0, 1] in LipSDP give a global Lipschitz bound
    assert learned["scope"]["box"] is None and learned["method"] == "lipschitz-affine-mlp"
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


def _as_safetensors(tmp_path: Path) -> Path:
    """The example with its network saved as a PyTorch state_dict in safetensors (the layout
    of nn.Sequential(Linear, ReLU, Linear, ReLU, Linear)), activations given in the table."""
    from safetensors.numpy import save_file

    spec = _make(tmp_path)
    mlp = load_spec(spec).system.blocks["pi_il"].mlp
    assert mlp is not None
    tensors = {}
    for k, (w, b) in enumerate(zip(mlp.weights, mlp.biases)):
        tensors[f"{2 * k}.weight"], tensors[f"{2 * k}.bias"] = w, b
    save_file(tensors, str(tmp_path / "policy.safetensors"))
    text = spec.read_text().replace(
        'weights = "policy.onnx"', 'weights = "policy.safetensors"\nactivation = "relu"'
    )
    out = tmp_path / "st.toml"
    out.write_text(text)
    return out


def test_the_safetensors_copy_loads_as_the_same_network(tmp_path):
    st = load_spec(_as_safetensors(tmp_path)).system.blocks["pi_il"].mlp
    ox = load_spec(tmp_path / "spec.toml").system.blocks["pi_il"].mlp
    assert st is not None and ox is not None
    assert st.activation_specs == ox.activation_specs
    for a, b in zip(st.weights + st.biases, ox.weights + ox.biases):
        np.testing.assert_array_equal(a, b)


@pytest.mark.slow
def test_the_safetensors_copy_is_certified_end_to_end(tmp_path, capsys):
    assert main(["certify", str(_as_safetensors(tmp_path)), "--json"]) == 0
    cert = json.loads(capsys.readouterr().out)
    assert cert["verdict"] == "certified"
    assert cert["contraction"]["learned"]["method"] == "lipschitz-affine-mlp"
