"""``System.transformed``: a constant change of coordinates ``z = Theta x``
(docs/math/contraction.md Proposition 5.1), exact in rational arithmetic."""

from __future__ import annotations

import itertools
import math

import numpy as np
import pytest
import sympy as sp

from drip_cert.analysis.contraction.lognorm import mu2_constant_bounds
from drip_cert.errors import SpecError
from drip_cert.model.blocks import mlp_block
from drip_cert.model.mlp import init_mlp
from drip_cert.model.system import System

FLOAT_RTOL = 1e-12  #: jax float64 evaluation of the same expression in two coordinate systems

q, v = sp.symbols("q v", real=True)
#: damped oscillator q'' = -q - 0.5 q' + u in natural coordinates; expert u = -q - q':
#: closed-loop Jacobian [[0, 1], [-2, -1.5]] has mu_2 > 0 (the zero (1,1) entry) although both
#: poles have real part -0.75
OSC = System(
    name="oscillator",
    states=(q, v),
    f=[v, -q - sp.Rational(1, 2) * v],
    g=[[0], [1]],
    expert=[-q - v],
    lambda_mu=[0, sp.Rational(1, 10) * sp.sin(q)],
    diffusion=[[0], [sp.Rational(1, 20)]],
    support=[(-1.0, 1.0), (-0.5, 0.5)],
    horizon=5.0,
)
#: a Lyapunov metric of the closed loop above (A^T P + P A < 0), and its Cholesky factor
P = np.array([[2.0, 0.5], [0.5, 1.0]])
THETA = np.linalg.cholesky(P).T  # P = Theta^T Theta


def _J(s: System) -> sp.Matrix:
    return sp.Matrix(s.closed_loop_jacobian("expert"))


def test_jacobian_transforms_by_similarity_exactly():
    Z = OSC.transformed(THETA)
    Th = sp.Matrix(THETA.tolist()).applyfunc(sp.Rational)
    expected = Th * _J(OSC) * Th.inv()
    assert sp.simplify(_J(Z) - expected) == sp.zeros(2, 2)


def test_the_metric_turns_a_positive_euclidean_log_norm_negative():
    """mu_2(J) > 0 in (q, q'), mu_2(Theta J Theta^{-1}) = mu_{2,P}(J) < 0 in z."""
    lo_x, _ = mu2_constant_bounds(np.array(_J(OSC), dtype=float))
    assert lo_x > 0.0
    Jz = _J(OSC.transformed(THETA))
    _, hi_z = mu2_constant_bounds(Jz)
    assert hi_z < 0.0


def test_round_trip_gives_back_the_system():
    Z = OSC.transformed(THETA)
    Th = sp.Matrix(THETA.tolist()).applyfunc(sp.Rational)
    back = Z.transformed(Th.inv())
    rename = dict(zip(back.states, OSC.states, strict=True))
    for a, b in ((back.f, OSC.f), (back.g, OSC.g), (back.expert, OSC.expert)):
        assert sp.simplify(sp.Matrix(a).xreplace(rename) - sp.Matrix(b)) == sp.zeros(*b.shape)
    assert sp.simplify(sp.Matrix(back.lambda_mu).xreplace(rename) - OSC.lambda_mu) == sp.zeros(2, 1)


def test_support_is_the_tightest_enclosing_box_of_the_image():
    """Each bound is the exact extreme of Theta x over the box's vertices, rounded outward by at
    most one float (checked in exact rational arithmetic)."""
    Z = OSC.transformed(THETA)
    Th = sp.Matrix(THETA.tolist()).applyfunc(sp.Rational)
    verts = [
        sp.Matrix([sp.Rational(a), sp.Rational(b)]) for a, b in itertools.product(*OSC.support)
    ]
    img = [Th * x for x in verts]
    for i, (lo, hi) in enumerate(Z.support):
        exact_lo, exact_hi = min(y[i] for y in img), max(y[i] for y in img)
        assert sp.Rational(lo) <= exact_lo < sp.Rational(np.nextafter(lo, np.inf))
        assert sp.Rational(np.nextafter(hi, -np.inf)) < exact_hi <= sp.Rational(hi)


