"""Regularity bounds of MLP policies: Lipschitz constants, Jacobian-Lipschitz constants, enclosures.

These are the constants of the DRIP paper's Assumption "PolicyRegularity"
(``assmp:PolicyRegularity``): ``L_pi`` bounds the Lipschitz constant of a policy and ``L_dpi`` the
Lipschitz constant of its Jacobian (equivalently, the second-order Taylor remainder
``||pi(z) - pi(z0) - dpi(z0)(z - z0)|| <= L_dpi/2 ||z - z0||^2``). For the TaSIL certificate
(docs/math/tasil.md section 3.1, assumption A2) ``L_Delta <= L_dpi(pi_hat) + L_dpi(pi_star)``.

Network convention (:class:`drip_cert.model.mlp.MLP`): ``z_0 = x``, ``a_k = W_k z_k + b_k``,
``z_{k+1} = s_k(a_k)`` where ``s_k`` is the hidden activation for ``k < L-1`` and the output
activation (identity when ``None``) for ``k = L-1``. All norms are Euclidean / spectral.

Activation constants (proved in :func:`activation_bounds`)

======== ======================== ====================== ============================
name     slope range [inf s', sup s']   sup |s'|          sup |s''|
======== ======================== ====================== ============================
tanh     [0, 1]                    1                     4/(3 sqrt 3) ~ 0.7698
gelu     [-0.12893, 1.12893]       1.12893               sqrt(2/pi) ~ 0.79788
identity [1, 1]                    1                     0
======== ======================== ====================== ============================

Floating-point soundness (:mod:`drip_cert.numerics.rounding` owns the rules): the activation
constants are
evaluated in Arb; spectral norms are rigorous upper bounds
(:func:`~drip_cert.numerics.rounding.spectral_norm_upper`), every product and sum of the Lipschitz
recursions is rounded up, and the LipSDP certificate is re-checked with a rigorous upper bound of
the largest eigenvalue of the LMI matrix (its float assembly error bounded entrywise). The
interval enclosures use directed rounding for every arithmetic operation and the
cancellation-free forms ``tanh' = sech^2 = 4 e^{-2|z|} / (1 + e^{-2|z|})^2`` and
``GELU = z Phi(z)``, ``GELU' = Phi(z) + z phi(z)`` with ``Phi`` from ``ndtr`` (``erfc`` in the
left tail) -- never ``1 - tanh^2`` or ``1 + erf``, which cancel to 0 for large ``|z|`` (then the
exact value lies outside any relative pad). They evaluate ``exp``, ``tanh`` and ``ndtr`` in
float (vectorised over boxes and neurons) and widen each result by the documented error budget of
those library functions (:data:`~drip_cert.numerics.rounding.LIBM_REL`,
:func:`~drip_cert.numerics.rounding.ndtr_rel_budget`, checked against mpmath in
``tests/test_rounding.py``):
sound as long as numpy and scipy meet their documented accuracy.
"""

from __future__ import annotations

import functools
import math
from dataclasses import dataclass

import numpy as np
from flint import arb
from scipy.special import ndtr

from drip_cert.errors import SpecError
from drip_cert.model.mlp import MLP, activation_fn
from drip_cert.numerics.rounding import (
    LIBM_REL,
    add_up,
    add_up_np,
    arb_bounds,
    arb_hi,
    arb_lo,
    down_np,
    gamma,
    mul_up,
    ndtr_rel_budget,
    norm2_up_np,
    spectral_norm_upper,
    sqrt_up,
    sub_down_np,
    sym_lambda_max_upper,
    up_np,
    widen_np,
)
from drip_cert.provenance import Check, How, Quantity

__all__ = [
    "ActivationBounds",
    "LipSDPResult",
    "activation_bounds",
    "enclose_activation",
    "enclose_activation_prime",
    "enclose_jacobian",
    "enclose_output",
    "jacobian_lipschitz_bound",
    "jacobian_np",
    "lipschitz_bound",
    "lipschitz_lipsdp",
    "lipschitz_product",
]

