"""Rigorous interval enclosures: containment (property test), exact cases, domains, callbacks."""

from __future__ import annotations

from fractions import Fraction

import mpmath as mp
import numpy as np
import pytest
import sympy as sp
from hypothesis import given, settings
from hypothesis import strategies as st

from drip_cert.numerics.interval import (
    MatrixEnclosure,
    UnsupportedExpression,
    cancellation_free,
    compile_enclosure,
    enclose_expr,
    opaque_functions,
)

#: numpy's own rounding of a sampled value of a depth-<=4 expression (relative, generous)
EVAL_SLACK = 1e-12
#: a tight enclosure of a monotone function at exact float endpoints is off by a few ulps
TIGHT = 1e-14
#: mean-value form: halving the box must shrink the overestimation by ~4; allow 0.35
QUADRATIC_RATIO = 0.35

x, y = sp.symbols("x y")

_UNARY = [
    sp.sin,
    sp.cos,
    sp.tanh,
    sp.atan,
    sp.Abs,
    lambda e: sp.exp(sp.sin(e)),
    lambda e: sp.sqrt(e**2 + 1),
    lambda e: sp.log(e**2 + 1),
    lambda e: e**2,
    lambda e: e**3,
    lambda e: sp.cosh(sp.tanh(e)),
    lambda e: 1 / (e**2 + sp.Rational(1, 2)),
]
_BINARY = [
    lambda a, b: a + b,
    lambda a, b: a - b,
    lambda a, b: a * b,
    lambda a, b: sp.Max(a, b),
    lambda a, b: sp.Min(a, b),
]

_leaves = st.sampled_from(
    [x, y, sp.Integer(2), sp.Rational(-3, 7), sp.Float(0.3), sp.pi, sp.Integer(-1)]
)


def _extend(children):
    return st.one_of(
        st.tuples(st.sampled_from(range(len(_UNARY))), children).map(lambda p: _UNARY[p[0]](p[1])),
        st.tuples(st.sampled_from(range(len(_BINARY))), children, children).map(
            lambda p: _BINARY[p[0]](p[1], p[2])
        ),
    )


_exprs = st.recursive(_leaves, _extend, max_leaves=6)
_bounds = st.floats(-3.0, 3.0, allow_nan=False)


@settings(max_examples=150)
@given(expr=_exprs, a=_bounds, b=_bounds, c=_bounds, d=_bounds, seed=st.integers(0, 2**31))
def test_enclosure_never_excludes_sampled_values(expr, a, b, c, d, seed):
    box = np.array([[min(a, b), max(a, b)], [min(c, d), max(c, d)]])
    lo, hi = enclose_expr(expr, [x, y], box)
    f = sp.lambdify((x, y), expr, modules="numpy")
    rng = np.random.default_rng(seed)
    pts = box[:, 0] + rng.random((200, 2)) * np.ptp(box, axis=1)
    corners = np.array([[box[0, i], box[1, j]] for i in (0, 1) for j in (0, 1)])
    pts = np.vstack([pts, corners, box.mean(axis=1)])
    vals = np.broadcast_to(np.asarray(f(pts[:, 0], pts[:, 1]), dtype=float), (len(pts),))
    vals = vals[np.isfinite(vals)]
    slack = EVAL_SLACK * (1 + np.abs(vals))
    assert np.all(vals >= lo - slack), (expr, box, lo, vals.min())
    assert np.all(vals <= hi + slack), (expr, box, hi, vals.max())


def test_even_power_of_interval_containing_zero():
    lo, hi = enclose_expr(x**2, [x], [[-1.0, 2.0]])
    assert lo == 0.0 and 4.0 <= hi <= 4.0 * (1 + TIGHT)
    lo, hi = enclose_expr(x**4 - x**2, [x], [[-0.5, 0.5]])
    assert lo <= -0.25 and hi >= 0.0625  # natural extension: [0,1/16] - [0,1/4]
    lo, hi = enclose_expr(-(x**3), [x], [[-1.0, 2.0]])
    assert -8 * (1 + TIGHT) <= lo <= -8 and 1 <= hi <= 1 + TIGHT


def test_trigonometric_extrema_and_poles():
    lo, hi = enclose_expr(sp.sin(x), [x], [[0.0, 3.2]])
    assert hi == 1.0 and lo <= np.sin(3.2)
    lo, hi = enclose_expr(sp.sin(x), [x], [[0.1, 0.2]])
    assert lo <= np.sin(0.1) <= lo + TIGHT and hi - TIGHT <= np.sin(0.2) <= hi
    lo, hi = enclose_expr(sp.cos(x), [x], [[3.0, 3.3]])
    assert lo == -1.0
    lo, hi = enclose_expr(sp.tan(x), [x], [[1.5, 1.6]])  # contains pi/2
    assert lo == -np.inf and hi == np.inf
    lo, hi = enclose_expr(sp.tan(x), [x], [[0.0, 1.5]])
    assert hi >= np.tan(1.5) and lo <= 0.0


