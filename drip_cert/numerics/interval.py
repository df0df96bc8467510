"""Rigorous interval enclosures of sympy expressions (natural extension and mean-value form).

An *interval* is a pair ``(lo, hi)`` of Python floats with ``lo <= hi`` (``-inf``/``inf`` allowed).
:func:`compile_enclosure` turns a sympy expression into a function that maps a box (one interval
per variable) to an interval that contains every value of the expression on the box. This is the
natural interval extension of the expression tree: each node is replaced by an interval operation.

Soundness of the rounding
-------------------------
* ``+ - * /`` are computed in IEEE-754 double precision, which rounds correctly to nearest;
  moving the result one ulp outward (``math.nextafter``) therefore gives a rigorous bound.
* Elementary functions (exp, log, sin, tanh, sech, erf, erfc, ...) are evaluated with
  python-flint's ``arb`` balls (Arb, rigorous error bounds) at the interval's endpoints; the
  ball's lower/upper end is converted to a float and moved one ulp outward. Monotone functions
  take their extremes at the endpoints; sin/cos also check (with a rigorous enclosure of pi)
  whether an interior extremum lies in the interval, cosh/sech/Abs whether 0 does.
* ``x**2k`` of an interval that contains 0 is ``[0, max(|lo|, |hi|)**2k]``, not the product
  ``x * x`` (which would give a negative lower end).
* Constant sub-expressions (``sqrt(2) * pi``) are enclosed through their own tree, in Arb.
* The cancelling forms of activation derivatives are rewritten before compilation
  (:func:`cancellation_free`): ``1 - tanh(u)^2 -> sech(u)^2`` (sympy's derivative of ``tanh``),
  ``1 + erf(u) -> erfc(-u)`` and ``1 - erf(u) -> erfc(u)`` (GELU). The natural extension of the
  left side is rigorous as well, but keeps no relative accuracy where it cancels.

The rounding primitives are those of :mod:`drip_cert.numerics.rounding` (which states the
guarantee).

Applied undefined functions (sympy ``Function('h')(x1, x2)``, their ``Derivative`` and ``Subs``
forms, standing for neural-network blocks) are passed to a user callback
``enclose(node, arg_enclosures) -> (lo, hi) | None`` where ``arg_enclosures`` are the intervals of
the arguments of the underlying undefined function. With no callback, or when it returns ``None``,
:class:`UnsupportedExpression` is raised, naming the function.
"""

from __future__ import annotations

import math
from collections.abc import Callable, Sequence
from fractions import Fraction

import numpy as np
import sympy as sp
from flint import arb
from sympy.core.function import AppliedUndef

from drip_cert.errors import DripCertError
from drip_cert.numerics.rounding import arb_hi, arb_lo, enclose_down, enclose_up

__all__ = [
    "UnsupportedExpression",
    "opaque_functions",
    "cancellation_free",
    "EncloseCallback",
    "compile_enclosure",
    "enclose_constant",
    "enclose_expr",
    "is_smooth",
    "MatrixEnclosure",
    "interval_add",
    "interval_mul",
]

Interval = tuple[float, float]
EncloseCallback = Callable[[sp.Expr, list[Interval]], Interval | None]
_Fn = Callable[[Sequence[Interval]], Interval]

_INF = math.inf
_ENTIRE: Interval = (-_INF, _INF)
_PI = arb.pi()
_TWO_PI = 2 * _PI
_HALF_PI = _PI / 2


class UnsupportedExpression(DripCertError, NotImplementedError):
    """An expression node has no rigorous interval extension here (or leaves its real domain)."""


# --------------------------------------------------------------------------------------------
# outward rounding (owned by drip_cert.numerics.rounding; NaN from inf - inf means "no information")
# --------------------------------------------------------------------------------------------

_dn = enclose_down
_up = enclose_up


def _exact(x: float) -> arb:
    return arb(x)


# --------------------------------------------------------------------------------------------
# interval operations
# --------------------------------------------------------------------------------------------


