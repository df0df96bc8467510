"""Fast vectorised enclosures of MLP values, Jacobians and Hessians over many boxes
(drip_cert.analysis.networks.mlp.derivatives): containment of the exact (Arb) point values,
tightness
against the plain interval route, and detection of a dropped rounding or a wrong sign."""

from __future__ import annotations

import numpy as np
import pytest
from flint import arb, ctx

import drip_cert.model.activations as acts
from drip_cert.analysis.networks.mlp import enclose_jacobian, enclose_output
from drip_cert.analysis.networks.mlp.derivatives import (
    enclose_activation_second,
    enclose_derivatives,
    enclose_jacobian_centred,
)
from drip_cert.model.mlp import MLP, init_mlp

#: Arb working precision of the reference values (bits): their balls must be far narrower than
#: the float enclosures' ulp-level padding
ARB_PREC = 200

#: the centred route intersects with the plain one's operations on tighter inputs; its float
#: centre may move by a few ulps of the O(1..100) entries
WIDTH_SLACK = 1e-12


def _mlp(act: str, sizes=(3, 8, 8, 2), seed: int = 0, scale: float = 1.0) -> MLP:
    """A random MLP with non-zero biases (LeCun-normal weights times ``scale``)."""
    rng = np.random.default_rng(seed)
    m = init_mlp(list(sizes), rng, activation=act, scale=scale)
    biases = tuple(0.3 * rng.normal(size=b.shape) for b in m.biases)
    return MLP(m.weights, biases, act, m.output_activation)


# ---------------------------------------------------------------------- Arb reference values


@pytest.fixture(autouse=True)
def _arb_precision():
    old = ctx.prec
    ctx.prec = ARB_PREC
    yield
    ctx.prec = old


def _arb_act(name, a: arb) -> tuple[arb, arb, arb]:
    """``s, s', s''`` at ``a`` in Arb."""
    if name is None or name == "identity":
        return a, arb(1), arb(0)
    if name == "tanh":
        t = a.tanh()
        return t, 1 - t * t, -2 * t * (1 - t * t)
    phi = (-a * a / 2).exp() / (2 * arb.pi()).sqrt()
    Phi = (-a / arb(2).sqrt()).erfc() / 2
    return a * Phi, Phi + a * phi, phi * (2 - a * a)


def _arb_derivatives(mlp: MLP, x: np.ndarray):
    """Value, Jacobian and Hessian of ``mlp`` at the float point ``x`` in Arb (forward mode)."""
    d = mlp.in_dim
    z = [arb(float(v)) for v in x]
    J = [[arb(1) if i == j else arb(0) for j in range(d)] for i in range(d)]
    T = [[[arb(0)] * d for _ in range(d)] for _ in range(d)]
    acts = [mlp.activation] * (len(mlp.weights) - 1) + [mlp.output_activation]
    for w, b, act in zip(mlp.weights, mlp.biases, acts):
        rows = range(w.shape[0])
        cols = range(w.shape[1])
        a = [sum((arb(float(w[m, k])) * z[k] for k in cols), arb(float(b[m]))) for m in rows]
        Ja = [
            [sum((arb(float(w[m, k])) * J[k][i] for k in cols), arb(0)) for i in range(d)]
            for m in rows
        ]
        Ta = [
            [
                [sum((arb(float(w[m, k])) * T[k][i][l] for k in cols), arb(0)) for l in range(d)]
                for i in range(d)
            ]
            for m in rows
        ]
        s = [_arb_act(act, am) for am in a]
        z = [sm[0] for sm in s]
        J = [[s[m][1] * Ja[m][i] for i in range(d)] for m in rows]
        T = [
            [
                [s[m][2] * Ja[m][i] * Ja[m][l] + s[m][1] * Ta[m][i][l] for l in range(d)]
                for i in range(d)
            ]
            for m in rows
        ]
    return z, J, T


def _contains(lo, hi, vals) -> bool:
    """Whether every Arb ball of ``vals`` lies inside ``[lo, hi]`` (nested lists vs arrays)."""
    lo, hi = np.asarray(lo), np.asarray(hi)
    flat = np.array(vals, dtype=object).ravel()
    for v, a, b in zip(flat, lo.ravel(), hi.ravel()):
        if not (arb(float(a)) <= v.lower() and v.upper() <= arb(float(b))):
            return False
    return True


def _points_in(lo, hi, rng, k):
    """Corners, centre and random points of the box ``[lo, hi]`` (k random)."""
    c = lo + 0.5 * (hi - lo)
    pts = [lo, hi, c] + [lo + rng.random(lo.shape) * (hi - lo) for _ in range(k)]
    return pts


@pytest.mark.parametrize("act", ["tanh", "gelu"])
@pytest.mark.parametrize("rad", [0.6, 0.05, 0.0])
def test_derivative_enclosures_contain_the_arb_values(act, rad):
    mlp = _mlp(act, seed=1, scale=1.5)
    rng = np.random.default_rng(2)
    c = rng.uniform(-2, 2, (4, 3))
    lo, hi = c - rad, c + rad
    e = enclose_derivatives(mlp, lo, hi)
    jc = enclose_jacobian_centred(mlp, lo, hi)
    assert e.hessian is not None
    for b in range(lo.shape[0]):
        for x in _points_in(lo[b], hi[b], rng, 3):
            z, J, T = _arb_derivatives(mlp, x)
            assert _contains(e.value[0][b], e.value[1][b], z)
            assert _contains(e.jacobian[0][b], e.jacobian[1][b], J)
            assert _contains(jc[0][b], jc[1][b], J)
            assert _contains(e.hessian[0][b], e.hessian[1][b], T)


