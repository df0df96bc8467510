"""``Delta_star`` (L1-DRAC Assumption 3) with a known diffusion: the nominal process (4b) is an
SDE, and its moments are bounded by docs/math/contraction.md Proposition 6.5, not by the
deterministic bound of Proposition 6.4 (issue 22, finding 1)."""

from __future__ import annotations

import math

import numpy as np
import pytest
import sympy as sp

from drip_cert.analysis.growth.closed_loop import closed_loop_constants, sde_moment_bound
from drip_cert.model.system import System
from drip_cert.provenance import How, Quantity

x = sp.Symbol("x", real=True)
LAM = 1.0  #: the rate of the closed loop x' = -x (exact)
R0 = 0.1  #: the support [-0.1, 0.1] of the initial law
TIGHT_FACTOR_Q1 = 1.0 + 1e-12  #: for q = 1 the bound is the OU stationary L2 norm (rounding only)


def _ou(diffusion, expert=None, support=((-R0, R0),)) -> System:
    """dX = -X dt + p dW: the expert closed loop of x' = u, u = -x (plus an offset if given)."""
    return System(
        name="ou",
        states=(x,),
        f=[0],
        g=[[1]],
        expert=[-x] if expert is None else expert,
        diffusion=diffusion,
        support=support,
        horizon=5.0,
    )


def _lam(how: How = How.EXACT) -> Quantity:
    return Quantity("lambda", LAM, how, "test", "mu_2(-1) = -1")


def ou_sup_norm(x0: float, lam: float, sigma: float, q: int, T: float = 50.0) -> float:
    """``sup_t (E|X_t|^{2q})^{1/(2q)}`` for the 1-D OU process from ``x0`` (Gaussian moments of
    ``N(x0 e^{-lam t}, sigma^2 (1 - e^{-2 lam t}) / (2 lam))``), on a fine grid of [0, T]."""
    best = 0.0
    for i in range(2001):
        t = T * i / 2000
        m = x0 * math.exp(-lam * t)
        v = sigma**2 * (-math.expm1(-2 * lam * t)) / (2 * lam)
        # E X^{2q} = sum_k C(2q, 2k) m^{2q-2k} v^k (2k-1)!!
        mom = sum(
            math.comb(2 * q, 2 * k) * m ** (2 * q - 2 * k) * v**k * math.prod(range(1, 2 * k, 2))
            for k in range(q + 1)
        )
        best = max(best, mom ** (1 / (2 * q)))
    return best


def test_issue_case_p2_bounds_the_ou_l2_norm_and_is_sound():
    """The issue's case: p = 2, lambda = 1, x0 in [-0.1, 0.1]. The true sup_t ||X*_t||_L2 is
    sqrt(2) (OU stationary law N(0, p^2 / (2 lambda))); 8844af7 gave 0.1, labelled sound."""
    cl = closed_loop_constants(_ou([[2]]), "expert", _lam(), True)
    ds = cl.Delta_star
    assert ds.value >= math.sqrt(2.0)
    assert ds.value >= ou_sup_norm(R0, LAM, 2.0, 1)
    assert ds.value <= math.sqrt(2.0) * TIGHT_FACTOR_Q1  # tight for q = 1
    assert ds.how is How.SOUND
    assert "Prop. 6.5" in ds.note


@pytest.mark.parametrize("q", [1, 2, 3, 4])
def test_the_moment_order_p_star_is_used(q):
    """Assumption 3 bounds the L_{2 p*} norm: the bound covers the OU closed form of that
    order, which grows with p*."""
    ds = closed_loop_constants(_ou([[2]]), "expert", _lam(), True, p_star=q).Delta_star
    assert ds.value >= ou_sup_norm(R0, LAM, 2.0, q)
    assert f"L{2 * q}" in ds.note


DETERMINISTIC_8844AF7 = 0.4000000000000005
"""Delta_star of x' = -x + 0.3 from [-0.1, 0.1] at 8844af7 (0.1 + 0.3 / 1 rounded up)."""


def test_without_diffusion_the_deterministic_bound_is_unchanged():
    """p = 0: Proposition 6.4 as before, max ||x0|| + ||F(0)|| / lambda, bit for bit."""
    s = _ou(None, expert=[-x + sp.Rational(3, 10)])
    ds = closed_loop_constants(s, "expert", _lam(), True).Delta_star
    assert ds.how is How.SOUND
    assert ds.value == DETERMINISTIC_8844AF7
    assert "max_box ||x0|| + ||F(0)||/lambda" in ds.note