def test_blocks_are_composed_and_numerics_agree():
    """With an MLP block in the policy, f_z(z) + g_z pi_z(z) = Theta (f + g pi)(Theta^{-1} z)."""
    mlp = init_mlp([2, 4, 1], np.random.default_rng(0), activation="tanh")
    blk = mlp_block("h", mlp)
    s = System(
        name="with block",
        states=(q, v),
        f=[v, -q],
        g=[[0], [1]],
        expert=[-q - v + blk.component(0)(q, v)],
        support=[(-1.0, 1.0), (-1.0, 1.0)],
        horizon=1.0,
        blocks={"h": blk},
    )
    Z = s.transformed(THETA)
    Ti = np.linalg.inv(THETA)
    rng = np.random.default_rng(1)
    for z in rng.normal(size=(5, 2)):
        x = Ti @ z
        fx = np.asarray(s.numeric.f(0.0, x)) + np.asarray(s.numeric.g(0.0, x)) @ np.asarray(
            s.numeric.expert(x)
        )
        fz = np.asarray(Z.numeric.f(0.0, z)) + np.asarray(Z.numeric.g(0.0, z)) @ np.asarray(
            Z.numeric.expert(z)
        )
        np.testing.assert_allclose(fz, THETA @ fx, rtol=FLOAT_RTOL, atol=FLOAT_RTOL)


def test_given_growth_bounds_are_scaled_soundly():
    s = System(
        name="given",
        states=(q, v),
        f=[v, -q],
        g=[[0], [1]],
        expert=[-q - v],
        Delta_mu=0.2,
        support=[(-1.0, 1.0), (-1.0, 1.0)],
        horizon=1.0,
    )
    Z = s.transformed(THETA)
    k = np.linalg.norm(THETA, 2) * max(1.0, np.linalg.norm(np.linalg.inv(THETA), 2))
    assert Z.Delta_mu >= 0.2 * k  # Frobenius >= spectral: never below the tight factor


@pytest.mark.parametrize(
    "theta, match",
    [
        ([[1.0, 2.0], [2.0, 4.0]], "singular"),
        ([[1.0, 0.0, 0.0]], "2 x 2"),
        ([[float("nan"), 0.0], [0.0, 1.0]], "finite"),
    ],
)
def test_bad_theta_is_a_spec_error(theta, match):
    with pytest.raises(SpecError, match=match):
        OSC.transformed(np.array(theta))


# ------------------------------------------------------------------ certify in metric coordinates
def _osc_spec(metric: str | None = None):
    from drip_cert.spec.load import Spec

    tables = {} if metric is None else {"contraction": {"metric": metric}}
    return Spec(None, OSC, tables)


SLOWEST_POLE = 0.75  #: closed-loop poles of [[0, 1], [-2, -1.5]]: -0.75 +- 1.2i
RATE_REL = 0.01  #: the issue's requirement: within 1 % of the best constant-metric rate


def test_certify_uses_the_metric_when_the_euclidean_rate_fails():
    from drip_cert.bounds.certificate import certify

    cert = certify(_osc_spec())
    assert cert.coordinates is not None
    assert cert.verdict.value == "certified"
    rate = cert.contraction_expert.euclidean.rate
    assert SLOWEST_POLE * (1 - RATE_REL) <= rate <= SLOWEST_POLE  # never above the true rate
    alt = cert.alternatives[0]
    assert alt["coordinates"] == "x" and alt["verdict"] == "not_certified"
    d = cert.to_dict()["coordinates"]
    assert d["system"] == "z = Theta x" and d["factor_to_x"] >= 1.0  # ||Theta^{-1}|| >= 1 here
    # the rigorous factors bracket the float norms of Theta and its inverse
    assert d["factor_to_z"] >= np.linalg.norm(cert.coordinates.theta, 2)
    assert d["factor_to_x"] >= np.linalg.norm(np.linalg.inv(cert.coordinates.theta), 2)


def test_euclidean_request_keeps_x_and_fails_honestly():
    from drip_cert.bounds.certificate import certify

    cert = certify(_osc_spec("euclidean"))
    assert cert.coordinates is None
    assert cert.verdict.value == "not_certified"


def test_a_given_metric_is_used_and_a_wrong_one_does_not_certify():
    from drip_cert.bounds.certificate import certify
    from drip_cert.spec.load import Spec

    good = certify(Spec(None, OSC, {"contraction": {"metric": P.tolist()}}))
    assert good.coordinates is not None and good.verdict.value == "certified"
    wrong = certify(Spec(None, OSC, {"contraction": {"metric": [[1.0, 0.0], [0.0, 1.0]]}}))
    assert wrong.verdict.value == "not_certified"  # identity metric = Euclidean: mu_2 > 0