def interval_add(a: Interval, b: Interval) -> Interval:
    """Rigorous ``a + b`` of two intervals (ends rounded outward)."""
    return (_dn(a[0] + b[0]), _up(a[1] + b[1]))


def _prod(x: float, y: float) -> float:
    p = x * y
    return 0.0 if p != p else p  # 0 * inf = 0 in interval arithmetic


def interval_mul(a: Interval, b: Interval) -> Interval:
    """Rigorous ``a * b`` of two intervals (``0 * inf = 0``; ends rounded outward)."""
    ps = (_prod(a[0], b[0]), _prod(a[0], b[1]), _prod(a[1], b[0]), _prod(a[1], b[1]))
    return (_dn(min(ps)), _up(max(ps)))


def _recip(a: Interval) -> Interval:
    if a[0] <= 0.0 <= a[1]:
        return _ENTIRE
    return (_dn(1.0 / a[1]), _up(1.0 / a[0]))


def _ipow(a: Interval, k: int) -> Interval:
    """``a**k`` for an integer ``k`` (even powers handle intervals that contain 0)."""
    if k == 0:
        return (1.0, 1.0)
    if k < 0:
        return _recip(_ipow(a, -k))
    if k == 1:
        return a
    lo, hi = a
    if k % 2 == 1:  # odd: increasing
        return (arb_lo(_exact(lo) ** k), arb_hi(_exact(hi) ** k))
    # even power: decreasing on (-inf, 0], increasing on [0, inf)
    if lo >= 0.0:
        return (arb_lo(_exact(lo) ** k), arb_hi(_exact(hi) ** k))
    if hi <= 0.0:
        return (arb_lo(_exact(hi) ** k), arb_hi(_exact(lo) ** k))
    m = max(-lo, hi)
    return (0.0, arb_hi(_exact(m) ** k))


def _monotone(name: str, lo_domain: float | None = None, strict: bool = False):
    """Interval extension of an increasing arb function ``arb.<name>``."""

    def op(a: Interval, _name: str = name) -> Interval:
        lo, hi = a
        if lo_domain is not None and (lo < lo_domain or (strict and lo <= lo_domain)):
            raise UnsupportedExpression(
                f"{_name} is evaluated on [{lo}, {hi}], which leaves its real domain "
                f"({'>' if strict else '>='} {lo_domain}); shrink the box or rewrite the expression"
            )
        vlo = -_INF if lo == -_INF else arb_lo(getattr(_exact(lo), _name)())
        vhi = _INF if hi == _INF else arb_hi(getattr(_exact(hi), _name)())
        return (vlo, vhi)

    return op


_exp = _monotone("exp")
_log = _monotone("log", 0.0, strict=True)
_sqrt = _monotone("sqrt", 0.0)
_tanh_raw = _monotone("tanh")
_atan = _monotone("atan")
_sinh = _monotone("sinh")
_asinh = _monotone("asinh")


def _clip(a: Interval, lo: float, hi: float) -> Interval:
    return (max(a[0], lo), min(a[1], hi))


def _tanh(a: Interval) -> Interval:
    return _clip(_tanh_raw(a), -1.0, 1.0)


_erf_raw = _monotone("erf")


def _erf(a: Interval) -> Interval:
    return _clip(_erf_raw(a), -1.0, 1.0)


def _erfc(a: Interval) -> Interval:
    """``erfc`` is decreasing, with values in ``(0, 2)``; no cancellation for large arguments
    (the reason to prefer ``erfc(-u)`` over ``1 + erf(u)``)."""
    lo, hi = a
    vlo = 0.0 if hi == _INF else arb_lo(_exact(hi).erfc())
    vhi = 2.0 if lo == -_INF else arb_hi(_exact(lo).erfc())
    return _clip((vlo, vhi), 0.0, 2.0)


