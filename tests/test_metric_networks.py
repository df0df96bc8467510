"""A network in the coordinates of a metric, ``N(Theta^{-1} z)``, read as a network block whose
first layer is ``W_0 Theta^{-1}`` (docs/math/contraction.md section 5.4): the exact fold, the
batched box bound and the slope-restricted LMI in ``z`` against the true ``z``-Jacobian
``Theta J_x(Theta^{-1} z) Theta^{-1}``, and the same numbers as in ``x`` for an orthogonal
``Theta``."""

from __future__ import annotations

from fractions import Fraction

import numpy as np
import pytest
import sympy as sp

from drip_cert.analysis.contraction.learned_loop import (
    difference_jacobian_bound,
    lipschitz_rate,
    slope_lmi_rate_global,
)
from drip_cert.analysis.contraction.mlp_loop import box_bounds, decompose_jacobian, system_mlps
from drip_cert.analysis.contraction.rate import contraction_rate
from drip_cert.analysis.contraction.slope_lmi import (
    box_slope_bnb,
    sampled_slopes,
    slope_lmi_rate,
    slope_structure,
)
from drip_cert.analysis.growth.closed_loop import affine_in_blocks, closed_loop_constants
from drip_cert.analysis.networks.mlp import jacobian_np
from drip_cert.learn.imitation import learned_system
from drip_cert.model.blocks import MappedMLP, linear_input_map
from drip_cert.model.mlp import MLP, init_mlp
from drip_cert.model.system import System
from drip_cert.provenance import GLOBAL, How, Quantity

#: float mu_2 of a sampled z-Jacobian (Theta J Theta^{-1} in floats) vs a rigorous bound:
#: the float products and eigvalsh err by O(n eps ||Theta|| ||J|| ||Theta^{-1}||)
SAMPLE_TOL = 1e-12
#: the folded network's float Jacobian vs Theta-mapped float Jacobian of the original (rounding)
FOLD_TOL = 1e-13
#: Clarabel's optimality gap on these small SDPs (relative ~1e-8) and the verified rate's back-off
SOLVER_TOL = 1e-6
#: an orthogonal permutation Theta: the z-problem is the x-problem with its axes renamed; the
#: enclosures sum in another order, so the bounds agree to rounding only
PERMUTATION_TOL = 1e-12
#: random states of the soundness checks
N_SAMPLES = 3000

q, v = sp.symbols("q v", real=True)
#: q'' = -q - 0.5 q' + u; the learned policy is K x + N(x) with K = (-1, -1) and a small tanh
#: network N: its loop [[0, 1], [-2, -1.5]] + B DN has mu_2 > 0 in (q, q') and contracts in the
#: metric P below
OSC = System(
    name="oscillator",
    states=(q, v),
    f=[v, -q - sp.Rational(1, 2) * v],
    g=[[0], [1]],
    expert=[-q - v],
    support=[(-1.0, 1.0), (-0.5, 0.5)],
    horizon=5.0,
)
P = np.array([[2.0, 0.5], [0.5, 1.0]])
THETA = np.linalg.cholesky(P).T  # P = Theta^T Theta; Theta^{-1} is not a float matrix


def _net(seed: int = 1, sizes=(2, 8, 1), scale: float = 0.3) -> MLP:
    rng = np.random.default_rng(seed)
    m = init_mlp(list(sizes), rng, activation="tanh", scale=scale)
    return MLP(m.weights, tuple(0.1 * rng.normal(size=b.shape) for b in m.biases), "tanh")


def _systems(theta=THETA, seed: int = 1):
    """The learned system in x, in z = theta x, theta and theta^{-1} as floats, the network."""
    mlp = _net(seed)
    s = learned_system(OSC, mlp, linear=np.array([[-1.0, -1.0]]))
    Th = sp.Matrix(np.asarray(theta).tolist()).applyfunc(sp.Rational)
    Ti = np.array(Th.inv().evalf(30).tolist(), dtype=float)
    return s, s.transformed(theta), np.asarray(theta, dtype=float), Ti, mlp


def _true_z_jacobian(Z: np.ndarray, theta: np.ndarray, Ti: np.ndarray, mlp: MLP) -> np.ndarray:
    """``Theta (A + B (K + DN(Theta^{-1} z))) Theta^{-1}`` in floats, from the x-system's parts
    (not from the z-system's expressions)."""
    X = Z @ Ti.T
    Jx = np.array([[0.0, 1.0], [-2.0, -1.5]]) + np.array([[0.0], [1.0]]) @ jacobian_np(mlp, X)
    return theta @ Jx @ Ti


