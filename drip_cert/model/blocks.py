"""Blocks: learned or opaque vector functions (neural networks) usable inside expressions.

A block is a named map ``R^k -> R^q`` with a jax implementation; its Jacobian and Hessian come
from jax autodiff. Inside sympy expressions component ``j`` of block ``h`` applied to arguments
``a_1..a_k`` is the applied function ``h__0(a_1, ..., a_k)``, an instance of a
:class:`BlockFunction` subclass made for that block. Differentiating it gives the
applied Jacobian entry ``h__d0_1(...)``, and once more the Hessian entry ``h__dd0_1_2(...)``,
so sympy's chain rule builds closed-loop Jacobians that contain blocks, and
:mod:`drip_cert.model.lower` turns them into jax functions that evaluate each block once.
"""

from __future__ import annotations

from collections.abc import Callable, Mapping, Sequence
from dataclasses import dataclass, field
from fractions import Fraction
from pathlib import Path
from typing import Any, ClassVar, TypeAlias

import numpy as np
import sympy as sp

from drip_cert.errors import SpecError
from drip_cert.model.mlp import MLP
from drip_cert.model.network_files import load_network


class BlockFunction(sp.Function):
    """Base class of the sympy functions standing for block components and derivatives.

    Class attributes set per subclass: ``block_name`` (str), ``out_index`` (int) and
    ``deriv`` (tuple of input indices: ``()`` value, ``(i,)`` Jacobian entry, ``(i, l)``
    Hessian entry).
    """

    block_name: str = ""
    out_index: int = 0
    deriv: tuple[int, ...] = ()
    _family: ClassVar[Family | None] = None

    def fdiff(self, argindex: int = 1) -> sp.Expr:  # noqa: D401 (sympy API)
        """Partial derivative with respect to argument ``argindex`` (1-based)."""
        i = argindex - 1
        key = (self.out_index, tuple(sorted((*self.deriv, i))))
        fam = type(self)._family
        if fam is None or key not in fam:
            raise SpecError(
                f"derivatives of order {len(self.deriv) + 1} of block '{self.block_name}' are not "
                "available (drip-cert uses block values, Jacobians and Hessians only)"
            )
        return fam[key](*self.args)


#: The sympy function classes of one block, by ``(out_index, deriv)``.
Family: TypeAlias = dict[tuple[int, tuple[int, ...]], type[BlockFunction]]


def _make_family(name: str, in_dim: int, out_dim: int) -> Family:
    """Create the sympy function classes of one block (values, Jacobian, Hessian entries)."""
    fam: Family = {}
    for j in range(out_dim):
        keys: list[tuple[int, ...]] = [()]
        keys += [(i,) for i in range(in_dim)]
        keys += [(i, l) for i in range(in_dim) for l in range(i, in_dim)]
        for d in keys:
            if not d:
                cname = f"{name}__{j}"
            elif len(d) == 1:
                cname = f"{name}__d{j}_{d[0]}"
            else:
                cname = f"{name}__dd{j}_{d[0]}_{d[1]}"
            cls = type(
                cname,
                (BlockFunction,),
                {"block_name": name, "out_index": j, "deriv": d, "nargs": in_dim},
            )
            assert issubclass(cls, BlockFunction)  # created with that base
            fam[(j, d)] = cls
    for cls in fam.values():
        cls._family = fam
    return fam


