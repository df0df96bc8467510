"""The opt-in float32 policy path: a float64 policy re-evaluated in float32.

The learned policy ``pi_IL`` of a :class:`~drip_cert.model.numeric.SimModel` is a float64 jax
callable (an MLP block of a ``System``, or any traceable function). :func:`lower_precision` traces
it once to a jaxpr and evaluates that jaxpr with every float64 constant, literal and dtype
parameter in float32 (the weights rounded to float32 once, every product, sum and activation in
float32), then casts the action back to float64. Only the policy changes: the state, the noise,
the other vector fields and the L1-DRAC filter stay float64 (:mod:`drip_cert.sim.kernel` casts
the state to float32 on the way in and the action to float64 on the way out). Primitives whose
parameters hold jaxprs other than plain calls (``scan``, ``while``, ``cond``) are evaluated in
float64 (their inputs widened, their outputs narrowed): correct, only not faster.

Why: the policy's 64x64 products run near the machine's float64 matrix throughput and are most of
an engine step (``benchmarks/mc_throughput.py``); float32 doubles the SIMD width. The price is
the policy's rounding, ~1e-7 relative per action instead of ~1e-16, which moves every simulated
path a little; :func:`drip_cert.sim.dtype_effect.policy_dtype_effect` measures how much the gap
statistics move, and a float32 run reports it. The certificate never uses float32: this touches
the simulation only.
"""

from __future__ import annotations

import math
from collections.abc import Callable, Sequence
from typing import Any

import numpy as np
from jax.extend import core as jcore

from drip_cert._jax import jax, jnp

__all__ = ["in_dtype", "lower_precision"]

# call-like primitives whose body is evaluated inline (their semantics is "call this jaxpr")
_INLINE = ("jit", "pjit", "closed_call", "core_call", "custom_jvp_call", "custom_vjp_call")
_BODY_PARAMS = ("jaxpr", "call_jaxpr", "fun_jaxpr")


def lower_precision(fn: Callable, n_in: int, dtype: Any = jnp.float32) -> Callable:
    """``fn`` (float64 ``(n_in,) -> (m,)``, jax-traceable) evaluated in ``dtype``.

    Parameters
    ----------
    fn
        The float64 policy (one path, unbatched).
    n_in
        Its input size.
    dtype
        The arithmetic dtype (``jnp.float32``).

    Returns
    -------
    callable
        ``x (n_in,) float64 -> (m,) float64``: ``x`` rounded to ``dtype``, every float64
        constant, literal and dtype parameter of ``fn``'s jaxpr replaced by ``dtype``, the result
        cast back to float64. Traceable, and batchable by ``vmap``.
    """
    closed = jax.make_jaxpr(fn)(jnp.zeros(n_in, dtype=jnp.float64))
    lo = np.dtype(dtype)
    consts = [_narrow(c, lo) for c in closed.consts]

    def low(x):
        outs = _eval(closed.jaxpr, consts, [jnp.asarray(x).astype(lo)], lo)
        return outs[0].astype(jnp.float64)

    return low


def in_dtype(fn: Callable, examples: Sequence, dtype: Any = jnp.float32) -> Callable:
    """``fn`` with every float64 input, constant, literal, dtype parameter and output in ``dtype``.

    The float32-end-to-end engine (``SimConfig(dtype="float32")``) evaluates the model's vector
    fields with this: ``fn`` is traced once on ``examples`` (float64 arrays of the call's shapes)
    and its jaxpr evaluated as :func:`lower_precision` does, except that the inputs are cast to
    ``dtype`` on the way in and the outputs stay in ``dtype``.
    """
    closed, shape = jax.make_jaxpr(fn, return_shape=True)(*examples)
    out_tree = jax.tree_util.tree_structure(shape)
    lo = np.dtype(dtype)
    consts = [_narrow(c, lo) for c in closed.consts]

    def low(*args):
        outs = _eval(closed.jaxpr, consts, [_narrow(jnp.asarray(a), lo) for a in args], lo)
        outs = [_narrow(o, lo) for o in outs]
        return jax.tree_util.tree_unflatten(out_tree, outs)

    return low


def _narrow(v, lo: np.dtype):
    """``v`` cast to ``lo`` when it is a float64 array or scalar, else ``v``."""
    dt = getattr(v, "dtype", None)
    if dt is None and isinstance(v, float):
        return lo.type(v)
    if dt is not None and np.dtype(dt) == np.float64:
        return v.astype(lo) if hasattr(v, "astype") else lo.type(v)
    return v