def _mu2(M: np.ndarray) -> np.ndarray:
    return np.linalg.eigvalsh(0.5 * (M + np.swapaxes(M, -1, -2)))[..., -1]


def _sample(box: np.ndarray, n: int, seed: int = 0) -> np.ndarray:
    rng = np.random.default_rng(seed)
    return box[:, 0] + rng.random((n, box.shape[0])) * (box[:, 1] - box[:, 0])


# ------------------------------------------------------------------ the fold


def test_fold_holds_the_exact_product_within_its_radius():
    """``W_0 S`` in exact rationals lies in ``[W_0' - rad0, W_0' + rad0]``, the radius at most
    half an ulp of the midpoint (nearest rounding) and nonzero where the product is no float."""
    mlp = _net(3, (2, 5, 1))
    S = sp.Matrix(THETA.tolist()).applyfunc(sp.Rational).inv()
    mm = MappedMLP(mlp, sp.ImmutableMatrix(S))
    W = mlp.weights[0]
    for r in range(W.shape[0]):
        for c in range(2):
            exact = sum(
                Fraction(float(W[r, i])) * Fraction(int(S[i, c].p), int(S[i, c].q))
                for i in range(2)
            )
            mid, rad = mm.folded.weights[0][r, c], mm.rad0[r, c]
            assert abs(exact - Fraction(float(mid))) <= Fraction(float(rad))
            assert rad <= 0.5 * np.spacing(abs(mid))
    assert not mm.exact
    # the rest of the network is the same
    assert all(np.array_equal(a, b) for a, b in zip(mm.folded.weights[1:], mlp.weights[1:]))


def test_fold_through_the_identity_or_a_permutation_is_exact():
    mlp = _net(3, (2, 5, 1))
    for S, cols in ((sp.eye(2), [0, 1]), (sp.Matrix([[0, 1], [1, 0]]), [1, 0])):
        mm = MappedMLP(mlp, sp.ImmutableMatrix(S))
        assert mm.exact
        np.testing.assert_array_equal(mm.folded.weights[0], mlp.weights[0][:, cols])


def test_input_map_is_read_exactly_from_the_z_system():
    _, z, _, _, _ = _systems()
    (app,) = {a for e in z.learned for a in e.atoms(sp.Function) if hasattr(a, "block_name")}
    S = linear_input_map(app, z.states)
    Th = sp.Matrix(THETA.tolist()).applyfunc(sp.Rational)
    assert S == Th.inv()
    # an offset or a nonlinearity is not a linear input map
    fn = type(app)
    assert linear_input_map(fn(z.states[0] + 1, z.states[1]), z.states) is None
    assert linear_input_map(fn(sp.sin(z.states[0]), z.states[1]), z.states) is None
    assert linear_input_map(fn(sp.sqrt(2) * z.states[0], z.states[1]), z.states) is None


# ------------------------------------------------------------------ the batched box bound in z


def test_z_jacobian_is_read_as_folded_blocks():
    """On 17f5740 ``decompose_jacobian`` returned ``None`` for ``N(Theta^{-1} z)`` (the generic
    interval search ran); now the decomposition evaluates the true z-Jacobian."""
    _, z, theta, Ti, mlp = _systems()
    dec = decompose_jacobian(z.closed_loop_jacobian("learned"), z.states, system_mlps(z))
    assert dec is not None
    assert dec.rad0(0) is not None and np.any(dec.rad0(0))
    Z = _sample(np.array(z.support), 200)
    np.testing.assert_allclose(
        dec.evaluate(Z), _true_z_jacobian(Z, theta, Ti, mlp), rtol=0, atol=FOLD_TOL
    )


