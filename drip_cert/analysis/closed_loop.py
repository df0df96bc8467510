"""Constants of the nominal closed loop that L1-DRAC needs (L1-DRAC Assumptions 1, 3 and 8).

In DRIP the L1-DRAC layer sees the nominal drift ``F(t, a) = f(t, a) + g(t) pi_IL(a)`` (the
closed loop under the mid-level policy). This module bounds

* ``Delta_f``: ``||F(t, a)||^2 <= Delta_f^2 (1 + ||a||^2)`` (Assumption 1);
* ``L_f``: the Lipschitz constant of ``F`` in ``a`` (Assumption 8, optional);
* ``Delta_star``: ``||X*_t||_{L_{2p*}} <= Delta_star`` (Assumption 3).

Sound route: when ``F(a) = A a + c + sum_k C_k h_k(a)`` with constant ``A, c, C_k`` and MLP blocks
``h_k`` applied to the state (as in the paper's example), ``||h_k(a)|| <= B_k`` (tanh/GELU hidden
layers and an affine output layer give a bounded output for tanh, see
:func:`mlp_output_bound`) and ``Lip(h_k) <= L_k``, so with ``beta = ||c|| + sum ||C_k|| B_k``:
``||F(a)|| <= ||A|| ||a|| + beta <= sqrt(||A||^2 + beta^2) sqrt(1 + ||a||^2)`` (Cauchy-Schwarz)
and ``Lip(F) <= ||A|| + sum ||C_k|| L_k``. ``Delta_star`` follows from contraction: the trajectory
from ``x_0`` stays within ``e^{-lambda t}||x_0||`` of the trajectory from ``0``, whose norm obeys
``d/dt ||y|| <= -lambda ||y|| + ||F(t, 0)||``, so ``||X*_t|| <= max_{x0 in box} ||x_0|| +
sup_t ||F(t, 0)|| / lambda`` almost surely, hence in every ``L_{2p}`` (valid when the rate holds
on all of ``R^n``; on a box it is labelled an estimate). Anything else is a sampled estimate.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np
import sympy as sp

from drip_cert.analysis.constants import batch_fn
from drip_cert.analysis.mlp_bounds import enclose_output, lipschitz_bound
from drip_cert.model.blocks import block_applications
from drip_cert.model.mlp import MLP
from drip_cert.model.system import System
from drip_cert.numerics.rounding import (
    add_down_np,
    add_up,
    add_up_np,
    div_up,
    matmul_bounds,
    mul_up,
    norm2_up_np,
    spectral_norm_upper,
    sq_up,
    sqrt_up,
    sub_down_np,
    sum_up_np,
    up_np,
)
from drip_cert.numerics.sampling import growth_ratio_estimate, holder_estimate
from drip_cert.provenance import How, Quantity

SUPERLINEAR_RADIUS = 1e5
#: a sampled growth ratio that peaks at radius >= this (the sampler goes to 1e6) is taken to grow
#: without bound (e.g. a cubic drift): Assumption 1's linear growth then fails


@dataclass(frozen=True)
class AffineBlocks:
    """``F(a) = A a + c + sum_k C_k h_k(a)`` (constant ``A``, ``c``, ``C_k``)."""

    A: np.ndarray
    c: np.ndarray
    C: dict[str, np.ndarray]


def affine_in_blocks(exprs: sp.MatrixBase, s: System) -> AffineBlocks | None:
    """Decompose ``exprs`` (a vector in the states) as affine in the states and in block outputs
    applied to the whole state; ``None`` when it is not of that form (or depends on ``t``)."""
    vec = sp.Matrix(exprs)
    x = list(s.states)
    apps = set()
    for e in vec:
        apps |= block_applications(e)
    if any(a.deriv or a.args != tuple(x) for a in apps):
        return None
    syms = {a: sp.Dummy(type(a).__name__) for a in apps}
    lin = vec.xreplace(syms).applyfunc(sp.expand)  # cancellations (e.g. after a change of
    # coordinates) must show before the coefficients are read
    variables = x + list(syms.values())
    for e in lin:
        if s.t in e.free_symbols:
            return None
        if not variables:
            continue
        try:
            if not sp.Poly(e, *variables).is_linear:
                return None
        except sp.PolynomialError:
            return None
    n = len(vec)
    A = np.array([[float(sp.diff(e, xi)) for xi in x] for e in lin])
    zero = {v: 0 for v in variables}
    c = np.array([float(e.xreplace(zero)) for e in lin])
    C: dict[str, np.ndarray] = {}
    for a, z in syms.items():
        M = C.setdefault(a.block_name, np.zeros((n, s.blocks[a.block_name].out_dim)))
        for i, e in enumerate(lin):
            M[i, a.out_index] += float(sp.diff(e, z))
    return AffineBlocks(A, c, C)


def mlp_output_bound(mlp: MLP) -> float:
    """``sup_x ||mlp(x)||_2`` for bounded hidden activations (tanh), else ``inf`` (rounded up).

    The last hidden layer outputs lie in ``[-1, 1]^w`` for tanh, so the affine output layer gives
    ``||W z + b|| <= || |W| 1 + |b| ||`` entrywise (row sums and the norm rounded up). A tanh
    output layer gives ``sqrt(out_dim)``. (GELU is unbounded: ``inf``.)
    """
    if (
        mlp.activation != "tanh"
        or len(mlp.weights) < 2
        or mlp.output_activation not in (None, "identity", "tanh")
    ):
        return math.inf
    if mlp.output_activation == "tanh":
        return sqrt_up(float(mlp.out_dim))
    W, b = mlp.weights[-1], mlp.biases[-1]
    rows = sum_up_np(np.concatenate([np.abs(W), np.abs(b)[:, None]], axis=1), axis=1)
    return float(norm2_up_np(rows))


CONVERSION_ULPS = 2
"""``affine_in_blocks`` converts the sympy coefficients with ``float()``: exact for floats,
correctly rounded for rationals (``int / int``) and within an ulp for other constants
(``evalf``), so each entry is within ``CONVERSION_ULPS`` spacings of the true coefficient."""


def _norm_of_converted(M: np.ndarray, spectral: bool) -> float:
    """Upper bound of the spectral (matrix) or Euclidean (vector) norm of the true coefficients
    whose floats are ``M``: the norm of ``M`` plus the Frobenius norm of the conversion radius
    (``||X||_2 <= ||X||_F`` bounds the spectral norm of the error)."""
    M = np.asarray(M, dtype=float)
    base = float(spectral_norm_upper(M)) if spectral else float(norm2_up_np(M.ravel()))
    rad = CONVERSION_ULPS * np.spacing(np.abs(M)).ravel()  # exact: a power-of-two multiple
    return add_up(base, float(norm2_up_np(rad)))


def _box_radius_up(box: np.ndarray) -> float:
    """``max_{x in box} ||x||`` (the farthest corner), rounded up: ``sqrt(sum max(lo^2, hi^2))``."""
    return float(norm2_up_np(np.max(np.abs(box), axis=1)))


def _f_at_zero_up(dec: AffineBlocks, s: System) -> float:
    """Upper bound of ``||F(0)|| = ||c + sum_k C_k h_k(0)||``: each ``h_k(0)`` enclosed by
    interval bound propagation, the affine combination in interval arithmetic."""
    c = np.asarray(dec.c, dtype=float)
    rad_c = CONVERSION_ULPS * np.spacing(np.abs(c))  # the conversion of the true c to floats
    lo = sub_down_np(c, rad_c)
    hi = add_up_np(c, rad_c)
    for b, C in dec.C.items():
        mlp = s.blocks[b].mlp
        assert mlp is not None  # the caller checked that every block of dec.C has an MLP
        zero = np.zeros(mlp.in_dim)
        hlo, hhi = enclose_output(mlp, zero, zero)
        # C h for h in [hlo, hhi]: centre-radius with the product rounding (matmul_bounds), plus
        # the conversion radius of C times |h|
        m = 0.5 * hlo + 0.5 * hhi
        r = up_np(np.maximum(hhi - m, m - hlo))
        clo, chi = matmul_bounds(C, m[:, None])
        rad = matmul_bounds(np.abs(C), r[:, None])[1][:, 0]
        habs = np.maximum(np.abs(hlo), np.abs(hhi))
        conv = matmul_bounds(CONVERSION_ULPS * np.spacing(np.abs(C)), habs[:, None])[1][:, 0]
        rad = add_up_np(rad, conv)
        lo = sub_down_np(add_down_np(lo, clo[:, 0]), rad)
        hi = add_up_np(add_up_np(hi, chi[:, 0]), rad)
    return float(norm2_up_np(np.maximum(np.abs(lo), np.abs(hi))))


@dataclass(frozen=True)
class ClosedLoopConstants:
    """``Delta_f``, ``L_f`` (and whether Assumption 8 is used) and ``Delta_star``."""

    Delta_f: Quantity
    L_f: Quantity
    Delta_star: Quantity

    def quantities(self) -> tuple[Quantity, ...]:
        return (self.Delta_f, self.L_f, self.Delta_star)


def closed_loop_constants(
    s: System, which: str, lam: Quantity, global_rate: bool
) -> ClosedLoopConstants:
    """Bound ``Delta_f``, ``L_f``, ``Delta_star`` of the closed loop under ``which`` policy.

    Parameters
    ----------
    s
        The system.
    which
        ``'learned'`` (DRIP's L1-DRAC nominal system) or ``'expert'``.
    lam
        The contraction rate of that closed loop (``> 0``).
    global_rate
        Whether ``lam`` holds on all of ``R^n`` (needed for a sound ``Delta_star``).
    """
    F = s.closed_loop(which)
    box = np.array(s.support, dtype=float)
    r0 = _box_radius_up(box)
    dec = affine_in_blocks(F, s)
    src_f = "L1-DRAC Assumption 1 (nominal drift = closed loop under the policy)"
    src_l = "L1-DRAC Assumption 8"
    src_s = "L1-DRAC Assumption 3"
    if dec is not None and all(s.blocks[b].mlp is not None for b in dec.C):
        # every norm is a rigorous upper bound and every operation is rounded up (all terms >= 0)
        nA = _norm_of_converted(dec.A, spectral=True)
        beta = _norm_of_converted(dec.c, spectral=False)
        lip = nA
        lips = []
        for b, C in dec.C.items():
            mlp = s.blocks[b].mlp
            assert mlp is not None  # checked above: every block of dec.C has an MLP
            nC = _norm_of_converted(C, spectral=True)
            Lh = lipschitz_bound(mlp)
            lips.append(Lh)
            beta = add_up(beta, mul_up(nC, mlp_output_bound(mlp)))
            lip = add_up(lip, mul_up(nC, Lh.value))
        dF = Quantity.derive(
            "Delta_f",
            sqrt_up(add_up(sq_up(nA), sq_up(beta))),
            method=How.SOUND,
            source=src_f,
            note=f"F = A a + c + sum C h(a): sqrt(||A||^2 + beta^2), ||A|| = {nA:.6g}, "
            f"beta = ||c|| + sum ||C|| sup||h|| = {beta:.6g} (norms and sums rounded up)",
        )
        lF = Quantity.derive(
            "L_f",
            lip,
            inputs=lips,
            method=How.SOUND,
            source=src_l,
            note="||A|| + sum ||C|| Lip(h) (spectral-norm product bound of each MLP)",
        )
        F0 = _f_at_zero_up(dec, s)
        bound = add_up(r0, div_up(F0, lam.value))
        global_ok = global_rate and lam.how.proved
        dS = Quantity.derive(
            "Delta_star",
            bound,
            inputs=[lam],
            method=How.SOUND if global_ok else How.ESTIMATE,
            source=src_s,
            note=f"max_box ||x0|| + ||F(0)||/lambda = {r0:.6g} + {F0:.6g}/{lam.value:.6g}"
            + ("" if global_ok else " (rate not global: estimate)"),
        )
        return ClosedLoopConstants(dF, lF, dS)
    # sampled estimates
    fn = batch_fn(s, sp.Matrix(F))
    times = np.linspace(0.0, s.horizon, 5)
    growth = growth_ratio_estimate(fn, s.n, 1.0, times)
    holder = holder_estimate(fn, s.n, 1.0, times)
    D, L = growth.value, holder.value
    est = "sampled (spheres of radii up to 1e6): an estimate, not a bound"
    est_D, est_L = est + growth.diagnostics(), est + holder.diagnostics()
    if float(np.linalg.norm(growth.argmax)) >= SUPERLINEAR_RADIUS:
        # the ratio is largest at the outermost sampled radius: it grows without bound
        D, L = math.inf, math.inf
        est_D = est_L = (
            "the sampled ratio ||F(a)|| / sqrt(1 + ||a||^2) still grows at ||a|| = 1e6: "
            "super-linear growth, L1-DRAC Assumption 1 fails"
        )
    F0 = max(float(np.linalg.norm(fn(float(t), np.zeros((1, s.n)))[0])) for t in times)
    return ClosedLoopConstants(
        Quantity("Delta_f", D, How.ESTIMATE, src_f, est_D),
        Quantity("L_f", L, How.ESTIMATE, src_l, est_L),
        Quantity(
            "Delta_star",
            r0 + F0 / lam.value,
            How.ESTIMATE,
            src_s,
            "max_box ||x0|| + ||F(t,0)||/lambda with F(t,0) sampled at 5 times",
        ),
    )