def _sech(a: Interval) -> Interval:
    """``sech`` is even and decreasing in ``|x|``, with values in ``(0, 1]``; ``sech(u)**2`` is the
    cancellation-free form of ``tanh'(u) = 1 - tanh(u)**2``."""
    m = _abs(a)
    vlo = 0.0 if m[1] == _INF else arb_lo(_exact(m[1]).sech())
    vhi = arb_hi(_exact(m[0]).sech())
    return _clip((vlo, vhi), 0.0, 1.0)


def _contains_point(lo: float, hi: float, offset: arb, period: arb) -> bool:
    """Whether ``[lo, hi]`` may contain ``offset + k * period``, ``k`` integer (conservative)."""
    kl = (_exact(lo) - offset) / period
    kh = (_exact(hi) - offset) / period
    return math.ceil(arb_lo(kl)) <= math.floor(arb_hi(kh))


def _periodic(a: Interval, fn: str, max_at: arb, min_at: arb) -> Interval:
    lo, hi = a
    if not (math.isfinite(lo) and math.isfinite(hi)) or hi - lo >= 6.0:
        return (-1.0, 1.0)
    vl = getattr(_exact(lo), fn)()
    vh = getattr(_exact(hi), fn)()
    rlo = min(arb_lo(vl), arb_lo(vh))
    rhi = max(arb_hi(vl), arb_hi(vh))
    if _contains_point(lo, hi, max_at, _TWO_PI):
        rhi = 1.0
    if _contains_point(lo, hi, min_at, _TWO_PI):
        rlo = -1.0
    return _clip((rlo, rhi), -1.0, 1.0)


def _sin(a: Interval) -> Interval:
    return _periodic(a, "sin", _HALF_PI, -_HALF_PI)


def _cos(a: Interval) -> Interval:
    return _periodic(a, "cos", arb(0), _PI)


def _tan(a: Interval) -> Interval:
    lo, hi = a
    if not (math.isfinite(lo) and math.isfinite(hi)) or hi - lo >= 3.0:
        return _ENTIRE
    if _contains_point(lo, hi, _HALF_PI, _PI):
        return _ENTIRE
    return (arb_lo(_exact(lo).tan()), arb_hi(_exact(hi).tan()))


def _abs(a: Interval) -> Interval:
    lo, hi = a
    if lo >= 0.0:
        return a
    if hi <= 0.0:
        return (-hi, -lo)
    return (0.0, max(-lo, hi))


def _cosh(a: Interval) -> Interval:
    m = _abs(a)
    vlo = arb_lo(_exact(m[0]).cosh())
    vhi = _INF if m[1] == _INF else arb_hi(_exact(m[1]).cosh())
    return (max(vlo, 1.0), vhi)


def _sign(a: Interval) -> Interval:
    lo, hi = a
    return (
        -1.0 if lo < 0 else (0.0 if lo == 0 else 1.0),
        1.0 if hi > 0 else (0.0 if hi == 0 else -1.0),
    )


def _heaviside(a: Interval) -> Interval:
    lo, hi = a
    return (0.0 if lo <= 0 else 1.0, 1.0 if hi >= 0 else 0.0)


def _max(a: Interval, b: Interval) -> Interval:
    return (max(a[0], b[0]), max(a[1], b[1]))


def _min(a: Interval, b: Interval) -> Interval:
    return (min(a[0], b[0]), min(a[1], b[1]))


def _rpow(a: Interval, r: sp.Rational) -> Interval:
    """``a**r`` for a non-integer rational ``r`` (real only for ``a >= 0``)."""
    lo, hi = a
    if lo < 0.0 or (r < 0 and lo <= 0.0):
        raise UnsupportedExpression(
            f"x**({r}) is evaluated on [{lo}, {hi}], which leaves its real domain "
            f"(x {'>' if r < 0 else '>='} 0); shrink the box or rewrite the expression"
        )
    ra = arb(int(r.p)) / arb(int(r.q))

    def pw(x: float) -> arb:
        return arb(0) if x == 0.0 else (_exact(x).log() * ra).exp()

    if hi == _INF:
        end = (_INF, _INF) if r > 0 else (0.0, 0.0)
    else:
        v = pw(hi)
        end = (arb_lo(v), arb_hi(v))
    v0 = pw(lo)
    start = (arb_lo(v0), arb_hi(v0))
    if r > 0:
        return (max(start[0], 0.0), end[1])
    return (max(end[0], 0.0), start[1])