def test_a_rate_not_global_gives_an_estimate():
    ds = closed_loop_constants(_ou([[2]]), "expert", _lam(), False).Delta_star
    assert ds.how is How.ESTIMATE and ds.value >= math.sqrt(2.0)
    ds = closed_loop_constants(_ou([[2]]), "expert", _lam(How.ESTIMATE), True).Delta_star
    assert ds.how is How.ESTIMATE


def test_the_label_follows_the_diffusion_constant():
    """A Delta_p given by the user makes Delta_star rest on it (given, not sound)."""
    dp = Quantity("Delta_p", 2.0, How.GIVEN, "test", "given in [constants]")
    ds = closed_loop_constants(_ou([[2]]), "expert", _lam(), True, Delta_p=dp).Delta_star
    assert ds.how is How.GIVEN


def test_condition_kappa_fails_gives_inf():
    """(6.5c): lambda <= (2q - 1) a2 / 2 leaves no bound (inf, so the check fails honestly)."""
    assert sde_moment_bound(0.1, 0.0, 1.0, 1, 0.0, 0.0, 2.0) == math.inf
    assert sde_moment_bound(0.1, 0.0, 1.0, 2, 0.0, 0.0, 0.7) == math.inf
    assert math.isfinite(sde_moment_bound(0.1, 0.0, 1.0, 2, 0.0, 0.0, 0.6))


def test_state_dependent_bounded_diffusion():
    """p = 1 + sin(x) (|p| <= 2): the whole-space bound gives sqrt(4 / 2) = sqrt(2) at q = 1,
    above the sampled stationary second moment of any such process (by Prop. 6.5)."""
    ds = closed_loop_constants(_ou([[1 + sp.sin(x)]]), "expert", _lam(), True).Delta_star
    assert ds.how is How.SOUND
    assert math.sqrt(2.0) <= ds.value <= math.sqrt(2.0) * TIGHT_FACTOR_Q1


# ----------------------------------------------------------------------------------------------
# validation: with p != 0 the uncertainty gaps are measured against the nominal SDE (4b)

SIM_PATHS = 64  #: paths of the engine runs below (the assertions are exact, not statistical)


def _sim_model(p: float):
    """dX = -X dt + p dW with pi_IL = pi* and no uncertainty: the true process IS (4b)."""
    from drip_cert._jax import jnp
    from drip_cert.model.numeric import make_model

    return make_model(
        1,
        1,
        1,
        f=lambda t, x: 0.0 * x,
        g=np.ones((1, 1)),
        expert=lambda x: -x,
        learned=lambda x: -x,
        p=lambda t, x: p * jnp.ones((1, 1)),
        name=f"ou-p{p}",
    )


def _sim(model, chunk_size: int = SIM_PATHS, extra: tuple[str, ...] = ("nominal_sde",)):
    from drip_cert._jax import jax, jnp
    from drip_cert.sim.config import DEFAULT_SCENARIOS, SimConfig
    from drip_cert.sim.engine import simulate

    cfg = SimConfig(
        T=1.0,
        dt=0.01,
        n_paths=SIM_PATHS,
        chunk_size=chunk_size,
        seed=3,
        scenarios=tuple(s for s in (*DEFAULT_SCENARIOS, *extra) if s != "learned_l1_true"),
        record_every=10,
    )

    def x0(key):
        return jax.random.uniform(key, (1,), minval=-R0, maxval=R0, dtype=jnp.float64)

    return simulate(model, cfg, x0, progress=False)


def test_the_nominal_sde_is_the_true_process_when_nothing_is_uncertain():
    """pi_IL = pi*, no uncertainty, p = 2: the true process and (4b) coincide path by path (same
    Brownian path), so the gap to the nominal SDE is exactly 0; to the ODE x' it is not (the
    comparison 8844af7 made)."""
    res = _sim(_sim_model(2.0))
    sde = res.gap("uncertainty_true_sde")
    assert sde.n == SIM_PATHS and np.all(sde.mean == 0.0) and np.all(sde.path_max == 0.0)
    assert res.gap("uncertainty_true").max_mean > 0.5  # ~ E|N(0, 2)|: the noise itself


