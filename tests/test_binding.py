"""The binding condition of each part of a certificate (drip_cert/bounds/binding.py).

A learned loop whose rate is not proved for all x leaves the L1-DRAC part short of certified;
the report must name the chain with its numbers: why no metric proves the rate for all x (the
trace condition of docs/math/contraction.md section 11), what the box search proved, and what the
exit probability of docs/math/l1drac.md section 11 can give (a displayed floor, never a verdict).
"""

from __future__ import annotations

import json
import math
from fractions import Fraction

import numpy as np
import pytest

from drip_cert.analysis.contraction.rate import ContractionResult
from drip_cert.analysis.contraction.slope_lmi import TraceObstruction
from drip_cert.bounds.binding import l1drac_learned_binding
from drip_cert.bounds.certificate import ContractionAnalysis
from drip_cert.bounds.l1drac.exit import exit_floor, exit_room
from drip_cert.provenance import How, Scope
from tests.helpers import write_spec

FLOOR_RTOL = 1e-12
"""exit_floor rounds q = 4 products down: a few ulps below the exact power, far inside 1e-12."""


def test_exit_room_is_the_smallest_face_distance_rounded_up():
    # support [-0.2, 0.2] in [-0.5, 0.5]: room 0.3 exactly in rationals of the floats
    r = exit_room([[-0.2, 0.2]], [[-0.5, 0.5]])
    exact = min(Fraction(-0.2) - Fraction(-0.5), Fraction(0.5) - Fraction(0.2))
    assert Fraction(r) >= exact and Fraction(math.nextafter(r, 0.0)) < exact
    # the smallest face wins, in any coordinate
    assert exit_room([[-1, 1], [0, 0.5]], [[-2, 2], [-0.25, 0.625]]) == 0.125
    # a support equal to the box, or sticking out of it: no room
    assert exit_room([[-1, 1]] * 4, [[-1, 1]] * 4) == 0.0
    assert exit_room([[-1, 1.5]], [[-2, 1]]) == 0.0


def test_exit_floor_is_a_lower_bound_of_the_power_and_infinite_without_room():
    fl = exit_floor(rho=0.17, room=0.3, q=4)
    exact = (Fraction(0.17) / Fraction(0.3)) ** 4
    assert Fraction(fl.floor) <= exact
    assert fl.floor == pytest.approx(float(exact), rel=FLOOR_RTOL)
    assert not fl.useless
    assert exit_floor(rho=0.4, room=0.3, q=2).useless  # rho >= room: >= 1 for every q
    none = exit_floor(rho=1e-9, room=0.0, q=8)
    assert none.floor == math.inf and none.useless
    assert exit_floor(rho=math.inf, room=1.0, q=2).floor == math.inf
    with pytest.raises(ValueError):
        exit_floor(rho=1.0, room=1.0, q=1)


def _box_result(upper: float, sampled: float, box) -> ContractionResult:
    return ContractionResult(
        rate=-upper,
        how=How.SOUND,
        method="mlp-bnb",
        scope=Scope(tuple(map(tuple, box))),
        max_mu_upper=upper,
        max_mu_sampled=sampled,
        witness=None,
        tolerance=1e-3,
        n_boxes=4095,
        time_s=0.0,
        stop="converged" if upper < 0 else "max_boxes",
        note="",
    )


def test_paper_like_chain_names_the_trace_the_box_bound_and_no_room():
    """The paper's plain-MLP situation: the trace condition rules out every LMI, the box search
    proves a positive bound only, the box is the support (no room)."""
    box = [[-1.0, 1.0]] * 4
    obs = TraceObstruction(0.2603, 0.5476, 0.5423, np.r_[np.ones(57), np.zeros(71)], 57)
    ca = ContractionAnalysis("learned", _box_result(2.1433, -0.02298, box), None, obstruction=obs)
    b = l1drac_learned_binding(ca, box, 7.48e6, 2)
    assert b is not None
    t = b["text"]
    assert "proves contraction for all x: tr J(s)/n = 0.2603 > 0" in t
    assert "57 of 128 neurons at the top of their slope range" in t
    assert "the proved bound is max mu_2 <= 2.143 > 0 (sampled -0.02298" in t
    assert "rho_L1 < room: 7.48e+06 >= 0" in t and "no room" in t and "delta_exit = 1" in t
    assert b["global"]["trace_over_n"] == 0.2603 and b["box"]["proved"] is False
    assert b["exit"]["room"] == 0.0 and b["exit"]["delta_exit_floor"] == "inf"
    assert b["exit"]["used_in_verdict"] is False
    json.dumps(b)  # JSON-ready


def test_chain_with_room_shows_the_floor_and_why_it_is_not_a_verdict():
    box = [[-0.5, 0.5]]
    ca = ContractionAnalysis("learned", _box_result(-1.255, -1.3, box), None)
    useful = l1drac_learned_binding(ca, [[-0.2, 0.2]], 0.1729, 2)
    assert useful is not None
    t = useful["text"]
    assert "no global route proves contraction for all x" in t
    assert "the rate 1.255 is proved (mlp-bnb), but L1-DRAC needs it for all x" in t
    assert "0.1729 < 0.3" in t and "not computed" in t
    assert 0.0 < useful["exit"]["delta_exit_floor"] < 1.0
    useless = l1drac_learned_binding(ca, [[-0.2, 0.2]], 2312.0, 2)
    assert useless is not None and "2312 >= 0.3" in useless["text"]
    assert useless["exit"]["useless"] is True and ">= 1" in useless["text"]
    # a rate proved for all x: no chain
    glob = ContractionAnalysis(
        "learned",
        ContractionResult(
            1.0, How.SOUND, "slope-lmi", Scope(), -1.0, -1.0, None, 0.0, 0, 0.0, "exact", ""
        ),
        None,
    )
    assert l1drac_learned_binding(glob, box, 1.0, 2) is None