_EPS = float(np.finfo(np.float64).eps)
_TINY = 2.0**-1074  # smallest subnormal: the absolute unit of underflow errors
# LMI size up to which "auto" uses Clarabel (interior point, ~1 s or less there)
_CLARABEL_MAX_DIM = 48
# LipSDP: the Schur-complement rho is raised by this much (relative, and absolute times the scale of
# the output weights) before the rigorous re-check, so that the check has room; NOT a soundness pad
# (the rigorous re-check alone decides whether the certificate holds)
_RHO_MARGIN_REL = 1e-7
_RHO_MARGIN_ABS = 1e-12
_SQRT2 = math.sqrt(2.0)
_INV_SQRT_2PI = 1.0 / math.sqrt(2.0 * math.pi)  # float, for point evaluations (estimates) only


# --------------------------------------------------------------------------- Arb constants


def _arb_Phi(z: arb) -> arb:
    """Normal CDF in Arb, ``erfc(-z / sqrt 2) / 2`` (no cancellation in the left tail)."""
    return (-z / arb(2).sqrt()).erfc() / 2


def _arb_phi(z: arb) -> arb:
    """Normal density in Arb."""
    return (-z * z / 2).exp() / (2 * arb.pi()).sqrt()


def _arb_gelu_prime(z: arb) -> arb:
    return _arb_Phi(z) + z * _arb_phi(z)


@dataclass(frozen=True)
class _Consts:
    """Rigorous float bounds of the constants the enclosures need: enclosures ``(lo, hi)`` of
    sqrt 2 and 1/sqrt(2 pi), bounds of GELU' and a bracket of GELU's minimiser."""

    sqrt2: tuple[float, float]
    inv_sqrt_2pi: tuple[float, float]
    gelu_prime_max: float  # upper bound of max GELU' = GELU'(sqrt 2)
    gelu_prime_min: float  # lower bound of min GELU' = GELU'(-sqrt 2)
    gelu_argmin_bracket: tuple[float, float]  # [a, b] containing the minimiser z* of GELU
    gelu_min_lo: float  # lower bound of min GELU


@functools.cache
def _consts() -> _Consts:
    """Rigorous float bounds of the constants the enclosures need (computed once, in Arb)."""
    sqrt2 = arb(2).sqrt()
    sqrt2_bounds = arb_bounds(sqrt2)
    inv_sqrt_2pi = arb_bounds(1 / (2 * arb.pi()).sqrt())
    # GELU' = Phi + z phi has its global max at +sqrt 2 and global min at -sqrt 2
    gelu_prime_max = arb_hi(_arb_gelu_prime(sqrt2))
    gelu_prime_min = arb_lo(_arb_gelu_prime(-sqrt2))
    # the minimiser z* of GELU (the zero of GELU'): a float estimate, then a bracket [a, b] whose
    # signs are verified in Arb; GELU' < 0 on (-inf, z*) and > 0 on (z*, inf) (see
    # activation_bounds), so z* in [a, b], and for z in [a, b] (all < 0)
    # z Phi(z) >= a Phi(z) >= a Phi(b): a rigorous lower bound of min GELU
    from scipy.optimize import brentq  # scipy.optimize: keep off the API's import path

    zs = float(brentq(lambda z: float(_gelu_prime(z)), -1.0, -0.5, xtol=1e-15))
    a, b = zs - 1e-12, zs + 1e-12
    if not (arb_hi(_arb_gelu_prime(arb(a))) < 0.0 < arb_lo(_arb_gelu_prime(arb(b)))):
        raise ArithmeticError("could not bracket the minimiser of GELU")  # pragma: no cover
    return _Consts(
        sqrt2=sqrt2_bounds,
        inv_sqrt_2pi=inv_sqrt_2pi,
        gelu_prime_max=gelu_prime_max,
        gelu_prime_min=gelu_prime_min,
        gelu_argmin_bracket=(a, b),
        gelu_min_lo=arb_lo(arb(a) * _arb_Phi(arb(b))),
    )


# --------------------------------------------------------------------------- activations
# --------------------------------------------------------------------------- activations


@dataclass(frozen=True)
class ActivationBounds:
    """Slope and curvature bounds of one activation function (each rounded outward).

    Attributes
    ----------
    name
        ``"tanh"``, ``"gelu"`` or ``"identity"``.
    slope_lo, slope_hi
        ``inf s'`` and ``sup s'`` over the real line (slope restriction of LipSDP).
    abs_slope
        ``sup |s'|`` (the factor of the product Lipschitz bound).
    abs_curv
        ``sup |s''|`` (the factor of the Jacobian-Lipschitz bound).
    """

    name: str
    slope_lo: float
    slope_hi: float
    abs_slope: float
    abs_curv: float


