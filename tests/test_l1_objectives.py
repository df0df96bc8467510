"""L1-DRAC design objectives, the (Ts, rho) Pareto front and the knife edge (issue 14).

Mathematics first: the monotonicity L1-DRAC states or implies (Remarks 3.1, 3.2: every
omega-dependent coefficient of (18b), (18c), (22), (23) falls for omega > 2 lambda, so the smallest
radii do not grow; Ts_max is non-decreasing in rho_a), the front is Pareto, each objective's
answer against the front, a closed-form case, and the default is never a knife edge. Every point
is re-verified independently by evaluating the design with every parameter fixed.
"""

from __future__ import annotations

import dataclasses
import json
import math
from pathlib import Path

import pytest

from drip_cert.bounds.l1drac import searches
from drip_cert.bounds.l1drac.constants import L1Constants
from drip_cert.bounds.l1drac.designer import design, knife_edge, pareto_front, tradeoff_table
from drip_cert.bounds.l1drac.request import PRACTICAL_TS, DesignRequest
from drip_cert.bounds.l1drac.result import KNIFE_EDGE_RTOL, KNIFE_EDGE_TS_MIN, L1Design
from drip_cert.bounds.l1drac.toml import load_l1_constants
from drip_cert.cli import main
from drip_cert.errors import SpecError
from drip_cert.spec.settings import L1Settings
from tests.helpers import EXAMPLES, di_constants

PAPER_4D_EXPERT = EXAMPLES / "l1drac_constants" / "paper_4d_expert.toml"
#: two bisections to ROOT_RTOL = 1e-12 through different brackets: a "non-increasing" sequence of
#: minimal roots may rise by this much between neighbours without contradicting the proof
ROOT_SLACK = 1e-9
#: omegas above 2 lambda, in multiples of lambda (the grid of the monotonicity check)
OMEGA_MULTIPLES = (2.5, 3, 5, 10, 30, 1e2, 1e3, 1e4, 1e5, 1e6)


@pytest.fixture(scope="module")
def paper() -> tuple[L1Constants, DesignRequest]:
    return load_l1_constants(PAPER_4D_EXPERT)


@pytest.fixture(scope="module")
def paper_default(paper) -> L1Design:
    c, req = paper
    return design(c, req)


@pytest.fixture(scope="module")
def di() -> L1Constants:
    return di_constants()


@pytest.fixture(scope="module")
def di_default(di) -> L1Design:
    return design(di, DesignRequest(p=1, lambda_s=100.0))


def closed_form_constants() -> L1Constants:
    """Gamma_r = Gamma_a = Theta_r = Theta_a = 0 and k_r = k_a = 0 (p = 1, no diffusion, no
    unmatched and no matched-parallel uncertainty): (16a) is rho_r^2 >= alpha^2 + eps_r = 1 and
    (16b) rho_a^2 >= eps_a = 0.25 at every omega; Delta_f, Delta_mu, L_mu > 0 keep (24) alive."""
    from drip_cert.bounds.l1drac.constants import CONSTANT_NAMES

    d: dict[str, float | int | bool] = {n: 0.0 for n in CONSTANT_NAMES}
    d.update(
        {
            "lambda": 10.0,
            "Delta_f": 1.0,
            "Delta_g": 1.0,
            "Delta_Theta": 1.0,
            "Delta_mu": 1.0,
            "L_mu": 1.0,
            "alpha": 0.5,
            "eps_r": 0.75,
            "eps_a": 0.25,
            "p_star": 8,
            "m": 1,
            "lip_f": False,
        }
    )
    return L1Constants.from_mapping(d)


def reverify(c: L1Constants, p: int, pt) -> L1Design:
    """The design with every parameter fixed: evaluated only, verified in Arb, never moved."""
    return design(
        c,
        DesignRequest(
            p=p,
            omega=pt.omega,
            lambda_s=pt.lambda_s,
            Ts=pt.Ts,
            rho_r=pt.rho_r,
            rho_a=pt.rho_a,
            front=False,
        ),
    )


# ------------------------------------------------------------------ monotonicity (paper)


