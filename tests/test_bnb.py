"""The one branch and bound (drip_cert.numerics.bnb): closed-form maxima, soundness, budgets.

The upper-bound functions are rigorous interval enclosures (drip_cert.numerics.interval), so the
certified bound must never be below the true maximum; a deliberately wrong upper-bound function
(the value at the centre) shows that the sampled soundness check used here can fail.
"""

from __future__ import annotations

import math
from collections.abc import Callable

import numpy as np
import pytest
import sympy as sp
from hypothesis import given, settings
from hypothesis import strategies as st

from drip_cert.numerics.bnb import BnbResult, maximize
from drip_cert.numerics.interval import compile_enclosure

#: absolute stopping tolerance of the converging searches
TOL = 1e-6
#: numpy's own rounding of a sampled value of these O(10) expressions (absolute)
EVAL_SLACK = 1e-12
#: points of the sampled soundness check
N_SAMPLES = 20_000
#: a maximum known to TOL in value locates a quadratic peak only to ~sqrt(TOL) = 1e-3 in x
ARGMAX_TOL = 1e-2
#: a stopping tolerance no search reaches in a few boxes: only the box budget stops it
UNREACHABLE_ATOL = 1e-12
#: no stopping tolerance at all: only a budget stops the search
NO_ATOL = 0.0
#: a tolerance the first box meets at once (upper 0 - lower -0.25 <= 0.5)
MET_AT_ONCE_ATOL = 0.5

x, y = sp.symbols("x y", real=True)


def _search(expr, variables, box, **kw) -> tuple[BnbResult, Callable]:
    """Branch and bound of ``expr`` with its natural interval extension as the upper bound."""
    enc = compile_enclosure(expr, variables)
    f = sp.lambdify(variables, expr, "numpy")

    def upper(b: np.ndarray) -> float:
        return enc([(float(lo), float(hi)) for lo, hi in b])[1]

    def value(p: np.ndarray) -> float:
        return float(f(*p))

    return maximize(box, upper, value, **kw), f


def _sampled_max(f, box, seed: int = 0) -> float:
    """Largest value of ``f`` at random points and at the corners of ``box``."""
    box = np.asarray(box, dtype=float)
    rng = np.random.default_rng(seed)
    pts = box[:, 0] + rng.random((N_SAMPLES, len(box))) * (box[:, 1] - box[:, 0])
    vals = np.asarray(f(*pts.T), dtype=float)
    return float(np.max(vals))


def _is_sound(res: BnbResult, f, box) -> bool:
    """The check: no sampled value above the certified bound (up to evaluation rounding)."""
    return _sampled_max(f, box) <= res.upper + EVAL_SLACK


# --------------------------------------------------------------------- closed-form maxima
def test_concave_quadratic_1d_reaches_its_maximum():
    # 1 - (x - 0.3)^2 on [-1, 2]: maximum 1 at x = 0.3
    res, f = _search(1 - (x - sp.Rational(3, 10)) ** 2, [x], [(-1.0, 2.0)], atol=TOL)
    assert res.converged and res.stop == "converged"
    assert 1.0 <= res.upper <= 1.0 + TOL
    assert res.lower <= 1.0 and abs(res.argmax[0] - 0.3) < ARGMAX_TOL
    assert _is_sound(res, f, [(-1.0, 2.0)])


def test_concave_quadratic_2d_reaches_its_maximum():
    # 3 - (x - 1/2)^2 - 2 (y + 1/4)^2 on [-2, 2]^2: maximum 3 at (1/2, -1/4)
    expr = 3 - (x - sp.Rational(1, 2)) ** 2 - 2 * (y + sp.Rational(1, 4)) ** 2
    box = [(-2.0, 2.0), (-2.0, 2.0)]
    res, f = _search(expr, [x, y], box, atol=TOL, max_boxes=50_000)
    assert res.converged
    assert 3.0 <= res.upper <= 3.0 + TOL
    assert res.gap <= TOL
    assert _is_sound(res, f, box)


def test_abs_sin_has_maximum_one():
    # |sin x| on [0, 10]: maximum 1 (at pi/2, 3 pi/2, 5 pi/2); the enclosure of sin checks for
    # interior extrema with a rigorous pi, so the bound is 1 to the last ulp
    res, f = _search(sp.Abs(sp.sin(x)), [x], [(0.0, 10.0)], atol=TOL, corners=True)
    assert res.converged and 1.0 <= res.upper <= 1.0 + TOL
    assert min(abs(res.argmax[0] - k * math.pi / 2) for k in (1, 3, 5)) < ARGMAX_TOL


