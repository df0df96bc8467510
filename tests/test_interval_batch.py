"""The batched interval evaluator (drip_cert.numerics.interval_batch) and the batched branch and
bound: every enclosure holds the exact values (Arb at random points of random boxes), contains the
scalar evaluator's enclosure (up to the rounding paths' difference), and the batched search gives
the scalar search's supremum within its stopping rule.
"""

from __future__ import annotations

import numpy as np
import pytest
import sympy as sp
from flint import arb, ctx

from drip_cert.analysis.growth.expr_sup import BATCHED_SPLITS_FACTOR, BNB_RTOL, expr_sup
from drip_cert.numerics.bnb import maximize
from drip_cert.numerics.interval import MatrixEnclosure, UnsupportedExpression
from drip_cert.numerics.interval_batch import BatchEnclosure, compile_batch

q, v = sp.symbols("q v", real=True)

#: boxes per expression in the random checks
N_BOXES = 400
#: random points per box where the exact value is computed in Arb
N_POINTS = 3
#: the two evaluators round along different paths (libm widened by 8 ulps against Arb at the
#: ends, repeated products against one Arb power), so the batched ends may sit a few ulps inside
#: the scalar ones; 64 ulps (relative) covers that, far below any difference that matters
CONTAIN_REL = 64 * 2.0**-52
#: libm's widening makes a batched end at most this much (relative) looser than the scalar one on
#: these expressions (8 ulps per elementary function, a few functions per path, plus the
#: mean-value terms); a looser batched evaluator would cost certificate tightness
LOOSER_REL = 1e-9
#: two sound searches with relative stopping tolerance BNB_RTOL end within twice it of each other
SUP_REL = 2 * BNB_RTOL

EXPRS = [
    (sp.Float(0.1) * sp.sin(q) + sp.Float(0.05) * sp.tanh(v)) ** 2 / (1 + q**2 + v**2),
    sp.cos(q) * sp.exp(-(v**2)) + sp.Abs(q - v) ** 3 - q**5 + sp.sqrt(1 + q**2) ** -3,
    sp.atan(q * v) + sp.cosh(v) / (2 + sp.sin(q)) + sp.log(2 + q**2) * sp.sech(v) ** 2,
    sp.Max(q, v) - sp.Min(q, 2 * v) + sp.sinh(q / 4) * (1 - sp.tanh(v) ** 2),
    (q - sp.pi) ** 4 * v ** sp.Rational(-2) + sp.Rational(1, 3) * q,
]


def _boxes(seed: int) -> np.ndarray:
    rng = np.random.default_rng(seed)
    c = rng.uniform(-6.0, 6.0, (N_BOXES, 2))
    w = 10.0 ** rng.uniform(-9.0, 0.7, (N_BOXES, 2))
    return np.stack([c - w, c + w], axis=-1)


def _rel(x: float, rel: float) -> float:
    """``rel |x|`` for a finite end, 0 for an infinite one."""
    return rel * abs(x) if np.isfinite(x) else 0.0


def _arb_value(expr: sp.Expr, point: np.ndarray) -> arb:
    """The exact value of ``expr`` at a float point, enclosed in Arb (sympy -> mpmath string)."""
    val = sp.N(expr.subs({q: sp.Float(point[0], 30), v: sp.Float(point[1], 30)}), 40)
    return arb(str(val))


@pytest.mark.parametrize("k", range(len(EXPRS)))
def test_batched_enclosure_holds_the_exact_values(k):
    expr = EXPRS[k]
    boxes = _boxes(k)
    lo, hi = BatchEnclosure(expr, [q, v])(boxes)
    rng = np.random.default_rng(100 + k)
    ctx.prec = 200
    try:
        checked = 0
        for i in range(0, N_BOXES, 8):  # Arb is slow: every 8th box
            if np.isnan(lo[i]):
                continue
            for _ in range(N_POINTS):
                p = boxes[i, :, 0] + rng.random(2) * (boxes[i, :, 1] - boxes[i, :, 0])
                try:
                    e = _arb_value(expr, p)
                except (ValueError, TypeError):
                    continue
                if not e.is_finite():
                    continue
                assert arb(lo[i]) <= e <= arb(hi[i]), (expr, boxes[i], lo[i], hi[i], e)
                checked += 1
        assert checked > N_BOXES // 8
    finally:
        ctx.prec = 53