def test_rho_maps_back_by_the_factor():
    """rho_TaSIL in x = factor_to_x * rho_TaSIL in z, rounded up; in x coordinates unchanged."""
    import dataclasses
    from types import SimpleNamespace

    from drip_cert.bounds.certificate import certify
    from drip_cert.numerics.rounding import mul_up

    cert = certify(_osc_spec())
    native = SimpleNamespace(rho=0.5)  # a TaSIL section with rho = 0.5 in z
    c2 = dataclasses.replace(
        cert, coordinates=dataclasses.replace(cert.coordinates, to_x=3.0), tasil=native
    )
    assert c2.rho_tasil_native == 0.5
    assert c2.rho_tasil == mul_up(3.0, 0.5)
    c3 = dataclasses.replace(cert, coordinates=None, tasil=native)
    assert c3.rho_tasil == 0.5


@pytest.mark.parametrize("name", ["pendulum", "van_der_pol", "cart_pole"])
def test_natural_coordinate_examples_are_certified_through_the_metric(name):
    """Each closed loop is linear (after the expert's cancellation): DRIP Assumption 2 holds in a
    metric at a rate within 1 % of the slowest pole, never above it; the whole certificate is
    certified in z, in the metric with the smallest final radius; in x it is not."""
    from drip_cert.bounds.certificate import certify
    from drip_cert.spec import load_spec
    from tests.helpers import example_spec

    spec = load_spec(example_spec(name))
    J = np.array(sp.Matrix(spec.system.closed_loop_jacobian("expert")).expand(), dtype=float)
    slowest = -max(np.linalg.eigvals(J).real)
    cert = certify(spec)
    best = cert.to_dict()["contraction"]["metric_rate"]  # the best constant-metric rate found
    assert slowest * (1 - RATE_REL) <= best <= slowest
    assert 0 < cert.contraction_expert.euclidean.rate <= best  # the metric chosen for rho
    assert cert.coordinates is not None
    assert cert.verdict.value == "certified", cert.verdict_reasons
    alts = cert.alternatives
    assert [a["verdict"] for a in alts if a["coordinates"] == "x"] == ["not_certified"]
    # every part certified, the L1-DRAC design at the simulable sampling period the spec gives
    # (Ts, objective "rho_at_Ts"; omega, lambda_s and the radii found by the designer)
    assert {k: v["verdict"] for k, v in cert.part_verdicts().items()} == {
        "contraction": "certified",
        "tasil": "certified",
        "l1drac": "certified",
    }
    assert cert.l1.design.Ts >= SIMULABLE_TS
    # issue 25: the design is the designer's at the spec's T_s (nothing else fixed), and its
    # rho_L1 does not grow back towards the ~8 of the former fixed omega = 50, rho_a = 8
    assert cert.l1.design.objective == "rho_at_Ts"
    assert cert.rho_l1 <= RHO_L1_MEASURED[name] * (1.0 + RHO_L1_RTOL)
    # chosen by the final radius: no certified alternative has a smaller rho_TaSIL + rho_L1 in x
    others = [a["rho_tasil_x"] + a["rho_l1_x"] for a in alts if a["verdict"] == "certified"]
    assert all(cert.rho_tasil + cert.rho_l1 <= r for r in others)
    from drip_cert.numerics.rounding import mul_up

    assert cert.rho_l1 == mul_up(cert.coordinates.to_x, cert.rho_l1_native)  # Proposition 5.3
    assert cert.rho_tasil == mul_up(cert.coordinates.to_x, cert.rho_tasil_native)


RHO_L1_MEASURED = {"pendulum": 0.849572, "van_der_pol": 0.643713, "cart_pole": 4.125280}
"""rho_L1 in x of the examples' certificates (branch h25gal; 8.417, 8.211, 8.754 with the former
fixed omega = 50, rho_a = 8): validated at the certified parameters in docs/gallery.md. Cart-pole
4.100999 -> 4.125280 (+0.6 %) since the metric SDP calls Clarabel directly (issue 26): another
feasible P (cond 8057 -> 7333, the same rate within the bisection's 1e-4) gives other natural
coordinates."""

RHO_L1_RTOL = 1e-3
"""The design is a function of its inputs (count-limited searches, Arb-verified); 0.1 % leaves
room for float differences across BLAS builds and nothing for a real loosening."""

SIMULABLE_TS = 1e-3
"""The examples give T_s = 1.81e-3 to 9.19e-3 s (the designer finds omega, lambda_s and the radii
for the smallest rho_L1 there): `validate` then simulates at the certified parameters."""