@dataclass(frozen=True, eq=False)
class Block:
    """A named vector function usable in expressions as ``name(args)[j]``.

    Parameters
    ----------
    name
        Identifier used in expressions.
    in_dim, out_dim
        Argument and output dimensions.
    fn
        jax-traceable map from an array of shape ``(in_dim,)`` to ``(out_dim,)``.
    mlp
        The network, when the block is an MLP (enables sound bounds in the analysis).
    source
        Where it came from (weights file), for reports.
    """

    name: str
    in_dim: int
    out_dim: int
    fn: Callable[[Any], Any]
    mlp: MLP | None = None
    source: str = ""
    family: Mapping[tuple[int, tuple[int, ...]], type[BlockFunction]] = field(
        init=False, repr=False
    )

    def __post_init__(self) -> None:
        if not self.name.isidentifier() or self.name.startswith("_") or "__" in self.name:
            raise SpecError(
                f"block name {self.name!r} must be an identifier without leading '_' or '__'"
            )
        if int(self.in_dim) < 1 or int(self.out_dim) < 1:
            raise SpecError(f"block '{self.name}': inputs and outputs must be >= 1")
        object.__setattr__(self, "family", _make_family(self.name, self.in_dim, self.out_dim))

    def component(self, j: int) -> type[BlockFunction]:
        """The sympy function class of output component ``j``."""
        return self.family[(j, ())]

    def jacobian_fn(self) -> Callable[[Any], Any]:
        """jax map ``z -> d fn / dz`` of shape ``(out_dim, in_dim)``."""
        from drip_cert._jax import jax  # jax: keep off the CLI start-up path

        return jax.jacfwd(self.fn)

    def hessian_fn(self) -> Callable[[Any], Any]:
        """jax map ``z -> d^2 fn / dz^2`` of shape ``(out_dim, in_dim, in_dim)``."""
        from drip_cert._jax import jax  # jax: keep off the CLI start-up path

        return jax.jacfwd(jax.jacrev(self.fn))

    def evaluate_np(self, z: np.ndarray) -> np.ndarray:
        """Evaluate on a batch ``(N, in_dim)`` (or one point) and return numpy."""
        from drip_cert._jax import jax, jnp  # jax: keep off the CLI start-up path

        zj = jnp.asarray(z, dtype=jnp.float64)
        if zj.ndim == 1:
            return np.asarray(self.fn(zj))
        return np.asarray(jax.vmap(self.fn)(zj))

    def to_dict(self) -> dict[str, Any]:
        out: dict[str, Any] = {"name": self.name, "inputs": self.in_dim, "outputs": self.out_dim}
        if self.mlp is not None:
            out.update(
                kind="mlp",
                sizes=list(self.mlp.sizes),
                activation=self.mlp.activation,
                activations=list(self.mlp.activation_specs),
            )
        if self.source:
            out["source"] = self.source
        return out


def mlp_block(name: str, mlp: MLP, source: str = "") -> Block:
    """Wrap an :class:`~drip_cert.model.mlp.MLP` as a block."""
    return Block(
        name=name, in_dim=mlp.in_dim, out_dim=mlp.out_dim, fn=mlp.apply_jax, mlp=mlp, source=source
    )


def load_mlp_block(
    name: str,
    weights: str | Path,
    inputs: int | None,
    outputs: int | None,
    activation: str | list[str] | None = None,
    field: str | None = None,
) -> Block:
    """Load an MLP block from ``weights`` (``.onnx``, ``.safetensors`` or ``.npz``:
    :func:`~drip_cert.model.network_files.load_network`), checking its shape when given."""
    mlp = load_network(
        weights, activation=activation, expect_in=inputs, expect_out=outputs, field=field
    )
    return mlp_block(name, mlp, source=str(weights))


def block_applications(expr: sp.Basic) -> set[BlockFunction]:
    """All applied block functions occurring in ``expr``."""
    return {a for a in expr.atoms(sp.Function) if isinstance(a, BlockFunction)}


def linear_input_map(app: BlockFunction, states: Sequence[sp.Symbol]) -> sp.ImmutableMatrix | None:
    """The constant matrix ``S`` with ``app.args == S @ states`` exactly (``None`` when an
    argument is not a linear form of the states with rational coefficients, e.g. it has an
    offset, a parameter, an irrational coefficient or a nonlinearity).

    A block of a system in the coordinates ``z = Theta x`` is applied to ``Theta^{-1} z``
    (:meth:`~drip_cert.model.system.System.transformed`): there ``S = Theta^{-1}``, exact
    rationals.
    """
    x = list(states)
    rows = []
    for a in app.args:
        a = sp.expand(a)
        if not isinstance(a, sp.Expr) or a.free_symbols - set(x):
            return None
        row = [sp.diff(a, xi) for xi in x]
        if any(not c.is_Rational for c in row):  # exact rationals only (MappedMLP folds them)
            return None
        if sp.expand(a - sum(c * xi for c, xi in zip(row, x))) != 0:
            return None
        rows.append(row)
    return sp.ImmutableMatrix(rows)


