"""Lipschitz constants of an MLP and of its Jacobian (DRIP Assumption "PolicyRegularity").

``L_pi`` bounds the Lipschitz constant of a policy and ``L_dpi`` the Lipschitz constant of its
Jacobian (equivalently, the second-order Taylor remainder
``||pi(z) - pi(z0) - dpi(z0)(z - z0)|| <= L_dpi/2 ||z - z0||^2``). For the TaSIL certificate
(docs/math/tasil.md section 3.1, assumption A2) ``L_Delta <= L_dpi(pi_hat) + L_dpi(pi_star)``.

Network convention (:class:`drip_cert.model.mlp.MLP`): ``z_0 = x``, ``a_k = W_k z_k + b_k``,
``z_{k+1} = s_k(a_k)`` with ``s_k`` the activation of layer ``k`` (:attr:`MLP.activations`, the
last one the output activation). All norms are Euclidean / spectral. Each activation class of
:mod:`drip_cert.model.activations` proves its slope range and curvature bound
(:attr:`~drip_cert.model.activations.Activation.bounds`); spectral norms are rigorous upper
bounds (:func:`~drip_cert.numerics.rounding.spectral_norm_upper`) and every product and sum of
the recursions is rounded up. A relu network is Lipschitz (Clarke slopes in ``[0, 1]``) but its
Jacobian is not: ``L_dpi = inf`` (docs/math/nonsmooth.md).
"""

from __future__ import annotations

import math

import numpy as np

from drip_cert.model.activations import Activation, ActivationBounds, get_activation
from drip_cert.model.mlp import MLP
from drip_cert.numerics.rounding import add_up, mul_up, norm2_up_np, spectral_norm_upper
from drip_cert.provenance import How, Quantity

__all__ = [
    "activation_bounds",
    "jacobian_lipschitz_bound",
    "layer_activation_bounds",
    "lipschitz_product",
    "spectral_norm_up",
]


def activation_bounds(name: str | Activation | None) -> ActivationBounds:
    """Global slope range and curvature bound of an activation (``None``: identity); the proofs
    are in the classes of :mod:`drip_cert.model.activations`."""
    return get_activation(name).bounds


def layer_activation_bounds(mlp: MLP) -> list[ActivationBounds]:
    """Activation bounds of each layer ``k = 0..L-1`` (the last is the output activation)."""
    return [a.bounds for a in mlp.activations]


def spectral_norm_up(w: np.ndarray) -> float:
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
    for w, act in zip(mlp.weights, layer_activation_bounds(mlp)):
        value = mul_up(value, mul_up(act.abs_slope, spectral_norm_up(w)))
    return Quantity(
        "L_pi",
        value,
        How.SOUND,
        "DRIP Assumption PolicyRegularity (a)",
        f"product of spectral norms times sup|s'| ({', '.join(mlp.activation_specs)}), "
        "global on R^n",
    )


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
    if not mlp.smooth:
        rough = [a.spec for a in mlp.activations if not a.smooth]
        return Quantity(
            "L_dpi",
            math.inf,
            How.SOUND,
            "DRIP Assumption PolicyRegularity (b)",
            f"not Lipschitz: the activation {rough[0]} has a discontinuous slope",
        )
    P, Q = 1.0, 0.0
    for w, act in zip(mlp.weights, layer_activation_bounds(mlp)):
        nw = spectral_norm_up(w)
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