@pytest.mark.parametrize("which", ["paper", "di"])
def test_smallest_rho_non_increasing_in_omega_above_2_lambda(which, paper, di) -> None:
    """Remarks 3.1, 3.2: for omega > 2 lambda the coefficients omega/|2l - w|, sqrt(w)/|2l - w|
    and 1/|2l - w| of (18b), (18c), (22), (23) all decrease in omega (d/dw sqrt(w)/(w - 2l) =
    -(w + 2l)/(2 sqrt(w)(w - 2l)^2) < 0), so each condition's feasible set of radii grows and the
    smallest rho_r, rho_a (hence rho) cannot increase."""
    c, p = (paper[0], 2) if which == "paper" else (di, 1)
    rho = []
    for k in OMEGA_MULTIPLES:
        w = k * c.lam
        rr = searches.smallest_rho_r(c, p, w)
        ra = None if rr is None else searches.smallest_rho_a(c, p, w, rr, which=("16b", "21b"))
        rho.append(math.inf if rr is None or ra is None else rr + ra)  # inf: (21) infeasible
    assert math.isfinite(rho[-1])  # Remark 3.2: (21) is feasible for a large enough omega
    assert all(b <= a * (1 + ROOT_SLACK) for a, b in zip(rho, rho[1:]))


def test_Ts_max_non_decreasing_in_rho_a_at_the_default_design(paper_default, paper) -> None:
    """(24) at fixed Ts is an up-set in rho_a (searches.smallest_rho_a), so a larger rho_a buys a
    larger Ts_max: checked at the default design's (omega, lambda_s)."""
    d = paper_default
    rows = tradeoff_table(paper[0], d.p, d.omega, d.lambda_s, n=10, max_factor=1e4)
    ts = [r.Ts_max for r in rows]
    assert all(t is not None for t in ts)
    assert all(b >= a for a, b in zip(ts, ts[1:]))


# ------------------------------------------------------------------ the front


@pytest.mark.parametrize("which", ["paper", "di"])
def test_front_is_pareto_sorted_and_every_point_verified(
    which, paper, paper_default, di, di_default
) -> None:
    c, p, d = (paper[0], 2, paper_default) if which == "paper" else (di, 1, di_default)
    front = d.front
    assert len(front) >= 5
    ts = [pt.Ts for pt in front]
    rho = [pt.rho for pt in front]
    assert ts == sorted(ts)
    # Pareto: along the front rho strictly increases with Ts, so no point is dominated
    assert all(b > a for a, b in zip(rho, rho[1:]))
    for a in front:
        assert not any(
            b is not a and b.Ts >= a.Ts and b.rho <= a.rho and (b.Ts > a.Ts or b.rho < a.rho)
            for b in front
        )
    for pt in front:
        assert pt.verified and pt.rho == pt.rho_r + pt.rho_a
        again = reverify(c, p, pt)  # an independent re-check with everything fixed
        assert again.feasible and again.verified and again.backoff == ()
        assert min(r.margin_lo for r in again.conditions) > 0.0
        assert bool(pt.knife_edge) == bool(knife_edge(again))


def test_pareto_front_function_matches_the_designs_front(paper, paper_default) -> None:
    c, req = paper
    front = pareto_front(c, req)
    chosen = paper_default
    # the same candidates, the returned design aside (it replaces the grid point at its Ts)
    assert [(pt.Ts, pt.rho) for pt in front] == [(pt.Ts, pt.rho) for pt in chosen.front]


# ------------------------------------------------------------------ objectives


def test_default_is_the_practical_Ts_and_not_a_knife_edge(paper_default, di_default) -> None:
    for d in (paper_default, di_default):
        assert d.feasible and d.verified and d.objective == "default"
        assert d.Ts == PRACTICAL_TS  # exactly: Ts is fixed by the objective, never backed off
        assert knife_edge(d) == "" and d.knife_edge == ""
        assert d.Ts >= KNIFE_EDGE_TS_MIN
        r21b = next(r for r in d.conditions if r.eq == "21b")
        assert r21b.margin_lo / r21b.rhs >= KNIFE_EDGE_RTOL
        assert "practical T_s" in d.choice
        assert dict(d.how)["Ts"] == "found"
        # no front point at the same Ts has a smaller rho
        assert all(pt.rho >= d.rho for pt in d.front if pt.Ts == d.Ts)