def _gelu_prime(z):
    """GELU'(z) = Phi(z) + z phi(z) for the exact (erf) GELU (float; a point value, not a bound)."""
    z = np.asarray(z, dtype=np.float64)
    return ndtr(z) + z * _INV_SQRT_2PI * np.exp(-0.5 * z * z)


def _tanh_prime(z):
    """tanh'(z) = sech^2 z = 4 e^{-2|z|} / (1 + e^{-2|z|})^2 (float; a point value). Unlike
    ``1 - tanh(z)^2`` it keeps full relative accuracy for large ``|z|``."""
    e = np.exp(-2.0 * np.abs(np.asarray(z, dtype=np.float64)))
    return 4.0 * e / ((1.0 + e) * (1.0 + e))


def activation_bounds(name: str | None) -> ActivationBounds:
    """Slope range and curvature bound of an activation, with the proof.

    * tanh: ``tanh' = 1 - tanh^2 in (0, 1]``; ``tanh'' = -2 tanh (1 - tanh^2)``; with
      ``u = tanh in (-1, 1)`` the map ``2u(1-u^2)`` peaks at ``u = 1/sqrt 3``, so
      ``sup |tanh''| = 4 / (3 sqrt 3)``.
    * GELU (exact, ``z Phi(z)``): ``GELU' = Phi + z phi``, ``GELU'' = phi (2 - z^2)``, vanishing at
      ``z = +-sqrt 2``, so ``sup GELU' = GELU'(sqrt 2) ~ 1.12893`` and
      ``inf GELU' = GELU'(-sqrt 2) ~ -0.12893`` (limits 1 and 0 at infinity);
      ``GELU''' = phi z (z^2 - 4)`` vanishes at ``0, +-2``, ``|GELU''(0)| = 2 phi(0) = sqrt(2/pi)``
      and ``|GELU''(+-2)| = 2 phi(2) ~ 0.108``, so ``sup |GELU''| = sqrt(2/pi) ~ 0.79788``.
      ``GELU'`` decreases from 0 to ``GELU'(-sqrt 2) < 0``, increases to ``GELU'(sqrt 2) > 0``
      and decreases to 1: it is negative before its single zero ``z* ~ -0.7518`` and positive
      after, so ``GELU`` decreases up to ``z*`` and increases after it.
    * identity: slope 1, curvature 0.

    Every value is evaluated in Arb and rounded outward.
    """
    return _activation_bounds(None if name == "identity" else name)


@functools.cache
def _activation_bounds(name: str | None) -> ActivationBounds:
    if name is None:
        return ActivationBounds("identity", 1.0, 1.0, 1.0, 0.0)
    if name == "tanh":
        curv = arb_hi(arb(4) / (3 * arb(3).sqrt()))
        return ActivationBounds("tanh", 0.0, 1.0, 1.0, curv)
    if name == "gelu":
        c = _consts()
        hi, lo = float(c.gelu_prime_max), float(c.gelu_prime_min)
        curv = arb_hi((2 / arb.pi()).sqrt())
        return ActivationBounds("gelu", lo, hi, max(hi, abs(lo)), curv)
    raise SpecError(
        f"activation {name!r} has no regularity bounds; use 'tanh', 'gelu' or 'identity'",
        field="activation",
    )


def _layer_activations(mlp: MLP) -> list[ActivationBounds]:
    """Activation bounds of each layer ``k = 0..L-1`` (the last is the output activation)."""
    n = len(mlp.weights)
    hidden = activation_bounds(mlp.activation)
    return [hidden] * (n - 1) + [activation_bounds(mlp.output_activation)]


def _spec_norm(w: np.ndarray) -> float:
    """Rigorous upper bound of ``||W||_2``
    (:func:`~drip_cert.numerics.rounding.spectral_norm_upper`)."""
    return float(spectral_norm_upper(w))


def _row_norm(w: np.ndarray) -> float:
    """``||W||_{2 -> inf}`` = the largest row 2-norm, rounded up."""
    return float(np.max(norm2_up_np(w, axis=1)))


