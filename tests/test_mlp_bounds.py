"""Tests of drip_cert.analysis.networks.mlp: activation constants, Lipschitz and Jacobian-Lipschitz
bounds of MLPs (DRIP Assumption PolicyRegularity), LipSDP, interval enclosures."""

from __future__ import annotations

import math

import mpmath as mp
import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from drip_cert._jax import jax, jnp
from drip_cert.analysis.networks.mlp import (
    activation_bounds,
    enclose_activation,
    enclose_activation_prime,
    enclose_jacobian,
    enclose_output,
    jacobian_lipschitz_bound,
    jacobian_np,
    lipschitz_bound,
    lipschitz_lipsdp,
    lipschitz_product,
)
from drip_cert.errors import SpecError
from drip_cert.model.mlp import MLP, activation_fn, init_mlp
from drip_cert.numerics.rounding import LIBM_REL, ndtr_rel_budget
from drip_cert.provenance import How
from tests.helpers import MP_DPS

# a sup over a grid of spacing 1e-4 misses the true sup of a smooth function by O(h^2) ~ 1e-8
GRID_SUP_TOL = 1e-7
# forward-mode Jacobian vs jax autodiff: both exact up to a few roundings of O(1) numbers
AUTODIFF_TOL = 1e-12
# central finite differences with step 1e-6: truncation O(h^2) ~ 1e-12, rounding O(eps/h) ~ 1e-10
FD_TOL = 1e-8
# LipSDP vs product bound: LipSDP is never larger in exact arithmetic; the solver margin (1e-7
# relative) and Clarabel's tolerances (~1e-8) may add a few 1e-6 at most
LIPSDP_SLACK = 1e-5
# LipSDP on a network whose exact Lipschitz constant is known: solver accuracy ~1e-6 relative
LIPSDP_EXACT_TOL = 1e-4
# SCS (first order, eps ~1e-4 relative by default) may end a little above Clarabel's optimum
SCS_VS_CLARABEL = 1.05
# the one-hidden-layer scalar Jacobian-Lipschitz bound is exact up to outward rounding (a few ulps)
EXACT_REL_TOL = 1e-10
# step of the central differences the Jacobian is compared with (see FD_TOL)
FD_STEP = 1e-6
# an Arb upper bound of a closed-form activation constant: a few ulps above it
ARB_BOUND_REL = 1e-14
# the same, absolute, for O(1) constants and sums of two of them
ARB_BOUND_ATOL = 1e-14
# an Arb upper bound of sup GELU' is above the exact value by at most its last ulp or so
ARB_EXCESS = 1e-15
# the brief quotes sup GELU' ~ 1.1289: four decimals
BRIEF_DECIMALS = 1e-4
# a degenerate box encloses the point value to a few ulps (outward rounding only)
POINT_WIDTH = 1e-12

ACTS = ("tanh", "gelu")


def _nets(rng: np.random.Generator, act: str, count: int = 4) -> list[MLP]:
    """Small random nets of varied depth, with biases, some with a tanh output."""
    out = []
    shapes = [(3, 8, 2), (4, 6, 6, 3), (2, 5, 5, 5, 1), (5, 7, 4)]
    for i in range(count):
        sizes = shapes[i % len(shapes)]
        m = init_mlp(sizes, rng, act, output_activation="tanh" if i == 3 else None, scale=1.5)
        biases = tuple(rng.normal(size=b.shape) for b in m.biases)
        out.append(MLP(m.weights, biases, act, m.output_activation))
    return out


# ----------------------------------------------------------------- activation constants


@pytest.mark.parametrize("act", ACTS)
def test_activation_constants_match_dense_grid_of_autodiff(act):
    f = activation_fn(act, jnp)
    d1 = jax.vmap(jax.grad(f))
    d2 = jax.vmap(jax.grad(jax.grad(f)))
    # [-20, 20] so that limits at infinity (inf tanh' = 0) are approached to 1e-16
    z = jnp.linspace(-20.0, 20.0, 400_001)
    s1, s2 = np.asarray(d1(z)), np.asarray(d2(z))
    ab = activation_bounds(act)
    assert ab.slope_hi >= s1.max() and ab.slope_hi - s1.max() < GRID_SUP_TOL
    assert ab.slope_lo <= s1.min() and s1.min() - ab.slope_lo < GRID_SUP_TOL
    assert ab.abs_curv >= np.abs(s2).max() and ab.abs_curv - np.abs(s2).max() < GRID_SUP_TOL
    assert ab.abs_slope == max(abs(ab.slope_lo), abs(ab.slope_hi))


