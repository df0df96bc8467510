"""Every part of a certificate named up front, defaults that make a certificate reachable, and
certificates that are a function of their inputs (work budgets, timings kept apart).

Issue "Same inputs, same certificate", findings 4 and 5: a learned policy 50 % off the expert with
no ``[tasil]`` table was certified without the imitation gap ever being computed; the default
``[tasil] heldout = 20`` could never pass the held-out form; every branch and bound stopped on
wall-clock time, so the same spec gave different certificates on machines of different speed.
"""

from __future__ import annotations

import math

import numpy as np
import pytest
import sympy as sp

from drip_cert import certify, load_spec
from drip_cert.analysis.contraction.rate import contraction_rate
from drip_cert.numerics.stats import clopper_pearson_upper, min_trials_zero_failures
from drip_cert.provenance import split_timings
from drip_cert.report import certificate_markdown
from drip_cert.spec.settings import TasilSettings
from tests.helpers import two_state_spec, write_spec

#: a linear loop whose learned policy is 50 % off the expert's gains; no [tasil] table
OFF_BY_HALF = (
    two_state_spec("off-by-half", uncertainty=False)
    .replace('expert = ["-x1 - 2*x2"]', 'expert = ["-x1 - 2*x2"]\nlearned = ["-1.5*x1 - 3*x2"]')
    # linear dynamics: every rate is exact and the certificate takes a few seconds
    .replace('"-x1 - x2**3"', '"-x1 - x2"')
)


@pytest.fixture(scope="module")
def off_by_half(tmp_path_factory):
    path = write_spec(tmp_path_factory.mktemp("parts"), OFF_BY_HALF)
    return certify(load_spec(path))


def test_tasil_part_is_computed_without_a_tasil_table(off_by_half):
    """Finding 4: with a learned policy the imitation gap is always bounded (defaults when
    [tasil] is absent, and the certificate says so)."""
    d = off_by_half.to_dict()
    assert d["parts"]["tasil"]["verdict"] in ("certified", "conditional", "not_certified")
    assert off_by_half.tasil is not None and d["rho"]["rho_tasil"] is not None
    assert any(t.id == "TaSIL" for t in off_by_half.assumptions)
    assert any("no [tasil] table" in n and "heldout = 59" in n for n in d["notes"])


def test_a_part_not_computed_is_named_in_json_and_first_lines(off_by_half):
    d = off_by_half.to_dict()
    assert set(d["parts"]) == {"contraction", "tasil", "l1drac"}
    assert d["parts"]["l1drac"]["verdict"] == "not_requested"
    assert "[l1drac]" in d["parts"]["l1drac"]["reasons"][0]
    # rho needs both parts: never certified with one missing
    assert d["rho"]["certified"] is False and d["rho"]["rho_total"] is None
    head = certificate_markdown(off_by_half).splitlines()[:8]
    assert any("l1drac not requested" in line for line in head)
    assert any("not: l1drac" in line for line in head)


def test_tasil_not_applicable_without_a_learned_policy(tmp_path):
    cert = certify(load_spec(write_spec(tmp_path, two_state_spec(uncertainty=False))))
    parts = cert.to_dict()["parts"]
    assert parts["tasil"]["verdict"] == "not_applicable"
    assert "no learned policy" in parts["tasil"]["reasons"][0]


# ------------------------------------------------------------------- defaults from formulas


@pytest.mark.parametrize("delta", [0.1, 0.05, 0.2, 0.01])
def test_heldout_default_is_the_smallest_count_that_can_pass(delta):
    """The default [tasil] heldout is the smallest n at which zero exceedances bring the sound
    one-sided Clopper-Pearson bound (confidence 1 - delta/2) to delta/2; one fewer cannot."""
    n = TasilSettings(delta=delta).heldout
    assert n == min_trials_zero_failures(delta / 2, delta / 2)
    assert float(clopper_pearson_upper(0, n, alpha=delta / 2, sound=True)) <= delta / 2
    assert float(clopper_pearson_upper(0, n - 1, alpha=delta / 2, sound=True)) > delta / 2


def test_heldout_default_at_delta_0_1_is_59():
    """The issue's number: log(0.05) / log(0.95) = 58.4, so 59 trajectories (20 never pass)."""
    assert TasilSettings().heldout == 59
    assert math.ceil(math.log(0.05) / math.log(0.95)) == 59


def test_an_impossible_heldout_says_the_smallest_value(tmp_path):
    """A held-out count that can never pass says so and names the smallest that can."""
    text = OFF_BY_HALF + "[tasil]\nheldout = 20\n"
    cert = certify(load_spec(write_spec(tmp_path, text)))
    held = next(f for f in cert.tasil.forms if f.name == "held_out")
    assert not held.holds
    assert "can never pass" in held.note and "heldout >= 59" in held.note


# ------------------------------------------------------------------- work, not seconds


def test_contraction_search_stops_on_work_not_time():
    """The default search has no wall-time guard; the same inputs give the same bound and the
    same box count, run after run (the count is the budget)."""
    x1, x2 = sp.symbols("x1 x2")
    # the maximum of mu_2 lies inside the box, so no finite budget closes the gap to 1e-12
    J = sp.Matrix([[-1 + 0.5 * sp.sin(3 * x1) * sp.cos(2 * x2), 0.2 * x1], [0.1 * x2, -1]])
    box = np.array([[-1.0, 1.0], [-1.0, 1.0]])
    a = contraction_rate(J, (x1, x2), box, tol=1e-12, max_boxes=300)
    b = contraction_rate(J, (x1, x2), box, tol=1e-12, max_boxes=300)
    assert a.stop == "max_boxes" and a.n_boxes >= 300
    assert (a.rate, a.n_boxes, a.max_mu_upper) == (b.rate, b.n_boxes, b.max_mu_upper)
    assert not a.machine_dependent


def test_a_fired_time_guard_is_reported_as_machine_dependent(tmp_path):
    """A wall-time guard, when the user sets one and it fires, makes the certificate say that
    its numbers depend on the machine's speed."""
    spec = (
        two_state_spec(uncertainty=False)
        .replace('"-x1 - x2**3"', '"-x1 - x2**3 - 0.5*sin(x1)"')
        .replace("[initial]", "[contraction]\nmax_time = 1e-9\ntol = 1e-12\n[initial]")
    )
    cert = certify(load_spec(write_spec(tmp_path, spec)))
    d = cert.to_dict()
    assert cert.contraction_expert.euclidean.stop == "max_time"
    assert d["reproducible"]["machine_independent"] is False
    assert d["reproducible"]["stopped_on_time"]


def test_same_spec_same_certificate_outside_timings(tmp_path):
    """Two runs of one spec: byte-identical JSON once the timings key is set apart."""
    import json

    spec = load_spec(write_spec(tmp_path, two_state_spec()))
    a, b = certify(spec).to_dict(), certify(spec).to_dict()
    assert a["reproducible"]["machine_independent"] is True
    ta, tb = a.pop("timings"), b.pop("timings")
    assert ta and set(ta) == set(tb)
    assert json.dumps(a, sort_keys=True) == json.dumps(b, sort_keys=True)
    assert "time_s" not in json.dumps(a)


def test_split_timings_moves_every_timing_and_keeps_the_rest():
    d = {"a": {"time_s": 1.0, "x": 2}, "b": [{"seconds": 3.0, "y": 4}], "time_s": 5.0}
    t = split_timings(d)
    assert t == {"a.time_s": 1.0, "b.0.seconds": 3.0, "time_s": 5.0}
    assert d == {"a": {"x": 2}, "b": [{"y": 4}]}