# --------------------------------------------------------------------------- Lipschitz bounds


def lipschitz_product(mlp: MLP) -> Quantity:
    """Product bound ``L_pi <= prod_k sup|s_k'| ||W_k||_2`` (DRIP Assumption PolicyRegularity a).

    Sound by the chain rule: ``||J(x)|| <= prod_k ||diag(s_k'(a_k))|| ||W_k||``.

    Returns
    -------
    Quantity
        ``L_pi``, :attr:`How.SOUND`.
    """
    value = 1.0
    for w, act in zip(mlp.weights, _layer_activations(mlp)):
        value = mul_up(value, mul_up(act.abs_slope, _spec_norm(w)))
    return Quantity(
        "L_pi",
        value,
        How.SOUND,
        "DRIP Assumption PolicyRegularity (a)",
        f"product of spectral norms times sup|s'| ({mlp.activation}), global on R^n",
    )


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
    act = activation_bounds(mlp.activation)
    a, b = act.slope_lo, act.slope_hi
    T = np.diag(lam)
    M = -2.0 * a * b * A.T @ T @ A + (a + b) * (A.T @ T @ B + B.T @ T @ A) - 2.0 * B.T @ T @ B
    M[:n0, :n0] -= rho * np.eye(n0)
    last = mlp.weights[-1]
    k = last.shape[1]
    M[-k:, -k:] += last.T @ last
    M = 0.5 * (M + M.T)
    aA, aB = np.abs(A), np.abs(B)
    mag = (
        2.0 * abs(a * b) * aA.T @ T @ aA
        + abs(a + b) * (aA.T @ T @ aB + aB.T @ T @ aA)
        + 2.0 * aB.T @ T @ aB
    )
    mag[:n0, :n0] += abs(rho) * np.eye(n0)
    mag[-k:, -k:] += np.abs(last).T @ np.abs(last)
    N = A.shape[0]
    err = add_up_np(up_np(2.0 * gamma(N + k + 8) * mag), (N + k + 8) * 8 * _TINY)
    return M, err


