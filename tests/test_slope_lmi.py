"""Slope-restricted LMI contraction of loops affine in MLP blocks (docs/math/contraction.md
section 10): closed forms, infeasibility, the Arb verification, the box route, the global route."""

from __future__ import annotations

import numpy as np
import pytest

from drip_cert.analysis.contraction.learned_loop import best_global_rate, lipschitz_rate
from drip_cert.analysis.contraction.slope_lmi import (
    box_slope_bnb,
    lmi_matrix,
    sampled_slopes,
    slope_lmi_rate,
    slope_structure,
    trace_obstruction,
    verify_slope_lmi,
)
from drip_cert.analysis.growth.closed_loop import AffineBlocks
from drip_cert.learn.imitation import learned_system
from drip_cert.model.mlp import MLP
from drip_cert.spec import load_spec
from tests.helpers import write_spec

#: Clarabel's optimality gap on these small SDPs is ~1e-8 relative; the verified rate is also
#: backed off by 1e-9 relative: a computed optimum this close to the closed form is the optimum
SOLVER_TOL = 1e-6
#: the verified rate may not exceed the true one by more than the float rounding of O(1) data
ROUNDING_TOL = 1e-12
#: random states for the "the bound holds" checks (a sampled max is a lower bound of the sup)
N_SAMPLES = 4000


def _one_neuron(a: float, c: float, w1: float, w2: float, act: str = "tanh"):
    """``F(x) = a x + c w2 s(w1 x)``: ``J = a + c w1 w2 s'``, ``s'`` in ``[0, 1]``."""
    mlp = MLP(
        weights=(np.array([[w1]]), np.array([[w2]])),
        biases=(np.zeros(1), np.zeros(1)),
        activation=act,
    )
    dec = AffineBlocks(np.array([[a]]), np.zeros(1), {"h": np.array([[c]])})
    return dec, {"h": mlp}


@pytest.mark.parametrize("act", ["tanh", "relu", "sigmoid"])
@pytest.mark.parametrize(("a", "c", "w1", "w2"), [(-1.0, 1.0, 1.0, 0.5), (-1.0, 1.0, 2.0, -3.0)])
def test_one_neuron_rate_is_the_closed_form(act, a, c, w1, w2):
    # 1 neuron, 1 constraint: the S-procedure is lossless (S-lemma), so the LMI rate is the exact
    # -max_{s in [lo, hi]} (a + c w1 w2 s)
    dec, mlps = _one_neuron(a, c, w1, w2, act)
    st = slope_structure(dec, mlps)
    lo, hi = float(st.alpha[0]), float(st.beta[0])
    exact = -max(a + c * w1 * w2 * lo, a + c * w1 * w2 * hi)
    res = slope_lmi_rate(st)
    assert res.rate is not None and res.euclidean
    assert res.rate <= exact + ROUNDING_TOL  # sound: never above the true rate
    assert res.rate == pytest.approx(exact, abs=SOLVER_TOL)


def test_infeasible_when_the_slope_set_holds_an_expanding_jacobian():
    # J = -1 + 2 s' reaches +1 at s' = 1: no LMI can prove contraction, and the reason names it
    dec, mlps = _one_neuron(-1.0, 1.0, 1.0, 2.0)
    res = slope_lmi_rate(slope_structure(dec, mlps))
    assert res.rate is None and res.status == "obstructed"
    assert res.obstruction.mean_eigenvalue == pytest.approx(1.0, abs=1e-6)
    assert "tr J(s)/n = 1" in res.reason


def test_trace_condition_is_the_exact_maximum_for_one_layer():
    # one hidden layer: tr J(s) is affine in s, so the per-layer maximum is the exact maximum;
    # compare with brute force over all 2^N vertices of a 5-neuron net
    rng = np.random.default_rng(3)
    W0, W1 = rng.standard_normal((5, 2)), rng.standard_normal((2, 5))
    mlp = MLP(weights=(W0, W1), biases=(np.zeros(5), np.zeros(2)))
    dec = AffineBlocks(-2.0 * np.eye(2), np.zeros(2), {"h": np.eye(2)})
    st = slope_structure(dec, {"h": mlp})
    obs = trace_obstruction(st)
    import itertools

    brute = max(
        np.trace(st.jacobian(np.where(np.array(v), st.beta, st.alpha))) / 2
        for v in itertools.product((0, 1), repeat=5)
    )
    assert obs.mean_eigenvalue == pytest.approx(brute, abs=1e-12)


def _nonnormal():
    """``A = [[-1, 3], [0, -1]]`` (Hurwitz, ``mu_2(A) = 0.5 > 0``) plus a small tanh net."""
    rng = np.random.default_rng(1)
    mlp = MLP(
        weights=(0.05 * rng.standard_normal((4, 2)), 0.05 * rng.standard_normal((2, 4))),
        biases=(np.zeros(4), np.zeros(2)),
    )
    dec = AffineBlocks(np.array([[-1.0, 3.0], [0.0, -1.0]]), np.zeros(2), {"h": np.eye(2)})
    return slope_structure(dec, {"h": mlp})