def test_min_rho_is_the_knife_edge_the_default_avoids(paper, paper_default) -> None:
    """The pre-issue-14 default: omega at the top of its interval, Ts ~ 1e-56 s."""
    c, req = paper
    d = design(c, dataclasses.replace(req, objective="min_rho", front=False))
    assert d.feasible and d.verified
    why = knife_edge(d)
    assert why and "below 1e-09 s" in why and "(21b)" in why
    assert d.rho < paper_default.rho  # the infimum of rho, bought with an absurd Ts
    assert any(pt.knife_edge and pt.rho <= d.rho * (1 + ROOT_SLACK) for pt in paper_default.front)


@pytest.mark.parametrize("Ts", [1e-5, 1e-3])
def test_Ts_given_is_exact_and_no_worse_than_the_front(paper, Ts) -> None:
    c, req = paper
    d = design(c, dataclasses.replace(req, objective=None, Ts=Ts))
    assert d.feasible and d.objective == "rho_at_Ts" and d.Ts == Ts
    assert dict(d.how)["Ts"] == "given" and "Ts" not in dict(d.backoff)
    at = [pt for pt in d.front if pt.Ts == Ts]
    assert at and all(d.rho <= pt.rho for pt in at)


def test_Ts_given_infeasible_says_what_would_be_feasible(paper) -> None:
    c, req = paper
    d = design(c, dataclasses.replace(req, objective=None, Ts=10.0))
    assert not d.feasible and d.objective == "rho_at_Ts"
    assert "largest T_s of the front with a verified design" in d.reason
    top = max(pt.Ts for pt in d.front)
    assert f"{top:.3g} s" in d.reason


def test_Ts_given_over_budget_is_infeasible(paper) -> None:
    c, req = paper
    d = design(c, dataclasses.replace(req, objective=None, Ts=1e-3, rho_budget=100.0, front=False))
    assert not d.feasible and "above rho_budget" in d.reason


@pytest.mark.parametrize("budget", [200.0, 1e3, 1e4])
def test_rho_budget_respected_and_Ts_beats_the_front(paper, budget) -> None:
    c, req = paper
    d = design(c, dataclasses.replace(req, objective=None, rho_budget=budget))
    assert d.feasible and d.verified and d.objective == "Ts_at_rho"
    assert d.rho <= budget
    within = [pt.Ts for pt in d.front if pt.rho <= budget]
    assert within and d.Ts >= max(within)


def test_budget_below_the_infimum_is_a_result_with_the_fix(paper) -> None:
    c, req = paper
    d = design(c, dataclasses.replace(req, objective=None, rho_budget=1.0, front=False))
    assert not d.feasible and "raise rho_budget" in d.reason


def test_default_falls_back_to_the_front_with_a_reason(di) -> None:
    """omega = 1e3 and rho_a = 1 fixed: (24) needs Ts ~ 2.8e-8 s (docs/math/l1drac.md section 8),
    so 1e-3 s fails; the default returns the largest Ts at the fixed radii and says why."""
    d = design(di, DesignRequest(p=1, lambda_s=100.0, omega=1e3, rho_a=1.0))
    assert d.feasible and d.objective == "default" and d.knife_edge == ""
    assert "no design at the practical T_s" in d.choice and "(24)" in d.choice
    rr = searches.smallest_rho_r(di, 1, 1e3)
    ts_max = searches.largest_Ts(di, 1, 1e3, 100.0, rr, 1.0)
    assert d.Ts <= ts_max and d.Ts == max(pt.Ts for pt in d.front)


def test_default_never_raises_for_a_fixed_omega_too_fast_for_1ms(di) -> None:
    """omega = 1e6 fixed: omega Ts = 1e3 at 1e-3 s overflows the exponentials of (A.13)-(A.19);
    the default reports that and falls back, no exception."""
    d = design(di, DesignRequest(p=1, lambda_s=100.0, omega=1e6))
    assert "too long for the fixed omega" in d.choice
    assert d.feasible and d.knife_edge == "" and d.Ts < PRACTICAL_TS


