"""The planar quadrotor example (examples/planar_quadrotor): g(x) through the pitch, certified in
its DRIP parts with L1-DRAC not applicable (issue 23). Minutes: slow."""

from __future__ import annotations

import pytest

from drip_cert import certify
from drip_cert.spec import load_spec
from tests.helpers import example_spec


@pytest.mark.slow  # 6-D interval branch and bound in three metric coordinates: ~5 min
def test_planar_quadrotor_drip_parts_with_g_of_x():
    spec = load_spec(example_spec("planar_quadrotor"))
    assert spec.system.g_depends_on_x
    cert = certify(spec)
    parts = cert.part_verdicts()
    assert parts["l1drac"]["verdict"] == "not_applicable"
    a2 = next(c for c in cert.assumptions if c.id == "DRIP-A2")
    assert a2.holds  # the expert contracts in the LMI metric on the small-angle box
    a1 = next(c for c in cert.assumptions if c.id == "DRIP-A1")
    assert a1.scope.box is not None  # sup ||g|| over a box, never a global claim
    assert cert.inputs.Delta_g.how.value == "sound"
