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

from drip_cert.analysis.constants import batch_fn, growth_ratio_estimate, holder_estimate
from drip_cert.learn.mlp import MLP
from drip_cert.provenance import How, Quantity
from drip_cert.system.blocks import block_applications
from drip_cert.system.system import System

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
    lin = vec.xreplace(syms)
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
    """``sup_x ||mlp(x)||_2`` for bounded hidden activations (tanh), else ``inf``.

    The last hidden layer outputs lie in ``[-1, 1]^w`` for tanh, so the affine output layer gives
    ``||W z + b|| <= || |W| 1 + |b| ||`` entrywise. (GELU is unbounded: ``inf``.)
    """
    if (
        mlp.activation != "tanh"
        or len(mlp.weights) < 2
        or mlp.output_activation not in (None, "identity", "tanh")
    ):
        return math.inf
    if mlp.output_activation == "tanh":
        return math.sqrt(mlp.out_dim)
    W, b = mlp.weights[-1], mlp.biases[-1]
    return float(np.linalg.norm(np.abs(W) @ np.ones(W.shape[1]) + np.abs(b))) * (1 + 1e-12)


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
    from drip_cert.learn.mlp_bounds import lipschitz_bound

    F = s.closed_loop(which)
    box = np.array(s.support)
    r0 = float(np.max(np.linalg.norm(np.array(np.meshgrid(*box)).reshape(s.n, -1).T, axis=1)))
    dec = affine_in_blocks(F, s)
    src_f = "L1-DRAC Assumption 1 (nominal drift = closed loop under the policy)"
    src_l = "L1-DRAC Assumption 8"
    src_s = "L1-DRAC Assumption 3"
    if dec is not None and all(s.blocks[b].mlp is not None for b in dec.C):
        nA = float(np.linalg.norm(dec.A, 2))
        beta = float(np.linalg.norm(dec.c))
        lip = nA
        for b, C in dec.C.items():
            mlp = s.blocks[b].mlp
            nC = float(np.linalg.norm(C, 2))
            beta += nC * mlp_output_bound(mlp)
            lip += nC * lipschitz_bound(mlp).value
        up = 1 + 1e-12  # covers the rounding of the few float operations above
        dF = Quantity(
            "Delta_f",
            math.sqrt(nA**2 + beta**2) * up,
            How.SOUND,
            src_f,
            f"F = A a + c + sum C h(a): sqrt(||A||^2 + beta^2), ||A|| = {nA:.6g}, "
            f"beta = ||c|| + sum ||C|| sup||h|| = {beta:.6g}",
        )
        lF = Quantity(
            "L_f",
            lip * up,
            How.SOUND,
            src_l,
            "||A|| + sum ||C|| Lip(h) (spectral-norm product bound of each MLP)",
        )
        F0 = float(
            np.linalg.norm(
                dec.c + sum(C @ s.blocks[b].evaluate_np(np.zeros(s.n)) for b, C in dec.C.items())
            )
        )
        bound = r0 + F0 / lam.value
        how = How.SOUND if (global_rate and lam.how in (How.EXACT, How.SOUND)) else How.ESTIMATE
        dS = Quantity(
            "Delta_star",
            bound * up,
            how,
            src_s,
            f"max_box ||x0|| + ||F(0)||/lambda = {r0:.6g} + {F0:.6g}/{lam.value:.6g}"
            + ("" if how == How.SOUND else " (rate not global: estimate)"),
        )
        return ClosedLoopConstants(dF, lF, dS)
    # sampled estimates
    fn = batch_fn(s, sp.Matrix(F))
    times = np.linspace(0.0, s.horizon, 5)
    D, arg = growth_ratio_estimate(fn, s.n, 1.0, times)
    L = holder_estimate(fn, s.n, 1.0, times)
    if float(np.linalg.norm(arg)) >= SUPERLINEAR_RADIUS:
        # the ratio is largest at the outermost sampled radius: it grows without bound
        D, L = math.inf, math.inf
    F0 = max(float(np.linalg.norm(fn(float(t), np.zeros((1, s.n)))[0])) for t in times)
    est = "sampled (spheres of radii up to 1e6): an estimate, not a bound"
    if math.isinf(D):
        est = (
            "the sampled ratio ||F(a)|| / sqrt(1 + ||a||^2) still grows at ||a|| = 1e6: "
            "super-linear growth, L1-DRAC Assumption 1 fails"
        )
    return ClosedLoopConstants(
        Quantity("Delta_f", D, How.ESTIMATE, src_f, est),
        Quantity("L_f", L, How.ESTIMATE, src_l, est),
        Quantity(
            "Delta_star",
            r0 + F0 / lam.value,
            How.ESTIMATE,
            src_s,
            "max_box ||x0|| + ||F(t,0)||/lambda with F(t,0) sampled at 5 times",
        ),
    )