def test_closed_form_case() -> None:
    """Gamma = Theta = 0: the smallest radii are rho_r = sqrt(alpha^2 + eps_r) = 1 and
    rho_a = sqrt(eps_a) = 0.5 at every omega and Ts (exact dyadic roots, moved into the interior
    by the first back-off factor); (24) is then the only condition that reads Ts."""
    c = closed_form_constants()
    d = design(c, DesignRequest(p=1, lambda_s=100.0))
    f = 1.0 + 1e-9  # BACKOFF_START: the first back-off step verifies an exact root
    # rho does not depend on Ts here: a longer Ts with the same radii dominates 1e-3 s
    assert d.feasible and d.Ts >= PRACTICAL_TS and "dominates" in d.choice
    assert d.rho_r == 1.0 * f and d.rho_a == 0.5 * f
    assert d.knife_edge == ""  # (16b) binds, (21b) keeps all of rho_a^2: no cancellation in (24)
    for pt in d.front:
        assert pt.rho_r == 1.0 * f and pt.rho_a >= 0.5
    b = design(c, DesignRequest(p=1, lambda_s=100.0, rho_budget=3.0))
    assert b.feasible and b.rho <= 3.0 and b.Ts >= max(pt.Ts for pt in b.front if pt.rho <= 3.0)


# ------------------------------------------------------------------ settings, JSON, CLI


@pytest.mark.parametrize(
    ("table", "field", "words"),
    [
        ({"objective": "fast"}, "l1drac.objective", ["fast", "rho_at_Ts"]),
        ({"objective": "rho_at_Ts"}, "l1drac.objective", ["needs", "Ts"]),
        ({"objective": "Ts_at_rho"}, "l1drac.objective", ["rho_budget"]),
        ({"objective": "default", "Ts": 1e-3}, "l1drac.objective", ["remove Ts"]),
        ({"objective": "min_rho", "rho_budget": 5.0}, "l1drac.objective", ["no rho_budget"]),
        ({"rho_budget": -1.0}, "l1drac.rho_budget", ["> 0"]),
        ({"rho_budget": 1.0, "rho_r": 1.0, "rho_a": 1.0}, "l1drac.rho_budget", ["raise"]),
        ({"front": 1}, "l1drac.front", ["true or false"]),
    ],
)
def test_settings_rejected_at_load(table, field, words) -> None:
    with pytest.raises(SpecError) as e:
        L1Settings.from_table(table)
    assert e.value.field == field
    assert all(w in str(e.value) for w in words), str(e.value)


def test_settings_infer_the_objective() -> None:
    assert L1Settings.from_table({}).objective == "default"
    assert L1Settings.from_table({"Ts": 1e-3}).objective == "rho_at_Ts"
    assert L1Settings.from_table({"rho_budget": 50.0}).objective == "Ts_at_rho"
    assert L1Settings.from_table({"omega": 50.0, "rho_a": 8.0}).objective == "default"


def test_json_has_objective_choice_knife_edge_and_front(paper_default) -> None:
    js = json.loads(json.dumps(paper_default.to_dict(), allow_nan=False))
    assert js["objective"] == "default" and js["choice"]
    assert js["knife_edge"]["is"] is False
    assert js["knife_edge"]["rules"]["Ts_min"] == KNIFE_EDGE_TS_MIN
    assert js["practical_Ts"] == PRACTICAL_TS
    keys = {"Ts", "rho", "rho_r", "rho_a", "omega", "lambda_s", "verified", "knife_edge", "source"}
    assert js["front"] and all(set(pt) == keys for pt in js["front"])


def test_cli_design_l1_Ts_rho_budget_and_figure(tmp_path: Path, capsys) -> None:
    fig = tmp_path / "front.png"
    rc = main(["design-l1", str(PAPER_4D_EXPERT), "--Ts", "1e-4", "--json", "--figure", str(fig)])
    out = json.loads(capsys.readouterr().out)
    assert rc == 0 and out["objective"] == "rho_at_Ts" and out["Ts"] == 1e-4
    assert fig.stat().st_size > 10_000 and out["figure"] == str(fig)
    rc = main(["design-l1", str(PAPER_4D_EXPERT), "--rho-budget", "500"])
    text = capsys.readouterr().out
    assert rc == 0 and "objective: Ts_at_rho" in text and "Pareto front" in text
    rc = main(["design-l1", str(PAPER_4D_EXPERT), "--rho-budget", "-1"])
    assert rc == 2


def test_figure_of_an_empty_front(tmp_path: Path) -> None:
    from drip_cert.figures_l1 import l1_front_figure

    out = l1_front_figure({"feasible": False, "front": []}, tmp_path / "empty.png")
    assert out.exists() and math.isfinite(out.stat().st_size)