def test_fewer_failing_checks_win_when_no_coordinates_certify(tmp_path):
    """Pendulum with only 20 held-out trajectories: the held-out form's Clopper-Pearson level
    cannot reach delta/2 = 0.05 (0.139 at best), so TaSIL fails wherever it is computed. In x
    DRIP Assumption 2 fails too (no contraction at all); in z contraction and L1-DRAC hold and
    only TaSIL fails. Both are not_certified; the z certificate, which proves more, is the one
    returned."""
    from drip_cert.bounds.certificate import certify
    from drip_cert.spec import load_spec
    from tests.helpers import example_spec

    text = example_spec("pendulum").read_text()
    old = "heldout = 100"
    assert old in text
    # a small non-affine term keeps pi_IL - pi* out of the sure tube form (docs/math/tasil.md
    # 3.10 needs it affine in MLP blocks), which would otherwise certify TaSIL without data
    pol = 'learned = ["9.81*sin(q) - 3.96*q - 4.04*q_dot"]'
    assert pol in text
    path = tmp_path / "pendulum.toml"
    path.write_text(
        text.replace(old, "heldout = 20").replace(
            pol, 'learned = ["9.81*sin(q) - 3.96*q - 4.04*q_dot + 0.01*sin(q_dot)"]'
        )
    )
    cert = certify(load_spec(path))
    assert cert.verdict.value == "not_certified"
    assert cert.coordinates is not None
    failing = [a.id for a in cert.assumptions if not a.holds]
    assert failing == ["TaSIL"]
    x = [a for a in cert.alternatives if a["coordinates"] == "x"]
    assert x and x[0]["verdict"] == "not_certified"


def test_validate_confirms_the_mapped_back_bounds_at_the_certified_parameters():
    """The pendulum (quick validation: 200 paths over 2 s) is simulated in z at the certified
    L1-DRAC parameters and validated in x: the checked bounds are the certificate's radii in x,
    the gaps are of x = Theta^{-1} z, and no bound is violated."""
    from drip_cert.workflows import validate_spec
    from tests.helpers import example_spec

    rep = validate_spec(example_spec("pendulum"), quick=True, trajectories=200)
    cert = rep.certificate
    assert cert.coordinates is not None and rep.at_certified_parameters
    by = {c.name: c for c in rep.checks}
    assert by["policy_radius"].bound == cert.rho_tasil
    assert by["uncertainty_L2_norm"].bound == cert.rho_l1
    assert rep.status == "holds", [(c.name, c.status) for c in rep.checks]
    assert by["policy_radius"].status == "holds" and by["uncertainty_L2_norm"].status == "holds"
    assert rep.result.config.gap_readout is not None
    assert any("validated in the user's x" in n for n in rep.notes)


def test_the_comparison_route_bounds_the_gap_where_the_lemma_fails(tmp_path):
    """Cart-pole with the LQR gain 1 % off: the TaSIL lemma's gap bound exceeds the tube radius
    (its condition fails), but the learned loop contracts on all of R^n (exact, in z), so the
    comparison bound ||g_z||_2 h0 / lambda_IL (docs/math/tasil.md Proposition 3.7) gives a
    finite deterministic gap bound; that gain is among the TaSIL check's inputs (sound)."""
    from drip_cert.bounds.certificate import certify
    from drip_cert.spec import load_spec
    from tests.helpers import example_spec

    text = example_spec("cart_pole").read_text()
    old = 'learned = ["3.17*x + 46.13*theta + 5.71*x_dot + 10.38*theta_dot"]'
    assert old in text
    path = tmp_path / "cart_pole.toml"
    path.write_text(
        text.replace(old, 'learned = ["3.13*x + 46.49*theta + 5.78*x_dot + 10.3*theta_dot"]')
    )
    cert = certify(load_spec(path))
    t = cert.tasil
    # the comparison route, or the sure form along the expert's tube (tasil.md 3.10), which
    # rests on the same gain and is never larger
    assert cert.coordinates is not None and t.gap_route in ("comparison", "uniform")
    lemma_fails = any(not c.holds for c in t.gap_checks)
    assert lemma_fails and math.isfinite(t.gap_bound)
    if t.gap_route == "comparison":
        assert t.gap_bound >= t.comparison_gain * t.h0  # rounded up, never down
    else:
        assert t.tube is not None and t.gap_bound == t.tube.rho
    gain = next(q for q in cert.all_quantities() if q.name == "gamma_IL")
    assert gain.value == t.comparison_gain and gain.how.value in ("exact", "sound")