def test_activation_closed_forms():
    assert activation_bounds("tanh").abs_curv == pytest.approx(
        4 / (3 * math.sqrt(3)), rel=ARB_BOUND_REL
    )
    gelu = activation_bounds("gelu")
    assert gelu.abs_curv == pytest.approx(math.sqrt(2 / math.pi), rel=ARB_BOUND_REL)
    # the brief's numbers: sup GELU' ~ 1.1289, inf GELU' ~ -0.1289, and they sum to 1 (GELU' is
    # Phi(z) + z phi(z), so GELU'(z) + GELU'(-z) = 1)
    assert gelu.slope_hi == pytest.approx(1.1289, abs=BRIEF_DECIMALS)
    assert gelu.slope_hi + gelu.slope_lo == pytest.approx(1.0, abs=ARB_BOUND_ATOL)
    relu = activation_bounds("relu")  # Clarke slopes [0, 1]; the slope is not Lipschitz
    assert (relu.slope_lo, relu.slope_hi, relu.abs_curv) == (0.0, 1.0, math.inf)
    with pytest.raises(SpecError, match="softsign"):
        activation_bounds("softsign")


# ----------------------------------------------------------------- Jacobian, Lipschitz


@pytest.mark.parametrize("act", ACTS)
def test_jacobian_np_matches_jax_and_finite_differences(act):
    rng = np.random.default_rng(1)
    for net in _nets(rng, act):
        x = rng.normal(size=(5, net.in_dim))
        J = jacobian_np(net, x)
        Jax = np.asarray(jax.jit(jax.vmap(jax.jacfwd(net.apply_jax)))(jnp.asarray(x)))
        np.testing.assert_allclose(J, Jax, atol=AUTODIFF_TOL, rtol=0)
        for i in range(net.in_dim):
            e = np.zeros(net.in_dim)
            e[i] = FD_STEP
            fd = (net.apply_np(x + e) - net.apply_np(x - e)) / (2 * FD_STEP)
            np.testing.assert_allclose(J[..., i], fd, atol=FD_TOL, rtol=0)


@pytest.mark.parametrize("act", ACTS)
def test_lipschitz_bounds_dominate_sampled_ratios_and_gradients(act):
    rng = np.random.default_rng(2)
    for net in _nets(rng, act):
        L = lipschitz_product(net)
        assert L.how == How.SOUND
        x = rng.normal(size=(2000, net.in_dim)) * 2
        y = x + rng.normal(size=x.shape) * rng.uniform(1e-3, 2, size=(2000, 1))
        ratio = np.linalg.norm(net.apply_np(x) - net.apply_np(y), axis=1) / np.linalg.norm(
            x - y, axis=1
        )
        grad = np.linalg.norm(jacobian_np(net, x), ord=2, axis=(1, 2))
        assert ratio.max() <= L.value
        assert grad.max() <= L.value


@pytest.mark.parametrize("act", ACTS)
def test_lipsdp_between_sampled_gradients_and_product(act):
    rng = np.random.default_rng(3)
    for net in _nets(rng, act, count=3):
        res = lipschitz_lipsdp(net)
        assert res.status == "optimal" and res.value is not None
        assert res.check.holds and res.check.margin > 0
        assert res.value <= res.product * (1 + LIPSDP_SLACK)
        x = rng.normal(size=(3000, net.in_dim)) * 2
        grad = np.linalg.norm(jacobian_np(net, x), ord=2, axis=(1, 2))
        assert grad.max() <= res.value
        q = lipschitz_bound(net, "lipsdp")
        assert q.value == res.best and q.how == How.SOUND


