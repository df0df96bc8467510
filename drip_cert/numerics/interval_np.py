"""Vectorised interval arithmetic on numpy arrays, every result rounded outward.

An interval array is a pair ``(lo, hi)`` of float64 arrays of one shape. Each function returns an
enclosure of the exact result for every choice of the operands inside their enclosures; the
rounding rules are those of :mod:`drip_cert.numerics.rounding` (one correctly rounded operation
moved one ulp outward; Higham's Thm 3.1 for dot products; library functions widened by their
documented error budgets :data:`~drip_cert.numerics.rounding.LIBM_REL` and
:func:`~drip_cert.numerics.rounding.ndtr_rel_budget`, sound as long as numpy and scipy meet them).

Contents: centre-radius forms (:func:`mid_rad`, :func:`affine_enclosure`,
:func:`matmul_point_left`, :func:`mean_value_form`), elementwise operations (:func:`imul`,
:func:`iadd`, :func:`intersect`, :func:`scale_rows`, :func:`scale_point`) and point enclosures of
the special functions the activations need (:func:`exp_bounds`, :func:`tanh_bounds`,
:func:`sech2_bounds`, :func:`Phi_bounds`, :func:`phi_bounds`, :func:`log1p_bounds`).
"""

from __future__ import annotations

import functools

import numpy as np
from flint import arb

from drip_cert.numerics.rounding import (
    LIBM_REL,
    add_down_np,
    add_up_np,
    arb_bounds,
    down_np,
    gamma,
    ndtr_rel_budget,
    sub_down_np,
    up_np,
    widen_np,
)

__all__ = [
    "Phi_bounds",
    "affine_enclosure",
    "affine_enclosure_rad",
    "exp_bounds",
    "iadd",
    "imul",
    "intersect",
    "log1p_bounds",
    "matmul_point_left",
    "mean_value_form",
    "mid_rad",
    "phi_bounds",
    "scale_point",
    "scale_rows",
    "sech2_bounds",
    "tanh_bounds",
]

TINY = 2.0**-1074
"""The smallest subnormal: the absolute unit of underflow errors."""


# --------------------------------------------------------------------------- centre-radius


