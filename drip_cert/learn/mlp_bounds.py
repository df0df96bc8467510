"""Regularity bounds of MLP policies: Lipschitz constants, Jacobian-Lipschitz constants, enclosures.

These are the constants of the DRIP paper's Assumption "PolicyRegularity"
(``assmp:PolicyRegularity``): ``L_pi`` bounds the Lipschitz constant of a policy and ``L_dpi`` the
Lipschitz constant of its Jacobian (equivalently, the second-order Taylor remainder
``||pi(z) - pi(z0) - dpi(z0)(z - z0)|| <= L_dpi/2 ||z - z0||^2``). For the TaSIL certificate
(math/tasil.md section 3.1, assumption A2) ``L_Delta <= L_dpi(pi_hat) + L_dpi(pi_star)``.

Network convention (:class:`drip_cert.learn.mlp.MLP`): ``z_0 = x``, ``a_k = W_k z_k + b_k``,
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

Floating-point soundness: spectral norms are inflated by a relative ``_NORM_INFLATE`` (covering
the backward error of the SVD); interval enclosures round outward (``np.nextafter`` after a
relative pad of ``_REL_PAD`` covering the few-ulp error of numpy's ``tanh`` and scipy's ``erf``),
and interval matrix products add the ``gamma_n = n u / (1 - n u)`` dot-product error bound,
doubled. This assumes the libm ``tanh``/``erf`` are accurate to a few ulps (true of glibc and
cephes); it is not an arb-level proof.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np
from scipy.special import erf, ndtr

from drip_cert.errors import SpecError
from drip_cert.learn.mlp import MLP, activation_fn
from drip_cert.provenance import Check, How, Quantity

__all__ = [
    "ActivationBounds",
    "LipSDPResult",
    "activation_bounds",
    "enclose_jacobian",
    "enclose_output",
    "jacobian_lipschitz_bound",
    "jacobian_np",
    "lipschitz_bound",
    "lipschitz_lipsdp",
    "lipschitz_product",
]

_EPS = float(np.finfo(np.float64).eps)
_UNIT_ROUNDOFF = _EPS / 2.0
# relative inflation of computed spectral norms: SVD backward error is O(n eps ||W||); 1e-12 covers
# n up to ~4e3 with a wide safety factor
_NORM_INFLATE = 1e-12
# relative outward pad of elementwise results (tanh/erf are accurate to a few ulps; 16 eps is ample)
_REL_PAD = 16.0 * _EPS
# absolute outward pad (results near 0 have tiny ulps; this dominates denormal effects)
_ABS_PAD = 1e-300
# LMI size up to which "auto" uses Clarabel (interior point, ~1 s or less there)
_CLARABEL_MAX_DIM = 48
_SQRT2 = math.sqrt(2.0)
_INV_SQRT_2PI = 1.0 / math.sqrt(2.0 * math.pi)


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
    """GELU'(z) = Phi(z) + z phi(z) for the exact (erf) GELU."""
    z = np.asarray(z, dtype=np.float64)
    return ndtr(z) + z * _INV_SQRT_2PI * np.exp(-0.5 * z * z)


def _tanh_prime(z):
    t = np.tanh(np.asarray(z, dtype=np.float64))
    return 1.0 - t * t


def _up(x, steps: int = 1):
    """``x`` moved outward (upward) by a relative pad and ``steps`` ulps."""
    x = np.asarray(x, dtype=np.float64)
    y = x + np.abs(x) * _REL_PAD + _ABS_PAD
    for _ in range(steps):
        y = np.nextafter(y, np.inf)
    return y


