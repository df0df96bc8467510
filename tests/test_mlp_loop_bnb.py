"""Vectorised branch and bound on matrices affine in MLP Jacobians
(drip_cert.analysis.contraction.mlp_loop):
the decomposition, soundness of the per-box vertex bounds against sampled values, closed-form
cases, the batched branch and bound, and the 'mlp-bnb' contraction route."""

from __future__ import annotations

import math

import numpy as np
import pytest
import sympy as sp

from drip_cert._jax import jax, jnp
from drip_cert.analysis.contraction.lognorm import mu_2
from drip_cert.analysis.contraction.mlp_loop import (
    box_bounds,
    decompose_jacobian,
    local_jacobian_lipschitz,
    matrix_bnb,
)
from drip_cert.analysis.contraction.rate import contraction_rate
from drip_cert.analysis.networks.block_enclosure import block_enclose_callback
from drip_cert.errors import SpecError
from drip_cert.model.blocks import mlp_block
from drip_cert.model.mlp import MLP, init_mlp
from drip_cert.numerics.bnb_batch import maximize_batch
from drip_cert.provenance import How

#: float mu_2 / norms of sampled matrices vs the rigorous bound: eigvalsh's error O(n eps ||M||)
SAMPLE_TOL = 1e-12
#: a constant matrix function (linear MLP): the vertex bound exceeds the exact value only by
#: the rounding terms of O(n eps ||M||)
CONST_TOL = 1e-12
#: jax autodiff Jacobian of the closed loop vs the decomposition's float evaluation
AUTODIFF_TOL = 1e-12

x1, x2 = sp.symbols("x1 x2")
X = (x1, x2)


def _mlp(act: str, sizes=(2, 6, 2), seed: int = 0, scale: float = 1.0) -> MLP:
    rng = np.random.default_rng(seed)
    m = init_mlp(list(sizes), rng, activation=act, scale=scale)
    return MLP(m.weights, tuple(0.3 * rng.normal(size=b.shape) for b in m.biases), act)


def _loop(mlp: MLP, gain: float = 0.3, name: str = "h"):
    """``F = -x + gain * C h(x)`` with a fixed non-symmetric ``C``: returns (J, mlps, fn)."""
    blk = mlp_block(name, mlp)
    C = np.array([[1.0, 0.5], [-0.25, 1.0]])
    h = sp.Matrix([blk.component(j)(*X) for j in range(2)])
    F = -sp.Matrix(X) + gain * sp.Matrix(C) * h
    J = F.jacobian(list(X))

    def jac(x):
        return -jnp.eye(2) + gain * jnp.asarray(C) @ jax.jacfwd(mlp.apply_jax)(x)

    return J, {name: mlp}, jax.vmap(jac)


def test_decomposition_reads_the_coefficients_and_evaluates_the_jacobian():
    mlp = _mlp("tanh")
    J, mlps, jac = _loop(mlp)
    dec = decompose_jacobian(J, X, mlps)
    assert dec is not None and dec.names == ("h",)
    assert np.array_equal(dec.A, -np.eye(2))
    pts = np.random.default_rng(0).uniform(-2, 2, (20, 2))
    assert np.max(np.abs(dec.evaluate(pts) - np.asarray(jac(jnp.asarray(pts))))) < AUTODIFF_TOL
    # not of the form: a product of block entries, a state factor, an unknown block, a value
    blk = mlp_block("h", mlp)
    d00 = blk.family[(0, (0,))](*X)
    assert decompose_jacobian(sp.Matrix([[d00 * d00, 0], [0, 0]]), X, mlps) is None
    assert decompose_jacobian(sp.Matrix([[x1 * d00, 0], [0, 0]]), X, mlps) is None
    assert decompose_jacobian(sp.Matrix([[d00, 0], [0, 0]]), X, {}) is None
    assert decompose_jacobian(sp.Matrix([[blk.component(0)(*X), 0], [0, 0]]), X, mlps) is None
    assert decompose_jacobian(-sp.eye(2), X, mlps) is None


@pytest.mark.parametrize(
    "act, objective",
    [(a, o) for a in ("tanh", "gelu") for o in ("mu2", "norm2")]
    + [(a, "mu2") for a in ("sigmoid", "softplus", "silu", "elu(1.0)")],
)
def test_box_bounds_dominate_sampled_values(act, objective):
    """Random-weight networks of every smooth activation: the bound on every box is never below
    the sampled value, so the rate proved on a box is never above the sampled one."""
    mlp = _mlp(act, seed=1, scale=2.0)
    J, mlps, jac = _loop(mlp, gain=1.0)
    dec = decompose_jacobian(J, X, mlps)
    assert dec is not None
    rng = np.random.default_rng(2)
    for rad in (1.0, 0.2, 0.02):
        c = rng.uniform(-1.5, 1.5, (30, 2))
        boxes = np.stack([c - rad, c + rad], axis=-1)
        ub, val, cen = box_bounds(dec, boxes, objective)
        assert np.all(np.isfinite(ub)) and np.allclose(cen, c, rtol=0, atol=1e-15)
        for k in range(boxes.shape[0]):
            pts = c[k] + rng.uniform(-rad, rad, (200, 2))
            M = np.asarray(jac(jnp.asarray(pts)))
            f = mu_2(M) if objective == "mu2" else np.linalg.norm(M, ord=2, axis=(1, 2))
            assert f.max() <= ub[k] + SAMPLE_TOL
            assert val[k] <= ub[k] + SAMPLE_TOL


