"""The safe expression parser: what it accepts, what it rejects, and that it never runs code."""

from __future__ import annotations

import builtins
import copy
import pickle

import pytest
import sympy as sp
from hypothesis import given
from hypothesis import strategies as st

from drip_cert.errors import SpecError
from drip_cert.model.blocks import mlp_block
from drip_cert.model.expr import parse_expression
from drip_cert.model.literals import (
    MAX_LITERAL_EXPONENT,
    DecimalFloat,
    exact_decimal,
    exact_number,
)
from drip_cert.model.mlp import init_mlp

X1, X2 = sp.symbols("x1 x2", real=True)
T = sp.Symbol("t", real=True)
SCALARS = {"x1": X1, "x2": X2, "t": T}
VALUE_RTOL = 1e-12  # exact rationals vs float arithmetic on O(1) values: rounding only


def parse(text, blocks=None):
    return parse_expression(
        text, field="dynamics.f[0]", scalars=SCALARS, vector=(X1, X2), blocks=blocks
    )


def test_arithmetic_and_functions_become_exact_sympy():
    e = parse("0.1*sin(x1) - x2**3 + exp(-t)/2")
    assert sp.simplify(e - (sp.Rational(1, 10) * sp.sin(X1) - X2**3 + sp.exp(-T) / 2)) == 0


def test_float_literals_are_exact_decimals():
    # 0.1 + 0.2 == 0.3 exactly as rationals (not as binary floats)
    assert parse("0.1 + 0.2") == sp.Rational(3, 10)


#: a 25-digit literal: its double is 0.65469604390304614..., whose repr is 0.6546960439030461
DIGITS_25 = "0.6546960439030461848070769"


@pytest.mark.parametrize(
    "text, exact",
    [
        (DIGITS_25, sp.Rational(6546960439030461848070769, 10**25)),
        ("1e-3", sp.Rational(1, 1000)),
        ("2.5E+10", sp.Integer(25_000_000_000)),
        ("1_000.5", sp.Rational(2001, 2)),
        ("1.", sp.Integer(1)),
        (".5", sp.Rational(1, 2)),
        ("1e1_0", sp.Integer(10**10)),
        (
            "0.1000000000000000055511151231257827",
            sp.Rational(1000000000000000055511151231257827, 10**34),
        ),
        ("1e-400", sp.Rational(1, 10**400)),  # below the smallest double: was 0
        ("12345678901234567890123.5e-30", sp.Rational(123456789012345678901235, 10**31)),
    ],
)
def test_float_literal_is_the_rational_of_its_source_text(text, exact):
    """Every digit written counts: the literal is not rounded to a double (nor to its repr)."""
    assert parse(text) == exact
    assert parse(f"-{text}*x1") == -exact * X1


def test_literal_text_is_found_after_non_ascii_names_and_line_breaks():
    # ast offsets count UTF-8 bytes: a 2-byte name before the literal must not shift its text
    theta = sp.Symbol("\u03b8", real=True)
    e = parse_expression(
        f"\u03b8\u03b8 * \u03b8 + {DIGITS_25}",
        field="f",
        scalars={"\u03b8\u03b8": X1, "\u03b8": theta},
    )
    assert e == X1 * theta + sp.Rational(6546960439030461848070769, 10**25)
    assert (
        parse(f"(x1 +\r\n  {DIGITS_25}\n * x2)")
        == X1 + sp.Rational(6546960439030461848070769, 10**25) * X2
    )


@given(
    st.integers(0, 10**40),
    st.integers(0, 40),
    st.integers(-330, 260),  # 10^40 * 10^260 stays below the largest double
    st.sampled_from(["e", "E"]),
)
def test_float_literals_are_exact_for_any_digits_and_exponent(mantissa, point, exp10, e):
    """Property: ``d1...dk.dk+1...dn e E`` parses to mantissa / 10^point * 10^E exactly."""
    digits = str(mantissa).rjust(point + 1, "0")
    text = f"{digits[: len(digits) - point]}.{digits[len(digits) - point :]}{e}{exp10:+d}"
    assert parse(text) == sp.Rational(mantissa, 10**point) * sp.Rational(10) ** exp10


def test_numbers_given_as_values_are_exact():
    # a TOML float keeps its text (DecimalFloat); a bare Python float is the double it stores
    assert parse(DecimalFloat(DIGITS_25)) == sp.Rational(6546960439030461848070769, 10**25)
    assert parse(DecimalFloat("1_000.5")) == sp.Rational(2001, 2)
    assert parse(0.1) == sp.Rational(3602879701896397, 2**55) != sp.Rational(1, 10)
    assert parse(float(DIGITS_25)) == sp.Rational(float(DIGITS_25))
    assert parse(7) == sp.Integer(7)


def test_decimal_float_is_the_double_and_survives_pickle_and_copy():
    v = DecimalFloat(DIGITS_25)
    assert v == float(DIGITS_25) and repr(v) == repr(float(DIGITS_25))
    assert type(v + 0.0) is float  # arithmetic forgets the text
    for w in (pickle.loads(pickle.dumps(v)), copy.deepcopy(v)):
        assert type(w) is DecimalFloat and w.text == DIGITS_25 and w == v


@pytest.mark.parametrize("text", ["1e-100000000", "-1.5e-2000", "1e-1001"])
def test_literal_exponent_beyond_the_bound_is_refused(text):
    # an unbounded exponent would be an unbounded integer (10^10^8 is 40 MB): refused, named
    with pytest.raises(SpecError, match=f"exponent beyond \\+-{MAX_LITERAL_EXPONENT}") as info:
        parse(text)
    assert "dynamics.f[0]" in str(info.value)