def _down(x, steps: int = 1):
    """``x`` moved outward (downward) by a relative pad and ``steps`` ulps."""
    x = np.asarray(x, dtype=np.float64)
    y = x - np.abs(x) * _REL_PAD - _ABS_PAD
    for _ in range(steps):
        y = np.nextafter(y, -np.inf)
    return y


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
    * identity: slope 1, curvature 0.

    Every value is rounded outward.
    """
    if name is None or name == "identity":
        return ActivationBounds("identity", 1.0, 1.0, 1.0, 0.0)
    if name == "tanh":
        curv = 4.0 / (3.0 * math.sqrt(3.0))
        return ActivationBounds("tanh", 0.0, 1.0, 1.0, float(_up(curv)))
    if name == "gelu":
        hi = float(_up(_gelu_prime(_SQRT2)))
        lo = float(_down(_gelu_prime(-_SQRT2)))
        curv = float(_up(2.0 * _INV_SQRT_2PI))
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
    """Spectral norm, inflated to cover the SVD rounding error."""
    return float(np.linalg.norm(w, 2)) * (1.0 + _NORM_INFLATE)


def _row_norm(w: np.ndarray) -> float:
    """``||W||_{2 -> inf}`` = the largest row 2-norm, inflated."""
    return float(np.max(np.linalg.norm(w, axis=1))) * (1.0 + _NORM_INFLATE)


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
        value *= act.abs_slope * _spec_norm(w)
    return Quantity(
        "L_pi",
        float(_up(value)),
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
        The numpy re-check: ``lhs`` = largest eigenvalue of the LMI matrix with the returned
        multipliers, ``rhs`` = ``-`` the rounding allowance; holds when strictly below.
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
    return 0.5 * (M + M.T)


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
    such ``rho``, inflated by ``1e-7`` relative, is then verified by a full numpy ``eigvalsh`` of
    ``M``: its largest eigenvalue must be below ``-`` a rounding allowance ``10 d eps ||M||_F``.
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
    import cvxpy as cp

    product = lipschitz_product(mlp).value
    if len(mlp.weights) < 2:
        # affine map: the product bound is the exact spectral norm (times output slope)
        chk = Check("lipsdp.recheck", False, "no hidden layer: LipSDP not applicable")
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
        chk = Check(
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
        chk = Check("lipsdp.recheck", False, f"solver raised {type(exc).__name__}: {exc}")
        return LipSDPResult(None, "solver_error", chk, product)
    status = str(prob.status)
    if status != cp.OPTIMAL or rho.value is None or lam.value is None:
        chk = Check("lipsdp.recheck", False, f"status {status!r} is not 'optimal'")
        return LipSDPResult(None, status, chk, product)
    lam_v = np.maximum(np.asarray(lam.value, dtype=np.float64), 0.0)
    rho_v = _schur_rho(mlp, lam_v)
    if rho_v is None:
        chk = Check("lipsdp.recheck", False, "hidden block S of M is not negative definite")
        return LipSDPResult(None, status, chk, product)
    rho_v = rho_v * (1.0 + 1e-7) + 1e-12 * scale
    Mn = _lipsdp_matrix(mlp, lam_v, rho_v)
    top = float(np.max(np.linalg.eigvalsh(Mn)))
    allowance = 10.0 * d * _EPS * float(np.linalg.norm(Mn, "fro"))
    holds = top < -allowance
    out_slope = activation_bounds(mlp.output_activation).abs_slope
    value = float(_up(math.sqrt(rho_v) * out_slope)) if holds else None
    chk = Check(
        "lipsdp.recheck",
        holds,
        f"numpy lambda_max(M) = {top:.3e} must be < -{allowance:.3e} (rounding allowance); "
        f"solver rho {float(rho.value):.6g}, certified rho {rho_v:.6g}",
        lhs=top,
        rhs=-allowance,
        margin=-allowance - top,
        source="Fazlyab et al. 2019, LipSDP-Neuron",
        how=How.SOUND,
    )
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
        Q = act.abs_curv * _row_norm(w) * nw * P * P + act.abs_slope * nw * Q
        P = act.abs_slope * nw * P
    return Quantity(
        "L_dpi",
        float(_up(Q)),
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


def _gamma(n: int) -> float:
    """``gamma_n = n u / (1 - n u)``: relative error bound of an n-term dot product."""
    nu = n * _UNIT_ROUNDOFF
    return nu / (1.0 - nu)


def _mid_rad(lo: np.ndarray, hi: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Centre and radius with ``[m - r, m + r] ⊇ [lo, hi]`` in exact arithmetic."""
    m = lo + 0.5 * (hi - lo)
    r = np.nextafter(np.maximum(hi - m, m - lo), np.inf)
    r = np.nextafter(r, np.inf)
    return m, r