def _widen(v):
    dt = getattr(v, "dtype", None)
    if dt is not None and jnp.issubdtype(dt, jnp.floating) and np.dtype(dt) != np.float64:
        return v.astype(jnp.float64)
    return v


def _param(v, lo: np.dtype):
    """A primitive parameter with float64 dtypes replaced by ``lo``."""
    if isinstance(v, np.dtype) and v == np.float64:
        return lo
    if v is np.float64 or v is jnp.float64:
        return lo
    return v


def _holds_jaxpr(p) -> bool:
    """Whether a primitive parameter is a jaxpr or a sequence of them (``cond``'s branches)."""
    if isinstance(p, tuple | list):
        return any(_holds_jaxpr(q) for q in p)
    return isinstance(p, jcore.Jaxpr | jcore.ClosedJaxpr)


def _unrolled_sum_applies(x, axes: Sequence[int], lo: np.dtype) -> bool:
    """Whether a float32 ``reduce_sum`` of ``x`` over ``axes`` is written as a sum in order.

    The engine vmaps these functions over the paths, and XLA's CPU reduction of a ``(B, 4)``
    array over its 4 columns (e.g. a norm inside ``Lambda_mu``) cost ~7-10 CPU ns per path-step
    in float32, more than in float64; :func:`_sum_in_order` makes it elementwise over the paths.
    Only small reductions (at most :data:`_UNROLL_MAX_TERMS` terms), only in float32.
    """
    if lo != np.float32 or getattr(x, "dtype", None) != np.float32:
        return False
    return 0 < math.prod(x.shape[a] for a in axes) <= _UNROLL_MAX_TERMS


_UNROLL_MAX_TERMS = 16
"""Most terms of a float32 sum that :func:`_sum_in_order` unrolls (beyond, XLA's reduction)."""


def _sum_in_order(x, axes: Sequence[int]):
    """``sum(x, axes)`` as ``x[0] + x[1] + ...`` along each axis (the last first), in order."""
    for ax in sorted(axes, reverse=True):
        acc = jax.lax.index_in_dim(x, 0, ax, keepdims=False)
        for k in range(1, x.shape[ax]):
            acc = acc + jax.lax.index_in_dim(x, k, ax, keepdims=False)
        x = acc
    return x


def _eval(jaxpr, consts: Sequence, args: Sequence, lo: np.dtype) -> list:
    """Evaluate ``jaxpr`` with float64 replaced by ``lo`` (see :func:`lower_precision`)."""
    env: dict = {}

    def read(v):
        if isinstance(v, jcore.Literal):
            return _narrow(v.val, lo)
        return env[v]

    for var, val in zip(jaxpr.constvars, consts):
        env[var] = val
    for var, val in zip(jaxpr.invars, args):
        env[var] = val
    for eqn in jaxpr.eqns:
        invals = [read(v) for v in eqn.invars]
        name = eqn.primitive.name
        body = next((eqn.params[k] for k in _BODY_PARAMS if k in eqn.params), None)
        if name in _INLINE and body is not None:
            if isinstance(body, jcore.ClosedJaxpr):
                outs = _eval(body.jaxpr, [_narrow(c, lo) for c in body.consts], invals, lo)
            else:
                outs = _eval(body, [], invals, lo)
        elif any(_holds_jaxpr(p) for p in eqn.params.values()):
            # control flow: evaluated as written, in float64, between two casts
            res = eqn.primitive.bind(*[_widen(v) for v in invals], **eqn.params)
            res = res if eqn.primitive.multiple_results else [res]
            outs = [_narrow(r, lo) for r in res]
        elif name == "reduce_sum" and _unrolled_sum_applies(invals[0], eqn.params["axes"], lo):
            outs = [_sum_in_order(invals[0], eqn.params["axes"])]
        else:
            params = {k: _param(v, lo) for k, v in eqn.params.items()}
            res = eqn.primitive.bind(*invals, **params)
            outs = res if eqn.primitive.multiple_results else [res]
        for var, val in zip(eqn.outvars, outs):
            if not isinstance(var, jcore.DropVar):
                env[var] = val
    return [read(v) for v in jaxpr.outvars]
