"""Private helpers of the TaSIL modules: argument checks, the upward pad of closed forms, and the
:class:`~drip_cert.provenance.Check` of one inequality (docs/math/tasil.md section 3)."""

from __future__ import annotations

import math

import numpy as np

from drip_cert.errors import SpecError
from drip_cert.numerics.rounding import add_up, mul_up
from drip_cert.provenance import Check, How

_EPS = float(np.finfo(np.float64).eps)
# Relative upward pad of the closed forms that :func:`up_closed_form` rounds (a pad that stays, with
# its proof). Each closed form it is applied to (parametric_epsilon, parametric_expectation,
# rho_tasil, the gap bounds 2 gamma0 h0, gamma0 eps* and the comparison bound c h0, the cone peaks
# of the continuous-time sups) is a sum of NON-NEGATIVE terms (no cancellation) built with at most
# 15 correctly rounded operations (each relative error <= u = EPS/2) and at most 3 library
# logarithms log / log1p (each within LIBM_ULPS = 8 EPS of drip_cert.numerics.rounding); a relative
# error e of the argument of log(y), y >= 2, or of log1p(x) gives a relative error <= e / log 2 of
# the result (log(1+x) >= x/(1+x)), so the total relative error is below 15 u + 3 (8 + 1.5) EPS < 36
# EPS; 64 EPS leaves a margin of 1.7. (eps_star and the Clopper-Pearson bound do not use it: they
# are bounded by directed rounding and verified in Arb respectively.)
REL_PAD = 64.0 * _EPS


def up_closed_form(x: float) -> float:
    """``x (1 + REL_PAD)`` rounded up: an upper bound of the exact closed form whose float
    evaluation is ``x`` (see ``REL_PAD`` for the proof)."""
    if not math.isfinite(x) or x == 0.0:
        return x  # inf stays inf; an exact zero (h0 = 0) stays exactly zero
    return add_up(x, mul_up(abs(x), REL_PAD))


def positive(
    name: str, value: float, *, allow_zero: bool = False, allow_inf: bool = False
) -> float:
    """``value`` as a float, checked ``> 0`` (``>= 0`` with ``allow_zero``) and finite (``inf``
    allowed with ``allow_inf``); otherwise :class:`~drip_cert.errors.SpecError` naming ``name``."""
    try:
        v = float(value)
    except (TypeError, ValueError):
        raise SpecError(f"{name} must be a number, got {value!r}", field=name) from None
    if math.isnan(v) or (math.isinf(v) and not allow_inf) or v < 0 or (v == 0 and not allow_zero):
        need = ">= 0" if allow_zero else "> 0"
        fin = "" if allow_inf else " and finite"
        raise SpecError(f"{name} must be {need}{fin}, got {value!r}", field=name)
    return v


def probability(delta: float) -> float:
    """``delta`` checked to lie in ``(0, 1)`` (a failure probability)."""
    d = float(delta)
    if not (0.0 < d < 1.0):
        raise SpecError(f"delta must lie in (0, 1), got {delta!r}; e.g. delta=0.05", field="delta")
    return d


def check_le(cid: str, lhs: float, rhs: float, text: str, source: str) -> Check:
    """The sound :class:`~drip_cert.provenance.Check` ``lhs <= rhs`` with margin ``rhs - lhs``
    (NaN when both sides are infinite)."""
    lhs, rhs = float(lhs), float(rhs)
    holds = bool(lhs <= rhs)
    margin = rhs - lhs if (math.isfinite(lhs) or math.isfinite(rhs)) else math.nan
    return Check(cid, holds, f"{text}: {lhs:.6g} <= {rhs:.6g}", lhs, rhs, margin, source, How.SOUND)
