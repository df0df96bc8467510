"""Vectorised branch and bound on matrices affine in MLP Jacobians: ``mu_2`` of a learned closed
loop, ``sup ||D (pi_IL - pi*)||_2`` and the local Jacobian-Lipschitz constant of ``pi_IL - pi*``.

Setting. A matrix function of the state that is affine in the Jacobians of MLP blocks applied to
the state,

``M(x) = A + sum_k T_k : D h_k(x)``, ``(T_k : D h)_{ji} = sum_{o, l} T_k[j, i, o, l] dh_o/dx_l``,

with constant ``A`` and ``T_k``. The closed-loop Jacobian of the paper's example is of this form
(``F = A x + c + sum_k C_k h_k(x)`` gives ``T_k[j, i, o, l] = C_k[j, o] [i = l]``), and so is
``D Delta`` for ``Delta = pi_IL - pi*`` when both policies are affine in MLP blocks.
:func:`decompose_jacobian` reads ``A`` and ``T_k`` from the symbolic matrix.

Bound on one box ``B = [c - r, c + r]`` (:func:`box_bounds`). Let ``[J_c]`` enclose ``M(c)``,
``[H_B]`` enclose the derivative ``dM/dx_l`` over ``B`` (both from the MLP enclosures of
:mod:`drip_cert.analysis.networks.mlp.derivatives`, contracted with ``T_k``), ``J0`` the float
midpoint of
``[J_c]`` and ``G_l`` the float midpoint of the enclosure of ``dM/dx_l(c)``. By the mean value
theorem applied to each entry,

``M(x) = L(x) + E(x)``, ``L(x) = J0 + sum_l G_l (x_l - c_l)``,
``|E(x)| <= rad[J_c] + sum_l max(H_B,hi - G_l, G_l - H_B,lo) r_l =: R`` (entrywise).

For a convex ``phi`` with ``phi(L + E) <= phi(L) + psi(R)`` whenever ``|E| <= R``:

* ``phi = mu_2 = lambda_max(sym .)`` (convex: a maximum of linear functions ``v^T sym(.) v``),
  ``psi(R) = rho(max(R, R^T))`` (Weyl and Perron-Frobenius, docs/math/contraction.md Prop. 3.1);
* ``phi = ||.||_2`` (convex), ``psi(R) = rho`` of the embedding ``[[0, R], [R^T, 0]]``, i.e.
  ``||L + E||_2 = lambda_max([[0, L + E], [(L + E)^T, 0]])``.

``phi(L(x))`` is convex in ``x`` (a convex function of an affine map), so its maximum over the box
is attained at one of its ``2^d`` vertices ``c + s r``, ``s in {-1, 1}^d``. Hence

``sup_{x in B} phi(M(x)) <= max_s [ phi(L(c + s r)) ] + psi(R)``,

and each vertex term, with its float evaluation error added to ``R``, is bounded rigorously by
:func:`~drip_cert.numerics.rounding.sym_lambda_max_upper`. The linear part is exact, so the
overestimate is second order in ``r`` (``R`` is ``O(r^2)`` once ``[H_B]`` shrinks like ``r``):
far fewer sub-boxes than the interval Rohn bound, whose overestimate is first order. The bound
is the largest of these over a partition of the box (:func:`~drip_cert.numerics.bnb_batch.
maximize_batch`); it holds **on the box only**.

Jacobian-Lipschitz constant (:func:`local_jacobian_lipschitz`): on a convex box,
``||M(x) - M(y)||_2 <= sup_B ||dM||_op ||x - y||`` with
``||dM[u]||_2 <= ||dM[u]||_F = sqrt(u^T Gram u)``, ``Gram_{lm} = sum_{ji} H_{jil} H_{jim}``, and
``u^T Gram u <= |u|^T |H|^T |H| |u| <= rho(|H|^T |H|) ||u||^2`` with ``|H|`` the entrywise bound of
``[H_B]`` (Perron-Frobenius), so ``L <= max over sub-boxes of sqrt(rho(|H|^T |H|))``.
"""

from __future__ import annotations

import itertools
import math
import time
from collections.abc import Callable, Mapping, Sequence
from dataclasses import dataclass
from typing import Any

import numpy as np
import sympy as sp