def test_lipsdp_exact_cases():
    # tanh layer with identity weights: Lipschitz constant exactly 1 (tanh'(0) = 1)
    n = 3
    net = MLP((np.eye(n), np.eye(n)), (np.zeros(n), np.zeros(n)), "tanh")
    assert lipschitz_lipsdp(net).value == pytest.approx(1.0, rel=LIPSDP_EXACT_TOL)
    # scalar chain x -> w1 tanh(w0 x): Lipschitz constant |w0 w1|
    net = MLP((np.array([[2.0]]), np.array([[-3.0]])), (np.zeros(1), np.zeros(1)), "tanh")
    assert lipschitz_lipsdp(net).value == pytest.approx(6.0, rel=LIPSDP_EXACT_TOL)
    # an affine map has no hidden layer: LipSDP not applicable, the product bound is used
    aff = MLP((np.array([[3.0, 4.0]]),), (np.zeros(1),), "tanh")
    res = lipschitz_lipsdp(aff)
    assert res.value is None and res.best == pytest.approx(5.0, rel=EXACT_REL_TOL)
    with pytest.raises(SpecError, match="method"):
        lipschitz_bound(aff, "magic")


def test_lipsdp_scs_path_and_size_guard():
    rng = np.random.default_rng(8)
    net = _nets(rng, "gelu")[1]
    clarabel = lipschitz_lipsdp(net, solver="CLARABEL")
    scs = lipschitz_lipsdp(net, solver="SCS")
    # SCS is less accurate, but the Schur re-certification keeps it sound and close
    assert scs.check.holds and scs.value >= clarabel.value * (1 - LIPSDP_EXACT_TOL)
    assert scs.value <= clarabel.value * SCS_VS_CLARABEL
    skipped = lipschitz_lipsdp(net, max_dim=3)
    assert skipped.status == "too_large" and skipped.value is None
    assert skipped.best == lipschitz_product(net).value
    with pytest.raises(SpecError, match="solver"):
        lipschitz_lipsdp(net, solver="MOSEK")


@pytest.mark.parametrize("act", ACTS)
def test_jacobian_lipschitz_dominates_sampled_ratios(act):
    rng = np.random.default_rng(4)
    for net in _nets(rng, act):
        Ld = jacobian_lipschitz_bound(net)
        assert Ld.how == How.SOUND
        x = rng.normal(size=(3000, net.in_dim)) * 1.5
        for scale in (1e-4, 1e-2, 1.0):
            y = x + rng.normal(size=x.shape) * scale
            dJ = np.linalg.norm(jacobian_np(net, x) - jacobian_np(net, y), ord=2, axis=(1, 2))
            ratio = dJ / np.linalg.norm(x - y, axis=1)
            assert ratio.max() <= Ld.value


@pytest.mark.parametrize("act", ACTS)
def test_jacobian_lipschitz_exact_for_scalar_one_hidden_layer(act):
    # f(x) = w1 s(w0 x): f'' = w1 w0^2 s''(w0 x), so Lip(f') = |w1| w0^2 sup|s''| exactly
    w0, w1 = 1.7, -0.6
    net = MLP((np.array([[w0]]), np.array([[w1]])), (np.array([0.3]), np.array([0.1])), act)
    want = abs(w1) * w0**2 * activation_bounds(act).abs_curv
    assert jacobian_lipschitz_bound(net).value == pytest.approx(want, rel=EXACT_REL_TOL)


# ----------------------------------------------------------------- interval enclosures


@pytest.mark.parametrize("act", ACTS)
def test_enclosures_contain_sampled_values(act):
    rng = np.random.default_rng(5)
    for net in _nets(rng, act):
        n = net.in_dim
        for width in (1e-6, 0.05, 0.5, 2.0):
            centre = rng.normal(size=(20, n))
            lo = centre - width * rng.uniform(0, 1, size=(20, n))
            hi = centre + width * rng.uniform(0, 1, size=(20, n))
            ylo, yhi = enclose_output(net, lo, hi)
            jlo, jhi = enclose_jacobian(net, lo, hi)
            assert ylo.shape == (20, net.out_dim) and jlo.shape == (20, net.out_dim, n)
            u = rng.uniform(size=(200, 20, n))
            u[:4] = rng.integers(0, 2, size=(4, 20, n))  # some corners
            pts = lo + u * (hi - lo)
            y = net.apply_np(pts)
            J = jacobian_np(net, pts)
            assert np.all(ylo <= y) and np.all(y <= yhi)
            assert np.all(jlo <= J) and np.all(J <= jhi)