def test_gelu_output_layer_and_identity_hidden_layers():
    """Output activations and an identity (linear) network: zero Hessian, exact Jacobian."""
    lin = _mlp("identity", seed=3)
    e = enclose_derivatives(lin, -np.ones(3), np.ones(3))
    assert e.hessian is not None
    assert np.all(e.hessian[0] == 0) and np.all(e.hessian[1] == 0)
    W = lin.weights[2] @ lin.weights[1] @ lin.weights[0]
    assert np.all(e.jacobian[0] <= W) and np.all(W <= e.jacobian[1])
    assert np.max(e.jacobian[1] - e.jacobian[0]) < 1e-12
    m = _mlp("tanh", seed=4)
    m = MLP(m.weights, m.biases, "tanh", "gelu")
    rng = np.random.default_rng(5)
    lo = rng.uniform(-1, 0, 3)
    hi = lo + 0.2
    e = enclose_derivatives(m, lo, hi)
    assert e.hessian is not None
    for x in _points_in(lo, hi, rng, 3):
        z, J, T = _arb_derivatives(m, x)
        assert _contains(*e.value, z) and _contains(*e.jacobian, J) and _contains(*e.hessian, T)


@pytest.mark.parametrize("act", ["tanh", "gelu"])
def test_never_wider_than_the_plain_interval_route_and_much_tighter_on_small_boxes(act):
    mlp = _mlp(act, sizes=(4, 32, 32, 4), seed=6)
    rng = np.random.default_rng(7)
    ratios = {}
    for rad in (1.0, 0.1, 0.01):
        c = rng.uniform(-1, 1, (50, 4))
        lo, hi = c - rad, c + rad
        old_j = enclose_jacobian(mlp, lo, hi)
        old_v = enclose_output(mlp, lo, hi)
        new = enclose_derivatives(mlp, lo, hi, hessian=False)
        cen = enclose_jacobian_centred(mlp, lo, hi)
        for (a, b), (p, q) in ((old_j, new.jacobian), (old_v, new.value), (old_j, cen)):
            w_old, w_new = b - a, q - p
            assert np.all(w_new <= w_old * (1 + WIDTH_SLACK) + WIDTH_SLACK)
        ratios[rad] = float(np.mean(cen[1] - cen[0]) / np.mean(old_j[1] - old_j[0]))
    # the centred form is first order with the true Hessian as constant: on small boxes it
    # beats plain interval propagation by a large factor (measured ~0.1 for rad = 0.01)
    assert ratios[0.01] < 0.3


@pytest.mark.parametrize("act", ["tanh", "gelu"])
def test_second_derivative_enclosure_contains_arb_values_on_a_grid(act):
    rng = np.random.default_rng(8)
    a = np.sort(rng.uniform(-6, 6, (300, 2)), axis=1)
    a[:10] = [[0.6, 0.7], [-0.7, -0.6], [-0.1, 0.1], [1.9, 2.1], [-2.1, -1.9]] * 2  # extremes
    lo, hi = enclose_activation_second(act, a[:, 0], a[:, 1])
    for k in range(a.shape[0]):
        for u in (0.0, 0.3, 0.5, 1.0):
            z = a[k, 0] + u * (a[k, 1] - a[k, 0])
            v = _arb_act(act, arb(float(z)))[2]
            assert arb(float(lo[k])) <= v.lower() and v.upper() <= arb(float(hi[k]))


def test_dropping_the_outward_rounding_or_flipping_a_sign_is_detected(monkeypatch):
    """The containment tests bite: without the outward rounding (library-function budgets and
    directed products) some exact value of tanh'' falls outside its point enclosure, and with
    the sign of tanh'' flipped the network Hessian enclosure misses the exact Hessian."""
    z = np.random.default_rng(10).uniform(-3, 3, 200)

    def second_contained() -> bool:
        lo, hi = enclose_activation_second("tanh", z, z)
        vals = [_arb_act("tanh", arb(float(v)))[2] for v in z]
        return _contains(lo, hi, vals)

    assert second_contained()

    def plain_mul(alo, ahi, blo, bhi):  # the four end products, NOT rounded outward
        p = np.stack([alo * blo, alo * bhi, ahi * blo, ahi * bhi])
        return p.min(axis=0), p.max(axis=0)

    with monkeypatch.context() as mp:
        mp.setattr(acts, "imul", plain_mul)
        mp.setattr(acts, "tanh_bounds", lambda x: (np.tanh(x), np.tanh(x)))
        mp.setattr(acts, "sech2_bounds", lambda a: (1.0 / np.cosh(a) ** 2,) * 2)
        assert not second_contained()

    mlp = _mlp("tanh", seed=9, scale=1.5)
    pts = np.random.default_rng(11).uniform(-2, 2, (10, 3))

    def hessian_contained() -> bool:
        e = enclose_derivatives(mlp, pts, pts, centred=False)
        assert e.hessian is not None
        return all(
            _contains(e.hessian[0][b], e.hessian[1][b], _arb_derivatives(mlp, pts[b])[2])
            for b in range(pts.shape[0])
        )

    assert hessian_contained()
    orig = acts.Tanh._second_point
    with monkeypatch.context() as mp:
        mp.setattr(
            acts.Tanh, "_second_point", lambda self, x: tuple(-v for v in orig(self, x)[::-1])
        )
        assert not hessian_contained()
