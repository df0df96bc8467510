"""Lowering of sympy expressions (possibly containing blocks) to jax functions.

:func:`lower` turns a matrix of expressions in ``(t, x_1..x_n)`` into a jax-traceable function
``(t, x) -> array``. Block applications are evaluated once per distinct argument tuple: each is
replaced by a placeholder symbol, the block (or its Jacobian/Hessian) is called on the lowered
arguments, and the remaining expression is lambdified with sympy's jax printer. The expressions
were built by the safe parser or by the user's own Python code, never from user text directly.
"""

from __future__ import annotations

from collections.abc import Callable, Mapping, Sequence
from dataclasses import dataclass
from typing import TYPE_CHECKING

import sympy as sp

from drip_cert.model.blocks import Block, BlockFunction, block_applications

if TYPE_CHECKING:
    import jax


@dataclass(frozen=True)
class _BlockCall:
    block: Block
    arg_fn: Callable  # (t, *states, *earlier placeholders) -> list of arg values
    n_prev: int  # number of placeholders (earlier nesting levels) arg_fn takes
    # (deriv tuple, out index, position in placeholder list)
    outputs: tuple[tuple[tuple[int, ...], int, int], ...]


def lower(
    exprs: sp.MatrixBase | Sequence[sp.Expr],
    t: sp.Symbol,
    states: Sequence[sp.Symbol],
    blocks: Mapping[str, Block],
) -> Callable:
    """Lower ``exprs`` to a jax function ``(t, x) -> array`` of ``exprs``' shape.

    Parameters
    ----------
    exprs
        A sympy matrix (the function returns arrays of its shape, ``(n, 1)`` included) or a
        flat sequence of expressions (the function returns a vector).
    t, states
        The time symbol and the state symbols, in order.
    blocks
        The blocks the expressions may call.

    Returns
    -------
    callable
        ``fn(t, x)`` with ``x`` of shape ``(n,)``; traceable, usable under ``jax.vmap``.
    """
    from drip_cert._jax import jnp  # jax: keep off the CLI start-up path

    is_matrix = isinstance(exprs, sp.MatrixBase)
    mat = sp.Matrix(exprs)
    shape = mat.shape if is_matrix else (len(mat),)
    flat = list(mat)
    states = tuple(states)
    placeholders: list[sp.Symbol] = []
    calls: list[_BlockCall] = []
    while True:
        apps: set[BlockFunction] = set()
        for e in flat:
            apps |= block_applications(e)
        if not apps:
            break
        inner = [a for a in apps if not any(block_applications(arg) for arg in a.args)]
        groups: dict[tuple[str, tuple], list[BlockFunction]] = {}
        for a in sorted(inner, key=sp.default_sort_key):
            groups.setdefault((a.block_name, a.args), []).append(a)
        subs: dict[BlockFunction, sp.Symbol] = {}
        level_prev = list(placeholders)
        for (bname, args), members in groups.items():
            arg_fn = sp.lambdify([t, *states, *level_prev], list(args), modules="jax")
            outs: list[tuple[tuple[int, ...], int, int]] = []  # as _BlockCall.outputs
            for a in members:
                sym = sp.Dummy(f"{bname}_{a.out_index}")
                outs.append((a.deriv, a.out_index, len(placeholders) + len(outs)))
                subs[a] = sym
            placeholders.extend(subs[a] for a in members)
            calls.append(_BlockCall(blocks[bname], arg_fn, len(level_prev), tuple(outs)))
        flat = [e.xreplace(subs) for e in flat]
    main = sp.lambdify([t, *states, *placeholders], flat, modules="jax")

    jac_cache: dict[str, Callable] = {}
    hess_cache: dict[str, Callable] = {}

    def _deriv_fn(block: Block, order: int) -> Callable:
        cache = jac_cache if order == 1 else hess_cache
        if block.name not in cache:
            cache[block.name] = block.jacobian_fn() if order == 1 else block.hessian_fn()
        return cache[block.name]

    def fn(tt: jax.Array, x: jax.Array) -> jax.Array:
        xs = [x[i] for i in range(len(states))]
        vals: list[jax.Array | None] = [None] * len(placeholders)
        for call in calls:
            z = jnp.stack(jnp.broadcast_arrays(*call.arg_fn(tt, *xs, *vals[: call.n_prev])))
            results: dict[int, jax.Array] = {}
            for deriv, j, pos in call.outputs:
                order = len(deriv)
                if order not in results:
                    results[order] = (
                        call.block.fn(z) if order == 0 else _deriv_fn(call.block, order)(z)
                    )
                r = results[order]
                vals[pos] = r[(j, *deriv)]
        out = main(tt, *xs, *vals)
        arr = jnp.stack(jnp.broadcast_arrays(*[jnp.asarray(o, dtype=jnp.float64) for o in out]))
        return arr.reshape(shape)

    return fn