@pytest.mark.parametrize("k", range(len(EXPRS)))
def test_batched_enclosure_contains_the_scalar_one(k):
    expr = EXPRS[k]
    boxes = _boxes(50 + k)
    blo, bhi = BatchEnclosure(expr, [q, v])(boxes)
    enc = MatrixEnclosure(sp.Matrix([[expr]]), [q, v])
    n_cmp = 0
    for i, b in enumerate(boxes):
        try:
            slo, shi = (float(a[0, 0]) for a in enc(b))
        except UnsupportedExpression:
            continue
        if np.isnan(blo[i]):
            continue  # no information: contains everything
        n_cmp += 1
        assert blo[i] <= slo + _rel(slo, CONTAIN_REL), (b, blo[i], slo)
        assert bhi[i] >= shi - _rel(shi, CONTAIN_REL), (b, bhi[i], shi)
        if np.isfinite(shi) and np.isfinite(slo):
            scale = max(abs(shi), abs(slo), shi - slo, 1.0)
            assert bhi[i] - shi <= LOOSER_REL * scale, (b, bhi[i], shi)
            assert slo - blo[i] <= LOOSER_REL * scale, (b, blo[i], slo)
    assert n_cmp > N_BOXES // 2


#: the point enclosure's ends sit within a few roundings of the float value (8 ulps of libm
#: widening per elementary function, one ulp per outward-rounded operation, ~10 of each here)
POINT_REL = 1e-12


@pytest.mark.parametrize("k", range(len(EXPRS)))
def test_point_enclosures_hold_the_exact_value_tightly(k):
    """``at_points`` (the lower values of the batched sup search): lo <= exact value <= hi in
    Arb, and both ends within POINT_REL of it (a lower value that is a bound, not a guess)."""
    expr = EXPRS[k]
    rng = np.random.default_rng(200 + k)
    pts = rng.uniform(-6.0, 6.0, (40, 2))
    lo, hi = BatchEnclosure(expr, [q, v]).at_points(pts)
    ctx.prec = 200
    try:
        checked = 0
        for p, a, b in zip(pts, lo, hi):
            e = _arb_value(expr, p)
            if np.isnan(a) or not e.is_finite():
                continue
            assert arb(a) <= e <= arb(b), (expr, p, a, b, e)
            scale = max(abs(float(e.mid())), 1e-300)
            assert b - a <= POINT_REL * scale + 1e-300, (expr, p, a, b)
            checked += 1
        assert checked >= 30
    finally:
        ctx.prec = 53


def test_batched_domain_violations_give_no_information():
    f = compile_batch(sp.log(q) + sp.sqrt(v), [q, v])
    boxes = np.array(
        [[[1.0, 2.0], [0.0, 1.0]], [[-1.0, 2.0], [0.0, 1.0]], [[1.0, 2.0], [-1.0, 1.0]]]
    )
    lo, hi = BatchEnclosure(sp.log(q) + sp.sqrt(v), [q, v])(boxes)
    assert np.isfinite(lo[0]) and np.isfinite(hi[0])
    assert np.isnan(hi[1:]).all() and np.isnan(lo[1:]).all()
    assert np.isfinite(f(boxes[:1])[1]).all()


def test_unsupported_node_falls_back_to_the_scalar_search():
    h = sp.Function("h")
    with pytest.raises(UnsupportedExpression):
        compile_batch(h(q) + q, [q])
    with pytest.raises(UnsupportedExpression):
        compile_batch(sp.erf(q), [q])
    # expr_sup still answers through the scalar evaluator
    res = expr_sup([sp.erf(q)], [q], [(-1.0, 1.0)])
    assert res.converged and res.upper >= float(sp.erf(1))


@pytest.mark.parametrize("k", range(len(EXPRS)))
def test_batched_sup_agrees_with_the_scalar_search(k):
    expr = EXPRS[k]
    box = [(0.5, 2.0), (0.3, 1.7)]
    a = expr_sup([expr], [q, v], box, max_splits=600)
    b = expr_sup([expr], [q, v], box, max_splits=600, batched=False)
    assert a.n_boxes <= 1 + 2 * BATCHED_SPLITS_FACTOR * 600
    # each upper bound is sound, so it is above the other's sampled value
    assert a.upper >= b.lower and b.upper >= a.lower
    if a.converged and b.converged:
        assert abs(a.upper - b.upper) <= SUP_REL * abs(b.upper) + 2e-12


def test_one_box_rounds_reproduce_the_scalar_driver_bit_for_bit():
    expr = EXPRS[1]
    enc = BatchEnclosure(expr, [q, v])
    f = sp.lambdify([q, v], expr, "numpy")
    box = np.array([(0.5, 2.0), (0.3, 1.7)])

    def upper_many(bs):
        return enc(bs)[1]

    def value_many(ps):
        return f(ps[:, 0], ps[:, 1])

    def upper(b):
        return float(enc(b[None])[1][0])

    def value(p):
        return float(f(p[0], p[1]))

    kw = dict(atol=1e-12, rtol=1e-9, max_boxes=301, corners=True, prefer_deep=True)
    one = maximize(box, upper, value, **kw)
    many = maximize(box, None, upper_many=upper_many, value_many=value_many, batch=1, **kw)
    assert one == many
    wide = maximize(box, None, upper_many=upper_many, value_many=value_many, batch=64, **kw)
    assert wide.n_boxes <= 301
    assert wide.upper >= one.lower and one.upper >= wide.lower