def test_literal_exponent_at_the_bound_is_read_exactly():
    assert parse(f"1e-{MAX_LITERAL_EXPONENT}") == sp.Rational(1, 10**MAX_LITERAL_EXPONENT)


def test_exact_decimal_refuses_non_numbers():
    for bad in ("nan", "inf", "x", "1..2"):
        with pytest.raises(ValueError):
            exact_decimal(bad)
    with pytest.raises(ValueError, match="finite"):
        exact_number(float("inf"))


def test_norm_of_state_vector_and_scalars():
    assert parse("norm(x)") == sp.sqrt(X1**2 + X2**2)
    assert parse("norm(x1, 2*x2)") == sp.sqrt(X1**2 + 4 * X2**2)


def test_max_min_abs():
    assert parse("Max(x1, 0)") == sp.Max(X1, 0)
    assert parse("abs(x2)") == sp.Abs(X2)


def test_block_call_with_index_and_derivative():
    import numpy as np

    h = mlp_block("h", init_mlp([2, 3, 2], np.random.default_rng(0)))
    e = parse("h(x)[1] + h(x1, x2)[0]", blocks={"h": h})
    d = sp.diff(e, X1)
    names = sorted(type(a).__name__ for a in d.atoms(sp.Function))
    assert names == ["h__d0_0", "h__d1_0"]


@pytest.mark.parametrize(
    "text, fragment",
    [
        ("__import__('os').system('echo pwned')", "cannot be called"),
        ("x1.real", "not allowed"),
        ("(lambda: 1)()", "cannot be called"),
        ("[x1 for x1 in range(3)][0]", "subscripts"),
        ("x[0]", "subscripts"),
        ("open('f')", "unknown function"),
        ("y + 1", "unknown symbol"),
        ("sin(x1, x2)", "exactly one argument"),
        ("'a'", "not a number"),
        ("sin(x=1)", "keyword"),
        ("x1 if x2 else 0", "not allowed"),
        ("x1 < x2", "not allowed"),
        ("x", "vector"),
        ("_x", "'_'"),
        ("1/0", "division by zero"),
        ("x1 +", "cannot parse"),
        ("", "empty"),
    ],
)
def test_rejections_name_field_and_text(text, fragment):
    with pytest.raises(SpecError) as info:
        parse(text)
    msg = str(info.value)
    assert fragment in msg
    if text:
        assert "dynamics.f[0]" in msg


def test_block_arity_and_index_checked():
    import numpy as np

    h = mlp_block("h", init_mlp([2, 3, 2], np.random.default_rng(0)))
    with pytest.raises(SpecError, match="takes 2 inputs"):
        parse("h(x1)[0]", blocks={"h": h})
    with pytest.raises(SpecError, match="out of range"):
        parse("h(x)[2]", blocks={"h": h})
    with pytest.raises(SpecError, match="2 outputs"):
        parse("h(x)", blocks={"h": h})


@given(st.text(max_size=60))
def test_arbitrary_text_never_executes_code(text):
    """Property: any text either parses to a sympy expression or raises SpecError, and no
    Python builtin that could run code or touch the system is ever reached."""
    called = []
    originals = {}
    # ast.parse itself calls compile(..., PyCF_ONLY_AST), which builds a tree and runs nothing,
    # and the tokenizer imports unicodedata for non-ASCII names: neither runs user text
    for name in ("eval", "exec", "open"):
        originals[name] = getattr(builtins, name)

        def spy(*a, _n=name, **k):
            called.append(_n)
            return originals[_n](*a, **k)

        setattr(builtins, name, spy)
    try:
        try:
            out = parse(text)
        except SpecError:
            out = None
    finally:
        for name, fn in originals.items():
            setattr(builtins, name, fn)
    assert out is None or isinstance(out, sp.Expr)
    assert called == []


def test_payloads_that_would_write_a_file_do_nothing(tmp_path):
    target = tmp_path / "pwned"
    payloads = [
        f"open({str(target)!r}, 'w').write('x')",
        f"__import__('pathlib').Path({str(target)!r}).touch()",
        "().__class__.__base__.__subclasses__()",
        "sin(x1).__globals__",
    ]
    for text in payloads:
        with pytest.raises(SpecError):
            parse(text)
    assert not target.exists()


_atoms = st.sampled_from(["x1", "x2", "t", "1", "0.5", "2"])


@st.composite
def _expressions(draw, depth=3):
    if depth == 0:
        return draw(_atoms)
    kind = draw(st.sampled_from(["atom", "bin", "fn", "neg"]))
    if kind == "atom":
        return draw(_atoms)
    if kind == "neg":
        return f"-({draw(_expressions(depth - 1))})"
    if kind == "fn":
        fn = draw(st.sampled_from(["sin", "cos", "tanh", "exp", "abs"]))
        return f"{fn}({draw(_expressions(depth - 1))})"
    op = draw(st.sampled_from(["+", "-", "*"]))
    return f"({draw(_expressions(depth - 1))}) {op} ({draw(_expressions(depth - 1))})"


@given(_expressions())
def test_whitelisted_expressions_parse_and_match_python_semantics(text):
    """Property: well-formed whitelisted expressions parse, and their value at a point agrees
    with the same arithmetic done by hand in Python (math module)."""
    import math

    e = parse(text)
    env = {
        "x1": 0.3,
        "x2": -0.7,
        "t": 1.1,
        "sin": math.sin,
        "cos": math.cos,
        "tanh": math.tanh,
        "exp": math.exp,
        "abs": abs,
    }
    # the reference evaluation is of our own generated grammar, not of user input
    ref = eval(text, {"__builtins__": {}}, env)  # noqa: S307
    val = float(e.subs({X1: 0.3, X2: -0.7, T: 1.1}))
    assert math.isclose(val, ref, rel_tol=VALUE_RTOL, abs_tol=VALUE_RTOL)