def test_z_box_bounds_enclose_sampled_mu2_of_the_true_z_jacobian():
    """Soundness: on random sub-boxes of the z-support, the per-box vertex bound is >= mu_2 of
    ``Theta J_x(Theta^{-1} z) Theta^{-1}`` at every sampled point of the box."""
    _, z, theta, Ti, mlp = _systems()
    dec = decompose_jacobian(z.closed_loop_jacobian("learned"), z.states, system_mlps(z))
    assert dec is not None
    sup = np.array(z.support)
    rng = np.random.default_rng(7)
    boxes = []
    for _ in range(40):
        a, b = _sample(sup, 2, seed=int(rng.integers(1 << 30)))
        w = rng.choice([1.0, 0.1, 0.01])
        lo = np.minimum(a, a + w * (b - a))
        hi = np.maximum(a, a + w * (b - a))
        boxes.append(np.stack([lo, hi], axis=1))
    ub, _, _ = box_bounds(dec, np.array(boxes), "mu2")
    for k, bx in enumerate(boxes):
        Z = _sample(bx, N_SAMPLES // 40, seed=k)
        assert _mu2(_true_z_jacobian(Z, theta, Ti, mlp)).max() <= ub[k] + SAMPLE_TOL


def test_learned_rate_in_z_uses_the_batched_search():
    """On 17f5740 ``auto`` ran ``interval-bnb`` in z; now ``mlp-bnb`` (and its bound is sound
    against the true z-Jacobian)."""
    _, z, theta, Ti, mlp = _systems()
    box = np.array(z.support)
    res = contraction_rate(
        z.closed_loop_jacobian("learned"), z.states, box, mlps=system_mlps(z), max_boxes=2000
    )
    assert res.method == "mlp-bnb"
    sampled = _mu2(_true_z_jacobian(_sample(box, N_SAMPLES), theta, Ti, mlp)).max()
    assert sampled <= res.max_mu_upper + SAMPLE_TOL
    assert res.holds  # the metric's coordinates contract this loop on the box


# ------------------------------------------------------------------ the slope LMI in z


def test_slope_lmi_proves_a_global_rate_in_z():
    """On 17f5740 the slope-lmi route returned ``None`` in z (``N(Theta^{-1} z)`` is not a block
    of the state); now it proves ``mu_2 <= -lambda`` for every z, which holds at sampled z far
    outside the support, and the z-slopes lie in the structure's ranges."""
    _, z, theta, Ti, mlp = _systems()
    g = slope_lmi_rate_global(z, "learned")
    assert g is not None and g.rate.value > 0.0 and g.rate.scope.all_x
    Z = 50.0 * (_sample(np.array([[-1.0, 1.0], [-1.0, 1.0]]), N_SAMPLES) ** 3)
    assert _mu2(_true_z_jacobian(Z, theta, Ti, mlp)).max() <= -g.rate.value + SAMPLE_TOL
    dec = affine_in_blocks(z.closed_loop("learned"), z, input_maps=True)
    assert dec is not None and set(dec.S) == {"pi_il"}
    st = slope_structure(dec, system_mlps(z))
    assert st.E_rad is not None and np.any(st.E_rad)
    s_at = sampled_slopes(st, {"pi_il": MappedMLP(mlp, dec.S["pi_il"]).folded}, Z)
    assert np.all(s_at >= st.alpha) and np.all(s_at <= st.beta)


def test_affine_in_blocks_keeps_its_old_answer_without_input_maps():
    """Callers that do not read the input maps still get ``None`` for ``N(Theta^{-1} z)``."""
    _, z, _, _, _ = _systems()
    assert affine_in_blocks(z.closed_loop("learned"), z) is None


# ------------------------------------------------------------------ equality with x


def test_identity_theta_gives_the_x_numbers_exactly():
    s, z, _, _, _ = _systems(np.eye(2))
    dx = decompose_jacobian(s.closed_loop_jacobian("learned"), s.states, system_mlps(s))
    dz = decompose_jacobian(z.closed_loop_jacobian("learned"), z.states, system_mlps(z))
    assert dx is not None and dz is not None and dz.rad0(0) is None
    box = np.array(s.support)[None]
    assert box_bounds(dx, box)[0][0] == box_bounds(dz, box)[0][0]
    rx = slope_lmi_rate_global(s, "learned")
    rz = slope_lmi_rate_global(z, "learned")
    assert (rx is None) == (rz is None)
    if rx is not None and rz is not None:
        assert rx.rate.value == rz.rate.value


def test_permutation_theta_gives_the_x_numbers():
    """An orthogonal Theta leaves mu_2 unchanged: the z-problem is the x-problem with its axes
    renamed, the fold is exact, and the bound and the LMI rate agree with x."""
    perm = np.array([[0.0, 1.0], [1.0, 0.0]])
    s, z, _, _, _ = _systems(perm)
    dx = decompose_jacobian(s.closed_loop_jacobian("learned"), s.states, system_mlps(s))
    dz = decompose_jacobian(z.closed_loop_jacobian("learned"), z.states, system_mlps(z))
    assert dx is not None and dz is not None
    assert dz.rad0(0) is not None and not np.any(dz.rad0(0))
    box = np.array(s.support)
    bx = box_bounds(dx, box[None])[0][0]
    bz = box_bounds(dz, box[::-1][None])[0][0]
    assert bz == pytest.approx(bx, abs=PERMUTATION_TOL)
    decx = affine_in_blocks(s.closed_loop("learned"), s, input_maps=True)
    decz = affine_in_blocks(z.closed_loop("learned"), z, input_maps=True)
    assert decx is not None and decz is not None
    rx = slope_lmi_rate(slope_structure(decx, system_mlps(s)), obstruct=False).rate
    rz = slope_lmi_rate(slope_structure(decz, system_mlps(z)), obstruct=False).rate
    assert rx is not None and rz is not None
    assert rz == pytest.approx(rx, abs=SOLVER_TOL)


# ------------------------------------------------------------------ a plant nonlinearity


#: the same oscillator with a pendulum's restoring force -sin q (its Jacobian holds -cos q):
#: not affine in blocks, so on 17f5740 the batched search did not apply in x either
PEND = System(
    name="pendulum-like",
    states=(q, v),
    f=[v, -sp.sin(q) - sp.Rational(1, 2) * v],
    g=[[0], [1]],
    expert=[sp.sin(q) - 2 * q - v],
    support=[(-1.0, 1.0), (-0.5, 0.5)],
    horizon=5.0,
)


def _true_pend_z_jacobian(Z, theta, Ti, mlp):
    X = Z @ Ti.T
    A = np.zeros((X.shape[0], 2, 2))
    A[:, 0, 1] = 1.0
    A[:, 1, 0] = -np.cos(X[:, 0]) - 1.0  # the plant's -cos q and K = (-1, -1)
    A[:, 1, 1] = -1.5
    Jx = A + np.array([[0.0], [1.0]]) @ jacobian_np(mlp, X)
    return theta @ Jx @ Ti


@pytest.mark.parametrize("theta", [np.eye(2), THETA])
def test_state_dependent_plant_part_is_enclosed_soundly(theta):
    """``-cos q`` (in z: ``Theta A(Theta^{-1} z) Theta^{-1}``, all four entries) enters the box
    bound through its batched enclosures; on 17f5740 ``decompose_jacobian`` returned ``None``.
    The per-box bound is >= the sampled mu_2 of the true Jacobian on every box."""
    mlp = _net(2)
    s = learned_system(PEND, mlp, linear=np.array([[-1.0, -1.0]]))
    z = s.transformed(theta)
    Th = sp.Matrix(np.asarray(theta).tolist()).applyfunc(sp.Rational)
    Ti = np.array(Th.inv().evalf(30).tolist(), dtype=float)
    dec = decompose_jacobian(z.closed_loop_jacobian("learned"), z.states, system_mlps(z))
    assert dec is not None and len(dec.varying) == (1 if theta is not THETA else 4)
    sup = np.array(z.support)
    Z = _sample(sup, 200)
    np.testing.assert_allclose(
        dec.evaluate(Z), _true_pend_z_jacobian(Z, np.asarray(theta), Ti, mlp), atol=FOLD_TOL
    )
    rng = np.random.default_rng(11)
    boxes = []
    for _ in range(40):
        a, b = _sample(sup, 2, seed=int(rng.integers(1 << 30)))
        w = rng.choice([1.0, 0.1, 0.01])
        boxes.append(np.stack([np.minimum(a, a + w * (b - a)), np.maximum(a, a + w * (b - a))], 1))
    ub, _, _ = box_bounds(dec, np.array(boxes), "mu2")
    for k, bx in enumerate(boxes):
        Zb = _sample(bx, N_SAMPLES // 40, seed=k)
        mu = _mu2(_true_pend_z_jacobian(Zb, np.asarray(theta), Ti, mlp)).max()
        assert mu <= ub[k] + SAMPLE_TOL
    res = contraction_rate(
        z.closed_loop_jacobian("learned"), z.states, sup, mlps=system_mlps(z), max_boxes=2000
    )
    assert res.method == "mlp-bnb"
    assert (
        _mu2(_true_pend_z_jacobian(_sample(sup, N_SAMPLES), np.asarray(theta), Ti, mlp)).max()
        <= res.max_mu_upper + SAMPLE_TOL
    )


def test_a_nonsmooth_or_block_dependent_coefficient_is_not_decomposed():
    """``|q|`` (no mean-value form) and a coefficient ``q`` on a block Jacobian entry are outside
    the form: ``None``, the generic route runs."""
    mlp = _net(2)
    s = learned_system(OSC, mlp)
    J = sp.Matrix(s.closed_loop_jacobian("learned"))
    mlps = system_mlps(s)
    assert decompose_jacobian(J + sp.Matrix([[sp.Abs(q), 0], [0, 0]]), s.states, mlps) is None
    assert decompose_jacobian(J.applyfunc(lambda e: q * e), s.states, mlps) is None
    assert decompose_jacobian(J, s.states, mlps) is not None


def test_lipschitz_routes_read_the_input_map():
    """The closed-form global routes in z: ``||C_k|| Lip(N) ||Theta^{-1}||`` for ``N(Theta^{-1} z)``
    (on 17f5740 both returned ``None`` in z); each bound holds at sampled z far from the support."""
    _, z, theta, Ti, mlp = _systems()
    g = lipschitz_rate(z, "learned")
    d = difference_jacobian_bound(z)
    assert g is not None and d is not None and g.rate.scope.all_x
    Z = 50.0 * (_sample(np.array([[-1.0, 1.0], [-1.0, 1.0]]), N_SAMPLES) ** 3)
    assert _mu2(_true_z_jacobian(Z, theta, Ti, mlp)).max() <= -g.rate.value + SAMPLE_TOL
    # D_z (pi_IL - pi*) = (K + DN(Theta^{-1} z)) Theta^{-1} - K_expert Theta^{-1} = DN(.) Theta^{-1}
    DD = jacobian_np(mlp, Z @ Ti.T) @ Ti
    assert np.linalg.norm(DD, ord=2, axis=(-2, -1)).max() <= d.value + SAMPLE_TOL


def test_closed_loop_growth_constants_are_sound_in_z():
    """``Delta_f`` and ``L_f`` of the z-loop: on 17f5740 ``N(Theta^{-1} z)`` was no block there,
    so ``Delta_f`` fell back to a sampled ratio (an estimate); now both are sound and hold at
    sampled z (``||F(z)|| <= Delta_f sqrt(1 + ||z||^2)``, ``||DF(z)|| <= L_f``)."""
    _, z, theta, Ti, mlp = _systems()
    lam = Quantity.derive("lambda", 0.1, method=How.SOUND, source="test", scope=GLOBAL)
    cl = closed_loop_constants(z, "learned", lam, True)
    assert cl.Delta_f.how == How.SOUND and cl.L_f.how == How.SOUND
    Z = 50.0 * (_sample(np.array([[-1.0, 1.0], [-1.0, 1.0]]), N_SAMPLES) ** 3)
    X = Z @ Ti.T
    Fx = np.stack([X[:, 1], -2.0 * X[:, 0] - 1.5 * X[:, 1] + mlp.apply_np(X)[:, 0]], axis=1)
    Fz = Fx @ theta.T
    ratio = np.linalg.norm(Fz, axis=1) / np.sqrt(1.0 + np.sum(Z**2, axis=1))
    assert ratio.max() <= cl.Delta_f.value * (1.0 + SAMPLE_TOL)
    Jz = _true_z_jacobian(Z, theta, Ti, mlp)
    assert np.linalg.norm(Jz, ord=2, axis=(-2, -1)).max() <= cl.L_f.value + SAMPLE_TOL


def test_box_slope_bound_in_z_holds_at_sampled_points():
    """The per-box slope LMI in z (slope ranges from the folded first layer's interval
    pre-activations) bounds mu_2 of the true z-Jacobian on the box."""
    _, z, theta, Ti, mlp = _systems()
    dec = affine_in_blocks(z.closed_loop("learned"), z, input_maps=True)
    assert dec is not None
    box = np.array(z.support)
    res = box_slope_bnb(dec, system_mlps(z), box, target=-10.0, max_boxes=5)
    assert np.isfinite(res.max_mu_upper)
    mu = _mu2(_true_z_jacobian(_sample(box, N_SAMPLES), theta, Ti, mlp)).max()
    assert mu <= res.max_mu_upper + SAMPLE_TOL
