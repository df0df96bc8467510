"""The elementwise interval product of :mod:`drip_cert.numerics.interval_np`.

``imul`` takes two products per end when one factor is non-negative everywhere; it must return
the same floats as the four-product form (rounding to nearest is monotone) and enclose every
exact product of points of the two intervals (exact rationals).
"""

from __future__ import annotations

from fractions import Fraction

import numpy as np
import pytest

from drip_cert.numerics.interval_np import imul
from drip_cert.numerics.rounding import down_np, up_np


def _four_products(alo, ahi, blo, bhi):
    """The generic form: the four end products, min / max, moved outward."""
    p = np.stack(np.broadcast_arrays(alo * blo, alo * bhi, ahi * blo, ahi * bhi))
    return down_np(p.min(axis=0)), up_np(p.max(axis=0))


def _interval(rng, shape, sign: str):
    """Random intervals: ``"pos"`` (lo >= 0, zero ends included), ``"mixed"``."""
    a, b = rng.normal(size=shape) * 10.0 ** rng.integers(-3, 4, shape), rng.normal(size=shape)
    lo, hi = np.minimum(a, b), np.maximum(a, b)
    if sign == "pos":
        lo, hi = np.abs(lo), np.abs(lo) + np.abs(hi)
        lo[..., 0] = 0.0
    return lo, hi


@pytest.mark.parametrize("signs", [("pos", "mixed"), ("mixed", "pos"), ("mixed", "mixed")])
def test_imul_equals_the_four_products_and_encloses_exact_products(signs):
    rng = np.random.default_rng(7)
    alo, ahi = _interval(rng, (300, 6), signs[0])
    blo, bhi = _interval(rng, (300, 6), signs[1])
    lo, hi = imul(alo, ahi, blo, bhi)
    want_lo, want_hi = _four_products(alo, ahi, blo, bhi)
    assert np.array_equal(lo, want_lo) and np.array_equal(hi, want_hi)
    for _ in range(3):  # exact products of points of the intervals (ends and inside)
        ta, tb = rng.uniform(size=alo.shape), rng.uniform(size=blo.shape)
        ta[:, 0], tb[:, 1] = 0.0, 1.0
        xa, xb = alo + ta * (ahi - alo), blo + tb * (bhi - blo)
        xa, xb = np.clip(xa, alo, ahi), np.clip(xb, blo, bhi)
        for i, j in zip(*np.nonzero(np.ones(alo.shape, bool)), strict=True):
            exact = Fraction(float(xa[i, j])) * Fraction(float(xb[i, j]))
            assert Fraction(float(lo[i, j])) <= exact <= Fraction(float(hi[i, j]))


def test_imul_broadcasts_a_non_negative_row_factor():
    """The diagonal scaling of a Jacobian by slopes in [0, 1] (the case the fast form is for):
    broadcasting shapes as ``scale_rows`` uses them, the same floats as the four products."""
    rng = np.random.default_rng(8)
    slo = rng.uniform(0.0, 0.5, size=(50, 8, 1))
    shi = slo + rng.uniform(0.0, 0.5, size=(50, 8, 1))
    mlo, mhi = _interval(rng, (50, 8, 5), "mixed")
    lo, hi = imul(slo, shi, mlo, mhi)
    want_lo, want_hi = _four_products(slo, shi, mlo, mhi)
    assert lo.shape == (50, 8, 5)
    assert np.array_equal(lo, want_lo) and np.array_equal(hi, want_hi)