def _fraction(v: Any) -> Fraction:
    """The exact rational of a float or a sympy rational (``TypeError`` for anything else)."""
    if isinstance(v, float | int | np.floating | np.integer):
        return Fraction(float(v)) if isinstance(v, float | np.floating) else Fraction(int(v))
    e = sp.sympify(v)
    if not e.is_Rational:
        raise TypeError(f"{v!r} is not a rational number")
    return Fraction(int(e.p), int(e.q))


def _float_up(q: Fraction) -> float:
    """The smallest float ``>= q`` (``Fraction.__float__`` rounds to nearest: step up once when
    it landed below)."""
    f = float(q)
    return f if Fraction(f) >= q else float(np.nextafter(f, np.inf))


@dataclass(frozen=True, eq=False)
class MappedMLP:
    """A network read through a constant input map: ``y -> mlp(S y)`` (docs/math/contraction.md
    section 5.4).

    ``S`` (``(mlp.in_dim, d)``, exact rationals) is folded into the first layer:
    ``folded`` is ``mlp`` with first weight ``W_0'`` = the float nearest to each entry of the
    exact product ``W_0 S`` (the float ``W_0`` read as the binary rationals it stores, the sums
    formed in exact rational arithmetic), and ``rad0`` bounds the rounding entrywise,
    ``|W_0 S - W_0'| <= rad0`` (rounded up). So ``mlp(S y)`` is the network ``folded`` with its
    first weight anywhere in ``[W_0' - rad0, W_0' + rad0]``: an analysis that encloses the first
    layer with that interval weight is sound for ``mlp(S y)``; one that reads ``folded`` as exact
    is not (it gets an estimate).
    """

    mlp: MLP
    S: sp.ImmutableMatrix
    folded: MLP = field(init=False, repr=False)
    rad0: np.ndarray = field(init=False, repr=False)

    def __post_init__(self) -> None:
        S = sp.ImmutableMatrix(self.S)
        if S.shape[0] != self.mlp.in_dim:
            raise SpecError(
                f"an input map for a network with {self.mlp.in_dim} inputs must have "
                f"{self.mlp.in_dim} rows, got {S.shape[0]}"
            )
        Sq = [[_fraction(S[i, j]) for j in range(S.shape[1])] for i in range(S.shape[0])]
        W = self.mlp.weights[0]
        m, k = W.shape
        d = S.shape[1]
        mid = np.empty((m, d))
        rad = np.empty((m, d))
        for r in range(m):
            wr = [Fraction(float(w)) for w in W[r]]
            for c in range(d):
                exact = sum((wr[i] * Sq[i][c] for i in range(k)), Fraction(0))
                mid[r, c] = float(exact)  # correctly rounded (nearest)
                rad[r, c] = _float_up(abs(exact - Fraction(float(mid[r, c]))))
        folded = MLP(
            weights=(mid, *self.mlp.weights[1:]),
            biases=self.mlp.biases,
            activations=self.mlp.activations,
        )
        rad.setflags(write=False)
        object.__setattr__(self, "S", S)
        object.__setattr__(self, "folded", folded)
        object.__setattr__(self, "rad0", rad)

    @property
    def in_dim(self) -> int:
        """``d``, the dimension of ``y``."""
        return int(self.S.shape[1])

    @property
    def exact(self) -> bool:
        """Whether the fold is exact (every ``W_0 S`` entry a float: ``rad0 == 0``)."""
        return not bool(np.any(self.rad0))
