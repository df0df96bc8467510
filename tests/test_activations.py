"""Tests of drip_cert.model.activations: every activation class's enclosures contain the exact
values (mpmath at 50 digits), dense float samples (within float evaluation error), and its point
slopes agree with jax autodiff."""

from __future__ import annotations

import math

import mpmath as mp
import numpy as np
import pytest
from scipy.special import ndtr

from drip_cert._jax import jax, jnp
from drip_cert.errors import SpecError
from drip_cert.model.activations import ACTIVATIONS, get_activation
from drip_cert.model.mlp import MLP, init_mlp

MP_DPS = 50  # mpmath digits: far beyond float64, so its values are "exact" for these checks
SAMPLE_REL = 8 * 2.0**-52  # float evaluation of the sampled value (a few roundings + libm ulps)
SAMPLE_ABS = 1e-300  # absolute floor of the same (values near underflow)
AUTODIFF_REL = 1e-12  # prime_np vs jax autodiff: two float evaluations of one formula
AUTODIFF_ABS = 1e-14  # ... near zero, relative error is meaningless
N_BOXES = 300
N_SAMPLES = 64

SPECS = [
    "identity",
    "relu",
    "leaky_relu(0.1)",
    "tanh",
    "sigmoid",
    "softplus",
    "silu",
    "elu(1.0)",
    "elu(0.5)",
    "gelu",
]


def _mp_sigma(z):
    return 1 / (1 + mp.exp(-z))


def _mp_fns(spec: str):
    """Exact value, derivative and second derivative (mpmath), at points off the kinks."""
    act = get_activation(spec)
    a = getattr(act, "alpha", None)
    s = _mp_sigma
    if spec == "identity":
        return (lambda z: z, lambda z: mp.mpf(1), lambda z: mp.mpf(0))
    if spec in ("relu", "leaky_relu(0.1)"):
        return (
            lambda z: z if z >= 0 else a * z,
            lambda z: mp.mpf(1) if z > 0 else mp.mpf(a),
            None,
        )
    if spec == "tanh":
        return (mp.tanh, lambda z: mp.sech(z) ** 2, lambda z: -2 * mp.tanh(z) * mp.sech(z) ** 2)
    if spec == "sigmoid":
        return (
            s,
            lambda z: s(z) * (1 - s(z)),
            lambda z: s(z) * (1 - s(z)) * (1 - 2 * s(z)),
        )
    if spec == "softplus":
        return (lambda z: mp.log(1 + mp.exp(z)), s, lambda z: s(z) * (1 - s(z)))
    if spec == "silu":
        return (
            lambda z: z * s(z),
            lambda z: s(z) + z * s(z) * (1 - s(z)),
            lambda z: 2 * s(z) * (1 - s(z)) + z * s(z) * (1 - s(z)) * (1 - 2 * s(z)),
        )
    if spec.startswith("elu"):
        return (
            lambda z: z if z > 0 else a * mp.expm1(z),
            lambda z: mp.mpf(1) if z > 0 else a * mp.exp(z),
            (lambda z: mp.mpf(0) if z > 0 else mp.exp(z)) if a == 1.0 else None,
        )
    if spec == "gelu":
        phi = mp.npdf
        return (
            lambda z: z * mp.ncdf(z),
            lambda z: mp.ncdf(z) + z * phi(z),
            lambda z: phi(z) * (2 - z * z),
        )
    raise AssertionError(spec)


def _boxes(seed: int):
    rng = np.random.default_rng(seed)
    lo = rng.uniform(-8, 8, N_BOXES)
    hi = lo + rng.exponential(1.0, N_BOXES)
    # intervals around every critical point of the classes and the kinks
    special = [
        -2.0,
        -1.4142,
        -1.2785,
        -0.7518,
        -0.3,
        0.0,
        0.3,
        1.3170,
        2.0,
        2.3994,
        3.4358,
        -3.4358,
    ]
    lo[: len(special)] = np.array(special) - 0.05
    hi[: len(special)] = np.array(special) + 0.05
    lo[len(special)] = hi[len(special)] = 0.0  # a degenerate interval at the kink
    lo[len(special) + 1], hi[len(special) + 1] = -40.0, -30.0  # deep left tail
    lo[len(special) + 2], hi[len(special) + 2] = 30.0, 45.0  # deep right tail
    return lo, hi


@pytest.mark.parametrize("spec", SPECS)
def test_enclosures_contain_exact_values_at_interval_points(spec):
    """Rigorous: the exact (mpmath) value, slope and second derivative at points of ``[lo, hi]``
    (the ends, the centre and points inside) lie in the enclosures over ``[lo, hi]``."""
    act = get_activation(spec)
    f, fp, fpp = _mp_fns(spec)
    lo, hi = _boxes(1)
    v = act.enclose(lo, hi)
    d = act.slope_range(lo, hi)
    sec = act.second_range(lo, hi)
    assert (sec is None) == (not act.smooth)
    with mp.workdps(MP_DPS):
        for k in range(N_BOXES):
            for u in (0.0, 0.25, 0.5, 0.9, 1.0):
                z = mp.mpf(float(lo[k])) + u * (mp.mpf(float(hi[k])) - mp.mpf(float(lo[k])))
                assert v[0][k] <= f(z) <= v[1][k], (spec, k, z)
                if z != 0 or spec in ("tanh", "sigmoid", "softplus", "silu", "gelu", "identity"):
                    assert d[0][k] <= fp(z) <= d[1][k], (spec, k, z)
                if fpp is not None and z != 0:
                    assert sec is not None
                    assert sec[0][k] <= fpp(z) <= sec[1][k], (spec, k, z)