def test_enclosures_of_a_point_are_tight_and_of_wider_boxes_monotone():
    rng = np.random.default_rng(6)
    net = _nets(rng, "gelu")[1]
    x = rng.normal(size=net.in_dim)
    ylo, yhi = enclose_output(net, x, x)
    jlo, jhi = enclose_jacobian(net, x, x)
    # a degenerate box encloses the point value to a few ulps (outward rounding only)
    assert np.max(yhi - ylo) < POINT_WIDTH and np.max(jhi - jlo) < POINT_WIDTH
    w_prev = 0.0
    for r in (1e-3, 1e-2, 1e-1, 1.0):
        jl, jh = enclose_jacobian(net, x - r, x + r)
        w = float(np.max(jh - jl))
        assert w >= w_prev
        w_prev = w


def test_gelu_output_enclosure_spans_its_minimum():
    # a single GELU unit on a box straddling the minimiser z* ~ -0.7518 must go down to GELU(z*)
    net = MLP((np.eye(1), np.eye(1)), (np.zeros(1), np.zeros(1)), "gelu")
    ylo, yhi = enclose_output(net, np.array([-2.0]), np.array([1.0]))
    z = np.linspace(-2, 1, 300_001)
    g = activation_fn("gelu", np)(z)
    assert ylo[0] <= g.min() and g.min() - ylo[0] < GRID_SUP_TOL
    assert yhi[0] >= g.max()


def test_box_errors_name_the_problem():
    net = _nets(np.random.default_rng(7), "tanh")[0]
    with pytest.raises(SpecError, match="swap"):
        enclose_jacobian(net, np.ones(3), np.zeros(3))
    with pytest.raises(SpecError, match="shape"):
        enclose_output(net, np.zeros(2), np.zeros(2))


# ----------------------------------------------------------------- rounding of activations

#: the old enclosures' relative pad (16 eps) and absolute pad (1e-300), reproduced as a contrast
OLD_REL_PAD = 16.0 * np.finfo(np.float64).eps
OLD_ABS_PAD = 1e-300
#: the sech^2 enclosure of a point: exp widened by LIBM_REL on each side, plus a few ulps of the
#: quotient (4 LIBM_REL ~ 7e-15 relative)
TANH_PRIME_POINT_WIDTH = 4 * LIBM_REL
#: a point enclosure of GELU is widened by the ndtr budget on each side, plus a few ulps
GELU_POINT_WIDTHS = 3  # times ndtr_rel_budget(z), relative
#: the Jacobian of the saturated one-neuron net: the sech^2 width plus the affine layers' gamma_n
#: rounding terms (n = 1), all O(1e-15) relative; 1e-12 is a generous named ceiling
JACOBIAN_POINT_WIDTH = 1e-12


def _mp(f, z: float):
    with mp.workdps(MP_DPS):
        return f(mp.mpf(z))


def _mp_tanh_prime(z):
    return mp.sech(z) ** 2


def _mp_gelu(z):
    return z * mp.ncdf(z)


def _mp_gelu_prime(z):
    return mp.ncdf(z) + z * mp.npdf(z)