def test_gap_is_second_order_in_the_box_size():
    mlp = _mlp("tanh", seed=3, scale=2.0)
    J, mlps, jac = _loop(mlp, gain=1.0)
    dec = decompose_jacobian(J, X, mlps)
    assert dec is not None
    c = np.array([[0.3, -0.2]])
    g = np.linspace(-1.0, 1.0, 41)
    grid = np.stack(np.meshgrid(g, g), axis=-1).reshape(-1, 2)
    gaps = []
    for rad in (0.04, 0.02, 0.01):
        ub, _, _ = box_bounds(dec, np.stack([c - rad, c + rad], axis=-1))
        sampled = mu_2(np.asarray(jac(jnp.asarray(c + rad * grid)))).max()
        gaps.append(float(ub[0] - sampled))
    # halving the box divides the gap by about 4 (second order); 3 leaves room
    assert gaps[1] < gaps[0] / 3 and gaps[2] < gaps[1] / 3


def test_constant_jacobian_is_bounded_to_rounding():
    lin = _mlp("identity", seed=4)
    J, mlps, jac = _loop(lin)
    dec = decompose_jacobian(J, X, mlps)
    assert dec is not None
    M = np.asarray(jac(jnp.zeros((1, 2))))[0]
    box = np.array([[-3.0, 3.0], [-1.0, 2.0]])
    ub, _, _ = box_bounds(dec, box[None], "mu2")
    assert mu_2(M) <= ub[0] <= mu_2(M) + CONST_TOL
    ub, _, _ = box_bounds(dec, box[None], "norm2")
    assert np.linalg.norm(M, 2) <= ub[0] <= np.linalg.norm(M, 2) + CONST_TOL
    lip = local_jacobian_lipschitz(dec, box)
    assert lip.upper <= 1e-150  # zero Hessian: only the underflow terms remain


def test_local_jacobian_lipschitz_dominates_sampled_difference_quotients():
    mlp = _mlp("tanh", seed=5, scale=2.0)
    J, mlps, jac = _loop(mlp, gain=1.0)
    dec = decompose_jacobian(J, X, mlps)
    assert dec is not None
    box = np.array([[-0.5, 0.5], [-0.5, 0.5]])
    res = local_jacobian_lipschitz(dec, box, tol=0.05, max_boxes=20_000)
    rng = np.random.default_rng(6)
    a = rng.uniform(-0.5, 0.5, (2000, 2))
    b = np.clip(a + rng.normal(scale=0.05, size=a.shape), -0.5, 0.5)
    Ma, Mb = np.asarray(jac(jnp.asarray(a))), np.asarray(jac(jnp.asarray(b)))
    q = np.linalg.norm(Ma - Mb, ord=2, axis=(1, 2)) / np.linalg.norm(a - b, axis=1)
    assert np.nanmax(q) <= res.upper
    assert math.isfinite(res.upper)


def test_batched_branch_and_bound_converges_on_a_closed_form():
    """``f(x) = -(x1 - 0.3)^2 - (x2 + 0.1)^2`` with its exact interval range: max 0 at
    (0.3, -0.1)."""
    centre = np.array([0.3, -0.1])

    def bound(bs):
        lo, hi = bs[..., 0] - centre, bs[..., 1] - centre
        low_sq = np.where((lo <= 0) & (hi >= 0), 0.0, np.minimum(lo * lo, hi * hi))
        mid = 0.5 * (bs[..., 0] + bs[..., 1])
        return -low_sq.sum(axis=1), -((mid - centre) ** 2).sum(axis=1), mid

    res = maximize_batch(np.array([[-1.0, 1.0], [-1.0, 1.0]]), bound, atol=1e-6, batch=8)
    assert res.converged and res.upper >= 0.0 and res.upper - res.lower <= 1e-6
    below = maximize_batch(np.array([[-1.0, 1.0], [-1.0, 1.0]]), bound, stop_below=0.5)
    assert below.stop == "below" and below.time_to_below >= 0.0
    capped = maximize_batch(np.array([[-1.0, 1.0], [-1.0, 1.0]]), bound, atol=0.0, max_boxes=10)
    assert capped.stop == "max_boxes" and capped.upper >= 0.0