def test_rational_constants_are_enclosed_exactly():
    lo, hi = enclose_expr(sp.Rational(1, 3), [x], [[0.0, 0.0]])
    assert Fraction(lo) <= Fraction(1, 3) <= Fraction(hi)
    lo, hi = enclose_expr(sp.pi * x, [x], [[1.0, 1.0]])
    assert lo < np.pi < hi or lo <= np.pi <= hi


def test_domain_violations_raise():
    with pytest.raises(UnsupportedExpression, match="log"):
        enclose_expr(sp.log(x), [x], [[-1.0, 1.0]])
    with pytest.raises(UnsupportedExpression, match="sqrt"):
        enclose_expr(sp.sqrt(x), [x], [[-1.0, 1.0]])
    with pytest.raises(UnsupportedExpression, match="symbol"):
        compile_enclosure(x + y, [x])


def test_undefined_functions_need_a_callback():
    h = sp.Function("h")
    expr = 1 + h(x, 2 * y)
    with pytest.raises(UnsupportedExpression, match="h"):
        compile_enclosure(expr, [x, y])
    seen = []

    def enclose(node, args):
        seen.append((node, args))
        return (-1.0, 1.0)  # |h| <= 1, e.g. a tanh output layer

    lo, hi = enclose_expr(expr, [x, y], [[0.0, 1.0], [1.0, 2.0]], enclose=enclose)
    assert -TIGHT <= lo <= 0.0 and 2.0 <= hi <= 2.0 + TIGHT  # 1 + [-1, 1], outward-rounded
    node, args = seen[0]
    assert node.func == h and args[0] == (0.0, 1.0) and args[1][0] <= 2.0 and args[1][1] >= 4.0
    # a derivative block (Subs / Derivative forms) is passed to the callback as well
    dexpr = sp.diff(h(x, x**2), x)
    lo, hi = enclose_expr(dexpr, [x], [[0.0, 1.0]], enclose=lambda n, a: (-1.0, 1.0))
    assert lo <= -3.0 and hi >= 3.0  # |dh/dx1| + 2x |dh/dx2| <= 3
    with pytest.raises(UnsupportedExpression, match="None"):
        enclose_expr(expr, [x, y], [[0.0, 1.0], [1.0, 2.0]], enclose=lambda n, a: None)


def test_mean_value_form_converges_quadratically():
    e = x * (1 - x) + sp.sin(3 * x)
    J = sp.Matrix([[e]])
    f = sp.lambdify(x, e)
    menc = MatrixEnclosure(J, [x])
    natural = MatrixEnclosure(J, [x], mean_value=False)
    excess = []
    for h in (0.1, 0.05):
        box = np.array([[0.4 - h, 0.4 + h]])
        vals = f(np.linspace(box[0, 0], box[0, 1], 2001))
        true_w = vals.max() - vals.min()
        lo, hi = menc(box)
        nlo, nhi = natural(box)
        assert lo[0, 0] <= vals.min() and hi[0, 0] >= vals.max()
        assert hi[0, 0] - lo[0, 0] <= nhi[0, 0] - nlo[0, 0]
        excess.append((hi[0, 0] - lo[0, 0]) - true_w)
    assert excess[1] <= QUADRATIC_RATIO * excess[0]


class _Block(sp.Function):
    """A sympy Function subclass (not an AppliedUndef), like the system's block functions."""

    def fdiff(self, argindex=1):
        return _BlockD(*self.args)


class _BlockD(sp.Function):
    """Its derivative, another opaque class."""


def test_function_subclasses_go_to_the_callback():
    expr = sp.sin(x) + sp.diff(_Block(x**2), x)  # cos x + 2 x dB(x^2)
    assert opaque_functions(expr) == {_BlockD(x**2)}
    with pytest.raises(UnsupportedExpression, match="_BlockD"):
        compile_enclosure(expr, [x])
    calls = []

    def enclose(node, args):
        calls.append(node.func)
        return (0.0, 1.0) if node.func is _BlockD else None

    lo, hi = enclose_expr(expr, [x], [[0.0, 1.0]], enclose=enclose)
    assert calls == [_BlockD] and lo <= np.sin(0.0) and hi >= np.sin(1.0) + 2.0


