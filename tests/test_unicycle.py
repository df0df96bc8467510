"""examples/unicycle: a unicycle tracking-error model with a state-dependent g(x) is certified in
its DRIP parts (contraction and TaSIL), with L1-DRAC not_applicable and the reason."""

from __future__ import annotations

import json
import math
from pathlib import Path

import pytest

from drip_cert.cli import main
from drip_cert.spec.load import load_spec

SPEC = Path(__file__).resolve().parents[1] / "examples" / "unicycle" / "unicycle.toml"


def test_the_unicycle_has_a_state_dependent_g():
    s = load_spec(SPEC).system
    assert s.g.free_symbols  # g depends on ex and ey


@pytest.mark.slow  # certify: interval branch and bound in 3-D, ~25-50 s on two shared cores
def test_unicycle_is_certified_in_its_drip_parts(capsys):
    assert main(["certify", str(SPEC), "--json"]) == 0
    cert = json.loads(capsys.readouterr().out)
    assert cert["verdict"] == "certified"
    parts = cert["parts"]
    assert parts["contraction"]["verdict"] == "certified"
    assert parts["tasil"]["verdict"] == "certified"
    assert parts["l1drac"]["verdict"] == "not_applicable"
    assert "g(t)" in parts["l1drac"]["reasons"][0]
    expert = cert["contraction"]["expert"]
    assert expert["holds"] and expert["rate"] > 0 and expert["scope"]["box"] is not None
    assert cert["contraction"]["invariant_set"]["proved"]
    assert math.isfinite(float(cert["tasil"]["rho"]))
