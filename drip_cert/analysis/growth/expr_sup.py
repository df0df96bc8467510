"""Rigorous supremum of a scalar sympy expression over a box (used by the growth constants).

The expression comes as several equivalent forms (rewritings by sympy, see
:mod:`drip_cert.analysis.growth.rewrites`); the upper bound on a box is the smallest of their
interval enclosures (natural extension intersected with the mean-value form), each rigorous, so
the smallest is too. The supremum over the box is then bounded by the one branch and bound of
:mod:`drip_cert.numerics.bnb`, sampling the first form at box centres and corners (for
stopping only): the lower end of its batched natural extension at the point (a lower bound on
the value there) in the batched search, the first form that ``lambdify`` accepts in the scalar
one.

When every form has a batched enclosure
(:class:`~drip_cert.numerics.interval_batch.BatchEnclosure`, numpy over many boxes per call) the
search splits up to :data:`BNB_BATCH` boxes per round and bounds their children in one call;
otherwise it falls back to the scalar enclosure
(:class:`~drip_cert.numerics.interval.MatrixEnclosure`, Arb at the elementary functions), one box
at a time. Both are rigorous; the batched search ends within the same stopping rule.
"""

from __future__ import annotations

import functools
from collections.abc import Sequence
from typing import Any

import numpy as np
import sympy as sp

from drip_cert.numerics.bnb import BnbResult, maximize
from drip_cert.numerics.interval import MatrixEnclosure, UnsupportedExpression
from drip_cert.numerics.interval_batch import BatchEnclosure

__all__ = ["BNB_ATOL", "BNB_BATCH", "BNB_MAX_SPLITS", "BNB_RTOL", "expr_sup"]

BNB_RTOL = 1e-7  #: branch and bound stops when its upper bound is within this of the best value
BNB_ATOL = 1e-12  #: absolute part of the stopping rule (values near 0)
BNB_MAX_SPLITS = 4000  #: at most this many box splits per supremum (the answer stays sound)
GIVE_UP_WIDTH = 1e-9  #: a box this narrow (relative) whose bound is still too loose: stop there
BNB_BATCH = 128  #: at most this many boxes split per round by the batched search
BATCHED_SPLITS_FACTOR = 2
"""The batched search may split this many times ``max_splits`` boxes: a round splits the top
``BNB_BATCH`` boxes at once, some of which one-at-a-time best first would never split, so with
the same count it can stop looser; with twice the count it met the stopping rule, below the
one-at-a-time bound, on every growth objective of the examples (and a box costs ~10x less)."""
RESULT_CACHE = 256  #: suprema kept: a certify asks for the same one several times (matched part)
ENCLOSURE_CACHE = 64  #: compiled batched enclosures kept (one per objective and variable list)

_EVAL_ERRORS = (UnsupportedExpression, ZeroDivisionError, OverflowError, ValueError)


def _first_lambdify(forms: Sequence[sp.Expr], variables: Sequence[sp.Symbol], module: str) -> Any:
    """The first of ``forms`` that ``sympy.lambdify`` can compile for ``module`` (``None`` when
    none can): the search's lower values are optional, so an unusual node only costs them."""
    for c in forms:
        try:
            return sp.lambdify(list(variables), c, module)
        except Exception:  # noqa: BLE001 - lambdify of unusual nodes; lower values are optional
            continue
    return None


def expr_sup(
    cands: Sequence[sp.Expr],
    variables: Sequence[sp.Symbol],
    box: Sequence[tuple[float, float]],
    rtol: float = BNB_RTOL,
    atol: float = BNB_ATOL,
    max_splits: int = BNB_MAX_SPLITS,
    batched: bool = True,
) -> BnbResult:
    """Rigorous upper bound (and a sampled lower value) of ``sup expr`` over ``box``.

    Parameters
    ----------
    cands
        Equivalent forms of one real expression in ``variables``.
    variables
        The symbols, in the order of the rows of ``box``.
    box
        One finite ``(lo, hi)`` per variable.
    rtol, atol
        Stopping rule: ``upper - lower <= atol + rtol |lower|``.
    max_splits
        At most this many box splits (the batched search: ``BATCHED_SPLITS_FACTOR`` times it).
    batched
        Use the batched enclosures when every form has one (``False``: the scalar search, one
        box at a time, as before the batched evaluator).

    Returns
    -------
    BnbResult
        ``upper >= sup`` (``inf`` when no form has an enclosure, or none is finite).
    """
    key = tuple((float(a), float(b)) for a, b in box)
    return _expr_sup(
        tuple(dict.fromkeys(cands)), tuple(variables), key, rtol, atol, max_splits, batched
    )