SPEC_1D = """
# learned loop x' = -2 sin x + 0.5 x: mu = -2 cos x + 0.5 <= -1.255 on [-0.5, 0.5], +2.5 at x = pi
[system]
name = "box-only-learned-1d"
states = ["x1"]
inputs = ["u"]
horizon = 2.0

[dynamics]
f = ["-2*sin(x1)"]
g = [["1"]]

[policy]
expert = ["2*sin(x1) - x1"]
learned = ["0.5*x1"]

[uncertainty]
drift = ["0.05*sin(x1)"]
diffusion = [["0.02"]]

[initial]
support = [[-0.2, 0.2]]

[contraction]
region = [[-0.5, 0.5]]

[tasil]
trajectories = 4
heldout = 8
samples = 50

[l1drac]
p = 2
lambda_s = 10.0
delta = 0.05
"""


def test_certificate_json_and_report_name_the_l1drac_binding_chain(tmp_path):
    """End to end on a 1-D box-only learned loop: the L1-DRAC part stays conditional (no verdict
    from the exit floor) and its JSON and Markdown name the chain with its numbers."""
    from drip_cert.bounds.certificate import certify
    from drip_cert.report import certificate_markdown
    from drip_cert.schema import problems
    from drip_cert.spec.load import load_spec

    cert = certify(load_spec(write_spec(tmp_path, SPEC_1D)))
    d = cert.to_dict()
    assert problems(json.loads(json.dumps(d)), "certificate") == []
    parts = d["parts"]
    l1 = parts["l1drac"]
    assert l1["verdict"] == "conditional"
    b = l1["binding"]
    assert b["box"]["proved"] is True and b["box"]["region"] == [[-0.5, 0.5]]
    assert b["exit"]["room"] == pytest.approx(0.3) and b["exit"]["q"] == 4
    assert b["exit"]["used_in_verdict"] is False
    rho = cert.rho_l1_native
    assert rho is not None and b["exit"]["rho"] == rho
    md = certificate_markdown(cert)
    line = next(x for x in md.splitlines() if x.startswith("* l1drac conditional, binding"))
    assert "on the box [[-0.5, 0.5]], all t the rate" in line and f"{rho:.4g}" in line
    # a certified part has no binding condition
    assert all("binding" not in v for v in parts.values() if v["verdict"] == "certified")


@pytest.mark.slow  # trains a 64-64 MLP and certifies the 4-D paper example: ~3 min on 2 cores
def test_paper_plain_mlp_binding_condition(tmp_path, capsys):
    """Done-means of issue 24 on the paper example: `drip-cert train` with a plain MLP (the
    spec's [tasil] architecture = "mlp", its 2000 steps (~10 s; at 300 steps the sampled mu_2
    on the box is still +0.0026), seed 0) then `certify`: the L1-DRAC part is not
    certified and its binding condition is the chain with numbers: the trace condition rules out
    every slope-restricted LMI (tr J(s)/n > 0), the box bound is positive while the sampled
    value is negative, and the exit route has no room (the box is the support)."""
    import shutil

    from drip_cert.bounds.certificate import certify
    from drip_cert.report import certificate_markdown
    from drip_cert.spec.load import load_spec
    from tests.helpers import PAPER_4D_SPEC, run_cli

    text = PAPER_4D_SPEC.read_text()
    text = text.replace(
        'architecture = "residual"\nlipschitz_budget = 0.1\n', 'architecture = "mlp"\n'
    )
    text = text.replace('structure = ["h(x)[0]", "h(x)[1]", "h(x)[2]", "h(x)[3]"]\n', "")
    assert 'architecture = "mlp"' in text and "structure =" not in text
    for f in ("h.npz", "h.json"):
        shutil.copy(PAPER_4D_SPEC.parent / f, tmp_path / f)
    spec = write_spec(tmp_path, text, "paper_mlp.toml")
    out, trained = tmp_path / "run", tmp_path / "trained.toml"
    code, _, err = run_cli(
        capsys, "train", str(spec), "--seed", "0", "--out", str(out),
        "--no-compare", "--no-certify", "--write-spec", str(trained), "--quiet",
    )  # fmt: skip
    assert code == 0, err
    cert = certify(load_spec(trained))
    d = cert.to_dict()
    l1 = d["parts"]["l1drac"]
    assert l1["verdict"] == "not_certified"
    b = l1["binding"]
    assert b["global"]["route"] == "slope-lmi" and b["global"]["trace_over_n"] > 0.0
    assert b["box"]["proved"] is False
    assert b["box"]["max_mu_upper"] > 0.0 > b["box"]["max_mu_sampled"]
    assert b["exit"]["room"] == 0.0 and b["exit"]["useless"] is True
    assert b["exit"]["used_in_verdict"] is False
    md = certificate_markdown(cert)
    line = next(x for x in md.splitlines() if x.startswith("* l1drac not certified, binding"))
    assert f"tr J(s)/n = {b['global']['trace_over_n']:.4g} > 0" in line
    assert f"max mu_2 <= {b['box']['max_mu_upper']:.4g} > 0" in line and "no room" in line
    # train's summary names the same chain as its binding condition (L1DRAC-A2 fails first)
    from drip_cert.workflows import _binding

    tb = _binding(cert)
    assert tb["check"] == "L1DRAC-A2" and b["text"] in tb["text"]
    print(line)  # the numbers, for the record (pytest -s)