def _old_enclosure(v: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """The previous code's outward pad of a float value (relative 16 eps, absolute 1e-300)."""
    pad = np.abs(v) * OLD_REL_PAD + OLD_ABS_PAD
    return np.nextafter(v - pad, -np.inf), np.nextafter(v + pad, np.inf)


@pytest.mark.parametrize("z", [19.0, 20.0, 25.0, 40.0, -30.0])
def test_tanh_prime_enclosure_where_one_minus_tanh_squared_cancels(z):
    exact = _mp(_mp_tanh_prime, z)
    # contrast: tanh(z)^2 rounds to 1, so the old formula gives 0 and its padded enclosure
    # [~-1e-300, ~1e-300] misses the exact value (1.3e-16 at z = 19) entirely
    t = np.tanh(np.array([z]))
    old_lo, old_hi = _old_enclosure(1.0 - t * t)
    assert not (old_lo[0] <= exact <= old_hi[0])
    lo, hi = enclose_activation_prime("tanh", np.array([z]), np.array([z]))
    assert lo[0] <= exact <= hi[0]
    assert hi[0] - lo[0] <= TANH_PRIME_POINT_WIDTH * float(exact)


@pytest.mark.parametrize("z", [-10.0, -20.0, -30.0])
def test_gelu_enclosure_where_one_plus_erf_cancels(z):
    from scipy.special import erf

    exact = _mp(_mp_gelu, z)
    # contrast: 1 + erf(z / sqrt 2) rounds to 0, so the old GELU is 0 and its enclosure misses
    old = 0.5 * z * (1.0 + erf(np.array([z]) / np.sqrt(2.0)))
    old_lo, old_hi = _old_enclosure(old)
    assert not (old_lo[0] <= exact <= old_hi[0])
    lo, hi = enclose_activation("gelu", np.array([z]), np.array([z]))
    assert lo[0] <= exact <= hi[0]
    assert hi[0] - lo[0] <= GELU_POINT_WIDTHS * ndtr_rel_budget(z) * abs(float(exact))


_ends = st.floats(min_value=-60.0, max_value=60.0, allow_nan=False)


@settings(max_examples=150)
@given(a=_ends, b=_ends, u=st.floats(0.0, 1.0), act=st.sampled_from(ACTS))
def test_activation_enclosures_contain_mpmath_values(a, b, u, act):
    lo, hi = min(a, b), max(a, b)
    f, fp = (mp.tanh, _mp_tanh_prime) if act == "tanh" else (_mp_gelu, _mp_gelu_prime)
    ylo, yhi = enclose_activation(act, np.array([lo]), np.array([hi]))
    dlo, dhi = enclose_activation_prime(act, np.array([lo]), np.array([hi]))
    for z in (lo, hi, lo + u * (hi - lo)):
        assert ylo[0] <= _mp(f, z) <= yhi[0]
        assert dlo[0] <= _mp(fp, z) <= dhi[0]


def test_saturated_tanh_network_jacobian_enclosure_contains_the_exact_jacobian():
    # x -> w1 tanh(w0 x + b0): at x = 1 the pre-activation is 22, tanh' = sech^2(22) ~ 3.1e-19;
    # the old enclosure was [0, 1e-300], i.e. it claimed the Jacobian is (practically) zero
    net = MLP((np.array([[20.0]]), np.array([[3.0]])), (np.array([2.0]), np.array([0.0])), "tanh")
    x = np.array([1.0])
    jlo, jhi = enclose_jacobian(net, x, x)
    exact = 3 * 20 * _mp(_mp_tanh_prime, 22.0)
    assert jlo[0, 0] <= exact <= jhi[0, 0] and jlo[0, 0] > 0
    assert jhi[0, 0] - jlo[0, 0] <= JACOBIAN_POINT_WIDTH * float(exact)


def test_activation_constants_are_arb_bounds_of_the_closed_forms():
    tanh, gelu = activation_bounds("tanh"), activation_bounds("gelu")
    with mp.workdps(MP_DPS):
        s2 = mp.sqrt(2)
        assert tanh.abs_curv >= 4 / (3 * mp.sqrt(3))
        assert gelu.slope_hi >= _mp_gelu_prime(s2) and gelu.slope_lo <= _mp_gelu_prime(-s2)
        assert gelu.abs_curv >= mp.sqrt(2 / mp.pi)
        assert gelu.slope_hi - _mp_gelu_prime(s2) < ARB_EXCESS


def test_output_bound_and_products_are_rounded_up():
    from fractions import Fraction

    from drip_cert.analysis.growth.closed_loop import mlp_output_bound

    # || |W| 1 + |b| || for a tanh net: 1/3 and 1/10 are not floats, the bound must cover the
    # exact norm of the float entries
    W1 = np.array([[1 / 3, -0.1, 0.7], [0.2, 0.3, -1 / 7]])
    b1 = np.array([0.1, -1 / 9])
    net = MLP((np.eye(3), W1), (np.zeros(3), b1), "tanh")
    rows = [sum((Fraction(abs(v)) for v in (*W1[i], b1[i])), Fraction(0)) for i in range(2)]
    assert Fraction(mlp_output_bound(net)) ** 2 >= sum(r * r for r in rows)
    # the product bound covers the exact product of exact spectral norms (mpmath SVD)
    with mp.workdps(MP_DPS):
        exact = 1
        for w in net.weights:
            exact *= max(mp.svd_r(mp.matrix(w.tolist()), compute_uv=False))
    assert lipschitz_product(net).value >= exact
