"""MLP evaluation: the jax path (broadcast first layer) equals numpy and the product form."""

from __future__ import annotations

import numpy as np
import pytest

from drip_cert._jax import jax, jnp
from drip_cert.model.mlp import apply_params, init_mlp

# float64 evaluation of the same sums in another order: a few ulps of the O(1) outputs
SUM_ORDER_TOL = 1e-13


@pytest.mark.parametrize(
    ("sizes", "output_activation"),
    [
        ([4, 64, 64, 4], None),  # narrow input: broadcast first layer
        ([2, 16, 1], "tanh"),  # narrow input, output activation
        ([12, 32, 3], None),  # wide input: plain products
        ([4, 3], None),  # a single affine layer
    ],
)
def test_apply_jax_equals_numpy_and_product_form(sizes, output_activation):
    rng = np.random.default_rng(11)
    mlp = init_mlp(sizes, rng, output_activation=output_activation)
    x = rng.normal(size=(50, sizes[0])) * 2.0
    ref = mlp.apply_np(x)
    params = [(jnp.asarray(w), jnp.asarray(b)) for w, b in mlp.params()]
    prod = apply_params(params, jnp.asarray(x), mlp.activation, output_activation, xp=jnp)
    got = jax.jit(mlp.apply_jax)(jnp.asarray(x))
    np.testing.assert_allclose(np.asarray(got), ref, rtol=0, atol=SUM_ORDER_TOL)
    np.testing.assert_allclose(np.asarray(prod), ref, rtol=0, atol=SUM_ORDER_TOL)
    # one unbatched path and its Jacobian agree with the product form too
    j1 = jax.jacfwd(mlp.apply_jax)(jnp.asarray(x[0]))
    j2 = jax.jacfwd(lambda z: apply_params(params, z, mlp.activation, output_activation, xp=jnp))(
        jnp.asarray(x[0])
    )
    assert j1.shape == (sizes[-1], sizes[0])
    np.testing.assert_allclose(np.asarray(j1), np.asarray(j2), rtol=0, atol=SUM_ORDER_TOL)