_UNARY: dict[type, Callable[[Interval], Interval]] = {
    sp.exp: _exp,
    sp.log: _log,
    sp.sin: _sin,
    sp.cos: _cos,
    sp.tan: _tan,
    sp.tanh: _tanh,
    sp.atan: _atan,
    sp.sinh: _sinh,
    sp.cosh: _cosh,
    sp.asinh: _asinh,
    sp.Abs: _abs,
    sp.sign: _sign,
    sp.sech: _sech,
    sp.erf: _erf,
    sp.erfc: _erfc,
}

#: function heads with an interval extension here (everything else goes to the callback)
_KNOWN_HEADS = frozenset(_UNARY) | {sp.Heaviside, sp.Max, sp.Min}

#: heads whose derivative is not continuous (the mean-value form is skipped for them)
_NONSMOOTH = (sp.Abs, sp.sign, sp.Heaviside, sp.Max, sp.Min)


# --------------------------------------------------------------------------------------------
# compilation of a sympy expression into an interval function
# --------------------------------------------------------------------------------------------


def _const(value: sp.Expr) -> Interval:
    if value.is_Integer:
        f = float(int(value))
        return (f, f) if float(int(f)) == int(value) else (_dn(f), _up(f))
    if value.is_Rational:
        p, q = int(value.p), int(value.q)
        f = p / q  # Python's int / int is correctly rounded
        if math.isfinite(f) and Fraction(f) == Fraction(p, q):
            return (f, f)  # a float exactly (1/2, -3/4): no widening
        v = arb(p) / arb(q)
        return (arb_lo(v), arb_hi(v))
    if value is sp.pi:
        return (arb_lo(_PI), arb_hi(_PI))
    if value is sp.E:
        e = arb.const_e()
        return (arb_lo(e), arb_hi(e))
    if value.is_Float:
        f = float(value)
        return (f, f) if sp.Rational(value) == sp.Rational(f) else (_dn(f), _up(f))
    if value.is_real:
        # sympy tracks the accuracy of evalf (mpmath, adaptive precision); strict=True raises
        # instead of returning fewer than 30 correct digits, so the float is within one ulp
        try:
            f = float(value.evalf(30, strict=True))
        except (sp.core.evalf.PrecisionExhausted, ValueError, TypeError) as exc:
            raise UnsupportedExpression(f"constant {value} could not be evaluated") from exc
        return (_dn(_dn(f)), _up(_up(f)))
    raise UnsupportedExpression(f"constant {value} is not a real number")


def _is_opaque_call(node: sp.Basic) -> bool:
    """A function application with no interval extension here (an undefined function, or a
    ``sympy.Function`` subclass such as the blocks of :mod:`drip_cert.model.blocks`)."""
    if isinstance(node, AppliedUndef):
        return True
    return isinstance(node, sp.Function) and node.func not in _KNOWN_HEADS


def opaque_functions(expr: sp.Basic) -> set[sp.Expr]:
    """The applications in ``expr`` that need an ``enclose`` callback (undefined functions,
    function classes unknown here, and ``Derivative``/``Subs`` of them)."""
    expr = sp.sympify(expr)
    out = {a for a in expr.atoms(sp.Function) if _is_opaque_call(a)}
    out |= {d for d in expr.atoms(sp.Derivative, sp.Subs) if _undef_call_args(d) is not None}
    return out


def _undef_call_args(node: sp.Expr) -> tuple[sp.Expr, ...] | None:
    """Arguments of the opaque function behind ``F(..)``, ``Derivative(F(..))`` or ``Subs``."""
    if _is_opaque_call(node):
        return tuple(node.args)
    if isinstance(node, sp.Derivative) and _is_opaque_call(node.expr):
        return tuple(node.expr.args)
    if isinstance(node, sp.Subs):
        inner = _undef_call_args(node.expr)
        if inner is None:
            return None
        sub = dict(zip(node.variables, node.point))
        return tuple(sp.sympify(a).xreplace(sub) for a in inner)
    return None