@functools.lru_cache(maxsize=RESULT_CACHE)
def _expr_sup(
    forms: tuple[sp.Expr, ...],
    variables: tuple[sp.Symbol, ...],
    box: tuple[tuple[float, float], ...],
    rtol: float,
    atol: float,
    max_splits: int,
    batched: bool,
) -> BnbResult:
    """:func:`expr_sup` (cached: a deterministic function of its arguments; the result is a
    frozen value)."""
    cands = forms
    batch_encs = _batch_enclosures(tuple(forms), tuple(variables)) if batched else None
    if batch_encs is not None:
        splits = BATCHED_SPLITS_FACTOR * max_splits
        return _expr_sup_batched(forms, batch_encs, variables, box, rtol, atol, splits)
    encs = []
    for c in forms:
        try:
            encs.append(MatrixEnclosure(sp.Matrix([[c]]), list(variables)))
        except UnsupportedExpression:
            continue
    if not encs:
        return BnbResult(np.inf, -np.inf, None, 0, False, "max_boxes")
    point = _first_lambdify(cands, variables, "math")

    def upper(b: np.ndarray) -> float:
        best = np.inf
        for enc in encs:
            try:
                hi = float(enc(b)[1][0, 0])
            except _EVAL_ERRORS:
                continue
            if hi == hi:
                best = min(best, hi)
        return best

    def value(pt: np.ndarray) -> float:
        try:
            return float(point(*pt.tolist()))
        except (ValueError, ZeroDivisionError, OverflowError, TypeError):
            return np.nan

    return maximize(
        box,
        upper,
        None if point is None else value,
        atol=atol,
        rtol=rtol,
        max_boxes=1 + 2 * max_splits,
        min_width=GIVE_UP_WIDTH,
        corners=True,
        prefer_deep=True,
    )


@functools.lru_cache(maxsize=ENCLOSURE_CACHE)
def _batch_enclosures(
    forms: tuple[sp.Expr, ...], variables: tuple[sp.Symbol, ...]
) -> list[BatchEnclosure] | None:
    """A batched enclosure of every form, or ``None`` when one has none (scalar fallback).
    Cached: one growth constant asks for the same objective on several boxes, and compiling it
    (with its gradient, symbolic differentiation) costs more than bounding it."""
    try:
        return [BatchEnclosure(c, variables) for c in forms]
    except UnsupportedExpression:
        return None


def _expr_sup_batched(
    forms: Sequence[sp.Expr],
    encs: Sequence[BatchEnclosure],
    variables: Sequence[sp.Symbol],
    box: Sequence[tuple[float, float]],
    rtol: float,
    atol: float,
    max_splits: int,
) -> BnbResult:
    """:func:`expr_sup` with many boxes per enclosure call.

    The lower values are the lower ends of the first form's natural interval extension at the
    sampled points (degenerate boxes): each is ``<= expr(point) <= sup``, a few ulps below the
    float value, and needs no ``sympy.lambdify`` (whose printers cost a certify ~0.1 CPU-s
    to import and compile)."""

    def upper_many(bs: np.ndarray) -> np.ndarray:
        best = np.full(bs.shape[0], np.inf)
        for enc in encs:
            hi = enc(bs)[1]
            best = np.where(np.isnan(hi), best, np.minimum(best, hi))
        return best

    def value_many(ps: np.ndarray) -> np.ndarray:
        return encs[0].at_points(ps)[0]

    return maximize(
        box,
        None,
        atol=atol,
        rtol=rtol,
        max_boxes=1 + 2 * max_splits,
        min_width=GIVE_UP_WIDTH,
        corners=True,
        prefer_deep=True,
        upper_many=upper_many,
        value_many=value_many,
        batch=BNB_BATCH,
    )
