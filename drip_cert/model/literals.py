"""Numbers read exactly: the rational a decimal literal's text denotes, not its double.

A certificate's "exact" route (for instance the exact ``mu_2`` of a constant closed-loop
Jacobian) is only as exact as its coefficients. A decimal literal with more digits than a double
holds, such as ``0.6546960439030461848070769``, differs from the double nearest to it by up to
half an ulp (here ``4.2e-17``), and that double's shortest text ``0.6546960439030461`` lies
``8.5e-17`` below it: a loop whose exact ``mu_2`` is ``+8.4e-27`` looked contracting at rate
``8.5e-17``.
So a literal becomes the rational of its own text, digit for digit:

* :func:`exact_decimal` turns the text of a decimal literal (``0.1``, ``1e-3``, ``2.5E+10``,
  ``1_000.5``) into that rational, ``0.1 -> 1/10``;
* :class:`DecimalFloat` is a ``float`` that keeps the text it was read from; the spec loader
  gives it to :func:`tomllib.load` as ``parse_float``, so a TOML float keeps its text while
  every numeric use still sees an ordinary ``float``;
* :func:`exact_number` is the rational of a number as given: an ``int`` as is, a
  :class:`DecimalFloat` by its text, any other ``float`` as the binary rational it stores
  (a double *is* that rational; its shortest ``repr`` is a rounding of it).
"""

from __future__ import annotations

import math
from decimal import Decimal, InvalidOperation

import sympy as sp

MAX_LITERAL_EXPONENT = 1000
"""Largest decimal exponent ``|e|`` of a literal ``d.ddd x 10^e`` read exactly. Doubles span
``10^-324 .. 10^308``, so no number a model needs is refused; the bound keeps the rational small
(``10^1000`` is a 3,322-bit integer, while the 12 characters ``1e-100000000`` would otherwise ask
for a 40 MB one)."""


class DecimalFloat(float):
    """A ``float`` that remembers the decimal text it was read from.

    It behaves as the double ``float(text)`` everywhere (arithmetic returns plain floats, ``repr``
    is the double's), and :func:`exact_number` reads it as the rational of ``text``.

    Parameters
    ----------
    text
        A float literal as TOML or Python writes it (``"0.1"``, ``"-2.5E+10"``, ``"1_000.5"``,
        ``"inf"``, ``"nan"``).
    """

    __slots__ = ("text",)
    text: str

    def __new__(cls, text: str) -> DecimalFloat:
        obj = super().__new__(cls, text)
        obj.text = text
        return obj

    def __getnewargs__(self) -> tuple[str]:  # type: ignore[override]
        # pickle and copy rebuild from the text, not from the double
        return (self.text,)


def exact_decimal(text: str) -> sp.Rational:
    """The exact rational of a finite decimal literal's text (``"0.1"`` -> ``1/10``).

    Accepts what Python and TOML write for a float: a sign, digits with ``_`` between them, an
    optional point and an optional exponent ``e``/``E`` with a sign. The value is
    ``m / 10^k`` of the digits written (decimal arithmetic, no rounding anywhere).

    >>> exact_decimal("0.1")
    1/10
    >>> exact_decimal("6.02_214e23")
    602214000000000000000000

    Raises
    ------
    ValueError
        When ``text`` is not a finite decimal number, or its exponent exceeds
        :data:`MAX_LITERAL_EXPONENT` in magnitude; the message says which.
    """
    try:
        d = Decimal(text.strip().replace("_", ""))
    except InvalidOperation:
        raise ValueError(f"{text!r} is not a decimal number") from None
    if not d.is_finite():
        raise ValueError(f"{text!r} is not a finite number")
    if d and abs(d.adjusted()) > MAX_LITERAL_EXPONENT:
        raise ValueError(
            f"the literal {text!r} has a decimal exponent beyond +-{MAX_LITERAL_EXPONENT}; "
            f"write 0 or a number between 1e-{MAX_LITERAL_EXPONENT} and 1e{MAX_LITERAL_EXPONENT}"
        )
    p, q = d.as_integer_ratio()
    return sp.Rational(p, q)


def exact_number(value: int | float) -> sp.Rational:
    """The exact rational of a number as given (integers, floats, :class:`DecimalFloat`).

    An ``int`` is itself; a :class:`DecimalFloat` is the rational of its text
    (:func:`exact_decimal`); any other ``float`` is the binary rational the double stores
    (``sp.Rational(0.1) = 3602879701896397/36028797018963968``): the value it denotes, never its
    shortest ``repr`` (a rounding of it).

    >>> exact_number(0.1)
    3602879701896397/36028797018963968
    >>> exact_number(DecimalFloat("0.1"))
    1/10

    Raises
    ------
    ValueError
        For a non-finite float, or a text :func:`exact_decimal` refuses.
    """
    if isinstance(value, bool):
        raise ValueError(f"{value!r} is a boolean, not a number")
    if isinstance(value, int):
        return sp.Integer(value)
    if not math.isfinite(value):
        raise ValueError(f"{value!r} is not a finite number")
    if isinstance(value, DecimalFloat):
        return exact_decimal(value.text)
    return sp.Rational(float(value))