@settings(max_examples=25, deadline=None)
@given(
    a=st.floats(0.1, 5.0),
    c=st.floats(-3.0, 3.0),
    d=st.floats(-2.0, 2.0),
    lo=st.floats(-4.0, 0.0),
    w=st.floats(0.1, 6.0),
)
def test_upper_bound_is_never_below_sampled_values(a, c, d, lo, w):
    # a random concave quadratic plus a wiggle, on a random interval; whether or not the search
    # converges, the certified bound is never below a sampled value
    expr = -a * (x - c) ** 2 + d * sp.sin(3 * x)
    box = [(lo, lo + w)]
    res, f = _search(expr, [x], box, atol=TOL, max_boxes=400)
    assert _is_sound(res, f, box)
    assert res.lower <= res.upper


def test_a_wrong_upper_bound_function_is_caught_by_the_check():
    # the value at the centre is not an upper bound: the search "converges" to a number below the
    # true maximum (the centre of the initial box, 0 here, is far from the maximiser 0.9), and
    # the sampled check fails
    expr = 1 - (x - sp.Rational(9, 10)) ** 2
    f = sp.lambdify([x], expr, "numpy")

    def wrong_upper(b: np.ndarray) -> float:
        return float(f(0.5 * (b[0, 0] + b[0, 1])))

    res = maximize([(-1.0, 1.0)], wrong_upper, None, atol=TOL, max_boxes=3)
    assert not _is_sound(res, f, [(-1.0, 1.0)])
    good, _ = _search(expr, [x], [(-1.0, 1.0)], atol=TOL)
    assert _is_sound(good, f, [(-1.0, 1.0)])


# ------------------------------------------------------------------------------ budgets
def test_box_budget_is_reported_and_the_bound_stays_sound():
    expr = 3 - (x - sp.Rational(1, 2)) ** 2 - 2 * (y + sp.Rational(1, 4)) ** 2
    box = [(-2.0, 2.0), (-2.0, 2.0)]
    res, f = _search(expr, [x, y], box, atol=UNREACHABLE_ATOL, max_boxes=9)
    assert res.stop == "max_boxes" and not res.converged
    assert res.n_boxes == 9  # 1 + 2 splits per step, 4 splits
    assert res.upper >= 3.0 and _is_sound(res, f, box)


def test_time_budget_is_reported():
    res, _ = _search(1 - x**2, [x], [(-1.0, 1.0)], atol=NO_ATOL, max_time_s=0.0)
    assert res.stop == "max_time" and not res.converged and res.upper >= 1.0


def test_too_thin_box_stops_the_search():
    # an upper bound that never tightens (true value + 1): the search stops at min_width
    f = sp.lambdify([x], 1 - x**2, "numpy")
    res = maximize(
        [(-1.0, 1.0)],
        lambda b: 2.0,
        lambda p: float(f(*p)),
        atol=TOL,
        min_width=1e-3,
        max_boxes=100_000,
    )
    assert res.stop == "min_width" and not res.converged and res.upper == 2.0
    assert res.n_boxes < 100_000


# ------------------------------------------------------------------------------ options
def test_inactive_variable_is_never_split_and_nan_upper_reads_as_inf():
    seen: list[np.ndarray] = []

    def upper(b: np.ndarray) -> float:
        seen.append(b.copy())
        return math.nan if b[0, 1] - b[0, 0] > 1.0 else 1.0 - max(0.0, b[0, 0]) ** 2

    res = maximize(
        [(0.0, 4.0), (-1.0, 1.0)], upper, None, atol=TOL, max_boxes=200, active=[True, False]
    )
    assert all(np.array_equal(b[1], [-1.0, 1.0]) for b in seen)
    # the NaN boxes (width > 1) are split first, as if their bound were infinite
    assert math.isfinite(res.upper) and res.upper >= 1.0


def test_initial_value_replaces_sampling_of_the_first_box():
    calls: list[np.ndarray] = []

    def value(p: np.ndarray) -> float:
        calls.append(p)
        return -1.0

    res = maximize(
        [(0.0, 1.0)],
        lambda b: 0.0,
        value,
        atol=MET_AT_ONCE_ATOL,
        initial=(-0.25, [0.3]),
        max_boxes=1,
    )
    assert not calls and res.lower == -0.25 and res.argmax == (0.3,) and res.converged


def test_result_rejects_an_unknown_stop_reason():
    with pytest.raises(ValueError, match="stop"):
        BnbResult(1.0, 0.0, None, 1, False, "tired")
