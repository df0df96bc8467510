"""Safe parsing of user expressions into sympy, by a whitelist over Python's ``ast``.

A specification file must never be able to run code, so user text is never given to ``eval``,
``sympify`` or ``parse_expr``. :func:`parse_expression` walks the syntax tree and accepts only

* numbers (int and float literals; a float literal becomes the exact rational of its source
  text, digit for digit: ``0.6546960439030461848070769`` keeps all 25 digits, ``1e-3`` is
  ``1/1000``; see :mod:`drip_cert.model.literals`),
* the declared scalar symbols (states, time) and the constants ``pi`` and ``E``,
* ``+ - * / **`` and unary ``-``/``+``,
* calls of :data:`FUNCTIONS` (``norm`` takes the state vector name or scalars),
* calls of declared blocks, ``h(x)[j]`` or ``h(x1, x2)[j]`` (index optional for one output),
  where the vector name of the state (``x`` unless a scalar state is called ``x``) expands to
  all states.

Everything else (attribute access, lambda, comprehensions, subscripts on non-blocks, keyword
arguments, strings, names starting with ``_``) is a :class:`~drip_cert.errors.SpecError`
that names the field, the offending text and what is allowed.
"""

from __future__ import annotations

import ast
import difflib
import re
from collections.abc import Callable, Mapping, Sequence

import sympy as sp

from drip_cert.errors import SpecError
from drip_cert.model.blocks import Block
from drip_cert.model.literals import DecimalFloat, exact_decimal, exact_number

#: Elementary functions accepted in expressions, with their sympy counterparts.
FUNCTIONS: Mapping[str, Callable[..., sp.Expr]] = {
    "sin": sp.sin,
    "cos": sp.cos,
    "tan": sp.tan,
    "exp": sp.exp,
    "log": sp.log,
    "sqrt": sp.sqrt,
    "tanh": sp.tanh,
    "abs": sp.Abs,
    "Abs": sp.Abs,
    "Max": sp.Max,
    "Min": sp.Min,
}
_UNARY = ("sin", "cos", "tan", "exp", "log", "sqrt", "tanh", "abs", "Abs")
CONSTANTS: Mapping[str, sp.Expr] = {"pi": sp.pi, "E": sp.E}
MAX_LENGTH = 20_000  #: longest expression text accepted (guards the parser's recursion)
_NEWLINE = re.compile(r"\r\n|\r|\n")  # the line breaks of Python's tokenizer (ast line numbers)
_ALLOWED_HELP = (
    "allowed: numbers, the declared symbols {symbols}, + - * / **, unary minus, "
    "the functions " + ", ".join(FUNCTIONS) + ", norm(x), pi, E{blocks}"
)


def parse_expression(
    text: object,
    *,
    field: str,
    scalars: Mapping[str, sp.Symbol],
    vector_name: str | None = "x",
    vector: Sequence[sp.Symbol] = (),
    blocks: Mapping[str, Block] | None = None,
    path: str | None = None,
    hints: Mapping[str, str] | None = None,
) -> sp.Expr:
    """Parse one user expression into a sympy expression, safely.

    Parameters
    ----------
    text
        The expression text, or a number: an ``int``; a
        :class:`~drip_cert.model.literals.DecimalFloat` (a TOML float with its text), parsed as
        its text; any other ``float``, taken as the exact binary rational of the double.
    field
        Where it came from, e.g. ``"dynamics.f[1]"``; used in error messages.
    scalars
        Declared scalar names and their symbols (states, time).
    vector_name, vector
        Name of the state vector and its components, usable in ``norm(x)`` and block calls.
    blocks
        Declared blocks by name.
    path
        The specification file, for error messages.
    hints
        Names that are declared but may not appear in this field, each with the fix the message
        gives (the time in a policy: "move the feed-forward term into f"; an input name).

    Raises
    ------
    SpecError
        For anything outside the whitelist; nothing is evaluated.
    """
    blocks = dict(blocks or {})
    if isinstance(text, bool):
        raise SpecError(f"expected an expression, got the boolean {text!r}", field=field, path=path)
    if isinstance(text, DecimalFloat):
        text = text.text
    elif isinstance(text, int | float):
        try:
            return exact_number(text)
        except ValueError as exc:
            raise SpecError(str(exc), field=field, path=path) from None
    if not isinstance(text, str):
        raise SpecError(
            f"expected an expression string, got {type(text).__name__} {text!r}",
            field=field,
            path=path,
        )
    if not text.strip():
        raise SpecError("empty expression", field=field, path=path)
    if len(text) > MAX_LENGTH:
        raise SpecError(f"expression longer than {MAX_LENGTH} characters", field=field, path=path)
    source = text.strip()
    try:
        tree = ast.parse(source, mode="eval")
    except (SyntaxError, ValueError, RecursionError, MemoryError) as exc:
        msg = getattr(exc, "msg", None) or type(exc).__name__
        raise SpecError(f"cannot parse {text!r}: {msg}", field=field, path=path) from None
    parser = _Parser(
        source, field, path, dict(scalars), vector_name, tuple(vector), blocks, dict(hints or {})
    )
    try:
        out = parser.visit(tree.body)
    except RecursionError:
        raise SpecError(
            f"expression {text!r} is nested too deeply", field=field, path=path
        ) from None
    if not isinstance(out, sp.Expr):
        raise SpecError(
            f"{text!r} is a vector; use it only inside norm(...) or a block call",
            field=field,
            path=path,
        )
    return out


