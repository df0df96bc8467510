"""Lipschitz bounds of an MLP by LipSDP-Neuron (Fazlyab et al. 2019), re-checked rigorously, and
:func:`lipschitz_bound`, the best sound Lipschitz constant (the smaller of LipSDP and the layer
product of :mod:`drip_cert.analysis.networks.mlp.lipschitz`).

The LipSDP certificate is re-checked with a rigorous upper bound of the largest eigenvalue of
the LMI matrix (its float assembly error bounded entrywise); the solver's float is never used
as a bound.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from drip_cert.analysis.networks.mlp.lipschitz import lipschitz_product, spectral_norm_up
from drip_cert.errors import SpecError
from drip_cert.model.mlp import MLP
from drip_cert.numerics.rounding import (
    add_up_np,
    gamma,
    mul_up,
    sqrt_up,
    sym_lambda_max_upper,
    up_np,
)
from drip_cert.provenance import Check, How, Quantity

__all__ = ["LipSDPResult", "lipschitz_bound", "lipschitz_lipsdp"]

_TINY = 2.0**-1074  # smallest subnormal: the absolute unit of underflow errors
# LMI size up to which "auto" uses Clarabel (interior point, ~1 s or less there)
_CLARABEL_MAX_DIM = 48
# LipSDP: the Schur-complement rho is raised by this much (relative, and absolute times the scale of
# the output weights) before the rigorous re-check, so that the check has room; NOT a soundness pad
# (the rigorous re-check alone decides whether the certificate holds)
_RHO_MARGIN_REL = 1e-7
_RHO_MARGIN_ABS = 1e-12


@dataclass(frozen=True)
class LipSDPResult:
    """Outcome of the LipSDP-Neuron semidefinite program (Fazlyab et al. 2019).

    Attributes
    ----------
    value
        The certified Lipschitz bound, or ``None`` when the solve or its re-check failed.
    status
        cvxpy status string (``"optimal"`` is the only accepted one).
    check
        The rigorous re-check: ``lhs`` = an upper bound (outward rounded) of the largest
        eigenvalue of the LMI matrix with the returned multipliers, ``rhs = 0``; holds when
        strictly below.
    product
        The product bound, always available as the fallback.
    """

    value: float | None
    status: str
    check: Check
    product: float

    @property
    def best(self) -> float:
        """The smaller of the certified LipSDP value (if any) and the product bound."""
        return self.product if self.value is None else min(self.value, self.product)


def _lipsdp_blocks(mlp: MLP) -> tuple[np.ndarray, np.ndarray]:
    """``A`` (stacked hidden pre-activations) and ``B`` (stacked hidden outputs) of LipSDP."""
    ws = mlp.weights
    n0 = mlp.in_dim
    N = int(sum(w.shape[0] for w in ws[:-1]))
    A = np.zeros((N, n0 + N))
    row, col = 0, 0
    for w in ws[:-1]:
        A[row : row + w.shape[0], col : col + w.shape[1]] = w
        row += w.shape[0]
        col += w.shape[1]
    B = np.hstack([np.zeros((N, n0)), np.eye(N)])
    return A, B


def _neuron_slopes(mlp: MLP) -> tuple[np.ndarray, np.ndarray]:
    """The slope restriction ``[alpha_i, beta_i]`` of every hidden neuron (its layer's global
    Clarke slope range, :attr:`Activation.bounds`), stacked in the order of
    :func:`_lipsdp_blocks`."""
    lo, hi = [], []
    for w, act in zip(mlp.weights[:-1], mlp.activations[:-1]):
        bnd = act.bounds
        lo.append(np.full(w.shape[0], bnd.slope_lo))
        hi.append(np.full(w.shape[0], bnd.slope_hi))
    return np.concatenate(lo), np.concatenate(hi)


def _lipsdp_matrix(mlp: MLP, lam: np.ndarray, rho: float) -> np.ndarray:
    """The LipSDP-Neuron matrix ``M(lam, rho)``; ``M <= 0`` certifies ``L <= sqrt(rho)``.

    ``v = (dx, dz_1, ..., dz_{L-1})``, ``A v`` = the stacked pre-activation increments of hidden
    layers, ``B v`` = the stacked hidden increments. Each neuron's slope restriction
    ``alpha <= ds/da <= beta`` gives the quadratic constraint
    ``[da; ds]^T [[-2 alpha beta l, (alpha+beta) l], [(alpha+beta) l, -2 l]] [da; ds] >= 0``, so
    ``M = [A;B]^T Q(lam) [A;B] + diag(-rho I, 0, W_{L-1}^T W_{L-1})``.
    """
    return _lipsdp_matrix_and_error(mlp, lam, rho)[0]


def _lipsdp_matrix_and_error(
    mlp: MLP, lam: np.ndarray, rho: float
) -> tuple[np.ndarray, np.ndarray]:
    """The float ``M(lam, rho)`` of :func:`_lipsdp_matrix` and an entrywise bound of its distance
    to the exact ``M`` for the same float ``lam``, ``rho`` and slope bounds.

    Every entry of ``M`` is a sum of at most ``N + k + 8`` rounded operations on the terms of the
    non-negative magnitude ``2|a b| |A|^T T |A| + |a + b| (|A|^T T |B| + |B|^T T |A|) +
    2 |B|^T T |B| + rho E_0 + |W_{L-1}|^T |W_{L-1}|`` (``N`` hidden neurons, ``k`` inputs of the
    last layer: the products with the diagonal ``T`` and the scalar factors, the dot products,
    the four matrix sums and the symmetrisation), so its error is at most ``gamma_{N+k+8}`` times
    that magnitude (Higham Thm 3.1, any order), plus underflow; twice the float magnitude covers
    the magnitude's own rounding.
    """
    A, B = _lipsdp_blocks(mlp)
    n0 = mlp.in_dim
    a, b = _neuron_slopes(mlp)
    T = np.diag(lam)
    Tab, Tapb = np.diag(lam * a * b), np.diag(lam * (a + b))
    M = -2.0 * A.T @ Tab @ A + (A.T @ Tapb @ B + B.T @ Tapb @ A) - 2.0 * B.T @ T @ B
    M[:n0, :n0] -= rho * np.eye(n0)
    last = mlp.weights[-1]
    k = last.shape[1]
    M[-k:, -k:] += last.T @ last
    M = 0.5 * (M + M.T)
    aA, aB = np.abs(A), np.abs(B)
    mag = (
        2.0 * aA.T @ np.abs(Tab) @ aA
        + (aA.T @ np.abs(Tapb) @ aB + aB.T @ np.abs(Tapb) @ aA)
        + 2.0 * aB.T @ T @ aB
    )
    mag[:n0, :n0] += abs(rho) * np.eye(n0)
    mag[-k:, -k:] += np.abs(last).T @ np.abs(last)
    N = A.shape[0]
    # N + k + 8 operations as before, plus the two roundings of lam * a * b and lam * (a + b)
    err = add_up_np(up_np(2.0 * gamma(N + k + 10) * mag), (N + k + 10) * 8 * _TINY)
    return M, err


def lipschitz_lipsdp(
    mlp: MLP, *, solver: str = "auto", max_dim: int = 400, margin: float = 1e-7
) -> LipSDPResult:
    """Lipschitz bound by LipSDP-Neuron (Fazlyab, Robey, Hassani, Morari, Pappas, NeurIPS 2019).

    Solves ``min rho`` subject to ``M(lam, rho) <= -margin * s * I``, ``lam >= 0`` with cvxpy
    (``s`` = the scale of the output weights), where ``M`` is given by :func:`_lipsdp_matrix`; the
    slope restriction of each neuron is ``[inf s', sup s']`` of its layer's activation (tanh and
    relu ``[0, 1]``, GELU ``[-0.1289, 1.1289]``; for relu the Clarke slopes, which LipSDP's
    incremental quadratic constraint covers since relu is slope-restricted in that sector).
    Only the per-neuron multiplier version is used (the coupled
    "LipSDP-Network" variant is known to be unsound).

    Re-check (the certificate never rests on the solver's float): with the returned multipliers
    clipped to ``>= 0``, split ``M(lam, 0) = [[P, Q], [Q^T, S]]`` (input block ``P``); ``M <= 0``
    iff ``S < 0`` and ``rho >= lambda_max(P - Q S^{-1} Q^T)`` (Schur complement). The smallest
    such ``rho``, raised by ``1e-7`` relative, is then verified rigorously: ``M`` is assembled in
    float with an entrywise bound of its rounding error and
    :func:`~drip_cert.numerics.rounding.sym_lambda_max_upper` must prove ``lambda_max(M) < 0``.
    Any non-``optimal`` status, solver exception or failed re-check gives ``value=None``; callers
    fall back to the product bound. An output activation multiplies the bound by its ``sup|s'|``.

    Parameters
    ----------
    solver
        ``"CLARABEL"`` (interior point, accurate, but its dense PSD scaling block makes each
        iteration cost ~``d^6/24`` with ``d = in_dim + hidden neurons``: measured 9 s at
        ``d = 74``, 13 min at ``d = 202``), ``"SCS"`` (first order: 0.6 s at ``d = 74``, 11 s at
        ``d = 202``; the Schur re-certification makes its lower accuracy safe), or ``"auto"``:
        Clarabel for ``d <= 48``, SCS above.
    max_dim
        Above this ``d`` LipSDP is skipped (status ``"too_large"``) and the product bound is used.
    """
    import cvxpy as cp  # cvxpy: keep off the API's import path

    product = lipschitz_product(mlp).value
    if len(mlp.weights) < 2:
        # affine map: the product bound is the exact spectral norm (times output slope)
        chk = Check.derive("lipsdp.recheck", False, "no hidden layer: LipSDP not applicable")
        return LipSDPResult(None, "not_applicable", chk, product)
    if solver not in ("auto", "CLARABEL", "SCS"):
        raise SpecError(
            f"solver={solver!r} is not one of 'auto', 'CLARABEL', 'SCS'", field="lipschitz.solver"
        )
    ws = mlp.weights
    n0 = mlp.in_dim
    N = int(sum(w.shape[0] for w in ws[:-1]))
    d = n0 + N
    if solver == "auto":
        solver = "CLARABEL" if d <= _CLARABEL_MAX_DIM else "SCS"
    if d > max_dim:
        chk = Check.derive(
            "lipsdp.recheck",
            False,
            f"LMI size {d} exceeds max_dim={max_dim}; raise max_dim or use solver='SCS'",
        )
        return LipSDPResult(None, "too_large", chk, product)
    scale = max(1.0, spectral_norm_up(ws[-1]) ** 2)
    lam = cp.Variable(N, nonneg=True)
    rho = cp.Variable(nonneg=True)
    A, B = _lipsdp_blocks(mlp)
    a, b = _neuron_slopes(mlp)
    # M(lam, rho) = sum_i lam_i M_i + C - rho E0, assembled as one dense linear map (fast to
    # canonicalise; the numpy re-check rebuilds M independently from A^T T A products)
    Mi = (
        -2.0 * (a * b)[:, None, None] * np.einsum("ij,ik->ijk", A, A)
        + (a + b)[:, None, None] * (np.einsum("ij,ik->ijk", A, B) + np.einsum("ij,ik->ijk", B, A))
        - 2.0 * np.einsum("ij,ik->ijk", B, B)
    )
    G = Mi.reshape(N, d * d).T
    C = np.zeros((d, d))
    k = ws[-1].shape[1]
    C[-k:, -k:] = ws[-1].T @ ws[-1]
    E0 = np.zeros((d, d))
    E0[:n0, :n0] = np.eye(n0)
    X = cp.reshape(G @ lam, (d, d), order="C") + C - rho * E0
    prob = cp.Problem(cp.Minimize(rho), [0.5 * (X + X.T) << -margin * scale * np.eye(d)])
    try:
        prob.solve(solver=getattr(cp, solver))
    except (cp.error.SolverError, ValueError, ArithmeticError) as exc:  # pragma: no cover
        chk = Check.derive("lipsdp.recheck", False, f"solver raised {type(exc).__name__}: {exc}")
        return LipSDPResult(None, "solver_error", chk, product)
    status = str(prob.status)
    if status != cp.OPTIMAL or rho.value is None or lam.value is None:
        chk = Check.derive("lipsdp.recheck", False, f"status {status!r} is not 'optimal'")
        return LipSDPResult(None, status, chk, product)
    lam_v = np.maximum(np.asarray(lam.value, dtype=np.float64), 0.0)
    rho_v = _schur_rho(mlp, lam_v)
    if rho_v is None:
        chk = Check.derive("lipsdp.recheck", False, "hidden block S of M is not negative definite")
        return LipSDPResult(None, status, chk, product)
    rho_v = rho_v * (1.0 + _RHO_MARGIN_REL) + _RHO_MARGIN_ABS * scale
    Mn, err = _lipsdp_matrix_and_error(mlp, lam_v, rho_v)
    top = float(sym_lambda_max_upper(Mn, err))
    out_slope = mlp.activations[-1].bounds.abs_slope
    chk = Check.compare(
        "lipsdp.recheck",
        top,
        0.0,
        f"rigorous upper bound of lambda_max(M) = {top:.3e} must be < 0 (M assembled in float "
        f"with entrywise error bounds, eigenvalue bounded with outward rounding); solver rho "
        f"{float(rho.value):.6g}, certified rho {rho_v:.6g}",
        strict=True,
        method=How.SOUND,
        source="Fazlyab et al. 2019, LipSDP-Neuron",
    )
    value = mul_up(sqrt_up(rho_v), out_slope) if chk.holds else None
    return LipSDPResult(value, status, chk, product)


def _schur_rho(mlp: MLP, lam: np.ndarray) -> float | None:
    """Smallest ``rho`` with ``M(lam, rho) <= 0`` by the Schur complement, ``None`` if the hidden
    block is not negative definite."""
    n0 = mlp.in_dim
    M = _lipsdp_matrix(mlp, lam, 0.0)
    P, Q, S = M[:n0, :n0], M[:n0, n0:], M[n0:, n0:]
    if float(np.max(np.linalg.eigvalsh(S))) >= 0.0:
        return None
    schur = P - Q @ np.linalg.solve(S, Q.T)
    return max(float(np.max(np.linalg.eigvalsh(0.5 * (schur + schur.T)))), 0.0)


def lipschitz_bound(mlp: MLP, method: str = "product") -> Quantity:
    """Sound Lipschitz constant ``L_pi`` of ``mlp`` (DRIP Assumption PolicyRegularity a).

    ``method="product"``: :func:`lipschitz_product`. ``method="lipsdp"``: the smaller of the
    re-checked LipSDP value and the product bound (the product bound when LipSDP fails; the
    note says which).
    """
    if method == "product":
        return lipschitz_product(mlp)
    if method != "lipsdp":
        raise SpecError(
            f"method={method!r} is not one of 'product', 'lipsdp'", field="lipschitz.method"
        )
    res = lipschitz_lipsdp(mlp)
    if res.value is None:
        note = f"LipSDP failed ({res.status}; {res.check.detail}); product bound used"
    else:
        note = f"LipSDP-Neuron re-checked (margin {res.check.margin:.2e}); min with product bound"
    return Quantity("L_pi", res.best, How.SOUND, "DRIP Assumption PolicyRegularity (a)", note)
