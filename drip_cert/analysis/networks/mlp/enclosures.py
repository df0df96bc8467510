"""Interval enclosures of an MLP's value and Jacobian over boxes (interval bound propagation).

Affine layers use the centre-radius product with a rigorous rounding term
(:func:`~drip_cert.numerics.interval_np.affine_enclosure`); each activation encloses its values
and (Clarke) slopes over the pre-activation interval (:mod:`drip_cert.model.activations`:
library functions widened by their documented error budgets, cancellation-free forms such as
``sech^2 = 4 e^{-2|z|} / (1 + e^{-2|z|})^2`` and ``GELU = z Phi(z)``). Sound as long as numpy and
scipy meet their documented accuracy (:mod:`drip_cert.numerics.rounding`). For piecewise-linear
networks the Jacobian enclosure contains the Clarke generalized Jacobian
(docs/math/nonsmooth.md). :func:`jacobian_np` is a float point Jacobian (an estimate).
"""

from __future__ import annotations

import numpy as np

from drip_cert.errors import SpecError
from drip_cert.model.activations import Activation, get_activation
from drip_cert.model.mlp import MLP
from drip_cert.numerics.interval_np import affine_enclosure, matmul_point_left, scale_rows

__all__ = [
    "check_box",
    "enclose_activation",
    "enclose_activation_prime",
    "enclose_jacobian",
    "enclose_output",
    "jacobian_np",
]


def enclose_activation(name: str | Activation | None, lo, hi) -> tuple[np.ndarray, np.ndarray]:
    """Sound enclosure of the activation over ``[lo, hi]`` (:meth:`Activation.enclose`)."""
    return get_activation(name).enclose(lo, hi)


def enclose_activation_prime(
    name: str | Activation | None, lo, hi
) -> tuple[np.ndarray, np.ndarray]:
    """Sound enclosure of the (Clarke) slopes over ``[lo, hi]``
    (:meth:`Activation.slope_range`)."""
    return get_activation(name).slope_range(lo, hi)


def jacobian_np(mlp: MLP, x: np.ndarray) -> np.ndarray:
    """Forward-mode Jacobian of ``mlp`` at ``x`` (``(..., in)``), shape ``(..., out, in)`` (float;
    at a kink of a piecewise-linear activation, one element of the Clarke Jacobian)."""
    x = np.asarray(x, dtype=np.float64)
    z = x
    J = np.broadcast_to(np.eye(mlp.in_dim), (*x.shape[:-1], mlp.in_dim, mlp.in_dim))
    for w, bias, act in zip(mlp.weights, mlp.biases, mlp.activations):
        a = z @ w.T + bias
        J = act.prime_np(a)[..., :, None] * (w @ J)
        z = act.value_np(a)
    return J


# --------------------------------------------------------------------------- interval enclosures


def check_box(mlp: MLP, lo, hi) -> tuple[np.ndarray, np.ndarray]:
    """``(lo, hi)`` as float arrays of shape ``(..., in_dim)``, finite, ``lo <= hi``; else a
    :class:`~drip_cert.errors.SpecError` saying which entry is wrong."""
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
    shape ``(..., out)``. Affine layers use the centre-radius form with a rigorous rounding term
    (:func:`~drip_cert.numerics.interval_np.affine_enclosure`); each activation encloses its
    values over the pre-activation interval (:meth:`Activation.enclose`).
    """
    lo, hi = check_box(mlp, lo, hi)
    for w, b, act in zip(mlp.weights, mlp.biases, mlp.activations):
        lo, hi = affine_enclosure(w, b, lo, hi)
        lo, hi = act.enclose(lo, hi)
    return lo, hi


def enclose_jacobian(mlp: MLP, lo, hi) -> tuple[np.ndarray, np.ndarray]:
    """Sound elementwise enclosure ``(J_lo, J_hi)`` of the Jacobian ``d mlp / dx`` over a box.

    For every ``x`` in ``[lo, hi]``: ``J_lo <= J(x) <= J_hi`` entrywise, shape ``(..., out, in)``;
    for a piecewise-linear network every element of the Clarke generalized Jacobian at every
    ``x`` in the box lies in it too (docs/math/nonsmooth.md). Pre-activation intervals come from
    :func:`enclose_output`'s propagation; ``s'`` is enclosed over each pre-activation interval
    (:meth:`Activation.slope_range`); then ``J_{k+1} = diag(s'(a_k)) W_k J_k`` in interval
    arithmetic (centre-radius for ``W_k J_k``, four-product rule for the diagonal scaling).
    """
    lo, hi = check_box(mlp, lo, hi)
    batch = lo.shape[:-1]
    eye = np.broadcast_to(np.eye(mlp.in_dim), (*batch, mlp.in_dim, mlp.in_dim))
    jlo, jhi = eye.copy(), eye.copy()
    zlo, zhi = lo, hi
    for k, (w, b, act) in enumerate(zip(mlp.weights, mlp.biases, mlp.activations)):
        alo, ahi = affine_enclosure(w, b, zlo, zhi)
        dlo, dhi = act.slope_range(alo, ahi)
        if k == 0:
            mlo = np.broadcast_to(w, (*batch, *w.shape))
            mhi = mlo
        else:
            mlo, mhi = matmul_point_left(w, jlo, jhi)
        jlo, jhi = scale_rows(dlo, dhi, mlo, mhi)
        zlo, zhi = act.enclose(alo, ahi)
    return jlo, jhi