from drip_cert.analysis.growth.closed_loop import CONVERSION_ULPS
from drip_cert.analysis.networks.mlp import jacobian_np
from drip_cert.analysis.networks.mlp.derivatives import enclose_box_and_centre
from drip_cert.errors import SpecError
from drip_cert.model.blocks import (
    BlockFunction,
    MappedMLP,
    block_applications,
    linear_input_map,
)
from drip_cert.model.mlp import MLP
from drip_cert.model.system import System
from drip_cert.numerics.bnb_batch import BatchBnbResult, maximize_batch
from drip_cert.numerics.interval import UnsupportedExpression, is_smooth
from drip_cert.numerics.interval_batch import compile_batch
from drip_cert.numerics.interval_np import mid_rad
from drip_cert.numerics.rounding import (
    add_down_np,
    add_up_np,
    gamma,
    matmul_bounds,
    sqrt_up_np,
    sub_down_np,
    sub_up_np,
    sym_lambda_max_upper,
    up_np,
)
from drip_cert.provenance import How, Quantity, Scope

__all__ = [
    "DEFAULT_BATCH",
    "DEFAULT_MAX_BOXES",
    "JacobianInBlocks",
    "MAX_VERTEX_DIM",
    "OBJECTIVES",
    "box_bounds",
    "decompose_jacobian",
    "difference_jacobian",
    "local_jacobian_lipschitz",
    "matrix_bnb",
    "sup_difference_jacobian_norm",
    "system_mlps",
    "difference_jacobian_lipschitz_box",
]

#: sub-boxes split per round of the batched branch and bound (2x that bounded per numpy call)
DEFAULT_BATCH = 256
#: work budget of the batched searches: a count of sub-boxes (never wall time, so that the same
#: inputs give the same bound on every machine); about 10-40 s on one core for d = 2..4
DEFAULT_MAX_BOXES = 200_000
#: the vertex bound evaluates 2^d vertices per sub-box; above this dimension only the centre
#: linearisation with the first-order term moved into the radius is used
MAX_VERTEX_DIM = 8
#: objectives of :func:`box_bounds`
OBJECTIVES = ("mu2", "norm2", "jac_lipschitz")

_TINY = 2.0**-1074


@dataclass(frozen=True, eq=False)
class StatePart:
    """A state-dependent entry ``a_ji(x)`` of the block-free part of ``M`` (no block in it, e.g.
    ``-9.81 cos q`` of a pendulum): its batched interval enclosure and those of its partial
    derivatives (:func:`~drip_cert.numerics.interval_batch.compile_batch`, sound over each box),
    and a float evaluator for sampling (an estimate)."""

    j: int
    i: int
    expr: sp.Expr
    value: Callable[[np.ndarray], tuple[np.ndarray, np.ndarray]]
    grad: tuple[Callable[[np.ndarray], tuple[np.ndarray, np.ndarray]], ...]
    fn: Callable[..., Any]


def _state_part(j: int, i: int, e: sp.Expr, x: tuple[sp.Symbol, ...]) -> StatePart | None:
    """:class:`StatePart` of ``e`` (``None`` when ``e`` is not smooth, not real or has a node
    without a batched enclosure: the caller then reads no decomposition)."""
    if not is_smooth(e):
        return None
    try:
        grads = [sp.diff(e, xi) for xi in x]
        value = compile_batch(e, x)
        grad = tuple(compile_batch(g, x) for g in grads)
    except (UnsupportedExpression, TypeError, ValueError):
        return None
    return StatePart(j, i, e, value, grad, sp.lambdify(x, e, "numpy"))


