"""``drip-cert train`` names the check that decides the verdict (issue 24): a failing check
before any that holds on an unproved region, never a holding check for a verdict it does not
decide, in the coordinates the certificate uses, with its margin and what to change."""

from __future__ import annotations

from types import SimpleNamespace

from drip_cert.provenance import Check, How, verdict_of
from drip_cert.workflows import _binding


def _cert(checks, coordinates=None):
    verdict, _ = verdict_of(checks)
    return SimpleNamespace(
        assumptions=tuple(checks),
        coordinates=coordinates,
        tasil=None,
        verdict=verdict,
        certified=verdict.value == "certified",
        rho_tasil=None,
        rho_l1=None,
        part_verdicts=lambda: {"contraction": {"verdict": verdict.value}},
    )


PROVED = Check("DRIP-A2", True, "expert rate", 0.0, 1.0, 1.0, how=How.SOUND)
ON_A_BOX = Check(
    "L1DRAC-A2", True, "learned rate on a box", -0.7, 0.0, 0.7, how=How.SOUND
).with_scope(False, "a rate on a box does not suffice")
FAILS = Check("L1DRAC-design", False, "no feasible design", 2.0, 1.0, -1.0, how=How.SOUND)


def test_a_failing_check_binds_before_one_that_holds_on_a_box():
    b = _binding(_cert([PROVED, ON_A_BOX, FAILS]))
    assert b["verdict"] == "not_certified"
    assert b["check"] == "L1DRAC-design" and b["role"] == "fails" and not b["holds"]
    assert b["margin"] == -1.0
    assert b["parts"] == {"contraction": "not_certified"}


def test_a_conditional_verdict_names_the_unproved_check_without_calling_it_binding_margin():
    b = _binding(_cert([PROVED, ON_A_BOX]))
    assert b["verdict"] == "conditional"
    assert b["check"] == "L1DRAC-A2" and b["role"] == "not proved"
    assert "holds (margin" not in b["text"]
    assert "a rate on a box does not suffice" in b["text"]
    assert "lipschitz_budget" in b["change"]


def test_the_coordinates_of_the_certificate_are_named():
    b = _binding(_cert([PROVED], coordinates=object()))
    assert b["role"] == "tightest" and b["coordinates"] == "z = Theta x"
    assert " in z = Theta x: " in b["text"]
    assert _binding(_cert([PROVED]))["coordinates"] == "x"


BUDGET = 0.5
BUDGET_REL = 1e-9
"""The projection scales each layer to norm <= budget^(1/L) in float: the product is within a few
roundings of the budget (observed ~1e-15 relative)."""

PLAIN_SPEC = """
[system]
name = "inverted-pendulum"
states = ["q", "q_dot"]
inputs = ["u"]
horizon = 2.0

[dynamics]
f = ["q_dot", "9.81*sin(q) - 0.5*q_dot"]
g = [["0"], ["1"]]

[policy]
expert = ["-9.81*sin(q) - 4*q - 4*q_dot"]

[initial]
support = [[-0.5, 0.5], [-0.5, 0.5]]

[tasil]
trajectories = 2
heldout = 0
samples = 20
hidden = [8, 8]
steps = 20
lipschitz_budget = 0.5
"""


def test_the_lipschitz_budget_holds_for_a_plain_mlp(tmp_path):
    """``[tasil] lipschitz_budget`` bounds the plain MLP too (projected after every step)."""
    import numpy as np

    from drip_cert.learn.imitation import train_on_system
    from drip_cert.spec.load import load_spec
    from tests.helpers import write_spec

    spec = load_spec(write_spec(tmp_path, PLAIN_SPEC))
    assert spec.settings.tasil.architecture == "mlp"
    tp = train_on_system(spec.system, spec.settings.tasil)
    prod = float(np.prod([np.linalg.norm(w, 2) for w in tp.mlp.weights]))
    assert prod <= BUDGET * (1 + BUDGET_REL)


def test_the_tasil_inequality_is_reported_when_another_part_fails_first():
    """Both parts fail: the binding check is the first, and the TaSIL part's own failing
    inequality comes with its margin and what to change (a smaller Jacobian error)."""
    b_fails = Check("tasil.sharp.b", False, "b = gamma0 h1 < 1: 4.66 <= 1", 4.66, 1.0, -3.66)
    tasil = SimpleNamespace(
        forms=(SimpleNamespace(name="held_out", checks=(b_fails,)),),
        gap_checks=(),
        rho_form="held_out",
        gamma0=1.57,
        h0=3.6,
        h1=2.97,
        L_Delta=0.5,
        delta=0.1,
        tau0=1.0,
        tau1=1.0,
        n_val=100,
    )
    tcheck = Check("TaSIL", False, "rho_TaSIL = inf", how=How.SOUND)
    cert = _cert([PROVED, FAILS, tcheck])
    b = _binding(SimpleNamespace(**{**vars(cert), "tasil": tasil}))
    assert b["check"] == "L1DRAC-design"
    tb = b["tasil_binding"]
    assert tb["check"] == "tasil.sharp.b" and tb["margin"] == -3.66
    assert "smaller Jacobian error" in tb["change"] and "h1 <= 0.6369" in tb["change"]


def test_the_advice_for_an_unproved_learned_loop_follows_the_policy_class():
    """A residual policy is not told to try the residual architecture (it is one)."""
    from types import SimpleNamespace

    from drip_cert.workflows import _what_to_change

    cert = SimpleNamespace(tasil=None)
    plain = _what_to_change(cert, "L1DRAC-A2", "not proved", None, "mlp")  # type: ignore[arg-type]
    resid = _what_to_change(cert, "L1DRAC-A2", "not proved", None, "residual")  # type: ignore[arg-type]
    assert "residual architecture" in plain and "lipschitz_budget" in plain
    assert "residual architecture" not in resid and "lipschitz_budget" in resid