def mid_rad(lo: np.ndarray, hi: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Centre and radius with ``[m - r, m + r] ⊇ [lo, hi]`` in exact arithmetic (each difference
    is one rounding, moved up)."""
    m = lo + 0.5 * (hi - lo)
    r = up_np(np.maximum(hi - m, m - lo))
    return m, r


def affine_enclosure(w: np.ndarray, b: np.ndarray, lo: np.ndarray, hi: np.ndarray):
    """Enclosure of ``W z + b`` for ``z`` in the box ``[lo, hi]`` (batched, ``(..., in)``).

    ``W z + b = (W m + b) + W (z - m)`` with ``|W (z - m)| <= |W| r``. The float ``c = W m + b``
    and ``rad = |W| r`` are within ``gamma_{k+1} (|W| |m| + |b|)`` and ``gamma_k |W| r`` of the
    exact values (Higham Thm 3.1, any summation order); ``2 gamma_{k+2}`` times the float
    ``(|m| + r) |W|^T + |b|`` covers both (and its own rounding). The two final sums are rounded
    outward one at a time.
    """
    m, r = mid_rad(lo, hi)
    c = m @ w.T + b
    aw = np.abs(w)
    rad = r @ aw.T
    k = w.shape[1]
    err = add_up_np(
        up_np(2.0 * gamma(k + 2) * ((np.abs(m) + r) @ aw.T + np.abs(b))), (k + 2) * 8 * TINY
    )
    return sub_down_np(sub_down_np(c, rad), err), add_up_np(add_up_np(c, rad), err)


def affine_enclosure_rad(
    w: np.ndarray, w_rad: np.ndarray | None, b: np.ndarray, lo: np.ndarray, hi: np.ndarray
):
    """Enclosure of ``W z + b`` for ``z`` in the box ``[lo, hi]`` and every ``W`` with
    ``|W - w| <= w_rad`` entrywise (``w_rad=None``: ``W = w``, :func:`affine_enclosure`).

    ``W z = w z + (W - w) z`` with ``|(W - w) z| <= w_rad |z|_max``, ``|z|_max`` the entrywise
    ``max(|lo|, |hi|)``; the float product of ``k`` non-negative terms is within ``gamma_k`` of
    the exact one, so ``1 + 2 gamma_{k+1}`` times it plus an underflow term covers it.
    """
    olo, ohi = affine_enclosure(w, b, lo, hi)
    if w_rad is None:
        return olo, ohi
    mag = np.maximum(np.abs(lo), np.abs(hi))
    k = w.shape[1]
    e = mag @ np.asarray(w_rad, dtype=float).T
    e = add_up_np(up_np(e * (1.0 + 2.0 * gamma(k + 1))), k * 8 * TINY)
    return sub_down_np(olo, e), add_up_np(ohi, e)


def matmul_point_left(w: np.ndarray, jlo: np.ndarray, jhi: np.ndarray):
    """Enclosure of ``W J`` for a point matrix ``W`` and an interval matrix ``J`` (batched); the
    rounding terms as in :func:`affine_enclosure`."""
    m, r = mid_rad(jlo, jhi)
    c = w @ m
    aw = np.abs(w)
    rad = aw @ r
    k = w.shape[1]
    err = add_up_np(up_np(2.0 * gamma(k + 2) * (aw @ (np.abs(m) + r))), (k + 2) * 8 * TINY)
    return sub_down_np(sub_down_np(c, rad), err), add_up_np(add_up_np(c, rad), err)


def mean_value_form(clo, chi, dlo, dhi, r):
    """Mean-value enclosure ``[c] + [D] [-r, r]`` summed over the last axis of ``D``.

    ``c`` has shape ``(..., m)``, ``D`` ``(..., m, d)``, ``r`` ``(..., d)`` (radii, ``>= 0``).
    ``|[D] [-r, r]| <= |D|_max r``; the float dot product ``|D|_max r`` of ``d`` non-negative
    terms is within ``gamma_d`` of the exact one, so ``2 gamma_{d+1}`` times it plus an underflow
    term covers it; the centre is enclosed by ``[c]``.
    """
    mag = np.maximum(np.abs(dlo), np.abs(dhi))
    d = mag.shape[-1]
    rad = np.einsum("...md,...d->...m", mag, r)
    rad = add_up_np(up_np(rad * (1.0 + 2.0 * gamma(d + 1))), d * 8 * TINY)
    return sub_down_np(clo, rad), add_up_np(chi, rad)


# --------------------------------------------------------------------------- elementwise


def imul(alo, ahi, blo, bhi):
    """Enclosure of ``a * b`` for intervals (elementwise, broadcasting): the four end products,
    each one rounding, moved outward.

    When one factor is non-negative everywhere (a slope ``s' >= 0``, a square), two products per
    end suffice: for ``a >= 0`` the product is non-decreasing in ``b``, so its minimum over the
    box is ``min(alo blo, ahi blo)`` and its maximum ``max(alo bhi, ahi bhi)``; rounding to
    nearest is monotone, so these are also the float minimum and maximum of the four rounded
    products (the same floats; where a product of the four is NaN, e.g. ``0 * inf``, the
    generic form returns NaN and this one the bound of the other two, both sound).
    """
    if np.all(alo >= 0.0):
        lo, hi = np.minimum(alo * blo, ahi * blo), np.maximum(alo * bhi, ahi * bhi)
    elif np.all(blo >= 0.0):
        lo, hi = np.minimum(alo * blo, alo * bhi), np.maximum(ahi * blo, ahi * bhi)
    else:
        p1, p2, p3, p4 = alo * blo, alo * bhi, ahi * blo, ahi * bhi
        lo = np.minimum(np.minimum(p1, p2), np.minimum(p3, p4))
        hi = np.maximum(np.maximum(p1, p2), np.maximum(p3, p4))
    return down_np(lo), up_np(hi)


def iadd(alo, ahi, blo, bhi):
    """Enclosure of ``a + b`` (one rounding per end, moved outward)."""
    return add_down_np(alo, blo), add_up_np(ahi, bhi)


def intersect(alo, ahi, blo, bhi):
    """Intersection of two enclosures of the same quantity (both sound, so is this)."""
    return np.maximum(alo, blo), np.minimum(ahi, bhi)


def scale_rows(dlo, dhi, mlo, mhi):
    """Enclosure of ``diag(d) M`` for interval ``d`` (``(..., k)``) and interval ``M``
    (``(..., k, n)``): the four end products, each one rounding, moved outward."""
    return imul(dlo[..., :, None], dhi[..., :, None], mlo, mhi)


def scale_point(z: np.ndarray, lo: np.ndarray, hi: np.ndarray):
    """Enclosure of ``z * v`` for float points ``z`` and ``v`` in ``[lo, hi]``."""
    pos = z >= 0
    return (
        down_np(np.where(pos, z * lo, z * hi)),
        up_np(np.where(pos, z * hi, z * lo)),
    )


# --------------------------------------------------------------------------- special functions


@functools.cache
def _inv_sqrt_2pi() -> tuple[float, float]:
    return arb_bounds(1 / (2 * arb.pi()).sqrt())


def exp_bounds(x: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Enclosure of ``exp(x)`` at float points ``x`` (numpy ``exp`` widened by ``LIBM_REL``)."""
    with np.errstate(over="ignore"):
        y = np.exp(x)
    # an overflowed exp means the exact value exceeds (within the budget) the largest float
    big = np.isinf(y)
    lo, hi = widen_np(np.where(big, np.finfo(np.float64).max, y), LIBM_REL)
    return np.maximum(lo, 0.0), np.where(big, np.inf, hi)


def log1p_bounds(x: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Enclosure of ``log(1 + x)`` at float points ``x >= 0`` (numpy ``log1p`` widened)."""
    lo, hi = widen_np(np.log1p(x), LIBM_REL)
    return np.maximum(lo, 0.0), hi


def tanh_bounds(x: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Enclosure of ``tanh(x)`` at float points (numpy ``tanh`` widened, clipped to [-1, 1])."""
    lo, hi = widen_np(np.tanh(x), LIBM_REL)
    return np.clip(lo, -1.0, 1.0), np.clip(hi, -1.0, 1.0)


def Phi_bounds(z: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Enclosure of the normal CDF ``Phi(z)`` (scipy ``ndtr``: ``erfc`` in the tails, no
    cancellation) widened by its error budget
    :func:`~drip_cert.numerics.rounding.ndtr_rel_budget`."""
    from scipy.special import ndtr  # scipy: 0.13 CPU-s to import, only GELU bounds need it

    lo, hi = widen_np(ndtr(z), ndtr_rel_budget(z))
    return np.clip(lo, 0.0, 1.0), np.clip(hi, 0.0, 1.0)


def phi_bounds(z: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Enclosure of the normal density ``exp(-z^2/2) / sqrt(2 pi)``: ``z^2/2`` rounded both
    ways, ``exp`` decreasing in it, ``1/sqrt(2 pi)`` from Arb."""
    c_lo, c_hi = _inv_sqrt_2pi()
    zz = z * z
    h_lo = down_np(0.5 * down_np(zz))
    h_hi = up_np(0.5 * up_np(zz))
    e_lo, _ = exp_bounds(-h_hi)
    _, e_hi = exp_bounds(-h_lo)
    return down_np(e_lo * c_lo), up_np(e_hi * c_hi)


def sech2_bounds(a: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Enclosure of ``tanh'(a) = sech^2(a) = 4 e / (1 + e)^2``, ``e = exp(-2a)``, for ``a >= 0``.

    ``2a`` is exact, ``e`` is enclosed in ``[0, 1]``, and ``4e / (1 + e)^2`` increases with ``e``
    there, so the ends come from the ends of ``e`` with every operation rounded outward. No
    cancellation: the relative accuracy is that of ``exp`` for every ``a`` (``1 - tanh^2`` is 0
    in float for ``a > 19``, where ``sech^2 a > 1e-17``).
    """
    e_lo, e_hi = exp_bounds(-2.0 * a)
    e_lo, e_hi = np.clip(e_lo, 0.0, 1.0), np.clip(e_hi, 0.0, 1.0)
    d_hi = up_np(1.0 + e_lo)
    d_lo = down_np(1.0 + e_hi)
    lo = down_np(4.0 * e_lo / up_np(d_hi * d_hi))
    hi = up_np(4.0 * e_hi / down_np(d_lo * d_lo))
    return np.clip(lo, 0.0, 1.0), np.clip(hi, 0.0, 1.0)
