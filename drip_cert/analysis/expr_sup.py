"""Rigorous supremum of a scalar sympy expression over a box (used by the growth constants).

The expression comes as several equivalent forms (rewritings by sympy, see
:mod:`drip_cert.analysis.growth_rewrites`); the upper bound on a box is the smallest of their
interval enclosures (:class:`~drip_cert.numerics.interval.MatrixEnclosure`: natural extension
intersected with the mean-value form), each rigorous, so the smallest is too. The supremum over
the box is then bounded by the one branch and bound of :mod:`drip_cert.numerics.bnb`, sampling
the first form that ``lambdify`` accepts at box centres and corners (for stopping only).
"""

from __future__ import annotations

from collections.abc import Sequence

import numpy as np
import sympy as sp

from drip_cert.numerics.bnb import BnbResult, maximize
from drip_cert.numerics.interval import MatrixEnclosure, UnsupportedExpression

__all__ = ["BNB_ATOL", "BNB_MAX_SPLITS", "BNB_RTOL", "expr_sup"]

BNB_RTOL = 1e-7  #: branch and bound stops when its upper bound is within this of the best value
BNB_ATOL = 1e-12  #: absolute part of the stopping rule (values near 0)
BNB_MAX_SPLITS = 4000  #: at most this many box splits per supremum (the answer stays sound)
GIVE_UP_WIDTH = 1e-9  #: a box this narrow (relative) whose bound is still too loose: stop there

_EVAL_ERRORS = (UnsupportedExpression, ZeroDivisionError, OverflowError, ValueError)


def expr_sup(
    cands: Sequence[sp.Expr],
    variables: Sequence[sp.Symbol],
    box: Sequence[tuple[float, float]],
    rtol: float = BNB_RTOL,
    atol: float = BNB_ATOL,
    max_splits: int = BNB_MAX_SPLITS,
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
        At most this many box splits.

    Returns
    -------
    BnbResult
        ``upper >= sup`` (``inf`` when no form has an enclosure, or none is finite).
    """
    encs = []
    for c in dict.fromkeys(cands):
        try:
            encs.append(MatrixEnclosure(sp.Matrix([[c]]), list(variables)))
        except UnsupportedExpression:
            continue
    if not encs:
        return BnbResult(np.inf, -np.inf, None, 0, False, "max_boxes")
    point = None
    for c in cands:
        try:
            point = sp.lambdify(list(variables), c, "math")
            break
        except Exception:  # noqa: BLE001 - lambdify of unusual nodes; lower values are optional
            continue

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
            return float(point(*pt.tolist()))  # type: ignore[misc]
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