def test_the_nominal_sde_changes_no_other_bit_and_not_with_chunking():
    """Simulating (4b) as well leaves every other gap bit-identical, and its own gaps do not
    depend on the chunk size."""
    model = _sim_model(2.0)
    with_sde = _sim(model)
    without = _sim(model, extra=())
    for g in without.gaps:
        h = with_sde.gap(g.name)
        for a, b in ((g.mean, h.mean), (g.moments, h.moments), (g.path_max, h.path_max)):
            assert np.array_equal(a, b), g.name
    chunked = _sim(model, chunk_size=7)
    for g in with_sde.gaps:
        h = chunked.gap(g.name)
        assert np.array_equal(g.moments, h.moments) and np.array_equal(g.path_max, h.path_max)


def test_validation_measures_the_l1_gap_against_the_nominal_sde():
    """run_scenarios adds (4b) exactly when p != 0, and the L1 checks then read its gap."""
    from drip_cert.validate.checks import uncertainty_gap_name
    from drip_cert.validate.scenarios import scenarios_for

    base = ("expert_nominal", "learned_nominal")
    assert scenarios_for(_ou([[2]]), base) == (*base, "nominal_sde")
    assert scenarios_for(_ou(None), base) == base
    res = _sim(_sim_model(2.0))
    assert uncertainty_gap_name(res, with_l1=False) == "uncertainty_true_sde"
    assert uncertainty_gap_name(_sim(_sim_model(2.0), extra=()), False) == "uncertainty_true"


# ------------------------------------------------- the third term: nominal SDE against the ODE


def ou_gap_sup(lam: float, sigma: float, q: int, T: float = 50.0) -> float:
    """``sup_t ||X*_t - x'_t||_{L_2q}`` for ``dX* = -lam X* dt + sigma dW`` and ``x' = e^{-lam t}
    x0``: the difference is the OU process from 0, ``N(0, sigma^2 (1 - e^{-2 lam t}) / (2 lam))``,
    whatever ``x0``."""
    return ou_sup_norm(0.0, lam, sigma, q, T)


@pytest.mark.parametrize("q", [1, 2, 3])
def test_rho_sde_covers_the_ou_gap_and_is_tight_for_q_1(q):
    """Proposition 6.6 on the OU process: the bound covers the closed-form gap of every moment
    order, equals it for q = 1 (rounding only), and a bound 1 % smaller fails there."""
    cl = closed_loop_constants(_ou([[2]]), "expert", _lam(), True, p=q)
    gap = cl.rho_sde
    assert gap is not None and gap.how is How.SOUND and "Prop. 6.6" in gap.note
    truth = ou_gap_sup(LAM, 2.0, q)
    assert gap.value >= truth
    assert gap.value == pytest.approx(math.sqrt((2 * q - 1) * 4.0 / (2 * LAM)), rel=1e-12)
    if q == 1:
        assert gap.value <= truth * (1.0 + 1e-6)  # the sup over a 50 s grid: e^{-100} short
        assert 0.99 * gap.value < truth


def test_rho_sde_absent_without_a_diffusion_and_an_estimate_without_a_global_rate():
    assert closed_loop_constants(_ou(None), "expert", _lam(), True).rho_sde is None
    est = closed_loop_constants(_ou([[2]]), "expert", _lam(), False).rho_sde
    assert est is not None and est.how is How.ESTIMATE


def test_the_certificate_adds_rho_sde_to_rho(tmp_path):
    """With a known diffusion the total radius is rho_TaSIL + rho_L1 + rho_sde (the nominal SDE
    of L1-DRAC is not the ODE TaSIL bounds)."""
    from drip_cert import certify, load_spec
    from tests.helpers import write_spec

    spec = write_spec(
        tmp_path,
        """
        [system]
        name = "ou-learned"
        states = ["x1"]
        inputs = ["u"]
        horizon = 2.0
        [dynamics]
        f = ["0"]
        g = [["1"]]
        diffusion = [["0.1"]]
        [policy]
        expert = ["-x1"]
        learned = ["-1.01*x1"]
        [uncertainty]
        drift = ["0.01*sin(x1)"]
        [initial]
        support = [[-0.1, 0.1]]
        [tasil]
        trajectories = 4
        samples = 20
        [l1drac]
        p = 1
        omega = 50.0
        rho_a = 1.0
        """,
    )
    cert = certify(load_spec(spec))
    d = cert.to_dict()["rho"]
    assert cert.rho_sde is not None
    assert cert.rho_sde == pytest.approx(0.1 / math.sqrt(2 * 1.01), rel=1e-9)
    if cert.rho_tasil is not None and cert.rho_l1 is not None:
        assert d["rho_total"] >= cert.rho_tasil + cert.rho_l1 + cert.rho_sde
    assert d["rho_sde"] == cert.rho_sde