def lipschitz_lipsdp(
    mlp: MLP, *, solver: str = "auto", max_dim: int = 400, margin: float = 1e-7
) -> LipSDPResult:
    """Lipschitz bound by LipSDP-Neuron (Fazlyab, Robey, Hassani, Morari, Pappas, NeurIPS 2019).

    Solves ``min rho`` subject to ``M(lam, rho) <= -margin * s * I``, ``lam >= 0`` with cvxpy
    (``s`` = the scale of the output weights), where ``M`` is given by :func:`_lipsdp_matrix`; the
    slope restriction is ``[inf s', sup s']`` of the hidden activation (tanh ``[0, 1]``, GELU
    ``[-0.1289, 1.1289]``). Only the per-neuron multiplier version is used (the coupled
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
    scale = max(1.0, _spec_norm(ws[-1]) ** 2)
    lam = cp.Variable(N, nonneg=True)
    rho = cp.Variable(nonneg=True)
    act = activation_bounds(mlp.activation)
    A, B = _lipsdp_blocks(mlp)
    a, b = act.slope_lo, act.slope_hi
    # M(lam, rho) = sum_i lam_i M_i + C - rho E0, assembled as one dense linear map (fast to
    # canonicalise; the numpy re-check rebuilds M independently from A^T T A products)
    Mi = (
        -2.0 * a * b * np.einsum("ij,ik->ijk", A, A)
        + (a + b) * (np.einsum("ij,ik->ijk", A, B) + np.einsum("ij,ik->ijk", B, A))
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
    out_slope = activation_bounds(mlp.output_activation).abs_slope
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


def jacobian_lipschitz_bound(mlp: MLP) -> Quantity:
    """Sound Lipschitz constant ``L_dpi`` of the Jacobian (operator norm), DRIP Assumption
    PolicyRegularity (b).

    Derivation. With ``J_{k+1}(x) = D_k(x) W_k J_k(x)``, ``D_k = diag(s_k'(a_k(x)))``, ``J_0 = I``,
    let ``P_k >= sup ||J_k||`` and ``Q_k >= Lip(J_k)``. For any ``x, y``,

    ``J_{k+1}(x) - J_{k+1}(y) = (D_k(x) - D_k(y)) W_k J_k(x) + D_k(y) W_k (J_k(x) - J_k(y))``.

    ``||D_k(x) - D_k(y)||_op = max_i |s'(a_i(x)) - s'(a_i(y))| <= sup|s''| ||a_k(x) - a_k(y)||_inf``
    and ``||a_k(x) - a_k(y)||_inf <= ||W_k||_{2->inf} P_k ||x - y||`` (largest row norm), so

    ``P_{k+1} = sup|s_k'| ||W_k|| P_k``,
    ``Q_{k+1} = sup|s_k''| ||W_k||_{2->inf} ||W_k|| P_k^2 + sup|s_k'| ||W_k|| Q_k``,
    ``P_0 = 1``, ``Q_0 = 0``, and ``L_dpi = Q_L``. For one hidden layer and an affine output this
    is ``||W_1|| sup|s''| ||W_0||_{2->inf} ||W_0||  <=  ||W_1|| sup|s''| ||W_0||^2``, with
    ``sup|tanh''| = 4/(3 sqrt 3)`` and ``sup|GELU''| = sqrt(2/pi)`` (:func:`activation_bounds`).

    Returns
    -------
    Quantity
        ``L_dpi``, :attr:`How.SOUND`, global on R^n.
    """
    P, Q = 1.0, 0.0
    for w, act in zip(mlp.weights, _layer_activations(mlp)):
        nw = _spec_norm(w)
        # every factor is >= 0, so rounding each product and sum up bounds the recursion
        curv_term = mul_up(mul_up(mul_up(act.abs_curv, _row_norm(w)), nw), mul_up(P, P))
        Q = add_up(curv_term, mul_up(mul_up(act.abs_slope, nw), Q))
        P = mul_up(mul_up(act.abs_slope, nw), P)
    return Quantity(
        "L_dpi",
        Q,
        How.SOUND,
        "DRIP Assumption PolicyRegularity (b)",
        "layerwise product rule: Q' = sup|s''| ||W||_2->inf ||W|| P^2 + sup|s'| ||W|| Q",
    )


def jacobian_np(mlp: MLP, x: np.ndarray) -> np.ndarray:
    """Exact forward-mode Jacobian of ``mlp`` at ``x`` (``(..., in)``), shape ``(..., out, in)``."""
    x = np.asarray(x, dtype=np.float64)
    acts = [mlp.activation] * (len(mlp.weights) - 1) + [mlp.output_activation]
    z = x
    J = np.broadcast_to(np.eye(mlp.in_dim), (*x.shape[:-1], mlp.in_dim, mlp.in_dim))
    for w, bias, act in zip(mlp.weights, mlp.biases, acts):
        a = z @ w.T + bias
        d = _act_prime(act, a)
        J = d[..., :, None] * (w @ J)
        z = activation_fn(act, np)(a)
    return J


def _act_prime(name: str | None, a: np.ndarray) -> np.ndarray:
    if name is None or name == "identity":
        return np.ones_like(a)
    if name == "tanh":
        return _tanh_prime(a)
    if name == "gelu":
        return _gelu_prime(a)
    raise SpecError(f"activation {name!r} is not supported", field="activation")


# --------------------------------------------------------------------------- interval enclosures


def _mid_rad(lo: np.ndarray, hi: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Centre and radius with ``[m - r, m + r] ⊇ [lo, hi]`` in exact arithmetic (each difference
    is one rounding, moved up)."""
    m = lo + 0.5 * (hi - lo)
    r = up_np(np.maximum(hi - m, m - lo))
    return m, r


def _affine(w: np.ndarray, b: np.ndarray, lo: np.ndarray, hi: np.ndarray):
    """Sound enclosure of ``W z + b`` for ``z`` in the box ``[lo, hi]`` (batched, ``(..., in)``).

    ``W z + b = (W m + b) + W (z - m)`` with ``|W (z - m)| <= |W| r``. The float ``c = W m + b``
    and ``rad = |W| r`` are within ``gamma_{k+1} (|W| |m| + |b|)`` and ``gamma_k |W| r`` of the
    exact values (Higham Thm 3.1, any summation order); ``2 gamma_{k+2}`` times the float
    ``(|m| + r) |W|^T + |b|`` covers both (and its own rounding). The two final sums are rounded
    outward one at a time.
    """
    m, r = _mid_rad(lo, hi)
    c = m @ w.T + b
    aw = np.abs(w)
    rad = r @ aw.T
    k = w.shape[1]
    err = add_up_np(
        up_np(2.0 * gamma(k + 2) * ((np.abs(m) + r) @ aw.T + np.abs(b))), (k + 2) * 8 * _TINY
    )
    return sub_down_np(sub_down_np(c, rad), err), add_up_np(add_up_np(c, rad), err)


# ---- activations and their derivatives, pointwise enclosures (vectorised)


def _exp_bounds(x: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Enclosure of ``exp(x)`` at float points ``x`` (numpy ``exp`` widened by ``LIBM_REL``)."""
    lo, hi = widen_np(np.exp(x), LIBM_REL)
    return np.maximum(lo, 0.0), hi


def _Phi_bounds(z: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Enclosure of the normal CDF ``Phi(z)`` (scipy ``ndtr``: ``erfc`` in the tails, no
    cancellation) widened by its error budget
    :func:`~drip_cert.numerics.rounding.ndtr_rel_budget`."""
    lo, hi = widen_np(ndtr(z), ndtr_rel_budget(z))
    return np.clip(lo, 0.0, 1.0), np.clip(hi, 0.0, 1.0)


def _phi_bounds(z: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Enclosure of the normal density ``exp(-z^2/2) / sqrt(2 pi)``: ``z^2/2`` rounded both
    ways, ``exp`` decreasing in it, ``1/sqrt(2 pi)`` from Arb."""
    c_lo, c_hi = _consts().inv_sqrt_2pi
    zz = z * z
    h_lo = down_np(0.5 * down_np(zz))
    h_hi = up_np(0.5 * up_np(zz))
    e_lo, _ = _exp_bounds(-h_hi)
    _, e_hi = _exp_bounds(-h_lo)
    return down_np(e_lo * c_lo), up_np(e_hi * c_hi)


def _scale_point(z: np.ndarray, lo: np.ndarray, hi: np.ndarray):
    """Enclosure of ``z * v`` for float points ``z`` and ``v`` in ``[lo, hi]``."""
    pos = z >= 0
    return (
        down_np(np.where(pos, z * lo, z * hi)),
        up_np(np.where(pos, z * hi, z * lo)),
    )


def _gelu_point(z: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Enclosure of ``GELU(z) = z Phi(z)`` at float points (never ``1 + erf``)."""
    return _scale_point(z, *_Phi_bounds(z))


def _gelu_prime_point(z: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Enclosure of ``GELU'(z) = Phi(z) + z phi(z)`` at float points."""
    p_lo, p_hi = _Phi_bounds(z)
    q_lo, q_hi = _scale_point(z, *_phi_bounds(z))
    return down_np(p_lo + q_lo), up_np(p_hi + q_hi)


def _sech2_bounds(a: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Enclosure of ``tanh'(a) = sech^2(a) = 4 e / (1 + e)^2``, ``e = exp(-2a)``, for ``a >= 0``.

    ``2a`` is exact, ``e`` is enclosed in ``[0, 1]``, and ``4e / (1 + e)^2`` increases with ``e``
    there, so the ends come from the ends of ``e`` with every operation rounded outward. No
    cancellation: the relative accuracy is that of ``exp`` for every ``a`` (``1 - tanh^2`` is 0
    in float for ``a > 19``, where ``sech^2 a > 1e-17``).
    """
    e_lo, e_hi = _exp_bounds(-2.0 * a)
    e_lo, e_hi = np.clip(e_lo, 0.0, 1.0), np.clip(e_hi, 0.0, 1.0)
    d_hi = up_np(1.0 + e_lo)
    d_lo = down_np(1.0 + e_hi)
    lo = down_np(4.0 * e_lo / up_np(d_hi * d_hi))
    hi = up_np(4.0 * e_hi / down_np(d_lo * d_lo))
    return np.clip(lo, 0.0, 1.0), np.clip(hi, 0.0, 1.0)


def enclose_activation(name: str | None, lo, hi) -> tuple[np.ndarray, np.ndarray]:
    """Sound enclosure of the activation ``s`` over ``[lo, hi]`` (elementwise, any shape).

    tanh is increasing (numpy ``tanh`` at the ends, widened by its error budget); GELU
    ``z Phi(z)`` decreases up to its minimiser ``z* ~ -0.7518`` and increases after it: over an
    interval on one side the ends give the range, otherwise the range is from a rigorous lower
    bound of ``min GELU`` (Arb) to the larger end value.
    """
    lo = np.asarray(lo, dtype=np.float64)
    hi = np.asarray(hi, dtype=np.float64)
    if name is None or name == "identity":
        return lo, hi
    if name == "tanh":
        ylo, _ = widen_np(np.tanh(lo), LIBM_REL)
        _, yhi = widen_np(np.tanh(hi), LIBM_REL)
        return np.clip(ylo, -1.0, 1.0), np.clip(yhi, -1.0, 1.0)
    if name == "gelu":
        c = _consts()
        a, b = c.gelu_argmin_bracket
        l_lo, l_hi = _gelu_point(lo)
        h_lo, h_hi = _gelu_point(hi)
        left = hi <= a  # [lo, hi] inside (-inf, z*]: decreasing
        right = lo >= b  # inside [z*, inf): increasing
        ylo = np.where(left, h_lo, np.where(right, l_lo, c.gelu_min_lo))
        yhi = np.where(left, l_hi, np.where(right, h_hi, np.maximum(l_hi, h_hi)))
        return ylo, yhi
    raise SpecError(f"activation {name!r} is not supported", field="activation")


def enclose_activation_prime(name: str | None, lo, hi) -> tuple[np.ndarray, np.ndarray]:
    """Sound enclosure of the derivative ``s'`` over ``[lo, hi]`` (elementwise, any shape).

    tanh: ``sech^2`` is even and decreasing in ``|z|``: its range is
    ``[sech^2(max |z|), sech^2(min |z|)]`` (:func:`_sech2_bounds`). GELU: ``GELU'`` decreases on
    ``(-inf, -sqrt 2]``, increases on ``[-sqrt 2, sqrt 2]`` and decreases after, so its minimum over
    an interval is at an end unless the interval contains ``-sqrt 2`` (then the global minimum
    ``GELU'(-sqrt 2)``, Arb), and likewise the maximum with ``+sqrt 2``.
    """
    lo = np.asarray(lo, dtype=np.float64)
    hi = np.asarray(hi, dtype=np.float64)
    if name is None or name == "identity":
        return np.ones_like(lo), np.ones_like(hi)
    if name == "tanh":
        a_max = np.maximum(np.abs(lo), np.abs(hi))
        a_min = np.where((lo <= 0.0) & (hi >= 0.0), 0.0, np.minimum(np.abs(lo), np.abs(hi)))
        return _sech2_bounds(a_max)[0], _sech2_bounds(a_min)[1]
    if name == "gelu":
        c = _consts()
        s_lo, s_hi = c.sqrt2
        l_lo, l_hi = _gelu_prime_point(lo)
        h_lo, h_hi = _gelu_prime_point(hi)
        # may contain -sqrt2 / +sqrt2 (conservative: the global extreme is always a valid bound)
        has_min = (lo <= -s_lo) & (hi >= -s_hi)
        has_max = (lo <= s_hi) & (hi >= s_lo)
        dlo = np.where(has_min, c.gelu_prime_min, np.minimum(l_lo, h_lo))
        dhi = np.where(has_max, c.gelu_prime_max, np.maximum(l_hi, h_hi))
        return dlo, dhi
    raise SpecError(f"activation {name!r} is not supported", field="activation")


_act_interval = enclose_activation
_act_prime_interval = enclose_activation_prime


def _check_box(mlp: MLP, lo, hi) -> tuple[np.ndarray, np.ndarray]:
    lo = np.asarray(lo, dtype=np.float64)
    hi = np.asarray(hi, dtype=np.float64)
    if lo.shape != hi.shape or lo.shape[-1:] != (mlp.in_dim,):
        raise SpecError(
            f"box bounds must both have shape (..., {mlp.in_dim}), got {lo.shape} and {hi.shape}",
            field="box",
        )
    if not (np.all(np.isfinite(lo)) and np.all(np.isfinite(hi))):
        raise SpecError("box bounds must be finite", field="box")
    if np.any(lo > hi):
        i = np.argwhere(lo > hi)[0]
        raise SpecError(
            f"box lower bound exceeds upper bound at index {tuple(i)}: "
            f"{lo[tuple(i)]} > {hi[tuple(i)]}; swap them",
            field="box",
        )
    return lo, hi


def enclose_output(mlp: MLP, lo, hi) -> tuple[np.ndarray, np.ndarray]:
    """Interval bound propagation: ``(y_lo, y_hi)`` with ``y_lo <= mlp(x) <= y_hi`` for every
    ``x`` in the box ``[lo, hi]``.

    ``lo``, ``hi`` have shape ``(..., in)`` (a batch of boxes is enclosed at once); the result has
    shape ``(..., out)``. Affine layers use the centre-radius form with a rigorous rounding term;
    tanh is monotone; GELU is decreasing then increasing around its minimiser ``z* ~ -0.7518``.
    """
    lo, hi = _check_box(mlp, lo, hi)
    acts = [mlp.activation] * (len(mlp.weights) - 1) + [mlp.output_activation]
    for w, b, act in zip(mlp.weights, mlp.biases, acts):
        lo, hi = _affine(w, b, lo, hi)
        lo, hi = _act_interval(act, lo, hi)
    return lo, hi


def _interval_matmul_point_left(w: np.ndarray, jlo: np.ndarray, jhi: np.ndarray):
    """Enclosure of ``W J`` for a point matrix ``W`` and an interval matrix ``J`` (batched); the
    rounding terms as in :func:`_affine`."""
    m, r = _mid_rad(jlo, jhi)
    c = w @ m
    aw = np.abs(w)
    rad = aw @ r
    k = w.shape[1]
    err = add_up_np(up_np(2.0 * gamma(k + 2) * (aw @ (np.abs(m) + r))), (k + 2) * 8 * _TINY)
    return sub_down_np(sub_down_np(c, rad), err), add_up_np(add_up_np(c, rad), err)


def _interval_scale_rows(dlo, dhi, mlo, mhi):
    """Enclosure of ``diag(d) M`` for interval ``d`` (``(..., k)``) and interval ``M``
    (``(..., k, n)``): the four end products, each one rounding, moved outward."""
    dlo = dlo[..., :, None]
    dhi = dhi[..., :, None]
    p = np.stack([dlo * mlo, dlo * mhi, dhi * mlo, dhi * mhi])
    return down_np(p.min(axis=0)), up_np(p.max(axis=0))


def enclose_jacobian(mlp: MLP, lo, hi) -> tuple[np.ndarray, np.ndarray]:
    """Sound elementwise enclosure ``(J_lo, J_hi)`` of the Jacobian ``d mlp / dx`` over a box.

    For every ``x`` in ``[lo, hi]``: ``J_lo <= J(x) <= J_hi`` entrywise, shape ``(..., out, in)``.
    Pre-activation intervals come from :func:`enclose_output`'s propagation; ``s'`` is enclosed
    over each pre-activation interval; then ``J_{k+1} = diag(s'(a_k)) W_k J_k`` in interval
    arithmetic (centre-radius for ``W_k J_k``, four-product rule for the diagonal scaling).
    """
    lo, hi = _check_box(mlp, lo, hi)
    acts = [mlp.activation] * (len(mlp.weights) - 1) + [mlp.output_activation]
    batch = lo.shape[:-1]
    eye = np.broadcast_to(np.eye(mlp.in_dim), (*batch, mlp.in_dim, mlp.in_dim))
    jlo, jhi = eye.copy(), eye.copy()
    zlo, zhi = lo, hi
    for k, (w, b, act) in enumerate(zip(mlp.weights, mlp.biases, acts)):
        alo, ahi = _affine(w, b, zlo, zhi)
        dlo, dhi = _act_prime_interval(act, alo, ahi)
        if k == 0:
            mlo = np.broadcast_to(w, (*batch, *w.shape))
            mhi = mlo
        else:
            mlo, mhi = _interval_matmul_point_left(w, jlo, jhi)
        jlo, jhi = _interval_scale_rows(dlo, dhi, mlo, mhi)
        zlo, zhi = _act_interval(act, alo, ahi)
    return jlo, jhi
