"""Issue 24's "Done means" for the plain class: a plain tanh MLP (no structure) trained by
``drip-cert train`` on the upright inverted pendulum, with the matching on the tube
(docs/math/tasil.md section 5.1), gets its TaSIL part certified."""

from __future__ import annotations

import math

import pytest

from tests.helpers import EXAMPLES

SPEC = EXAMPLES / "inverted_pendulum" / "plain_mlp.toml"
TRAJECTORIES = 100  # the spec's [tasil] trajectories: the held-out form needs about this many


@pytest.mark.slow
def test_trained_plain_mlp_gets_its_tasil_part_certified(tmp_path):
    from drip_cert.workflows import train_from_spec

    summary = train_from_spec(
        SPEC,
        method="tasil",
        trajectories=TRAJECTORIES,
        seed=0,
        out=tmp_path / "run",
        progress=False,
        compare=False,
    )
    cert = summary["certificate"]
    assert cert["parts"]["tasil"] == "certified", cert["tasil_binding"]
    assert cert["rho_tasil"] is not None and math.isfinite(cert["rho_tasil"])