def _compile(expr: sp.Expr, index: dict[sp.Symbol, int], enclose: EncloseCallback | None) -> _Fn:
    if expr.is_Symbol:
        if expr not in index:
            raise UnsupportedExpression(
                f"symbol {expr} is not a state or the time variable; substitute its value first"
            )
        i = index[expr]
        return lambda box: box[i]
    if expr.is_Number or expr.is_NumberSymbol:
        c = _const(expr)
        return lambda box: c
    if not expr.free_symbols and not expr.has(AppliedUndef):
        c = _const_tree(expr)
        return lambda box: c
    return _compile_op(expr, index, enclose)


def _const_tree(expr: sp.Expr) -> Interval:
    """Enclosure of a constant expression (no symbols): its own tree in interval arithmetic,
    with Arb at the leaves and at every elementary function. Only a head with no interval
    extension here falls back to :func:`_const` (sympy ``evalf`` at 30 digits with strict
    accuracy checking, then two ulps outward)."""
    if expr.is_real is False:
        raise UnsupportedExpression(f"constant {expr} is not a real number")
    try:
        return _compile_op(expr, {}, None)(())
    except UnsupportedExpression:
        if expr.is_real:
            return _const(expr)
        raise


def _fold(op: Callable[[Interval, Interval], Interval], parts: list[_Fn]) -> _Fn:
    """The interval function ``op(...op(op(p0, p1), p2)..., pk)`` of the parts (left fold, the
    order of sympy's arguments)."""

    def folded(box):
        acc = parts[0](box)
        for p in parts[1:]:
            acc = op(acc, p(box))
        return acc

    return folded


def _compile_op(expr: sp.Expr, index: dict[sp.Symbol, int], enclose: EncloseCallback | None) -> _Fn:
    """The interval extension of an operation node (sums, products, powers, functions)."""
    if expr.is_Add:
        return _fold(interval_add, [_compile(a, index, enclose) for a in expr.args])
    if expr.is_Mul:
        return _fold(interval_mul, [_compile(a, index, enclose) for a in expr.args])
    if expr.is_Pow:
        base, ex = expr.args
        fb = _compile(base, index, enclose)
        if ex.is_Integer:
            k = int(ex)
            return lambda box: _ipow(fb(box), k)
        if ex.is_Rational:
            if ex == sp.Rational(1, 2):
                return lambda box: _sqrt(fb(box))
            r = sp.Rational(ex)
            return lambda box: _rpow(fb(box), r)
        fe = _compile(ex, index, enclose)
        if base is sp.E:
            return lambda box: _exp(fe(box))
        return lambda box: _exp(interval_mul(fe(box), _log(fb(box))))
    head = expr.func
    if head in _UNARY:
        op = _UNARY[head]
        fa = _compile(expr.args[0], index, enclose)
        return lambda box: op(fa(box))
    if head is sp.Heaviside:
        fa = _compile(expr.args[0], index, enclose)
        return lambda box: _heaviside(fa(box))
    if head in (sp.Max, sp.Min):
        op2 = _max if head is sp.Max else _min
        return _fold(op2, [_compile(a, index, enclose) for a in expr.args])
    call_args = _undef_call_args(expr)
    if call_args is not None:
        name = str(expr.func) if _is_opaque_call(expr) else str(expr)
        if enclose is None:
            raise UnsupportedExpression(
                f"{name} is an undefined function (a learned block?); pass an `enclose` callback "
                "that returns an interval for it, or use the sampled estimate"
            )
        parts = [_compile(a, index, enclose) for a in call_args]

        def undef(box, parts=parts, node=expr, name=name):
            args = [p(box) for p in parts]
            res = enclose(node, args)
            if res is None:
                raise UnsupportedExpression(
                    f"the enclose callback returned None for {name}; no sound enclosure available"
                )
            lo, hi = float(res[0]), float(res[1])
            if not lo <= hi:
                raise UnsupportedExpression(
                    f"the enclose callback returned ({lo}, {hi}) for {name}"
                )
            return (lo, hi)

        return undef
    raise UnsupportedExpression(
        f"no interval extension for {head.__name__} in {expr}; supported: + * / integer and "
        "rational powers, exp log sqrt sin cos tan tanh sech atan sinh cosh asinh erf erfc Abs "
        "sign Heaviside Max Min, and undefined functions through an `enclose` callback"
    )