class _Parser:
    """Recursive walk over an expression AST that builds sympy objects."""

    _lines: list[bytes] | None

    def __init__(self, text, field, path, scalars, vector_name, vector, blocks, hints):
        self.text = text
        self.hints = hints
        self.field = field
        self.path = path
        self.scalars = scalars
        self.vector_name = vector_name if vector else None
        self.vector = vector
        self.blocks = blocks
        self._lines = None  # the source's lines as UTF-8 bytes, split at the first float

    def fail(self, what: str) -> SpecError:
        names = ", ".join(sorted(self.scalars)) or "(none)"
        blk = ""
        if self.blocks:
            blk = ", blocks " + ", ".join(f"{b}(...)[j]" for b in sorted(self.blocks))
        if self.vector_name:
            names += f", {self.vector_name} (the state vector, in norm() and block calls)"
        return SpecError(
            f"in {self.text!r}: {what}; " + _ALLOWED_HELP.format(symbols=names, blocks=blk),
            field=self.field,
            path=self.path,
        )

    def visit(self, node: ast.AST):
        method = getattr(self, "visit_" + type(node).__name__, None)
        if method is None:
            raise self.fail(f"'{_describe(node)}' is not allowed")
        return method(node)

    def visit_Constant(self, node: ast.Constant):
        v = node.value
        if isinstance(v, bool) or not isinstance(v, int | float):
            raise self.fail(f"the literal {v!r} is not a number")
        if isinstance(v, float):
            if v != v or v in (float("inf"), float("-inf")):
                raise self.fail("NaN or infinite literal")
            return self._exact_float(node)
        return sp.Integer(v)

    def _exact_float(self, node: ast.Constant) -> sp.Expr:
        """The exact rational of a float literal's source text (``ast`` keeps only its double)."""
        if self._lines is None:
            self._lines = [line.encode() for line in _NEWLINE.split(self.text)]
        # col_offset / end_col_offset count UTF-8 bytes; a number token lies on one line
        line = self._lines[node.lineno - 1]
        literal = line[node.col_offset : node.end_col_offset].decode()
        if float(literal) != node.value:  # the token and the value ast gave must agree
            raise RuntimeError(
                f"internal error: literal text {literal!r} does not match {node.value!r}"
            )
        try:
            return exact_decimal(literal)
        except ValueError as exc:
            raise self.fail(str(exc)) from None

    def visit_Name(self, node: ast.Name):
        name = node.id
        if name.startswith("_"):
            raise self.fail(f"the name {name!r} (names starting with '_' are not allowed)")
        if name in self.scalars:
            return self.scalars[name]
        if self.vector_name and name == self.vector_name:
            return list(self.vector)
        if name in CONSTANTS:
            return CONSTANTS[name]
        if name in FUNCTIONS or name == "norm" or name in self.blocks:
            raise self.fail(f"the function {name!r} must be called")
        if name in self.hints:
            raise self.fail(f"the name {name!r} cannot be used here: {self.hints[name]}")
        known = [*self.scalars, *CONSTANTS]  # not the vector x: x3 is a misspelt x2, not x
        raise self.fail(f"unknown symbol {name!r}{_did_you_mean(name, known)}")

    def visit_UnaryOp(self, node: ast.UnaryOp):
        operand = self._scalar(node.operand)
        if isinstance(node.op, ast.USub):
            return -operand
        if isinstance(node.op, ast.UAdd):
            return operand
        raise self.fail(f"the operator '{_describe(node)}' is not allowed")

    def visit_BinOp(self, node: ast.BinOp):
        a = self._scalar(node.left)
        b = self._scalar(node.right)
        op = node.op
        if isinstance(op, ast.Add):
            return a + b
        if isinstance(op, ast.Sub):
            return a - b
        if isinstance(op, ast.Mult):
            return a * b
        if isinstance(op, ast.Div):
            if b == 0:
                raise self.fail("division by zero")
            return a / b
        if isinstance(op, ast.Pow):
            return a**b
        if isinstance(op, ast.BitXor):  # x1^3: the power of other languages, xor in Python
            fixed = self.text.replace("^", "**")
            raise self.fail(f"'^' is not a power here: use ** for powers, as in {fixed!r}")
        raise self.fail(f"the operator {type(op).__name__} is not allowed")

    def visit_Call(self, node: ast.Call):
        return self._call(node, index=None)

    def visit_Subscript(self, node: ast.Subscript):
        if not (
            isinstance(node.value, ast.Call)
            and isinstance(node.value.func, ast.Name)
            and node.value.func.id in self.blocks
        ):
            called = node.value
            if isinstance(called, ast.Call) and isinstance(called.func, ast.Name):
                raise self.fail(self._undeclared_block(called.func.id))
            raise self.fail("subscripts are allowed only on block calls, as h(x)[0]")
        sl = node.slice
        if not (
            isinstance(sl, ast.Constant)
            and isinstance(sl.value, int)
            and not isinstance(sl.value, bool)
        ):
            raise self.fail("a block output index must be a non-negative integer literal")
        return self._call(node.value, index=sl.value)

    def _scalar(self, node: ast.AST) -> sp.Expr:
        v = self.visit(node)
        if isinstance(v, list):
            raise self.fail("the state vector can be used only inside norm() or a block call")
        return v

    def _args(self, node: ast.Call) -> list[sp.Expr]:
        out: list[sp.Expr] = []
        for a in node.args:
            if isinstance(a, ast.Starred):
                raise self.fail("starred arguments are not allowed")
            v = self.visit(a)
            out.extend(v if isinstance(v, list) else [v])
        return out

    def _call(self, node: ast.Call, index: int | None):
        if not isinstance(node.func, ast.Name):
            raise self.fail(f"'{_describe(node.func)}' cannot be called")
        if node.keywords:
            raise self.fail("keyword arguments are not allowed")
        name = node.func.id
        if name in self.blocks:
            block = self.blocks[name]
            args = self._args(node)
            if len(args) != block.in_dim:
                raise self.fail(
                    f"block {name!r} takes {block.in_dim} inputs but {len(args)} were given"
                )
            if index is None:
                if block.out_dim != 1:
                    raise self.fail(
                        f"block {name!r} has {block.out_dim} outputs: pick one as {name}(...)[j]"
                    )
                index = 0
            if not 0 <= index < block.out_dim:
                raise self.fail(
                    f"output index {index} of block {name!r} is out of range 0..{block.out_dim - 1}"
                )
            return block.component(index)(*args)
        if index is not None:  # pragma: no cover - visit_Subscript admits block calls only
            raise self.fail("subscripts are allowed only on block calls")
        if name == "norm":
            args = self._args(node)
            if not args:
                raise self.fail("norm() needs an argument")
            return sp.sqrt(sum(a**2 for a in args))
        if name not in FUNCTIONS:
            close = _did_you_mean(name, [*FUNCTIONS, "norm", *self.blocks])
            if close:
                raise self.fail(f"unknown function {name!r}{close}")
            raise self.fail(self._undeclared_block(name))
        args = [self._scalar(a) for a in node.args]
        if name in _UNARY and len(args) != 1:
            raise self.fail(f"{name}() takes exactly one argument")
        if name in ("Max", "Min") and len(args) < 2:
            raise self.fail(f"{name}() takes at least two arguments")
        return FUNCTIONS[name](*args)

    def _undeclared_block(self, name: str) -> str:
        """The message of a call of ``name``, which is neither a function nor a block."""
        declared = ", ".join(sorted(self.blocks)) or "none"
        return (
            f"unknown function {name!r}, and no block of that name (blocks declared: "
            f"{declared}): to call a network, declare it in a table [blocks.{name}] with "
            'kind = "mlp" and weights = FILE (.onnx, .safetensors or .npz); else fix the name'
        )


def _did_you_mean(name: str, known: Sequence[str]) -> str:
    """``"; did you mean 'x2'?"`` for the closest of ``known``, or ``""``."""
    close = difflib.get_close_matches(name, list(known), n=1, cutoff=0.5)
    return f"; did you mean {close[0]!r}?" if close else ""


def _describe(node: ast.AST) -> str:
    try:
        return ast.unparse(node)
    except Exception:  # pragma: no cover - unparse handles every node parse produced
        return type(node).__name__