def test_euclidean_lmi_cannot_beat_mu2_but_a_metric_can():
    st = _nonnormal()
    eu = slope_lmi_rate(st)
    # P = I: the verified rate is an upper bound of -mu_2 at every Jacobian of the set, e.g. at
    # the midpoint slopes; here negative (no Euclidean contraction)
    J = st.jacobian(0.5 * (st.alpha + st.beta))
    assert eu.rate is not None and eu.rate <= -np.linalg.eigvalsh(0.5 * (J + J.T))[-1] < 0
    met = slope_lmi_rate(st, metric=True)
    assert met.rate is not None and met.rate > 0 and not met.euclidean


def test_arb_verification_rejects_a_perturbed_certificate():
    st = _nonnormal()
    res = slope_lmi_rate(st, metric=True)
    assert res.rate is not None
    P, t, lam = res.P, res.t, res.rate
    assert verify_slope_lmi(st, P, t, lam)
    # a faster rate, a perturbed metric, negative multipliers, a non-symmetric P: all rejected
    assert not verify_slope_lmi(st, P, t, lam + 0.05)
    Pp = P + np.array([[0.0, 0.0], [0.0, 0.5 * P[1, 1]]])
    assert np.linalg.eigvalsh(lmi_matrix(st, Pp, t, lam))[-1] > 0  # the float LMI fails too
    assert not verify_slope_lmi(st, Pp, t, lam)
    assert not verify_slope_lmi(st, P, -np.abs(t) - 1.0, lam)
    Pn = P.copy()
    Pn[0, 1] += 1e-3
    assert not verify_slope_lmi(st, Pn, t, lam)


def _two_layer(seed: int, scale: float):
    rng = np.random.default_rng(seed)
    mlp = MLP(
        weights=(
            scale * rng.standard_normal((6, 2)),
            scale * rng.standard_normal((6, 6)),
            scale * rng.standard_normal((2, 6)),
        ),
        biases=(0.3 * rng.standard_normal(6), 0.3 * rng.standard_normal(6), np.zeros(2)),
    )
    dec = AffineBlocks(np.array([[-1.0, 0.5], [-0.5, -1.0]]), np.zeros(2), {"h": 0.5 * np.eye(2)})
    return dec, {"h": mlp}


def _sampled_mu(st, mlps, X):
    S = sampled_slopes(st, mlps, X)
    Js = np.array([st.jacobian(s) for s in S])
    return np.linalg.eigvalsh(0.5 * (Js + np.swapaxes(Js, 1, 2)))[:, -1]


def test_global_rate_holds_at_sampled_states_of_a_deep_net():
    dec, mlps = _two_layer(0, 0.6)
    st = slope_structure(dec, mlps)
    res = slope_lmi_rate(st)
    assert res.rate is not None and res.rate > 0
    X = np.random.default_rng(0).uniform(-20, 20, (N_SAMPLES, 2))
    S = sampled_slopes(st, mlps, X)
    assert np.all(S >= st.alpha) and np.all(S <= st.beta)
    assert float(np.max(_sampled_mu(st, mlps, X))) <= -res.rate