def _rewrite_add(expr: sp.Add) -> sp.Expr:
    """``c - c tanh(u)^2 -> c sech(u)^2``, ``c + c erf(u) -> c erfc(-u)``,
    ``c - c erf(u) -> c erfc(u)`` inside one sum (``c`` a number); other terms are kept."""
    terms = list(expr.args)
    consts = [t for t in terms if t.is_Number]
    if len(consts) != 1:
        return expr
    c = consts[0]
    for i, t in enumerate(terms):
        k, rest = t.as_coeff_Mul()
        repl = None
        if rest.is_Pow and rest.exp == 2 and isinstance(rest.base, sp.tanh) and k == -c:
            repl = c * sp.sech(rest.base.args[0]) ** 2
        elif isinstance(rest, sp.erf) and k == c:
            repl = c * sp.erfc(-rest.args[0], evaluate=False)  # no reflection to 2 - erfc
        elif isinstance(rest, sp.erf) and k == -c:
            repl = c * sp.erfc(rest.args[0])
        if repl is not None:
            others = [u for j, u in enumerate(terms) if j != i and u is not c]
            return sp.Add(repl, *others, evaluate=False) if others else repl
    return expr


def cancellation_free(expr: sp.Expr) -> sp.Expr:
    """``expr`` with the cancelling forms of activation derivatives rewritten.

    ``1 - tanh(u)^2`` (sympy's derivative of ``tanh``) becomes ``sech(u)^2`` and ``1 + erf(u)`` /
    ``1 - erf(u)`` become ``erfc(-u)`` / ``erfc(u)`` (the GELU forms), also with a common numeric
    factor. Both sides are equal; the enclosure of the left side is rigorous too, but loses all
    relative accuracy where the two terms nearly cancel (``tanh(20)^2`` rounds to 1), the right
    side keeps it.
    """
    expr = sp.sympify(expr)
    if not expr.has(sp.tanh, sp.erf):
        return expr
    return expr.replace(lambda e: e.is_Add, _rewrite_add)


def compile_enclosure(
    expr: sp.Expr | float,
    variables: Sequence[sp.Symbol],
    enclose: EncloseCallback | None = None,
) -> Callable[[Sequence[Interval]], Interval]:
    """Compile the natural interval extension of ``expr``.

    Parameters
    ----------
    expr
        A real sympy expression in ``variables``.
    variables
        The symbols, in the order of the box's rows.
    enclose
        Callback for undefined functions, see the module docstring.

    Returns
    -------
    callable
        ``F(box) -> (lo, hi)`` where ``box`` is a sequence of ``(lo, hi)`` pairs, one per
        variable; ``lo <= expr(x) <= hi`` for every ``x`` in the box (rigorous).

    Raises
    ------
    UnsupportedExpression
        A node has no interval extension (raised at compile time, or at evaluation time for
        domain violations and callback refusals).
    """
    index = {s: i for i, s in enumerate(variables)}
    return _compile(cancellation_free(sp.sympify(expr)), index, enclose)


def enclose_expr(
    expr: sp.Expr | float,
    variables: Sequence[sp.Symbol],
    box: np.ndarray | Sequence[Interval],
    enclose: EncloseCallback | None = None,
) -> Interval:
    """Rigorous enclosure ``(lo, hi)`` of ``expr`` over ``box`` (shape ``(len(variables), 2)``)."""
    ivs = [(float(r[0]), float(r[1])) for r in np.asarray(box, dtype=float)]
    return compile_enclosure(expr, variables, enclose)(ivs)


