"""Counter-based Gaussian noise of the engine: ``threefry2x32`` unrolled, then the inverse CDF.

Each standard normal of a run is a pure function of the seed, the path's global index ``i``,
the step ``j`` and the component ``c``: the 64 output bits of ``threefry2x32(k; (i, j d + c))``
(Salmon et al., "Parallel random numbers: as easy as 1, 2, 3", SC 2011; 20 rounds, the hash
behind ``jax.random``) give a uniform ``u`` on the open interval (-1, 1) with 53 random bits,
and ``z = sqrt(2) erfinv(u)`` (the map ``jax.random.normal`` uses). Nothing depends on how the
paths are grouped into chunks, so chunk size and thread count cannot change a number.

Why not ``jax.extend.random.threefry_2x32``: on the CPU, JAX lowers that primitive with a rolled
``fori_loop`` over the five 4-round blocks, which XLA cannot fuse with the surrounding step; in
the engine's time loop it cost 21 ns per path-step for four normals. :func:`threefry2x32` below
is the same function written as straight-line ``jnp`` code (20 rounds, key injection every 4
rounds, the Skein rotation constants), which XLA fuses into one loop: 5 ns per path-step, and
bit-for-bit the same words (``tests/test_noise.py`` compares them with JAX's on random keys and
counters).
"""

from __future__ import annotations

import math

from jax.extend.random import threefry_2x32

from drip_cert._jax import jax, jnp

__all__ = ["normal_columns", "normals", "normals_via_jax", "threefry2x32"]

# Threefry-2x32 rotation constants (Random123 / Skein), used for rounds 0-3, 4-7, 8-11, ...
_ROTATIONS = ((13, 15, 26, 6), (17, 29, 16, 24))
_PARITY = 0x1BD11BDA  # Skein key-schedule parity constant


def _rotl(v, r: int):
    return (v << jnp.uint32(r)) | (v >> jnp.uint32(32 - r))


def threefry2x32(key1, key2, x0, x1):
    """Threefry-2x32 with 20 rounds: ``(key1, key2)`` hash the counter pair ``(x0, x1)``.

    Parameters
    ----------
    key1, key2
        uint32 scalars (the two words of a ``jax.random.PRNGKey``).
    x0, x1
        uint32 arrays of one shape (the counter words).

    Returns
    -------
    tuple of two uint32 arrays
        The two output words; identical to the halves of
        ``jax.extend.random.threefry_2x32((key1, key2), concatenate([x0, x1]))``.
    """
    ks = (key1, key2, key1 ^ key2 ^ jnp.uint32(_PARITY))
    x0 = x0 + ks[0]
    x1 = x1 + ks[1]
    for block in range(5):
        for r in _ROTATIONS[block % 2]:
            x0 = x0 + x1
            x1 = _rotl(x1, r) ^ x0
        x0 = x0 + ks[(block + 1) % 3]
        x1 = x1 + ks[(block + 2) % 3] + jnp.uint32(block + 1)
    return x0, x1


def normals(keypair, idx, j, d: int, dtype=jnp.float64):
    """Standard normals ``(B, d)`` for paths ``idx`` (uint32, ``(B,)``) at step ``j`` (uint32).

    Entry ``(b, c)`` hashes the counter pair ``(idx[b], j d + c)`` under ``keypair``; the high 53
    of the 64 output bits (first word high) give ``u = (k + 1/2) 2^-52 - 1`` on the open interval
    (-1, 1), and the normal is ``sqrt(2) erfinv(u)``. The smallest ``|u|`` away from the
    endpoints is ``1 - 2^-53``, so the largest normal is about 8.3: tails are exact to
    ``P(|Z| > 8.3) ~ 1e-16``.

    ``dtype=float32`` (the float32 engine): the high 23 bits of the first word give
    ``u = (k + 1/2) 2^-22 - 1`` (exact in float32) and ``z = sqrt(2) erfinv(u)`` in float32 (about
    the resolution of ``jax.random.normal`` in float32; the largest normal is about 5.3,
    ``P(|Z| > 5.3) ~ 1e-7``).
    The same counters, so the same path sees a float32 rounding of the same Brownian increments.
    """
    w0, w1 = _counters(idx, j, d)
    hi, lo = threefry2x32(keypair[0], keypair[1], w0, w1)
    if jnp.dtype(dtype) == jnp.float32:
        return _to_normal32(hi)
    return _to_normal(hi, lo)


