"""Box-only learned loops: the extension and the exit bound (docs/math/l1drac.md section 11)."""

from __future__ import annotations

import math

import pytest

from drip_cert.bounds.l1drac.exit import (
    extension_constants,
    extension_gain,
    grid_exit_bound,
    l1drac_exit_inputs,
)
from proofs_check import Verdict
from proofs_check._core import Context, make_rng

REL = 1e-12  # outward rounding moves a few ulps; a closed form is matched to this relative error


def _ctx(name: str) -> Context:
    return Context(rng=make_rng(0, name), quick=True, seed=0)


def test_extension_gain_is_the_closed_form_rounded_up():
    """(11.1a): k = lam' + L^2 / (4 (lam - lam')) = 0.5 + 4 / 2 for lam = 1, lam' = 0.5, L = 2."""
    k = extension_gain(1.0, 0.5, 2.0)
    assert 2.5 <= k <= 2.5 * (1 + REL)
    k, lf, df = extension_constants(1.0, 0.5, 2.0, 3.0, 1.0)
    assert lf >= 4.5 and df >= math.sqrt((3.0 + 2.5) ** 2 + 2.5**2)
    assert df <= math.sqrt(5.5**2 + 2.5**2) * (1 + REL)
    with pytest.raises(ValueError):
        extension_gain(1.0, 1.0, 2.0)


def test_grid_bound_closed_form_at_q2_without_drift_or_moment():
    """(11.4) with rho = B = 0, q = 2: N (c_2 sqrt(T/N) S / eta)^2 = 4 T S^2 / eta^2 for every N
    (c_2 = 2); the best split takes the smallest a = r/20, so eta = 0.95 r."""
    d = grid_exit_bound(rho=0.0, b=0.0, s=1.0, q=2, room=4.0, horizon=1.0, n_max=8)
    expected = 4.0 / (0.95 * 4.0) ** 2
    assert expected <= d.delta <= expected * (1 + REL)
    assert d.a == pytest.approx(0.2)


def test_grid_bound_is_informative_for_ou_at_six_standard_deviations():
    """OU lam = 1, sig = 1, T = 1, r = 6 s: the best order in p <= 16 gives a bound below 0.01
    (measured 0.0053); below 1 means the lemma says something."""
    s = 1 / math.sqrt(2)
    best = min(
        grid_exit_bound(
            rho=s * math.prod(range(1, 2 * p, 2)) ** (1 / (2 * p)),
            b=s * math.prod(range(1, 2 * p, 2)) ** (1 / (2 * p)),
            s=1.0,
            q=2 * p,
            room=6 * s,
            horizon=1.0,
        ).delta
        for p in range(1, 17)
    )
    assert best < 0.01


def test_l1drac_exit_inputs_hand_computed():
    """(11.5) with m = 2, e^{-lambda_s T_s} = 1/2, p = 1, T_s = 1/4:
    S = sqrt 3, B_U = 1.5 + 2 sqrt 3, B = 2 * 3 + B_U + 0.5."""
    b, s = l1drac_exit_inputs(
        rho=1.0,
        r_x=1.0,
        sup_f=0.5,
        delta_f=1.0,
        delta_mu=1.0,
        delta_sigma=1.0,
        delta_p=0.0,
        delta_g=1.0,
        delta_theta=1.0,
        lambda_s=math.log(2.0) / 0.25,
        t_s=0.25,
        p=1,
    )
    assert math.sqrt(3) <= s <= math.sqrt(3) * (1 + REL)
    exp_b = 6.0 + 1.5 + 2 * math.sqrt(3) + 0.5
    assert exp_b * (1 - REL) <= b <= exp_b * (1 + 1e-9)  # e^{-u} enclosed by Arb, a few ulps


def test_extension_check_holds_and_fails_on_a_smaller_slope():
    """Proposition 11.1: no pair violates the rate lambda' with k of (11.1a); a tenth of it does."""
    from proofs_check.l1drac_exit import check_extension_rate

    assert check_extension_rate(_ctx("l1drac_exit.extension_rate")).verdict is Verdict.PASS
    res = check_extension_rate(_ctx("l1drac_exit.extension_rate"), k_scale=0.1)
    assert res.verdict is Verdict.FAIL and res.residual > 0


def test_grid_union_check_holds_and_fails_without_the_union():
    """Lemma 11.4 on simulated OU paths holds; the fixed-time bound used for the supremum fails."""
    from proofs_check.l1drac_exit import check_ou_grid_union

    assert check_ou_grid_union(_ctx("l1drac_exit.ou_grid_union")).verdict is Verdict.PASS
    res = check_ou_grid_union(_ctx("l1drac_exit.ou_grid_union"), union=False)
    assert res.verdict is Verdict.FAIL and res.residual > 0


def test_box_only_sde_exit_frequency_below_the_bound():
    """Section 11 end to end on dx = (x^3 - x) dt + sig dW (rate on [-1/2, 1/2] only)."""
    from proofs_check.l1drac_exit import check_box_only_sde_1d

    res = check_box_only_sde_1d(_ctx("l1drac_exit.box_only_sde_1d"))
    assert res.verdict is Verdict.PASS, res.detail