def test_box_route_never_reports_a_rate_below_the_sampled_max():
    dec, mlps = _two_layer(2, 1.2)
    box = np.array([[-1.0, 1.0], [-0.5, 1.5]])
    out = box_slope_bnb(dec, mlps, box, target=-10.0, max_boxes=7)
    assert out.n_boxes == 7 and out.stop == "max_boxes"
    rng = np.random.default_rng(5)
    for b, ub in out.leaves:
        b = np.array(b)
        X = b[:, 0] + rng.random((N_SAMPLES // 4, 2)) * (b[:, 1] - b[:, 0])
        st = slope_structure(dec, mlps, b)
        S = sampled_slopes(st, mlps, X)
        assert np.all(S >= st.alpha) and np.all(S <= st.beta)  # local ranges contain the slopes
        assert float(np.max(_sampled_mu(st, mlps, X))) <= ub
    assert out.max_mu_upper == max(ub for _, ub in out.leaves)
    # local slope ranges are narrower than the global ones: the box bound is below the global
    glob = slope_lmi_rate(slope_structure(dec, mlps), obstruct=False)
    assert glob.rate is not None and out.max_mu_upper <= -glob.rate


SPEC = """
[system]
name = "two"
states = ["x1", "x2"]
horizon = 2.0

[dynamics]
f = ["-x1 + 0.5*x2", "-0.5*x1 - x2"]
g = [["0.5", "0"], ["0", "0.5"]]

[policy]
expert = ["-x1", "-x2"]

[initial]
support = [[-1.0, 1.0], [-1.0, 1.0]]
"""


@pytest.fixture(scope="module")
def system(tmp_path_factory):
    return load_spec(write_spec(tmp_path_factory.mktemp("sl"), SPEC)).system


def test_global_route_proves_what_the_lipschitz_route_cannot(system):
    # pi(x) = -W^T tanh(W x): J = A - 0.5 W^T S W with S >= 0, so mu_2(J) <= mu_2(A) = -1 for all
    # x (the exact sup over the slope set, at S = 0); the Lipschitz route sees +0.5 ||W||^2
    W = 2.0 * np.random.default_rng(4).standard_normal((6, 2))
    net = MLP(weights=(W, -W.T), biases=(np.zeros(6), np.zeros(2)))
    s = learned_system(system, net)
    lip = lipschitz_rate(s)
    assert lip is not None and not lip.result.holds
    reasons: list[str] = []
    g = best_global_rate(s, None, reasons)
    assert g is not None and g.result.method == "slope-lmi" and g.result.holds
    assert g.result.scope.all_x and g.result.how.proved
    assert g.rate.value <= 1.0 + ROUNDING_TOL
    assert g.rate.value == pytest.approx(1.0, abs=SOLVER_TOL)
    assert reasons == []


def test_global_route_gives_the_obstruction_as_its_reason(system):
    # pi(x) = +W^T tanh(W x): at S = I the loop expands (tr > 0), so the route proves nothing
    W = 2.0 * np.random.default_rng(4).standard_normal((6, 2))
    net = MLP(weights=(W, W.T), biases=(np.zeros(6), np.zeros(2)))
    s = learned_system(system, net)
    reasons: list[str] = []
    g = best_global_rate(s, None, reasons)
    assert g is None or not g.result.holds
    assert len(reasons) == 1 and "slope-lmi route" in reasons[0] and "tr J(s)/n" in reasons[0]


def _ctx(name: str):
    from proofs_check._core import Context, make_rng

    return Context(rng=make_rng(0, name), quick=True, seed=0)


def test_proofs_check_incremental_contraction_holds_and_fails_on_narrow_slopes():
    from proofs_check import Verdict
    from proofs_check.slope_lmi import check_incremental_contraction

    name = "slope_lmi.incremental_contraction"
    assert check_incremental_contraction(_ctx(name)).verdict is Verdict.PASS
    # half of every slope range is a wrong constraint (11.2): pairs of states violate the rate
    bad = check_incremental_contraction(_ctx(name), slope_scale=0.5)
    assert bad.verdict is Verdict.FAIL and bad.residual > 0


def test_proofs_check_trace_condition_holds_and_fails_without_the_division_by_n():
    from proofs_check import Verdict
    from proofs_check.slope_lmi import check_trace_condition

    name = "slope_lmi.trace_condition"
    assert check_trace_condition(_ctx(name)).verdict is Verdict.PASS
    assert check_trace_condition(_ctx(name), divisor=1.0).verdict is Verdict.FAIL


SIGNED_NET_SPEC = """
[system]
name = "signed-net"
states = ["x1", "x2"]
inputs = ["u1", "u2"]
horizon = 2.0

[blocks.pi_il]
kind = "mlp"
weights = "pi.npz"
inputs = 2
outputs = 2

[dynamics]
f = ["-x1 + 0.5*x2", "-0.5*x1 - x2"]
g = [["0.5", "0"], ["0", "0.5"]]

[policy]
expert = ["-x1", "-x2"]
learned = ["pi_il(x)[0]", "pi_il(x)[1]"]

[uncertainty]
drift = ["0.05*sin(x1)", "0.05*cos(x2)"]
diffusion = [["0.02", "0"], ["0", "0.02"]]

[initial]
support = [[-1.0, 1.0], [-1.0, 1.0]]

[contraction]
max_boxes = 200
metric = "euclidean"

[l1drac]
p = 2
lambda_s = 10.0
delta = 0.05
"""


@pytest.mark.slow
def test_certify_proves_a_plain_mlp_loop_globally_and_certifies_l1drac(tmp_path, capsys):
    # pi = -W^T tanh(W x) with ||W||^2 ~ 30: the Lipschitz routes fail, the box route proves only
    # a box (before this route: verdict not_certified); the slope LMI proves rate 1 on all x
    import json

    from drip_cert.model.mlp import save_mlp
    from tests.helpers import run_cli

    W = 2.0 * np.random.default_rng(4).standard_normal((6, 2))
    save_mlp(MLP(weights=(W, -W.T), biases=(np.zeros(6), np.zeros(2))), tmp_path / "pi.npz")
    spec = write_spec(tmp_path, SIGNED_NET_SPEC)
    code, out, _ = run_cli(capsys, "certify", str(spec), "--json")
    cert = json.loads(out)
    learned = cert["contraction"]["learned"]
    assert learned["method"] == "slope-lmi" and learned["scope"]["box"] is None
    assert learned["rate"] == pytest.approx(1.0, abs=SOLVER_TOL)
    assert all(p["verdict"] == "certified" for p in cert["parts"].values())
    assert code == 0 and cert["verdict"] == "certified"