# ------------------------------------------------------------ cancellation-free rewriting

#: mpmath reference precision (digits): the literal forms evaluated as references cancel up to
#: 40 digits (1 - tanh(45)^2 ~ 3e-39), so 120 digits leave 80 correct ones
MP_DPS = 120
#: a point enclosure of a rewritten sech^2 / erfc form is tight to the few-ulp width of its
#: argument times the condition number of the function (erfc at u = 7: 2 u^2 ~ 100; measured
#: 1.5e-13 relative for GELU(-10)): 1e-12 relative
REWRITE_REL_WIDTH = 1e-12
#: the rewritten and the literal form of one function at MP_DPS digits agree to ~80 digits (the
#: literal form loses up to 40 to cancellation); 40 digits leave room
IDENTITY_ATOL = mp.mpf(10) ** -40


def _mp_eval(expr: sp.Expr, value: float):
    with mp.workdps(MP_DPS):
        return sp.lambdify(x, expr, modules="mpmath")(mp.mpf(value))


@pytest.mark.parametrize(
    ("expr", "form"),
    [
        (sp.diff(sp.tanh(x), x), sp.sech(x) ** 2),  # sympy writes 1 - tanh(x)**2
        (3 - 3 * sp.tanh(x) ** 2, 3 * sp.sech(x) ** 2),
        (x * (1 + sp.erf(x / sp.sqrt(2))) / 2, None),  # GELU
        (1 - sp.erf(x), sp.erfc(x)),
    ],
)
def test_cancelling_forms_are_rewritten(expr, form):
    out = cancellation_free(expr)
    assert not out.has(sp.tanh) and not (out.has(sp.erf))
    if form is not None:
        assert sp.simplify(out - form) == 0
    for v in (-3.0, -0.2, 0.0, 0.7, 2.5):  # the rewrite is an identity
        assert abs(_mp_eval(out, v) - _mp_eval(expr, v)) < IDENTITY_ATOL


@pytest.mark.parametrize(
    ("expr", "z"),
    [
        (sp.diff(sp.tanh(x), x), 20.0),
        (sp.diff(sp.tanh(x), x), -40.0),
        (x * (1 + sp.erf(x / sp.sqrt(2))) / 2, -10.0),
        (sp.diff(x * (1 + sp.erf(x / sp.sqrt(2))) / 2, x), -12.0),
    ],
    ids=["tanh'(20)", "tanh'(-40)", "gelu(-10)", "gelu'(-12)"],
)
def test_enclosure_of_a_cancelling_form_is_tight(expr, z):
    exact = _mp_eval(expr, z)
    lo, hi = enclose_expr(expr, [x], [[z, z]])
    assert lo <= exact <= hi
    assert hi - lo <= REWRITE_REL_WIDTH * abs(float(exact))
    # contrast: the literal form (no rewrite) is rigorous too, but keeps no correct digit: its
    # width, that of the rounding of the terms that cancel (~1e-16 absolute), exceeds the value
    from drip_cert.numerics.interval import _compile

    llo, lhi = _compile(sp.sympify(expr), {x: 0}, None)([(z, z)])
    assert llo <= exact <= lhi and lhi - llo > abs(float(exact))


_wide = st.floats(-45.0, 45.0, allow_nan=False)


@settings(max_examples=150)
@given(a=_wide, b=_wide, u=st.floats(0.0, 1.0), k=st.integers(0, 4))
def test_new_heads_contain_mpmath_values(a, b, u, k):
    expr = [sp.sech(x), sp.erf(x), sp.erfc(x), sp.sech(x) ** 2, 1 - sp.tanh(x) ** 2][k]
    lo, hi = min(a, b), max(a, b)
    elo, ehi = enclose_expr(expr, [x], [[lo, hi]])
    for z in (lo, hi, lo + u * (hi - lo)):
        assert elo <= _mp_eval(expr, z) <= ehi


def test_constant_subexpressions_are_enclosed_in_arb():
    with mp.workdps(MP_DPS):
        exact = mp.sqrt(2) * mp.pi - mp.e
    lo, hi = enclose_expr(sp.sqrt(2) * sp.pi - sp.exp(1), [x], [[0.0, 0.0]])
    assert lo <= exact <= hi and hi - lo < REWRITE_REL_WIDTH
    # a constant with cancellation keeps its sign: pi - 355/113 = -2.67e-7
    lo, hi = enclose_expr(sp.pi - sp.Rational(355, 113), [x], [[0.0, 0.0]])
    with mp.workdps(MP_DPS):
        exact = mp.pi - mp.mpf(355) / 113
    assert lo <= exact <= hi < 0
