"""Linear systems from state-space objects and numpy arrays (``System.from_statespace``).

A control user has ``(A, B)`` as arrays, a ``control.ss`` object or a ``scipy.signal.StateSpace``,
and a gain ``K`` from ``control.lqr`` or ``scipy``. This module reads them by duck typing (an
object with ``.A`` and ``.B``; python-control is never imported) into the expressions of a
:class:`~drip_cert.model.system.System`: ``f = A x``, ``g = B``, the expert ``u = -K x`` (the sign
of ``lqr``) or expressions, the learned policy as expressions, a gain or an MLP value object.

Every number is taken exactly, as the TOML route (``[dynamics] A, B``, ``expert = { K = ... }``,
:mod:`drip_cert.spec.linear`) takes its decimals: a float is the exact binary rational it stores
(:func:`~drip_cert.model.literals.exact_number`), so the certified expert is exactly ``-K x`` with
the solver's floats.
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from typing import Any

import numpy as np
import sympy as sp

from drip_cert.errors import InputTypeError, SpecError
from drip_cert.model.blocks import Block, mlp_block
from drip_cert.model.expr import parse_expression
from drip_cert.model.literals import exact_number
from drip_cert.model.mlp import MLP

__all__ = ["statespace_system"]

#: name of the block a learned MLP becomes
LEARNED_BLOCK = "pi_il"


def _exact_matrix(value: Any, what: str) -> sp.ImmutableMatrix:
    """A 2-D array of finite real numbers as exact rationals (a float: its binary rational)."""
    try:
        arr = np.asarray(value)
    except Exception as exc:  # noqa: BLE001 - any array-like failure is the user's input
        raise SpecError(f"{what}: not an array of numbers ({exc})", field=what) from None
    if arr.ndim == 1:
        arr = arr.reshape(-1, 1) if what == "B" else arr.reshape(1, -1)
    if arr.ndim != 2 or arr.size == 0:
        raise SpecError(f"must be a non-empty 2-D array, got shape {arr.shape}", field=what)
    if np.iscomplexobj(arr):
        if np.any(np.imag(arr) != 0):
            raise SpecError("has complex entries; give a real matrix", field=what)
        arr = np.real(arr)
    rows = []
    for i, row in enumerate(arr.tolist()):
        out = []
        for j, v in enumerate(row):
            if isinstance(v, bool) or not isinstance(v, int | float):
                raise SpecError(f"entry [{i}][{j}] = {v!r} is not a real number", field=what)
            if isinstance(v, float) and not math.isfinite(v):
                raise SpecError(f"entry [{i}][{j}] = {v!r} is not finite", field=what)
            out.append(exact_number(v))
        rows.append(out)
    return sp.ImmutableMatrix(rows)


def _state_space(obj: Any) -> tuple[Any, Any, Any]:
    """``(A, B, obj or None)`` from an object with ``.A``/``.B`` or a pair ``(A, B)``."""
    if hasattr(obj, "A") and hasattr(obj, "B"):
        dt = getattr(obj, "dt", None)
        if dt is not None and dt is not False and dt != 0:
            raise SpecError(
                f"the state-space object is discrete-time (dt = {dt!r}); drip-cert certifies "
                "continuous-time systems dx/dt = A x + B u: give the continuous model (e.g. "
                "control.ss(A, B, C, D) without dt)",
                field="sys_or_AB",
            )
        return obj.A, obj.B, obj
    if isinstance(obj, tuple | list) and len(obj) == 2:
        return obj[0], obj[1], None
    raise InputTypeError(
        f"System.from_statespace takes an object with attributes .A and .B (control.ss, "
        f"scipy.signal.StateSpace) or a pair (A, B) of arrays, got {type(obj).__name__}"
    )


def _labels(obj: Any, attr: str, given: Sequence[str] | None, k: int, prefix: str) -> list[str]:
    if given is not None:
        names = [str(v) for v in given]
        if len(names) != k:
            raise SpecError(f"{len(names)} names for {k} {attr}", field=attr)
        return names
    found = getattr(obj, f"{attr[:-1]}_labels", None) if obj is not None else None
    if isinstance(found, list | tuple) and len(found) == k:
        names = [str(v) for v in found]
        if all(n.isidentifier() for n in names) and len(set(names)) == k:
            return names
    return [f"{prefix}{i + 1}" for i in range(k)]


def _policy(
    value: Any,
    what: str,
    states: tuple[sp.Symbol, ...],
    m: int,
    blocks: dict[str, Block],
) -> sp.ImmutableMatrix:
    """A policy: a gain ``K`` (``u = -K x``), ``m`` expressions, or (learned) an MLP."""
    n = len(states)
    if isinstance(value, MLP):
        if what != "learned":
            raise SpecError("an MLP is accepted as the learned policy only", field=what)
        if value.in_dim != n or value.out_dim != m:
            raise SpecError(
                f"the network maps R^{value.in_dim} -> R^{value.out_dim}, the system needs "
                f"R^{n} -> R^{m}",
                field=what,
            )
        block = mlp_block(LEARNED_BLOCK, value, source="System.from_statespace")
        blocks[LEARNED_BLOCK] = block
        return sp.ImmutableMatrix([block.component(j)(*states) for j in range(m)])
    arr = None
    if not isinstance(value, str):
        try:
            arr = np.asarray(value)
        except Exception:  # noqa: BLE001 - ragged or odd objects: treated as expressions below
            arr = None
    if arr is not None and arr.dtype.kind in "biuf" and arr.ndim in (1, 2):
        K = _exact_matrix(arr.reshape(m, -1) if arr.ndim == 1 and m == 1 else arr, what)
        if K.shape != (m, n):
            raise SpecError(
                f"a gain must be m x n = {m} x {n} (u = -K x), got {K.shape[0]} x {K.shape[1]}",
                field=what,
            )
        return sp.ImmutableMatrix(-K * sp.Matrix(states))
    items = [value] if isinstance(value, str | sp.Expr) else list(value)
    if len(items) != m:
        raise SpecError(f"{len(items)} expressions for {m} inputs", field=what)
    scalars = {str(s): s for s in states}
    out = []
    for j, e in enumerate(items):
        if isinstance(e, sp.Expr):
            out.append(e)
        else:
            out.append(
                parse_expression(
                    e, field=f"{what}[{j}]", scalars=scalars, vector=states, blocks=blocks
                )
            )
    return sp.ImmutableMatrix(out)


def statespace_system(
    cls: Any,
    sys_or_AB: Any,
    *,
    expert: Any,
    support: Sequence[Sequence[float]],
    horizon: float,
    states: Sequence[str] | None = None,
    inputs: Sequence[str] | None = None,
    name: str = "statespace",
    learned: Any = None,
    **uncertainty: Any,
) -> Any:
    """The :class:`System` ``dx/dt = A x + B u`` (see ``System.from_statespace``; ``cls`` is
    the class, passed in so that this module does not import it)."""
    A_raw, B_raw, obj = _state_space(sys_or_AB)
    A = _exact_matrix(A_raw, "A")
    B = _exact_matrix(B_raw, "B")
    n = A.shape[0]
    if A.shape != (n, n):
        raise SpecError(f"A must be square, got {A.shape[0]} x {A.shape[1]}", field="A")
    if B.shape[0] != n:
        raise SpecError(f"B must have n = {n} rows (one per state), got {B.shape[0]}", field="B")
    m = B.shape[1]
    names = _labels(obj, "states", states, n, "x")
    syms = tuple(sp.Symbol(v, real=True) for v in names)
    blocks: dict[str, Block] = {}
    exp = _policy(expert, "expert", syms, m, blocks)
    lrn = None if learned is None else _policy(learned, "learned", syms, m, blocks)
    scalars = {str(s): s for s in syms}
    for key in ("lambda_mu", "lambda_sigma", "diffusion"):
        v = uncertainty.get(key)
        if v is not None and not isinstance(v, sp.MatrixBase):
            uncertainty[key] = sp.ImmutableMatrix(_parse_nested(v, key, scalars, syms, blocks))
    return cls(
        name=name,
        states=syms,
        f=sp.ImmutableMatrix(A * sp.Matrix(syms)),
        g=B,
        expert=exp,
        support=support,
        horizon=horizon,
        inputs=tuple(_labels(obj, "inputs", inputs, m, "u")),
        learned=lrn,
        blocks=blocks,
        **uncertainty,
    )


def _parse_nested(
    v: Any, key: str, scalars: dict[str, sp.Symbol], syms: tuple[sp.Symbol, ...], blocks: dict
) -> Any:
    """Expressions (text, numbers or sympy) in a list or a list of rows, parsed safely."""
    if isinstance(v, list | tuple):
        return [_parse_nested(e, key, scalars, syms, blocks) for e in v]
    if isinstance(v, sp.Expr):
        return v
    return parse_expression(v, field=key, scalars=scalars, vector=syms, blocks=blocks)