def _affine(w: np.ndarray, b: np.ndarray, lo: np.ndarray, hi: np.ndarray):
    """Sound enclosure of ``W z + b`` for ``z`` in the box ``[lo, hi]`` (batched, ``(..., in)``)."""
    m, r = _mid_rad(lo, hi)
    c = m @ w.T + b
    aw = np.abs(w)
    rad = r @ aw.T
    err = 2.0 * _gamma(w.shape[1] + 2) * ((np.abs(m) + r) @ aw.T + np.abs(b))
    return _down(c - rad - err), _up(c + rad + err)


def _gelu_argmin() -> float:
    """The minimiser of GELU (root of GELU' = Phi(z) + z phi(z), about -0.7518)."""
    from scipy.optimize import brentq

    return float(brentq(lambda z: float(_gelu_prime(z)), -1.0, -0.5, xtol=1e-15))


def _act_interval(name: str | None, lo: np.ndarray, hi: np.ndarray):
    """Sound enclosure of the activation over ``[lo, hi]`` (elementwise)."""
    if name is None or name == "identity":
        return lo, hi
    f = activation_fn(name, np)
    flo, fhi = f(lo), f(hi)
    if name == "tanh":
        return _down(flo), _up(fhi)
    # GELU: decreasing on (-inf, z*], increasing on [z*, inf)
    zs = _gelu_argmin()
    gmin = 0.5 * zs * (1.0 + erf(zs / _SQRT2))
    ymin = np.where(hi <= zs, fhi, np.where(lo >= zs, flo, gmin))
    ymax = np.maximum(flo, fhi)
    # a wrong z* by dz changes gmin by O(dz^2): 1e-14 absolute slack covers xtol=1e-15
    return _down(ymin) - 1e-14 * (lo < zs) * (hi > zs), _up(ymax)


def _act_prime_interval(name: str | None, lo: np.ndarray, hi: np.ndarray):
    """Sound enclosure of ``s'`` over ``[lo, hi]`` (elementwise)."""
    if name is None or name == "identity":
        return np.ones_like(lo), np.ones_like(hi)
    if name == "tanh":
        # tanh' is even, increasing on (-inf, 0], decreasing on [0, inf)
        plo, phi = _tanh_prime(lo), _tanh_prime(hi)
        dmin = np.minimum(plo, phi)
        dmax = np.where((lo <= 0.0) & (hi >= 0.0), 1.0, np.maximum(plo, phi))
        return np.maximum(_down(dmin), 0.0), np.minimum(_up(dmax), 1.0)
    if name == "gelu":
        # GELU' decreases on (-inf, -sqrt2], increases on [-sqrt2, sqrt2], decreases after
        plo, phi = _gelu_prime(lo), _gelu_prime(hi)
        gmin = _gelu_prime(-_SQRT2)
        gmax = _gelu_prime(_SQRT2)
        dmin = np.where((lo <= -_SQRT2) & (hi >= -_SQRT2), gmin, np.minimum(plo, phi))
        dmax = np.where((lo <= _SQRT2) & (hi >= _SQRT2), gmax, np.maximum(plo, phi))
        return _down(dmin), _up(dmax)
    raise SpecError(f"activation {name!r} is not supported", field="activation")


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
    """Enclosure of ``W J`` for a point matrix ``W`` and an interval matrix ``J`` (batched)."""
    m, r = _mid_rad(jlo, jhi)
    c = w @ m
    aw = np.abs(w)
    rad = aw @ r
    err = 2.0 * _gamma(w.shape[1] + 2) * (aw @ (np.abs(m) + r))
    return _down(c - rad - err), _up(c + rad + err)


def _interval_scale_rows(dlo, dhi, mlo, mhi):
    """Enclosure of ``diag(d) M`` for interval ``d`` (``(..., k)``) and interval ``M``
    (``(..., k, n)``)."""
    dlo = dlo[..., :, None]
    dhi = dhi[..., :, None]
    p = np.stack([dlo * mlo, dlo * mhi, dhi * mlo, dhi * mhi])
    return _down(p.min(axis=0)), _up(p.max(axis=0))


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