def normal_columns(keypair, idx, j, d: int, dtype=jnp.float32) -> tuple:
    """The ``d`` columns of :func:`normals` ``(keypair, idx, j, d, dtype)``, each ``(B,)``.

    The same numbers bit for bit (the same counters, the same elementwise map), computed one
    component at a time on arrays of the batch. Why: XLA's CPU backend vectorizes an
    elementwise loop over a ``(B, d)`` array across its ``d = 4`` components only (``<4 x
    float>``: as many lanes as float64's ``<4 x double>``), so float32 normals built as
    ``(B, d)`` were only 2.1x cheaper than float64 ones although every operation is half as
    wide; over ``(B,)`` arrays it uses full vectors (``benchmarks/mc_throughput.py``: 26 -> 18
    CPU ns per path-step for four float32 normals). The float32 engine uses these; float64
    keeps :func:`normals` (one ``(B, d)`` array is faster there).
    """
    out = []
    for c in range(d):
        w1 = jnp.broadcast_to(j * jnp.uint32(d) + jnp.uint32(c), idx.shape)
        hi, lo = threefry2x32(keypair[0], keypair[1], idx, w1)
        out.append(_to_normal32(hi) if jnp.dtype(dtype) == jnp.float32 else _to_normal(hi, lo))
    return tuple(out)


def normals_via_jax(keypair, idx, j, d: int):
    """:func:`normals` through JAX's own ``threefry_2x32`` primitive on the flattened counters.

    The reference that :func:`normals` equals bit for bit (``tests/test_noise.py``) and the slow
    variant timed by ``benchmarks/mc_throughput.py``: on the CPU the primitive is a rolled loop.
    """
    w0, w1 = _counters(idx, j, d)
    out = threefry_2x32(keypair, jnp.concatenate([w0.reshape(-1), w1.reshape(-1)]))
    half = w0.size
    return _to_normal(out[:half].reshape(w0.shape), out[half:].reshape(w0.shape))


def _counters(idx, j, d: int):
    """The counter words ``(idx[b], j d + c)`` of entry ``(b, c)``, each ``(B, d)`` uint32."""
    b = idx.shape[0]
    w0 = jnp.broadcast_to(idx[:, None], (b, d))
    w1 = jnp.broadcast_to((j * jnp.uint32(d) + jnp.arange(d, dtype=jnp.uint32))[None, :], (b, d))
    return w0, w1


def _to_normal32(hi):
    """float32 ``sqrt(2) erfinv(u)``, ``u = (k + 1/2) 2^-22 - 1`` from the top 23 bits of ``hi``."""
    u = ((hi >> jnp.uint32(9)).astype(jnp.float32) + 0.5) * jnp.float32(2.0**-22) - 1.0
    return jnp.float32(math.sqrt(2.0)) * jax.scipy.special.erfinv(u)


def _to_normal(hi, lo):
    """``sqrt(2) erfinv(u)``, ``u = (k + 1/2) 2^-52 - 1`` from the high 53 of the 64 bits."""
    bits = (hi.astype(jnp.uint64) << jnp.uint64(32)) | lo.astype(jnp.uint64)
    u = ((bits >> jnp.uint64(11)).astype(jnp.float64) + 0.5) * (2.0**-52) - 1.0
    return math.sqrt(2.0) * jax.scipy.special.erfinv(u)
