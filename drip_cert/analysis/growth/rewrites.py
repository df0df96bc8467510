"""Symbolic rewritings behind the growth constants: radial profiles and equivalent forms.

* :func:`radial_profile` finds ``G`` with ``vec F(a) = G(||a||)`` (the radial route of
  :mod:`drip_cert.analysis.growth.regularity`; docs/math/l1drac.md section 2), by substituting
  ``||a||^2 = rho^2`` and checking that no state is left.
* :func:`rewritings` gives equivalent forms of a list of expressions (``expand``, ``cancel``,
  ``powsimp``, ``simplify``); the enclosure of a box is the best of theirs
  (:func:`drip_cert.analysis.growth.expr_sup.expr_sup`), each being rigorous.
* :func:`sum_sq` is the squared norm on which branch and bound runs.
"""

from __future__ import annotations

import functools
from collections.abc import Sequence

import numpy as np
import sympy as sp

__all__ = ["radial_profile", "rewritings", "sum_sq"]

_CHECK_SEED = 7  #: seed of the points at which a radial rewriting is re-checked numerically
_CHECK_POINTS = 3  #: how many points
_CHECK_RTOL = 1e-12  #: the rewriting is an identity; 30-digit evaluation agrees far below this
_SIMPLIFY_MAX_OPS = 150  #: ``simplify`` only expressions smaller than this (it is slow)
_REWRITES_KEPT = 256  #: expressions whose forms are kept (the paper example asks 11, 176 times)


def radial_profile(
    entries: Sequence[sp.Expr],
    xs: Sequence[sp.Symbol],
    rho: sp.Symbol,
    t: sp.Symbol | None,
) -> list[sp.Expr] | None:
    """``G(rho)`` with ``entries(a) = G(||a||)``, or ``None`` when ``entries`` is not radial.

    Parameters
    ----------
    entries
        The entries of ``vec F`` in the (real) state symbols ``xs`` and the time ``t``.
    xs
        The state symbols.
    rho
        A nonnegative symbol standing for ``||a||``.
    t
        The time symbol, or ``None``.
    """
    s2 = sum(x**2 for x in xs)
    out = []
    for e in entries:
        g = e.xreplace({s2: rho**2})
        if g.has(*xs):
            g = g.subs(s2, rho**2)
        if len(xs) == 1 and g.has(xs[0]):
            g = g.xreplace({sp.Abs(xs[0]): rho}).subs(xs[0] ** 2, rho**2)
        if g.has(*xs):
            return None
        out.append(g)
    # numerical sanity check of the rewriting at a few points (it is an identity by construction)
    rng = np.random.default_rng(_CHECK_SEED)
    for _ in range(_CHECK_POINTS):
        a = rng.normal(size=len(xs)) * 1.7
        tv = {t: 0.37} if t is not None else {}
        r = float(np.linalg.norm(a))
        for e, g in zip(entries, out):
            try:
                v1 = complex(e.xreplace({**dict(zip(xs, map(sp.Float, a))), **tv}).evalf(30))
                v2 = complex(g.xreplace({rho: sp.Float(r), **tv}).evalf(30))
            except (TypeError, ValueError):
                return None
            if not abs(v1 - v2) <= _CHECK_RTOL * (1.0 + abs(v1)):
                return None
    return out


@functools.lru_cache(maxsize=_REWRITES_KEPT)
def _rewrites(e: sp.Expr) -> tuple[sp.Expr, ...]:
    """Equivalent forms of ``e`` (identities for positive symbols), the cheap ones first.

    Kept per expression (a deterministic function of it): the growth routes ask for the same
    few entries many times (every entry of a diagonal diffusion, each rewriting of a norm)."""
    forms = [e]
    for fn in (
        sp.expand,
        lambda z: sp.cancel(sp.together(z)),
        sp.powsimp,
        lambda z: sp.simplify(z) if sp.count_ops(z) < _SIMPLIFY_MAX_OPS else z,
    ):
        try:
            f = fn(e)
        except (TypeError, ValueError, NotImplementedError, RecursionError):  # pragma: no cover
            continue
        if all(f != g for g in forms):
            forms.append(f)
    return tuple(forms)


def rewritings(exprs: Sequence[sp.Expr]) -> list[list[sp.Expr]]:
    """The k-th rewriting of every entry (a list of k-th forms), for the candidate objectives.

    An entry with fewer forms repeats its last one.
    """
    per = [_rewrites(e) for e in exprs]
    k = max((len(p) for p in per), default=1)
    return [[p[min(i, len(p) - 1)] for p in per] for i in range(k)]


def sum_sq(entries: Sequence[sp.Expr]) -> sp.Expr:
    """``||entries||^2``: branch and bound runs on squares (smooth, so the mean-value form
    applies; ``sqrt(g^2)`` would become the non-smooth ``|g|``) and takes the root at the end."""
    return sum((e**2 for e in entries), sp.Integer(0))
