"""DRIP Assumption PolicyRegularity (b): a policy whose Jacobian jumps has no L_dpi, and says so."""

from __future__ import annotations

import math

import numpy as np
import pytest

from drip_cert.analysis.networks.policy_regularity import jacobian_lipschitz
from drip_cert.model.mlp import init_mlp
from drip_cert.provenance import How
from drip_cert.spec.load import load_spec
from tests.helpers import run_cli, write_spec

BOX = np.array([[-1.0, 1.0], [-1.0, 1.0]])

INTERVAL_BOUND_REL = 1e-9
"""An interval enclosure of a monotone second derivative on the box is exact up to outward
rounding (observed 7e-16 relative); 1e-9 is a generous ceiling."""

SPEC = """
[system]
name = "kinked-expert"
states = ["x1", "x2"]
inputs = ["u"]
horizon = 3.0

[dynamics]
f = ["-x1 + 0.5*sin(x2)", "-x2"]
g = [["0"], ["1"]]

[policy]
expert = ["{expert}"]
{learned}

[initial]
support = [[-1.0, 1.0], [-1.0, 1.0]]
{extra}
"""


def _system(tmp_path, expert: str, learned: str = "", extra: str = ""):
    path = write_spec(tmp_path, SPEC.format(expert=expert, learned=learned, extra=extra))
    return load_spec(path).system, path


@pytest.mark.parametrize("box", [BOX, None])
def test_abs_through_the_box_has_no_jacobian_lipschitz_constant(tmp_path, box):
    s, _ = _system(tmp_path, "-0.5*x2 - 0.2*Abs(x2)")
    q = jacobian_lipschitz(s, "expert", box)
    assert math.isinf(q.value) and q.how == How.SOUND
    assert "discontinuous where x2 = 0" in q.note and "not C^1" in q.note


def test_abs_with_its_kink_outside_the_box_equals_the_smooth_branch(tmp_path):
    """Abs(x2 - 5) = 5 - x2 on [-1, 1]^2: both spellings get the same sound bound."""
    kinked, _ = _system(tmp_path, "-0.5*x2 - 0.2*x2**3 + 0.1*Abs(x2 - 5)")
    smooth, _ = _system(tmp_path, "-0.5*x2 - 0.2*x2**3 + 0.1*(5 - x2)")
    a = jacobian_lipschitz(kinked, "expert", BOX)
    b = jacobian_lipschitz(smooth, "expert", BOX)
    assert a.how == b.how == How.SOUND
    assert a.value == b.value
    # d^2/dx2^2 of -0.2 x2^3 is -1.2 x2: |.| <= 1.2 on the box, and the bound is that
    assert a.value == pytest.approx(1.2, rel=INTERVAL_BOUND_REL)
    # without a box the kink may be reached: no constant
    assert math.isinf(jacobian_lipschitz(kinked, "expert", None).value)


def test_a_kink_off_the_box_gives_no_global_constant(tmp_path):
    """Affine on the box (Abs(x2 - 5) = 5 - x2) but not on R^2: the zero bound holds on the box
    only and must say so (the tube radius is then capped), not claim 'affine policy' globally."""
    s, _ = _system(tmp_path, "-0.5*x2 + 0.1*Abs(x2 - 5)")
    q = jacobian_lipschitz(s, "expert", BOX)
    assert q.how == How.SOUND and q.value == 0.0
    assert "box only" in q.note and "affine policy" not in q.note


def test_certify_reports_the_failing_assumption(tmp_path, capsys):
    rng = np.random.default_rng(0)
    init_mlp([2, 8, 1], rng, scale=0.1).save(tmp_path / "policy.npz")
    learned = 'learned = ["pi_il(x1, x2)[0]"]'
    extra = (
        '[blocks.pi_il]\nkind = "mlp"\nweights = "policy.npz"\ninputs = 2\noutputs = 1\n\n'
        "[tasil]\ntrajectories = 4\nheldout = 2\nsamples = 20\n"
        # a small work budget: the failing assumption under test does not depend on it
        "[contraction]\nmax_boxes = 100\n"
    )
    _, path = _system(tmp_path, "-0.5*x2 - 0.2*Abs(x2)", learned, extra)
    rc, out, _ = run_cli(capsys, "certify", str(path))
    assert rc == 1
    assert "PolicyRegularity (b) fails for L_dpi_expert" in out
    assert "discontinuous where x2 = 0" in out


def test_the_difference_cancels_shared_terms(tmp_path):
    """pi* and pi_IL share 0.5 sin(x2)^3 (a compensation both carry): d(pi_IL - pi*) is constant,
    so its Lipschitz constant is exactly 0, while the triangle bound adds the two policies' own
    (equal, positive) constants."""
    from drip_cert.analysis.networks.policy_regularity import difference_jacobian_lipschitz

    s, _ = _system(
        tmp_path,
        "0.5*sin(x2)**3 - x1 - 2*x2",
        'learned = ["0.5*sin(x2)**3 - 1.02*x1 - 1.98*x2"]',
    )
    tri = jacobian_lipschitz(s, "learned", BOX).value + jacobian_lipschitz(s, "expert", BOX).value
    assert tri > 1.0
    d = difference_jacobian_lipschitz(s, BOX)
    assert d is not None and d.value == 0.0 and d.how == How.EXACT and d.scope.all_x


def test_the_difference_bound_is_sound_where_terms_do_not_cancel(tmp_path):
    """Delta = 0.1 sin(x2)^2 (not shared): the interval bound on the box is >= the true sup of
    |d^2 Delta / dx2^2| = 0.2 |cos(2 x2)| (= 0.2 at x2 = 0), within interval overestimation."""
    from drip_cert.analysis.networks.policy_regularity import difference_jacobian_lipschitz

    s, _ = _system(tmp_path, "-x1 - 2*x2", 'learned = ["-x1 - 2*x2 + 0.1*sin(x2)**2"]')
    d = difference_jacobian_lipschitz(s, BOX)
    assert d is not None and d.how == How.SOUND and not d.scope.all_x
    assert 0.2 <= d.value <= 0.2 * 2  # an interval enclosure of cos(2 x2) on [-2, 2] in [-1, 1]
    assert difference_jacobian_lipschitz(s, None) is None  # no box, no blocks: no sound route