@pytest.mark.parametrize("spec", SPECS)
def test_enclosures_contain_dense_float_samples(spec):
    act = get_activation(spec)
    lo, hi = _boxes(2)
    t = np.linspace(0.0, 1.0, N_SAMPLES)[:, None]
    z = lo + t * (hi - lo)
    for (elo, ehi), vals in (
        # GELU sampled as z Phi(z): the 1 + erf form of act.np cancels in the left tail
        (act.enclose(lo, hi), z * ndtr(z) if spec == "gelu" else act.value_np(z)),
        (act.slope_range(lo, hi), act.prime_np(z)),
    ):
        pad = SAMPLE_REL * np.abs(vals) + SAMPLE_ABS
        assert np.all(vals >= elo - pad) and np.all(vals <= ehi + pad), spec
        assert np.all(elo <= ehi)


def test_relu_slope_range_is_the_clarke_derivative():
    act = get_activation("relu")
    lo = np.array([-2.0, -1.0, 0.0, 0.5, -1.0])
    hi = np.array([-1.0, 0.0, 0.0, 2.0, 1.0])
    slo, shi = act.slope_range(lo, hi)
    np.testing.assert_array_equal(slo, [0.0, 0.0, 0.0, 1.0, 0.0])
    np.testing.assert_array_equal(shi, [0.0, 1.0, 1.0, 1.0, 1.0])
    assert act.second_range(lo, hi) is None and not act.smooth


@pytest.mark.parametrize("spec", SPECS)
def test_point_slope_agrees_with_jax_autodiff(spec):
    act = get_activation(spec)
    z = np.random.default_rng(3).uniform(-6, 6, 500)
    z = z[np.abs(z) > 1e-3]  # off the kinks
    auto = np.asarray(jax.vmap(jax.grad(lambda x: act.value_jax(x)))(jnp.asarray(z)))
    np.testing.assert_allclose(act.prime_np(z), auto, rtol=AUTODIFF_REL, atol=AUTODIFF_ABS)
    np.testing.assert_allclose(
        act.value_np(z),
        np.asarray(act.value_jax(jnp.asarray(z))),
        rtol=AUTODIFF_REL,
        atol=AUTODIFF_ABS,
    )


@pytest.mark.parametrize("spec", SPECS)
def test_global_bounds_contain_the_exact_extremes(spec):
    """``bounds`` holds the global slope range and ``sup |s''|``: checked against a dense mpmath
    scan (a lower bound of the true extremes, so the global bounds must contain them)."""
    act = get_activation(spec)
    b = act.bounds
    f, fp, fpp = _mp_fns(spec)
    with mp.workdps(30):
        zs = [mp.mpf(x) for x in np.linspace(-12, 12, 2401) if x != 0]
        slopes = [fp(z) for z in zs]
        assert b.slope_lo <= min(slopes) and max(slopes) <= b.slope_hi
        if fpp is not None:
            assert max(abs(fpp(z)) for z in zs) <= b.abs_curv
        else:
            assert b.abs_curv == math.inf


def test_known_constants():
    assert get_activation("sigmoid").bounds.slope_hi == pytest.approx(0.25, abs=1e-15)
    assert get_activation("sigmoid").bounds.abs_curv == pytest.approx(math.sqrt(3) / 18, rel=1e-12)
    assert get_activation("silu").bounds.abs_curv == pytest.approx(0.5, abs=1e-15)
    assert get_activation("gelu").bounds.abs_curv == pytest.approx(
        math.sqrt(2 / math.pi), rel=1e-12
    )


def test_registry_parses_names_and_parameters():
    assert set(ACTIVATIONS) == {
        "identity",
        "relu",
        "leaky_relu",
        "prelu",
        "tanh",
        "sigmoid",
        "softplus",
        "silu",
        "elu",
        "gelu",
    }
    assert get_activation("swish") == get_activation("silu")
    assert get_activation("leaky_relu(0.2)").alpha == 0.2
    assert get_activation("leaky_relu").alpha == 0.01
    assert get_activation(get_activation("elu(0.5)").spec) == get_activation("elu(0.5)")
    assert get_activation(None).spec == "identity"
    for bad in ("softsign", "tanh(2)", "leaky_relu(x)", "leaky_relu(-1)", "elu(0)"):
        with pytest.raises(SpecError):
            get_activation(bad)