def _enclosed(f, boxes: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """``f(boxes)`` with NaN (no information) read as ``[-inf, inf]``."""
    lo, hi = f(boxes)
    lo = np.where(np.isnan(lo), -np.inf, np.broadcast_to(lo, boxes.shape[:1]))
    hi = np.where(np.isnan(hi), np.inf, np.broadcast_to(hi, boxes.shape[:1]))
    return lo, hi


@dataclass(frozen=True)
class JacobianInBlocks:
    """``M(x) = A + sum_k T_k : D h_k(x)``; ``A`` is ``(p, q)``, ``T[k]`` ``(p, q, out_k, d)``.

    ``A_rad``, ``T_rad`` bound the distance of the float coefficients to the exact ones
    (:data:`~drip_cert.analysis.growth.closed_loop.CONVERSION_ULPS` spacings of the sympy
    constants). ``first_rad[k]`` (``None``: exact) is the radius of ``mlps[k]``'s first-layer
    weight when ``h_k`` is a network read through an input map, ``h_k(x) = N(S x)``, folded
    (:class:`~drip_cert.model.blocks.MappedMLP`): ``mlps[k]`` is the folded network, its first
    weight the float midpoint of ``W_0 S``, and every enclosure holds for the interval weight.
    ``varying`` are the entries of the block-free part that depend on ``x`` (their ``A`` entry is
    0): ``M(x) = A + sum_j a_ji(x) e_j e_i^T + sum_k T_k : D h_k(x)``.
    """

    A: np.ndarray
    A_rad: np.ndarray
    T: tuple[np.ndarray, ...]
    T_rad: tuple[np.ndarray, ...]
    mlps: tuple[MLP, ...]
    names: tuple[str, ...]
    first_rad: tuple[np.ndarray | None, ...] = ()
    varying: tuple[StatePart, ...] = ()

    @property
    def dim(self) -> int:
        """``d``, the state dimension."""
        return int(self.mlps[0].in_dim) if self.mlps else 0

    def rad0(self, k: int) -> np.ndarray | None:
        """The first-layer weight radius of block ``k`` (``None``: exact)."""
        return self.first_rad[k] if k < len(self.first_rad) else None

    def evaluate(self, X: np.ndarray) -> np.ndarray:
        """Float ``M(x)`` at points ``X`` (``(N, d)``): an estimate, for sampling."""
        X = np.asarray(X, dtype=float)
        out = np.broadcast_to(self.A, (X.shape[0], *self.A.shape)).copy()
        for part in self.varying:
            out[:, part.j, part.i] += part.fn(*X.T)
        for T, mlp in zip(self.T, self.mlps):
            out += np.einsum("jiol,nol->nji", T, jacobian_np(mlp, X))
        return out


def _input_maps(
    apps: set[BlockFunction], x: tuple[sp.Symbol, ...], mlps: Mapping[str, MLP]
) -> dict[str, sp.ImmutableMatrix | None] | None:
    """Per block name, its input map ``S`` (``None``: applied to the state itself), or ``None``
    when a block is applied to anything but ``S x`` with one constant invertible square ``S``."""
    maps: dict[str, sp.ImmutableMatrix | None] = {}
    for a in apps:
        if a.args == x:
            S = None
        else:
            S = linear_input_map(a, x)
            if S is None or S.shape != (len(x), len(x)) or S.det() == 0:
                return None
            if S == sp.eye(len(x)):
                S = None
        if a.block_name in maps and maps[a.block_name] != S:
            return None
        maps[a.block_name] = S
    if any(S is not None and mlps[b].in_dim != len(x) for b, S in maps.items()):
        return None
    return maps


def decompose_jacobian(
    M: sp.MatrixBase,
    states: Sequence[sp.Symbol],
    mlps: Mapping[str, MLP],
    *,
    state_part: bool = True,
) -> JacobianInBlocks | None:
    """Read ``M = A + sum_k T_k : D h_k(x)`` from a symbolic matrix, ``None`` when ``M`` is not of
    that form (an entry non-linear in the block Jacobian entries, depending on the state or on
    other symbols, a block value or Hessian entry, a block without an MLP, a block applied to
    anything but the state or a constant invertible linear map of it).

    A block applied to ``S x`` (e.g. ``N(Theta^{-1} z)`` in the coordinates of a metric,
    docs/math/contraction.md section 5.4) is read as the folded network ``h(x) = N(S x)``
    (:class:`~drip_cert.model.blocks.MappedMLP`): its Jacobian entries in ``M`` are ``DN(S x)``,
    and ``DN(S x) = Dh(x) S^{-1}`` is substituted exactly (sympy) before ``T_k`` is read, so
    ``M = A + sum_k T_k : Dh_k(x)`` with ``h_k`` the folded network (first weight an interval).

    The block-free part may depend on the state (``state_part=True``): an entry such as the
    ``-9.81 cos q`` of a pendulum's Jacobian, smooth and with a batched interval enclosure
    (:class:`StatePart`), enters the box bound with its enclosures at the centre and its
    gradient's over the box, as the networks do; the block coefficients ``T_k`` must still be
    constant."""
    M = sp.Matrix(M)
    x = tuple(states)
    apps: set[BlockFunction] = set()
    for e in M:
        apps |= block_applications(e)
    if not apps:
        return None
    for a in apps:
        if len(a.deriv) != 1 or a.block_name not in mlps:
            return None
    maps = _input_maps(apps, x, mlps)
    if maps is None:
        return None
    dummies = {a: sp.Dummy(f"d{type(a).__name__}") for a in apps}
    lin = M.xreplace(dummies)
    # the folded blocks' Jacobian entries: d'_{o, m} = (DN(S x) S)_{o, m} = Dh(x)_{o, m}
    folded: dict[tuple[str, int, int], sp.Dummy] = {}
    subs: dict[sp.Dummy, sp.Expr] = {}
    for a, dv in dummies.items():
        S = maps[a.block_name]
        if S is None:
            continue
        Si = S.inv()
        o, l_ = a.out_index, a.deriv[0]
        terms = []
        for m in range(len(x)):
            key = (a.block_name, o, m)
            if key not in folded:
                folded[key] = sp.Dummy(f"f{a.block_name}_{o}_{m}")
            terms.append(folded[key] * Si[m, l_])
        subs[dv] = sp.Add(*terms)
    if subs:
        lin = lin.xreplace(subs)
    lin = lin.applyfunc(sp.expand)
    # (block, out, in) -> the variable of M's linear form
    slots: dict[sp.Dummy, tuple[str, int, int]] = {
        dv: (a.block_name, a.out_index, a.deriv[0])
        for a, dv in dummies.items()
        if maps[a.block_name] is None
    }
    slots.update({dv: key for key, dv in folded.items()})
    dvars = list(slots)
    p, q = M.shape
    d = len(x)
    zero = {v: sp.S.Zero for v in dvars}
    A = np.zeros((p, q))
    varying: list[StatePart] = []
    for j in range(p):
        for i in range(q):
            e = lin[j, i]
            if e.free_symbols - set(dvars) - set(x):
                return None
            e0 = sp.sympify(e.xreplace(zero))
            coef = [sp.diff(e, dv) for dv in dvars]
            # linear in the block Jacobian entries with constant coefficients
            if any(c.free_symbols for c in coef):
                return None
            if sp.expand(e - e0 - sum(c * dv for c, dv in zip(coef, dvars))) != 0:
                return None
            if e0.free_symbols:
                if not state_part:
                    return None
                part = _state_part(j, i, e0, x)
                if part is None:
                    return None
                varying.append(part)
                continue
            try:
                A[j, i] = float(e0)
            except TypeError:
                return None
    names = tuple(sorted(maps))
    Ts = {b: np.zeros((p, q, mlps[b].out_dim, d)) for b in names}
    for z, (b, o, l_) in slots.items():
        T = Ts[b]
        for j in range(p):
            for i in range(q):
                T[j, i, o, l_] = float(sp.diff(lin[j, i], z))
    if not all(np.all(np.isfinite(T)) for T in Ts.values()) or not np.all(np.isfinite(A)):
        return None
    # float() is exact for binary floats, correctly rounded for rationals, within an ulp else
    A_rad = CONVERSION_ULPS * np.spacing(np.abs(A))
    Tt = tuple(Ts[b] for b in names)
    mapped = {b: MappedMLP(mlps[b], S) for b, S in maps.items() if S is not None}
    return JacobianInBlocks(
        A=A,
        A_rad=A_rad,
        T=Tt,
        T_rad=tuple(CONVERSION_ULPS * np.spacing(np.abs(T)) for T in Tt),
        mlps=tuple(mapped[b].folded if b in mapped else mlps[b] for b in names),
        names=names,
        first_rad=tuple(mapped[b].rad0 if b in mapped else None for b in names),
        varying=tuple(varying),
    )


def system_mlps(s: System) -> dict[str, MLP]:
    """The MLPs of the blocks of ``s`` by block name (blocks without an MLP left out)."""
    return {b: blk.mlp for b, blk in s.blocks.items() if blk.mlp is not None}


def difference_jacobian(s: System) -> JacobianInBlocks | None:
    """``D (pi_IL - pi*)`` of ``s`` as :class:`JacobianInBlocks` (``None`` when either policy is
    not affine in MLP blocks applied to the state)."""
    diff = (sp.Matrix(s.policy("learned")) - sp.Matrix(s.policy("expert"))).applyfunc(sp.expand)
    return decompose_jacobian(diff.jacobian(list(s.states)), s.states, system_mlps(s))


# ------------------------------------------------------------------------------ one batch


def _contract(T: np.ndarray, T_rad: np.ndarray, lo: np.ndarray, hi: np.ndarray):
    """Enclosure of ``X @ T^T`` for interval rows ``X`` (``(N, K)``) and a point ``T`` (``(P, K)``)
    known to within ``T_rad``.

    Centre-radius: ``X = m + [-rr, rr]``; ``|X T^T - m T^T| <= rr |T|^T``, the coefficient error
    adds ``(|m| + rr) T_rad^T``; the float products are within ``gamma_K`` of the exact ones and
    ``2 gamma_{K+2}`` times the float magnitude ``(|m| + rr) (|T| + T_rad)^T`` covers both (Higham
    Thm 3.1), plus an underflow term. Sums rounded outward one at a time.
    """
    m, rr = mid_rad(lo, hi)
    aT = np.abs(T)
    c = m @ T.T
    am = np.abs(m) + rr
    rad = add_up_np(rr @ aT.T, am @ T_rad.T)
    K = T.shape[1]
    err = add_up_np(up_np(2.0 * gamma(K + 2) * (am @ (aT + T_rad).T)), (K + 2) * 8 * _TINY)
    rad = add_up_np(rad, err)
    return sub_down_np(c, rad), add_up_np(c, rad)


def _combine(dec: JacobianInBlocks, lo: np.ndarray, hi: np.ndarray):
    """``[M]`` (``(N, p, q)``), ``[dM/dx(c)]`` and ``[dM/dx(B)]`` (``(N, p, q, d)``) for boxes
    ``(N, d)``, as ``(lo, hi)`` pairs, and ``[M(c)]`` at the centres (for the estimates).

    A smooth block enters ``[M]`` at the centre and the derivative terms through its Hessian
    (the mean-value form of the module docstring). A nonsmooth block (relu) has no Hessian: it
    enters ``[M]`` with the enclosure of its Clarke Jacobian over the WHOLE box and the derivative
    terms with zero, so ``M(x) in [M]`` for every ``x`` in the box and every element of the
    generalized Jacobian there (docs/math/nonsmooth.md); the bound is then first order in the box
    radius.
    """
    N, d = lo.shape
    p, q = dec.A.shape
    jc_lo = np.broadcast_to(sub_down_np(dec.A, dec.A_rad), (N, p, q))
    jc_hi = np.broadcast_to(add_up_np(dec.A, dec.A_rad), (N, p, q))
    jv_lo, jv_hi = jc_lo, jc_hi
    hc_lo = hc_hi = hb_lo = hb_hi = np.zeros((N, p, q, d))
    if dec.varying:
        # the block-free entries that depend on x: value at the centre, gradient at the centre
        # and over the box (mean-value form, as for a smooth network)
        c = mid_rad(lo, hi)[0]
        cb = np.stack([c, c], axis=-1)
        bb = np.stack([lo, hi], axis=-1)
        jc_lo, jc_hi = jc_lo.copy(), jc_hi.copy()
        hc_lo, hc_hi, hb_lo, hb_hi = (np.zeros((N, p, q, d)) for _ in range(4))
        for part in dec.varying:
            vlo, vhi = _enclosed(part.value, cb)
            jc_lo[:, part.j, part.i] = add_down_np(jc_lo[:, part.j, part.i], vlo)
            jc_hi[:, part.j, part.i] = add_up_np(jc_hi[:, part.j, part.i], vhi)
            for l_, g in enumerate(part.grad):
                hc_lo[:, part.j, part.i, l_], hc_hi[:, part.j, part.i, l_] = _enclosed(g, cb)
                hb_lo[:, part.j, part.i, l_], hb_hi[:, part.j, part.i, l_] = _enclosed(g, bb)
        jv_lo, jv_hi = jc_lo, jc_hi
    for k, (T, T_rad, mlp) in enumerate(zip(dec.T, dec.T_rad, dec.mlps)):
        box, cen = enclose_box_and_centre(mlp, lo, hi, hessian=mlp.smooth, first_rad=dec.rad0(k))
        o = mlp.out_dim
        Tm, Tr = T.reshape(p * q, o * d), T_rad.reshape(p * q, o * d)

        def contract(jac, Tm=Tm, Tr=Tr, o=o):
            a_lo, a_hi = _contract(Tm, Tr, jac[0].reshape(N, o * d), jac[1].reshape(N, o * d))
            return a_lo.reshape(N, p, q), a_hi.reshape(N, p, q)

        v_lo, v_hi = contract(cen.jacobian)
        jv_lo, jv_hi = add_down_np(jv_lo, v_lo), add_up_np(jv_hi, v_hi)
        if not mlp.smooth:
            b_lo, b_hi = contract(box.jacobian)
            jc_lo, jc_hi = add_down_np(jc_lo, b_lo), add_up_np(jc_hi, b_hi)
            continue
        jc_lo, jc_hi = add_down_np(jc_lo, v_lo), add_up_np(jc_hi, v_hi)
        assert box.hessian is not None and cen.hessian is not None
        for (hlo, hhi), which in ((cen.hessian, "c"), (box.hessian, "b")):
            # H[n, o, i, l] -> rows (n, l), columns (o, i)
            flo = np.moveaxis(hlo, -1, 1).reshape(N * d, o * d)
            fhi = np.moveaxis(hhi, -1, 1).reshape(N * d, o * d)
            g_lo, g_hi = _contract(Tm, Tr, flo, fhi)
            g_lo = np.moveaxis(g_lo.reshape(N, d, p, q), 1, -1)
            g_hi = np.moveaxis(g_hi.reshape(N, d, p, q), 1, -1)
            if which == "c":
                hc_lo, hc_hi = add_down_np(hc_lo, g_lo), add_up_np(hc_hi, g_hi)
            else:
                hb_lo, hb_hi = add_down_np(hb_lo, g_lo), add_up_np(hb_hi, g_hi)
    return (jc_lo, jc_hi), (hc_lo, hc_hi), (hb_lo, hb_hi), (jv_lo, jv_hi)


def _embed(L: np.ndarray, R: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """``[[0, L], [L^T, 0]]`` and the same for ``R`` (exact copies): ``lambda_max`` of the first
    is ``||L||_2``."""
    *b, p, q = L.shape
    E = np.zeros((*b, p + q, p + q))
    F = np.zeros((*b, p + q, p + q))
    E[..., :p, p:] = L
    E[..., p:, :p] = np.swapaxes(L, -1, -2)
    F[..., :p, p:] = R
    F[..., p:, :p] = np.swapaxes(R, -1, -2)
    return E, F


def _sign_matrix(d: int) -> np.ndarray:
    return np.array(list(itertools.product((-1.0, 1.0), repeat=d)))


def box_bounds(
    dec: JacobianInBlocks, boxes: np.ndarray, objective: str = "mu2"
) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Rigorous upper bounds of ``sup_B phi(M(x))`` on each sub-box (see the module docstring).

    Parameters
    ----------
    dec
        The matrix function.
    boxes
        ``(N, d, 2)``.
    objective
        ``'mu2'`` (``mu_2(M)``, square ``M``), ``'norm2'`` (``||M||_2``) or ``'jac_lipschitz'``
        (``sqrt(rho(|dM|^T |dM|))``, a bound of the Lipschitz constant of ``M`` on the box).

    Returns
    -------
    (upper, value, centre)
        ``upper`` (``(N,)``): the sound bounds; ``value``: the float objective at the centres
        (estimates, for stopping and the witness); ``centre`` (``(N, d)``).
    """
    if objective not in OBJECTIVES:
        raise SpecError(f"objective {objective!r} is not one of {OBJECTIVES}", field="objective")
    boxes = np.asarray(boxes, dtype=float)
    lo, hi = boxes[..., 0], boxes[..., 1]
    N, d = lo.shape
    c, r = mid_rad(lo, hi)
    (jc_lo, jc_hi), (hc_lo, hc_hi), (hb_lo, hb_hi), (jv_lo, jv_hi) = _combine(dec, lo, hi)
    if objective == "jac_lipschitz" and not all(m.smooth for m in dec.mlps):
        # a relu block's Jacobian jumps across a kink: no Lipschitz constant exists
        return np.full(N, np.inf), np.full(N, np.inf), c
    if objective == "jac_lipschitz":
        H = np.maximum(np.abs(hb_lo), np.abs(hb_hi)).reshape(N, -1, d)
        _, gram = matmul_bounds(np.swapaxes(H, -1, -2), H)
        gram = np.maximum(gram, np.swapaxes(gram, -1, -2))  # symmetric, >= the exact Gram
        # rho(gram) = lambda_max(gram) for a symmetric non-negative matrix (Perron-Frobenius)
        ub = sqrt_up_np(np.maximum(sym_lambda_max_upper(gram), 0.0))
        Hc = (0.5 * (hc_lo + hc_hi)).reshape(N, -1, d)
        val = np.sqrt(np.linalg.eigvalsh(np.swapaxes(np.abs(Hc), -1, -2) @ np.abs(Hc))[:, -1])
        return ub, val, c
    J0, jrad = mid_rad(jc_lo, jc_hi)
    G = 0.5 * (hc_lo + hc_hi)
    D = np.maximum(sub_up_np(hb_hi, G), sub_up_np(G, hb_lo))
    # R = rad[J_c] + sum_l D_l r_l (d non-negative terms: 2 gamma_{d+1} covers the float sum)
    R = np.einsum("npql,nl->npq", D, r)
    R = add_up_np(jrad, add_up_np(up_np(R * (1.0 + 2.0 * gamma(d + 1))), d * 8 * _TINY))
    if d <= MAX_VERTEX_DIM:
        S = _sign_matrix(d)  # (V, d)
        off = S[None, :, :] * r[:, None, :]  # exact: sign changes of the radii
        L = J0[:, None] + np.einsum("npql,nvl->nvpq", G, off)
        # float error of J0 + sum_l G_l off_l: gamma_{d+1} (|J0| + sum |G_l| r_l), doubled
        mag = np.abs(J0) + np.einsum("npql,nl->npq", np.abs(G), r)
        Rv = add_up_np(up_np(2.0 * gamma(d + 2) * mag), (d + 2) * 8 * _TINY)
        Rtot = np.broadcast_to(add_up_np(R, Rv)[:, None], L.shape)
    else:
        # first-order term into the radius: |G (x - c)| <= |G| r
        L = J0[:, None]
        Rg = np.einsum("npql,nl->npq", np.abs(G), r)
        Rg = add_up_np(up_np(Rg * (1.0 + 2.0 * gamma(d + 1))), d * 8 * _TINY)
        Rtot = add_up_np(R, Rg)[:, None]
    V = L.shape[1]
    p, q = J0.shape[-2:]
    if objective == "mu2":
        ub = np.asarray(
            sym_lambda_max_upper(L.reshape(N * V, p, q), Rtot.reshape(N * V, p, q))
        ).reshape(N, V)
        Jv = 0.5 * (jv_lo + jv_hi)  # M at the centre (an estimate)
        val = np.linalg.eigvalsh(0.5 * (Jv + np.swapaxes(Jv, -1, -2)))[:, -1]
    else:
        E, F = _embed(L.reshape(N * V, p, q), np.ascontiguousarray(Rtot).reshape(N * V, p, q))
        ub = np.asarray(sym_lambda_max_upper(E, F)).reshape(N, V)
        val = np.linalg.norm(0.5 * (jv_lo + jv_hi), ord=2, axis=(-2, -1))
    return ub.max(axis=1), val, c


# ------------------------------------------------------------------------------ the searches


@dataclass(frozen=True)
class MatrixBnbResult:
    """Outcome of :func:`matrix_bnb`: the search result, the objective and the wall time."""

    objective: str
    result: BatchBnbResult
    time_s: float
    box: tuple[tuple[float, float], ...]

    @property
    def upper(self) -> float:
        """The sound bound of ``sup phi(M(x))`` on the box."""
        return self.result.upper

    @property
    def lower(self) -> float:
        """The largest sampled value (an estimate from below)."""
        return self.result.lower


def _check_region(box, d: int) -> np.ndarray:
    b = np.asarray(box, dtype=float)
    if b.shape != (d, 2) or not np.all(np.isfinite(b)) or np.any(b[:, 0] > b[:, 1]):
        raise SpecError(
            f"box must be a finite ({d}, 2) array with lo <= hi per row, got {box!r}", field="box"
        )
    return b


def matrix_bnb(
    dec: JacobianInBlocks,
    box,
    objective: str = "mu2",
    *,
    tol: float = 1e-3,
    max_boxes: int = DEFAULT_MAX_BOXES,
    max_time_s: float = math.inf,
    batch: int = DEFAULT_BATCH,
    stop_below: float | None = None,
    n_samples: int = 4096,
    seed: int = 0,
) -> MatrixBnbResult:
    """Sound upper bound of ``sup_{x in box} phi(M(x))`` by batched branch and bound.

    ``objective`` as in :func:`box_bounds`. The search stops when the bound is within ``tol`` of
    the best sampled value, below ``stop_below`` (when given), or a budget is spent (the bound is
    then looser, still sound). ``n_samples`` uniform random points (``seed``) start the sampled
    lower value.
    """
    t0 = time.perf_counter()
    b = _check_region(box, dec.dim)
    initial = None
    if n_samples and objective != "jac_lipschitz":
        rng = np.random.default_rng(seed)
        X = b[:, 0] + rng.random((n_samples, b.shape[0])) * (b[:, 1] - b[:, 0])
        Ms = dec.evaluate(X)
        if objective == "mu2":
            vals = np.linalg.eigvalsh(0.5 * (Ms + np.swapaxes(Ms, -1, -2)))[:, -1]
        else:
            vals = np.linalg.norm(Ms, ord=2, axis=(-2, -1))
        k = int(np.argmax(vals))
        initial = (float(vals[k]), X[k])
    res = maximize_batch(
        b,
        lambda bs: box_bounds(dec, bs, objective),
        atol=tol,
        max_boxes=max_boxes,
        max_time_s=max_time_s,
        batch=batch,
        stop_below=stop_below,
        initial=initial,
    )
    return MatrixBnbResult(
        objective, res, time.perf_counter() - t0, tuple((float(r[0]), float(r[1])) for r in b)
    )


_SRC_DELTA = "DRIP Corollary 2.3 (docs/math/contraction.md): sup ||D(pi_IL - pi*)||_2"
_SRC_LDELTA = "DRIP Assumption PolicyRegularity (b) for Delta = pi_IL - pi* (local, on a box)"


def sup_difference_jacobian_norm(
    s: System,
    box=None,
    *,
    tol: float = 1e-3,
    max_time_s: float = math.inf,
    max_boxes: int = DEFAULT_MAX_BOXES,
) -> Quantity | None:
    """Sound bound of ``sup_{x in box} ||D pi_IL(x) - D pi*(x)||_2`` (vectorised branch and bound).

    ``box`` defaults to the support of ``s``. ``None`` when the difference is not affine in MLP
    Jacobians (:func:`difference_jacobian`). The quantity is ``How.SOUND`` with the box as its
    scope; an affine difference (no block left after cancellation) is not handled here.
    """
    dec = difference_jacobian(s)
    if dec is None:
        return None
    b = _check_region(s.support if box is None else box, s.n)
    out = matrix_bnb(dec, b, "norm2", tol=tol, max_time_s=max_time_s, max_boxes=max_boxes)
    r = out.result
    return Quantity.derive(
        "sup_DDelta",
        r.upper,
        method=How.SOUND,
        source=_SRC_DELTA,
        note=f"mlp-bnb (vertex bound of the centred linearisation, {r.n_boxes} sub-boxes, "
        f"stop {r.stop}); sampled max {r.lower:.6g}; on the box only",
        scope=Scope(tuple(map(tuple, b))),
    )


def local_jacobian_lipschitz(
    dec: JacobianInBlocks,
    box,
    *,
    tol: float = 1e-2,
    max_time_s: float = math.inf,
    max_boxes: int = DEFAULT_MAX_BOXES,
) -> MatrixBnbResult:
    """Sound bound of the Lipschitz constant of ``x -> M(x)`` (spectral norm) on the box, from
    Hessian enclosures of the MLPs (objective ``'jac_lipschitz'`` of :func:`box_bounds`)."""
    b = _check_region(box, dec.dim)
    return matrix_bnb(
        dec, b, "jac_lipschitz", tol=tol, max_time_s=max_time_s, max_boxes=max_boxes, n_samples=0
    )


def difference_jacobian_lipschitz_box(
    s: System,
    box=None,
    *,
    tol: float = 1e-2,
    max_time_s: float = math.inf,
) -> Quantity | None:
    """Local ``L_Delta``: a sound bound of the Lipschitz constant of ``D (pi_IL - pi*)`` on the
    box (default: the support), valid for points of the box only. ``None`` when the difference
    is not affine in MLP Jacobians."""
    dec = difference_jacobian(s)
    if dec is None:
        return None
    b = _check_region(s.support if box is None else box, s.n)
    out = local_jacobian_lipschitz(dec, b, tol=tol, max_time_s=max_time_s)
    r = out.result
    return Quantity.derive(
        "L_dDelta",
        r.upper,
        method=How.SOUND,
        source=_SRC_LDELTA,
        note=f"mlp-bnb on Hessian enclosures (sqrt rho(|H|^T |H|), {r.n_boxes} sub-boxes, "
        f"stop {r.stop}); valid for x, y in the box only",
        scope=Scope(tuple(map(tuple, b))),
    )
