"""The deterministic imitation-gap lemma of TaSIL-type training (docs/math/tasil.md section 3.1;
Proposition 4.1 in continuous time): from ``h_0, h_1`` along the expert trajectory of one initial
state, a bound on ``max_t ||x_hat_t - x*_t||``.

Quarter form (Lemma 3.1): gap ``<= 2 gamma_0 h_0``; sharp form (Lemma 3.1'): gap
``<= gamma_0 eps*`` with ``eps*`` the smaller root of (S). Both are **this project's
construction**, not TaSIL's own constant.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from drip_cert.bounds.tasil._common import check_le, positive, up_closed_form
from drip_cert.numerics.rounding import down_np, up_np
from drip_cert.provenance import Check, How

__all__ = ["GapLemma", "eps_star", "imitation_gap_lemma"]


def eps_star(h0, h1, gamma0, L_Delta):
    """Smallest root ``eps*`` of ``h0 + gamma0 h1 e + (L/2) gamma0^2 e^2 = e``
    (docs/math/tasil.md Lemma 3.1').

    Cancellation-free form ``eps* = 2 h0 / ((1 - b) + sqrt((1 - b)^2 - 2 L gamma0^2 h0))``,
    ``b = gamma0 h1``; ``inf`` where ``b >= 1`` or the discriminant is negative.

    Parameters
    ----------
    h0, h1, gamma0, L_Delta
        Non-negative scalars or arrays (broadcast together).

    Returns
    -------
    float or np.ndarray
        ``eps*``, rounded upward (interval evaluation in the safe direction).
    """
    h0 = np.asarray(h0, dtype=np.float64)
    h1 = np.asarray(h1, dtype=np.float64)
    g = np.asarray(gamma0, dtype=np.float64)
    L = np.asarray(L_Delta, dtype=np.float64)
    # interval evaluation in the safe direction (every input >= 0): b up, 1 - b down, the
    # discriminant down, the denominator down, the quotient up; a relative pad would not do,
    # because 1 - b and the discriminant cancel
    with np.errstate(invalid="ignore", divide="ignore", over="ignore"):
        b_up = up_np(g * h1)
        one_b = down_np(1.0 - b_up)
        q_up = up_np(up_np(up_np(2.0 * L) * up_np(g * g)) * h0)
        disc = down_np(down_np(one_b * one_b) - q_up)
        ok = (one_b > 0) & (disc >= 0)
        den = down_np(one_b + down_np(np.sqrt(np.where(ok, disc, 0.0))))
        e = up_np(2.0 * h0 / den)
    e = np.where(ok & (den > 0), e, np.inf)
    e = np.where(h0 == 0.0, np.where(ok, 0.0, np.inf), e)
    return e if e.ndim else float(e)


@dataclass(frozen=True)
class GapLemma:
    """Verdict of the deterministic imitation-gap lemma for one initial state
    (docs/math/tasil.md 3.1; section 4 in continuous time, with sups over ``[0, t)``).

    Attributes
    ----------
    h0, h1
        The trajectory quantities (A3) the lemma was applied to.
    gamma0, L_Delta, eta, R
        The constants of A1-A2.
    bound_quarter
        ``2 gamma0 h0`` when the four quarter conditions hold, else ``inf``.
    eps_star
        Smallest root of ``h0 + gamma0 h1 e + (L/2) gamma0^2 e^2 = e`` (``inf`` if none).
    bound_sharp
        ``gamma0 eps*`` when the sharp conditions hold, else ``inf``.
    checks
        Every condition: ``tasil.quarter.*`` (the lemma) and ``tasil.sharp.*`` (its sharp form).
    continuous
        Whether the h's are continuous-time sups (Proposition 4.1).
    """

    h0: float
    h1: float
    gamma0: float
    L_Delta: float
    eta: float
    R: float
    bound_quarter: float
    eps_star: float
    bound_sharp: float
    checks: tuple[Check, ...]
    continuous: bool = False

    @property
    def holds(self) -> bool:
        """The sharp form holds (implied by the quarter conditions)."""
        return math.isfinite(self.bound_sharp)

    @property
    def bound(self) -> float:
        """The certified gap bound ``max_t ||x_hat_t - x*_t||`` (``inf`` when the lemma fails)."""
        return self.bound_sharp

    @property
    def sharp_checks(self) -> tuple[Check, ...]:
        """The conditions of the sharp form (``tasil.sharp.*``), the ones :attr:`bound` rests on."""
        return tuple(c for c in self.checks if c.id.startswith("tasil.sharp"))

    @property
    def reason(self) -> str:
        """Empty when the lemma holds, else the failed sharp conditions and by how much."""
        if self.holds:
            return ""
        bad = [c for c in self.sharp_checks if not c.holds]
        return "; ".join(f"{c.id}: {c.detail} (fails by {-c.margin:.4g})" for c in bad)


def imitation_gap_lemma(
    h0: float,
    h1: float,
    gamma0: float,
    L_Delta: float,
    eta: float = math.inf,
    R: float = math.inf,
    *,
    continuous: bool = False,
) -> GapLemma:
    """The deterministic imitation-gap lemma (docs/math/tasil.md section 3.1; section 4 if
    continuous).

    Quarter form (Lemma 3.1): if ``gamma0 h1 <= 1/4``, ``gamma0^2 L h0 <= 1/4``, ``2 h0 <= eta``
    and ``2 gamma0 h0 <= R``, then ``max_t ||x_hat_t - x*_t|| <= 2 gamma0 h0``.
    Sharp form (Lemma 3.1'): with ``b = gamma0 h1 < 1`` and ``(1-b)^2 >= 2 L gamma0^2 h0``, if
    ``eps* <= eta`` and ``gamma0 eps* <= R`` then the gap is ``<= gamma0 eps*`` (and
    ``max_t ||Delta(x_hat_t)|| <= eps*``).
    The quarter conditions imply the sharp ones (Corollary 3.1a), so the sharp bound is the one
    reported as :attr:`GapLemma.bound`.

    Parameters
    ----------
    h0, h1
        Trajectory quantities (A3) of the initial state.
    gamma0
        Linear delta-ISS gain (A1), e.g. from DRIP Proposition ``prop:deltaISS``.
    L_Delta
        Lipschitz constant of ``d Delta`` on the tube (A2).
    eta, R
        delta-ISS radius (A1) and tube radius (A2); ``inf`` allowed.
    continuous
        The h's are continuous-time sups (Proposition 4.1; only the cited source changes).

    Returns
    -------
    GapLemma
    """
    h0 = positive("h0", h0, allow_zero=True)
    h1 = positive("h1", h1, allow_zero=True)
    g = positive("gamma0", gamma0)
    L = positive("L_Delta", L_Delta, allow_zero=True)
    eta = positive("eta", eta, allow_inf=True)
    R = positive("R", R, allow_inf=True)
    src = "docs/math/tasil.md section 4" if continuous else "docs/math/tasil.md section 3.1"
    b = g * h1
    q = [
        check_le("tasil.quarter.h1", b, 0.25, "gamma0 h1 <= 1/4", src),
        check_le("tasil.quarter.L", g * g * L * h0, 0.25, "gamma0^2 L_Delta h0 <= 1/4", src),
        check_le("tasil.quarter.eta", 2 * h0, eta, "2 h0 <= eta", src),
        check_le("tasil.quarter.R", 2 * g * h0, R, "2 gamma0 h0 <= R", src),
    ]
    bound_q = up_closed_form(2 * g * h0) if all(c.holds for c in q) else math.inf
    es = float(eps_star(h0, h1, g, L))
    one_b = 1.0 - b
    s = [
        check_le("tasil.sharp.b", b, 1.0, "b = gamma0 h1 < 1", src),
        check_le(
            "tasil.sharp.disc",
            2 * L * g * g * h0,
            one_b * one_b if one_b > 0 else -math.inf,
            "2 L_Delta gamma0^2 h0 <= (1 - b)^2",
            src,
        ),
        check_le("tasil.sharp.eta", es, eta, "eps* <= eta", src),
        check_le("tasil.sharp.R", g * es, R, "gamma0 eps* <= R", src),
    ]
    if b >= 1.0:  # strict inequality needed
        s[0] = Check(s[0].id, False, s[0].detail, b, 1.0, 1.0 - b, src, How.SOUND)
    bound_s = up_closed_form(g * es) if all(c.holds for c in s) and math.isfinite(es) else math.inf
    return GapLemma(h0, h1, g, L, eta, R, bound_q, es, bound_s, tuple(q + s), continuous)