def test_contraction_rate_mlp_bnb_route_proves_a_rate_and_beats_interval_bnb():
    mlp = _mlp("tanh", seed=7)
    J, mlps, _ = _loop(mlp, gain=0.3)
    box = np.array([[-1.0, 1.0], [-1.0, 1.0]])
    res = contraction_rate(J, X, box, mlps=mlps, max_boxes=20_000)
    assert res.method == "mlp-bnb" and res.how == How.SOUND and res.holds
    assert res.scope.box == ((-1.0, 1.0), (-1.0, 1.0)) and "only on the box" in res.note
    assert res.max_mu_upper - res.max_mu_sampled <= res.tolerance
    enclose = block_enclose_callback({"h": mlp_block("h", mlp)})
    old = contraction_rate(J, X, box, method="interval-bnb", enclose=enclose, max_boxes=400)
    assert res.max_mu_upper <= old.max_mu_upper + 1e-9
    # the sampled maximum of both routes agree (same grid), the sound bounds bracket it
    assert res.max_mu_sampled <= res.max_mu_upper
    with pytest.raises(SpecError, match="mlp-bnb"):
        contraction_rate(J, X, box, method="mlp-bnb")


def test_matrix_bnb_on_a_wider_network_reaches_its_tolerance():
    mlp = _mlp("tanh", sizes=(2, 16, 16, 2), seed=8)
    J, mlps, _ = _loop(mlp, gain=0.3)
    dec = decompose_jacobian(J, X, mlps)
    assert dec is not None
    out = matrix_bnb(dec, np.array([[-1.0, 1.0], [-1.0, 1.0]]), "mu2", tol=1e-3, max_boxes=200_000)
    assert out.result.converged and out.upper < 0


# ----------------------------------------------------------------- nonsmooth (relu) networks


PRELU_16 = "prelu(" + ", ".join(repr(0.05 * k) for k in range(16)) + ")"  # one slope per unit


@pytest.mark.parametrize("act", ["relu", "leaky_relu(0.1)", "elu(0.5)", PRELU_16])
@pytest.mark.parametrize("objective", ["mu2", "norm2"])
def test_relu_box_bounds_dominate_every_sampled_clarke_jacobian(act, objective):
    """A random-weight relu network's closed loop: the bound on every box is never below the
    sampled value (so the proved rate is never above the sampled one), including boxes that
    cross the kinks, where the sampled Jacobians on both sides are elements of the Clarke
    Jacobian (docs/math/nonsmooth.md)."""
    m = _mlp("relu", sizes=(2, 16, 16, 2), seed=7, scale=2.0)
    mlp = MLP(m.weights, m.biases, activations=(act, act, "identity"))
    assert not mlp.smooth
    J, mlps, jac = _loop(mlp, gain=1.0)
    dec = decompose_jacobian(J, X, mlps)
    assert dec is not None
    rng = np.random.default_rng(8)
    for rad in (1.0, 0.2, 0.02):
        c = rng.uniform(-1.5, 1.5, (30, 2))
        boxes = np.stack([c - rad, c + rad], axis=-1)
        ub, val, _ = box_bounds(dec, boxes, objective)
        assert np.all(np.isfinite(ub))
        for k in range(boxes.shape[0]):
            pts = c[k] + rng.uniform(-rad, rad, (400, 2))
            M = dec.evaluate(pts)  # jacobian_np: one Clarke element at every point
            f = mu_2(M) if objective == "mu2" else np.linalg.norm(M, ord=2, axis=(1, 2))
            assert f.max() <= ub[k] + SAMPLE_TOL
            assert val[k] <= ub[k] + SAMPLE_TOL


def test_relu_rate_on_a_box_is_never_above_the_sampled_rate_and_has_no_jacobian_lipschitz():
    mlp = _mlp("relu", sizes=(2, 16, 16, 2), seed=9, scale=1.5)
    J, mlps, _ = _loop(mlp, gain=0.5)
    dec = decompose_jacobian(J, X, mlps)
    assert dec is not None
    box = np.array([[-1.0, 1.0], [-1.0, 1.0]])
    res = matrix_bnb(dec, box, "mu2", max_boxes=400, n_samples=2000)
    g = np.linspace(-1.0, 1.0, 101)
    grid = np.stack(np.meshgrid(g, g), axis=-1).reshape(-1, 2)
    sampled = float(mu_2(dec.evaluate(grid)).max())
    assert res.upper >= sampled - SAMPLE_TOL  # rate = -upper <= -sampled
    # the Jacobian jumps across the kinks: no Lipschitz constant, never a finite one
    ub, _, _ = box_bounds(dec, box[None], "jac_lipschitz")
    assert ub[0] == math.inf
