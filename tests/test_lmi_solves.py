"""The metric SDP of :mod:`drip_cert.analysis.contraction.lmi`: its count of work and its answers.

A constant Jacobian with entries that are not binary fractions (``317/100``) encloses to one-ulp
intervals, and ``k`` of them give ``2^k`` vertices of a polytope that is a rounding hull; the
bisection solves on their midpoint (one LMI block per solve), a fixed number of solves set by the
bracket, and the answer is still verified in Arb on every vertex.
"""

from __future__ import annotations

import math

import clarabel
import numpy as np
import pytest
import sympy as sp

from drip_cert.analysis.contraction import lmi
from drip_cert.analysis.contraction.lognorm import mu_2, mu_2_weighted, spectral_abscissa

#: numpy re-evaluation of a verified metric at the exact matrix (rounding of eigvalsh)
RECHECK_TOL = 1e-9

x = sp.symbols("x1:5")

#: the cart-pole's learned closed loop (examples/cart_pole): constant, 8 entries not in binary
CART_POLE_J = sp.Matrix(
    [
        [0, 0, 1, 0],
        [0, 0, 0, 1],
        [
            sp.Rational(317, 100),
            sp.Rational(45149, 1000),
            sp.Rational(571, 100),
            sp.Rational(519, 50),
        ],
        [
            -sp.Rational(317, 50),
            -sp.Rational(35339, 500),
            -sp.Rational(571, 50),
            -sp.Rational(519, 25),
        ],
    ]
)


class _CountingSolver:
    """Stands in for ``clarabel.DefaultSolver``: records the cones of each solve, then solves."""

    calls: list[int] = []

    def __init__(self, P, q, A, b, cones, settings):
        type(self).calls.append(len(cones))
        self._inner = _REAL_SOLVER(P, q, A, b, cones, settings)

    def solve(self):
        return self._inner.solve()


_REAL_SOLVER = clarabel.DefaultSolver


@pytest.fixture
def counted(monkeypatch):
    _CountingSolver.calls = []
    monkeypatch.setattr(clarabel, "DefaultSolver", _CountingSolver)
    return _CountingSolver.calls


def _expected_solves(As: np.ndarray) -> int:
    """Bisection steps from the bracket of :func:`lmi.metric_rate_lmi` down to its tolerance."""
    euclid = -float(np.max(mu_2(As)))
    lo = euclid - 1e-6 * (1 + abs(euclid))
    hi = -float(np.max(spectral_abscissa(As)))
    return max(0, math.ceil(math.log2((hi - lo) / lmi.DEFAULT_BISECTION_TOL)))


def test_rounding_hull_of_a_constant_jacobian_is_solved_as_one_lmi_block(counted):
    box = np.array([[-1.0, 1.0]] * 4)
    m = lmi.contraction_metric(CART_POLE_J, list(x), box)
    assert m.n_vertices == 2**8  # 8 entries enclosed to one-ulp intervals
    V = lmi.jacobian_vertices(CART_POLE_J, list(x), box)
    n = _expected_solves(V)
    assert n > 10  # a real bisection, not an empty loop
    # the count of work: a fixed number of solves, each on P >= I, P <= kappa I and ONE LMI block
    assert counted == [3] * n
    assert f"{n} SDP solves on 1 of 256 vertices" in m.note
    # the answer: verified in Arb on every vertex, and it holds at the exact matrix
    assert lmi.verify_metric(V, m.P, m.metric_rate)
    A = np.array(CART_POLE_J.evalf(30).tolist(), dtype=float)
    assert mu_2_weighted(A, m.P) <= -m.metric_rate + RECHECK_TOL
    assert m.metric_rate <= -spectral_abscissa(A)


def test_same_inputs_same_metric_bit_for_bit():
    V = lmi.jacobian_vertices(CART_POLE_J, list(x), np.array([[-1.0, 1.0]] * 4))
    r1, P1, _ = lmi.metric_rate_lmi(V)
    r2, P2, _ = lmi.metric_rate_lmi(V)
    assert r1 == r2 and np.array_equal(P1, P2)


def test_genuine_variation_is_kept_and_every_vertex_verifies(counted):
    # two vertices that differ in a real way (entry (0, 1) in [1, 3]) and a one-ulp entry (1, 0)
    base = np.array([[-1.0, 1.0], [0.1, -2.0]])
    As = np.stack([base.copy() for _ in range(4)])
    As[2:, 0, 1] = 3.0
    As[1::2, 1, 0] = np.nextafter(0.1, 1.0)
    red, margin = lmi._solve_set(As, lmi.DEFAULT_KAPPA)
    assert len(red) == 2 and margin > lmi._MARGIN
    assert sorted(red[:, 0, 1]) == [1.0, 3.0]
    rate, P, _ = lmi.metric_rate_lmi(As)
    assert set(counted) == {4}  # 2 normalisation blocks + the 2 kept matrices
    assert lmi.verify_metric(As, P, rate)
    # mu_{2,P} <= -rate on the segment between the vertices (the LMI is affine in A)
    for s in np.linspace(0.0, 1.0, 11):
        A = (1 - s) * As[0] + s * As[3]
        assert mu_2_weighted(A, P) <= -rate + RECHECK_TOL
    # nothing thin: the set is unchanged
    same, m0 = lmi._solve_set(As[[0, 2]], lmi.DEFAULT_KAPPA)
    assert np.array_equal(same, As[[0, 2]]) and m0 == lmi._MARGIN
