"""``Delta_star`` (L1-DRAC Assumption 3) with a known diffusion: the nominal process (4b) is an
SDE, and its moments are bounded by docs/math/contraction.md Proposition 6.5, not by the
deterministic bound of Proposition 6.4 (issue 22, finding 1)."""

from __future__ import annotations

import math

import pytest
import sympy as sp

from drip_cert.analysis.closed_loop import closed_loop_constants, sde_moment_bound
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