def is_smooth(expr: sp.Expr) -> bool:
    """Whether ``expr`` has no head with a discontinuous derivative (``Abs sign Heaviside Max
    Min``): the mean-value form applies to it."""
    return not any(expr.has(h) for h in _NONSMOOTH)


def enclose_constant(expr: sp.Expr) -> Interval:
    """Rigorous enclosure of a constant expression (no symbols): its own tree in interval
    arithmetic, Arb at the leaves and at every elementary function."""
    return _const_tree(sp.sympify(expr))


class MatrixEnclosure:
    """Entry-wise rigorous enclosure of a matrix-valued expression ``J(v)`` over boxes.

    Each entry is enclosed by the natural interval extension, intersected (when the entry is
    smooth and its gradient has an enclosure) with the mean-value form
    ``J_ij(c) + sum_k [d_k J_ij](B) (B_k - c_k)``, which converges quadratically as boxes shrink
    (Moore, *Interval Analysis*, 1966, Sec. 6.4).

    Parameters
    ----------
    J
        ``sympy.Matrix`` of shape ``(n, n)``.
    variables
        Symbols of the box rows (the states, then the time symbol if any).
    enclose
        Callback for undefined functions.
    mean_value
        Whether to use the mean-value form where possible.
    """

    def __init__(
        self,
        J: sp.Matrix,
        variables: Sequence[sp.Symbol],
        enclose: EncloseCallback | None = None,
        mean_value: bool = True,
    ) -> None:
        self.shape = J.shape
        self.variables = tuple(variables)
        self._natural: list[_Fn] = []
        self._mv: list[tuple[_Fn, list[_Fn | None]] | None] = []
        for e in J:
            e = sp.sympify(e)
            self._natural.append(compile_enclosure(e, variables, enclose))
            mv = None
            if mean_value and e.free_symbols & set(variables) and is_smooth(e):
                try:
                    grads = [
                        compile_enclosure(sp.diff(e, v), variables, enclose) if e.has(v) else None
                        for v in variables
                    ]
                    mv = (self._natural[-1], grads)
                except UnsupportedExpression:
                    mv = None
            self._mv.append(mv)

    def __call__(self, box: np.ndarray | Sequence[Interval]) -> tuple[np.ndarray, np.ndarray]:
        """Return ``(lo, hi)``, two ``(n, n)`` float arrays with ``lo <= J(v) <= hi`` on the box."""
        ivs = [(float(r[0]), float(r[1])) for r in np.asarray(box, dtype=float)]
        centre = [(0.5 * (a + b), 0.5 * (a + b)) for a, b in ivs]
        n_entries = len(self._natural)
        lo = np.empty(n_entries)
        hi = np.empty(n_entries)
        for k in range(n_entries):
            a, b = self._natural[k](ivs)
            mv = self._mv[k]
            if mv is not None:
                try:
                    a, b = _intersect((a, b), _mean_value(mv, ivs, centre))
                except UnsupportedExpression:
                    pass
            lo[k], hi[k] = a, b
        return lo.reshape(self.shape), hi.reshape(self.shape)


def _mean_value(mv: tuple[_Fn, list[_Fn | None]], ivs: list[Interval], centre: list[Interval]):
    f, grads = mv
    acc = f(centre)
    for k, g in enumerate(grads):
        if g is None:
            continue
        c = centre[k][0]
        dx = (_dn(ivs[k][0] - c), _up(ivs[k][1] - c))
        acc = interval_add(acc, interval_mul(g(ivs), dx))
    return acc


def _intersect(a: Interval, b: Interval) -> Interval:
    lo, hi = max(a[0], b[0]), min(a[1], b[1])
    if lo > hi:  # both are rigorous, so this cannot happen unless rounding touched; keep the union
        return (min(a[0], b[0]), max(a[1], b[1]))
    return (lo, hi)