def test_mlp_per_layer_activations_and_both_constructors():
    rng = np.random.default_rng(4)
    m = init_mlp((2, 5, 4, 1), rng, activation="tanh")
    mixed = MLP(m.weights, m.biases, activations=("relu", "sigmoid", "identity"))
    assert mixed.activation == "mixed" and mixed.output_activation is None
    assert mixed.activation_specs == ("relu", "sigmoid", "identity") and not mixed.smooth
    x = rng.normal(size=(7, 2))
    h = np.maximum(x @ m.weights[0].T + m.biases[0], 0.0)
    h = 1 / (1 + np.exp(-(h @ m.weights[1].T + m.biases[1])))
    np.testing.assert_allclose(mixed.apply_np(x), h @ m.weights[2].T + m.biases[2], rtol=1e-14)
    np.testing.assert_allclose(
        np.asarray(mixed.apply_jax(jnp.asarray(x))), mixed.apply_np(x), rtol=1e-13
    )
    old = MLP(m.weights, m.biases, "gelu", "tanh")
    assert old.activation_specs == ("gelu", "gelu", "tanh") and old.smooth
    with pytest.raises(SpecError, match="one per layer"):
        MLP(m.weights, m.biases, activations=("relu", "relu"))


AUTODIFF_ROUNDING = 1e-12
"""The float64 rounding of an autodiff Jacobian of a 2-8-8-1 network with O(1) weights (~1e-15)
with room: the enclosure is rigorous, the sampled Jacobian is not."""


@pytest.mark.parametrize("activation", ["relu", "leaky_relu(0.1)", "tanh"])
def test_centred_jacobian_enclosure_contains_sampled_jacobians(activation):
    """The centred Jacobian enclosure over boxes (used by the sup of ||pi_IL - pi*||): for a
    smooth network the mean-value form, for a relu one the plain Clarke enclosure (no Hessian
    through a kink; this asserted a Hessian before). Every autodiff Jacobian at points of the box
    (almost everywhere differentiable) lies inside."""
    from drip_cert.analysis.networks.mlp import enclose_jacobian_centred

    rng = np.random.default_rng(3)
    m = init_mlp((2, 8, 8, 1), rng, activation=activation)
    lo, hi = np.array([[-0.5, -0.2]]), np.array([[0.1, 0.4]])
    jlo, jhi = enclose_jacobian_centred(m, lo, hi)
    X = lo + rng.random((500, 2)) * (hi - lo)
    J = np.asarray(jax.vmap(jax.jacfwd(lambda x: m.apply_jax(x[None, :])[0]))(jnp.asarray(X)))
    assert np.all(J >= jlo[0] - AUTODIFF_ROUNDING) and np.all(J <= jhi[0] + AUTODIFF_ROUNDING)


def test_prelu_is_leaky_relu_unit_by_unit():
    """Per-unit slopes (nn.PReLU(num_parameters=n)): every enclosure of unit i is that of
    leaky_relu(alpha_i); the global constants are the hull over the units; the spec string
    parses back; an MLP checks the slope count against the layer width."""
    slopes = (0.0, 0.1, 0.5, 2.0)
    act = get_activation(f"prelu({', '.join(map(repr, slopes))})")
    assert act.slopes == slopes and get_activation(act.spec) == act and not act.smooth
    rng = np.random.default_rng(5)
    lo = rng.uniform(-2, 1, (50, 4))
    hi = lo + rng.uniform(0, 2, (50, 4))
    lo[0], hi[0] = 0.0, 0.0  # a degenerate interval at the kink: both slopes (Clarke)
    for i, a in enumerate(slopes):
        leaky = get_activation(f"leaky_relu({a!r})")
        for mine, ref in zip(
            (act.enclose(lo, hi), act.slope_range(lo, hi)),
            (leaky.enclose(lo[:, i], hi[:, i]), leaky.slope_range(lo[:, i], hi[:, i])),
        ):
            np.testing.assert_array_equal(mine[0][:, i], ref[0])
            np.testing.assert_array_equal(mine[1][:, i], ref[1])
        z = rng.normal(size=(30, 4))
        np.testing.assert_array_equal(act.value_np(z)[:, i], leaky.value_np(z[:, i]))
        np.testing.assert_array_equal(act.prime_np(z)[:, i], leaky.prime_np(z[:, i]))
    assert act.second_range(lo, hi) is None
    b = act.bounds
    assert (b.slope_lo, b.slope_hi, b.abs_slope, b.abs_curv) == (0.0, 2.0, 2.0, math.inf)
    z = rng.normal(size=(7, 4))
    np.testing.assert_array_equal(np.asarray(act.value_jax(jnp.asarray(z))), act.value_np(z))
    w = rng.normal(size=(4, 3))
    MLP((w, rng.normal(size=(1, 4))), (np.zeros(4), np.zeros(1)), activations=(act, "identity"))
    with pytest.raises(SpecError, match="4 per-unit parameters but the layer has 3 units"):
        MLP((w[:3], rng.normal(size=(1, 3))), (np.zeros(3), np.zeros(1)), activations=(act, None))
    for bad in ("prelu(0.1, x)", "prelu(0.1, -1)"):
        with pytest.raises(SpecError):
            get_activation(bad)
