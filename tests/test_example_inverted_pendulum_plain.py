"""The plain-MLP inverted pendulum of issue 24 (examples/inverted_pendulum/plain_mlp.toml): a
32-32 tanh network with no known structure, trained by ``drip-cert train`` with the spec's own
settings, gets its TaSIL part certified (README of the example: the numbers)."""

from __future__ import annotations

import json

import pytest

from tests.helpers import EXAMPLES, run_cli

SPEC = EXAMPLES / "inverted_pendulum" / "plain_mlp.toml"


@pytest.mark.slow
def test_plain_mlp_trained_by_train_gets_its_tasil_part_certified(tmp_path, capsys):
    """About 2 min on two cores: 6000 steps at 4000 samples per trajectory (mini-batches with
    replacement), then the certificate in ``z = Theta x``."""
    code, out, _ = run_cli(
        capsys, "train", str(SPEC), "--out", str(tmp_path / "run"), "--no-compare", "--json"
    )
    summary = json.loads(out)
    cert = summary["certificate"]
    assert cert["coordinates"] == "z = Theta x"
    assert cert["parts"]["tasil"] == "certified", cert
    assert 0.0 < cert["rho_tasil"] < float("inf")
    assert code == 0
