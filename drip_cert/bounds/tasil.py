"""The TaSIL certificate: a bound on the policy-induced imitation gap (rho_TaSIL).

Implements docs/math/tasil.md sections 3 and 4, **a construction of this project, not TaSIL's own
constant** (the body of Pfrommer et al. 2022, whose Thm 4.3 the DRIP paper's Theorem "TaSIL"
cites, is not available). Every report carries :data:`LABEL`.

Pieces (docs/math/tasil.md numbering):

* :func:`h_discrete`, :func:`h_continuous` -- the trajectory quantities
  ``h_0 = sup_t ||Delta(x*_t)||`` and ``h_1 = sup_t ||d Delta(x*_t)||_op`` (A3), where
  ``Delta = pi_hat - pi_star``; in continuous time (section 4) a sound sup from grid values plus
  a Lipschitz-in-time correction.
* :func:`imitation_gap_lemma` -- the deterministic lemma of section 3.1 (quarter conditions, gap
  ``<= 2 gamma_0 h_0``) and its sharp form (gap ``<= gamma_0 eps*``), with every condition as a
  :class:`~drip_cert.provenance.Check`.
* :func:`clopper_pearson_upper`, :func:`parametric_epsilon`, :func:`parametric_expectation`,
  :func:`rho_tasil` -- the statistical forms of sections 3.3 (a), (b), (c) and 3.4.
* :func:`tasil_certificate` -- the frozen :class:`TasilCertificate`.

Assumptions (checked where data allow, otherwise stated in :data:`ASSUMPTIONS`): (A1) the expert
closed loop is (eta, gamma_0 s)-locally delta-ISS (DRIP Proposition ``prop:deltaISS`` and its
corollary give ``gamma_0 = sup_t (theta lambda_theta)^{-1/2} (1 - e^{-lambda_theta t})^{1/2}``);
(A2) ``d Delta`` is ``L_Delta``-Lipschitz on the tube of radius ``R`` around expert trajectories
(``L_Delta <= L_dpi(pi_hat) + L_dpi(pi_star)``, DRIP Assumption ``PolicyRegularity`` b); (A3) the
h's are measured on the expert trajectories.

Probability semantics of ``rho``: every gap-radius form is stated at the *joint* level ``1 - delta``
over the data and a fresh initial state ``xi ~ D``: ``P[max_t ||x_hat_t - x*_t|| > rho] <= delta``
(the DRIP-shaped form of section 3.4 splits delta in three; the held-out and threshold forms give
``delta/2`` to the data and require the exceedance probability ``<= delta/2``). This is a
high-probability radius, not a bound on the expectation ``E_xi`` in DRIP's policy-IG
(``eqn:Decomposition:IG:Policy``).
"""

from __future__ import annotations

import math
from collections.abc import Callable, Sequence
from dataclasses import dataclass, field
from typing import Any

import numpy as np
from flint import arb, ctx
from scipy.stats import beta as beta_dist

from drip_cert.errors import SpecError
from drip_cert.numerics.rounding import (
    add_up,
    arb_hi,
    down_np,
    mul_up,
    norm2_up_np,
    spectral_norm_upper,
    up,
    up_np,
)
from drip_cert.provenance import Check, How, json_float

__all__ = [
    "ASSUMPTIONS",
    "FORMS",
    "LABEL",
    "ClassConstants",
    "GapLemma",
    "TasilCertificate",
    "TasilForm",
    "TrajectoryH",
    "clopper_pearson_upper",
    "eps_star",
    "h_continuous",
    "h_discrete",
    "h_from_functions",
    "imitation_gap_lemma",
    "parametric_epsilon",
    "parametric_expectation",
    "rho_tasil",
    "tasil_certificate",
]

LABEL = "construction of this project (docs/math/tasil.md section 3), not TaSIL's own constant"
ASSUMPTIONS = (
    "A1: expert closed loop locally delta-ISS with linear gain gamma0 on perturbations <= eta",
    "A2: d(pi_hat - pi_star) is L_Delta-Lipschitz (operator norm) on the radius-R tube",
    "A3: h0, h1 are sups along expert trajectories (sound sups in continuous time)",
    "statistical forms: training / held-out initial states i.i.d. from D, independent of each "
    "other; held-out states unused in training; tau and class constants fixed before the data",
)
FORMS = ("held_out", "threshold", "expectation", "drip_shaped")
_SOURCE = "docs/math/tasil.md section 3 (this project's construction)"

_EPS = float(np.finfo(np.float64).eps)
# Relative upward pad of the closed forms that :func:`_up` rounds (a pad that stays, with its
# proof). Each closed form it is applied to (parametric_epsilon, parametric_expectation, rho_tasil,
# the gap bounds 2 gamma0 h0 and gamma0 eps*, the cone peaks of _sound_sup) is a sum of
# NON-NEGATIVE terms (no cancellation) built with at most 15 correctly rounded operations (each
# relative error <= u = EPS/2) and at most 3 library logarithms log / log1p (each within
# LIBM_ULPS = 8 EPS of drip_cert.numerics.rounding); a relative error e of the argument of
# log(y), y >= 2,
# or of log1p(x) gives a relative error <= e / log 2 of the result (log(1+x) >= x/(1+x)), so the
# total relative error is below 15 u + 3 (8 + 1.5) EPS < 36 EPS; 64 EPS leaves a margin of 1.7.
# (eps_star and clopper_pearson_upper do not use it: they are bounded by directed rounding and
# verified in Arb respectively.)
_REL_PAD = 64.0 * _EPS
# Clopper-Pearson: first relative step above scipy's inverse, and how many tenfold steps to try
# before falling back to the trivial bound 1 (scipy's ppf is accurate to ~1e-12 relative)
_CP_STEP0 = 1e-12
_CP_TRIES = 12
_CP_PREC = 128  # bits of the Arb evaluation: balls far narrower than the 1e-12 steps
# relative allowance when checking grid values against the claimed Lipschitz-in-time rate
_CONSISTENCY_RTOL = 1e-9
# size of the geometric grid tau_j in {b_j 2^{-k/2}: k = 0..K-1} used when tau is data-chosen
_TAU_GRID_SIZE = 64


def _up(x: float) -> float:
    """``x (1 + _REL_PAD)`` rounded up: an upper bound of the exact closed form whose float
    evaluation is ``x`` (see ``_REL_PAD`` for the proof)."""
    if not math.isfinite(x) or x == 0.0:
        return x  # inf stays inf; an exact zero (h0 = 0) stays exactly zero
    return add_up(x, mul_up(abs(x), _REL_PAD))


def _pos(name: str, value: float, *, allow_zero: bool = False, allow_inf: bool = False) -> float:
    try:
        v = float(value)
    except (TypeError, ValueError):
        raise SpecError(f"{name} must be a number, got {value!r}", field=name) from None
    if math.isnan(v) or (math.isinf(v) and not allow_inf) or v < 0 or (v == 0 and not allow_zero):
        need = ">= 0" if allow_zero else "> 0"
        fin = "" if allow_inf else " and finite"
        raise SpecError(f"{name} must be {need}{fin}, got {value!r}", field=name)
    return v


def _delta_ok(delta: float) -> float:
    d = float(delta)
    if not (0.0 < d < 1.0):
        raise SpecError(f"delta must lie in (0, 1), got {delta!r}; e.g. delta=0.05", field="delta")
    return d


# =============================================================================== h_0 and h_1


@dataclass(frozen=True)
class TrajectoryH:
    """``h_0`` and ``h_1`` of one expert trajectory (docs/math/tasil.md A3; section 4 if
    continuous).

    Attributes
    ----------
    h0, h1
        The sups used by the lemma: grid maxima of rounded-up norms in discrete time, sound sups
        over the continuous time interval otherwise (both :attr:`How.SOUND`).
    h0_grid, h1_grid
        The maxima over the grid points.
    t_h0, t_h1
        Times (or grid indices in discrete time) of the grid maxima.
    continuous
        Whether ``h0``/``h1`` are continuous-time sups.
    how
        :class:`~drip_cert.provenance.How` of ``h0`` and ``h1``.
    """

    h0: float
    h1: float
    h0_grid: float
    h1_grid: float
    t_h0: float
    t_h1: float
    continuous: bool
    how: How


def _norms(delta, jac) -> tuple[np.ndarray, np.ndarray]:
    """Euclidean norms of ``delta`` ((N,) norms or (N, m) vectors) and operator norms of ``jac``
    ((N,) norms or (N, m, n) matrices, the spectral norm rounded up)."""
    d = np.asarray(delta, dtype=np.float64)
    j = np.asarray(jac, dtype=np.float64)
    if d.ndim == 2:
        d = norm2_up_np(d, axis=1)  # rigorous upper bounds (drip_cert.numerics.rounding)
    if j.ndim == 3:
        j = np.asarray(spectral_norm_upper(j), dtype=np.float64).reshape(j.shape[0])
    if d.ndim != 1 or j.ndim != 1 or d.shape != j.shape or d.size == 0:
        raise SpecError(
            "delta must be (N,) norms or (N, m) vectors and jac (N,) norms or (N, m, n) matrices "
            f"on the same N >= 1 grid points; got shapes {np.shape(delta)} and {np.shape(jac)}",
            field="delta",
        )
    if not (np.all(np.isfinite(d)) and np.all(np.isfinite(j))) or np.any(d < 0) or np.any(j < 0):
        raise SpecError("delta/jac norms must be finite and >= 0", field="delta")
    return d, j


def h_discrete(delta, jac) -> TrajectoryH:
    """``h_0 = max_t ||Delta(x*_t)||`` and ``h_1 = max_t ||d Delta(x*_t)||_op`` over the time steps
    ``t = 0..T-1`` of a discrete-time expert trajectory (docs/math/tasil.md section 3.1, A3).

    Parameters
    ----------
    delta
        ``(N,)`` norms or ``(N, m)`` values of ``Delta = pi_hat - pi_star`` at ``x*_0..x*_{T-1}``.
    jac
        ``(N,)`` operator norms or ``(N, m, n)`` Jacobians of ``Delta`` there. (Frobenius norms
        are a valid, conservative substitute for operator norms.)
    """
    d, j = _norms(delta, jac)
    i0, i1 = int(np.argmax(d)), int(np.argmax(j))
    return TrajectoryH(
        float(d[i0]), float(j[i1]), float(d[i0]), float(j[i1]), i0, i1, False, How.SOUND
    )


def _sound_sup(t: np.ndarray, v: np.ndarray, rate: np.ndarray, what: str) -> np.ndarray:
    """Per-interval sound sup of a function with grid values ``v`` and time-Lipschitz constant
    ``rate[i]`` on ``[t_i, t_{i+1}]``: ``max(v_i, v_{i+1}, (v_i + v_{i+1} + rate_i dt_i) / 2)``.

    The function lies below both cones ``v_i + rate (s - t_i)`` and
    ``v_{i+1} + rate (t_{i+1} - s)``; the lower envelope peaks at
    ``(v_i + v_{i+1} + rate dt) / 2``. Grid values that jump by more than ``rate * dt``
    contradict the constants and raise :class:`SpecError`.
    """
    dt = np.diff(t)
    slack = rate * dt
    jump = np.abs(np.diff(v))
    bad = jump > slack * (1.0 + _CONSISTENCY_RTOL) + _CONSISTENCY_RTOL * np.maximum(v[1:], v[:-1])
    if np.any(bad):
        i = int(np.argmax(bad))
        raise SpecError(
            f"{what}: the grid values jump by {jump[i]:.6g} on [{t[i]:.6g}, {t[i + 1]:.6g}] "
            f"but the given constants allow only {slack[i]:.6g}; the speed bound or L_Delta "
            "is too small",
            field="speed",
        )
    peak = 0.5 * (v[:-1] + v[1:] + slack)
    peak = np.maximum(peak, np.maximum(v[:-1], v[1:]))
    return peak * (1.0 + _REL_PAD) + 1e-300


def h_continuous(t, delta, jac, speed, L_Delta: float) -> TrajectoryH:
    """Sound continuous-time ``h_0``, ``h_1`` along an expert trajectory (docs/math/tasil.md
    section 4).

    Between grid points, ``|d/dt ||d Delta(x*_t)||| <= L_Delta ||x*_dot||`` gives the sound ``h_1``;
    then ``|d/dt ||Delta(x*_t)||| <= ||d Delta(x*_t)|| ||x*_dot||``, with ``||d Delta||`` bounded on
    each interval by that interval's sound sup, gives the sound ``h_0``. Only ``d Delta`` *along the
    trajectory* enters, so no global Lipschitz constant of ``Delta`` is needed.

    Parameters
    ----------
    t
        Increasing time grid ``(N,)`` covering the interval ``[t_0, t_{N-1}]`` of the sup.
    delta, jac
        As in :func:`h_discrete`, at the grid times.
    speed
        ``sup ||x*_dot||``: a scalar, or ``(N-1,)`` per-interval sups.
    L_Delta
        Lipschitz constant of ``d Delta`` (operator norm) along the trajectory.

    Returns
    -------
    TrajectoryH
        ``how = SOUND``; ``h0 >= h0_grid``, ``h1 >= h1_grid``.
    """
    d, j = _norms(delta, jac)
    t = np.asarray(t, dtype=np.float64)
    if t.shape != d.shape or t.size < 2 or np.any(np.diff(t) <= 0) or not np.all(np.isfinite(t)):
        raise SpecError(
            f"t must be a strictly increasing finite grid with one time per value "
            f"(>= 2 points), got shape {t.shape} for {d.size} values",
            field="t",
        )
    L = _pos("L_Delta", L_Delta, allow_zero=True)
    v = np.broadcast_to(np.asarray(speed, dtype=np.float64), (t.size - 1,))
    if not np.all(np.isfinite(v)) or np.any(v < 0):
        raise SpecError(f"speed must be finite and >= 0, got {speed!r}", field="speed")
    sup1 = _sound_sup(t, j, L * v, "h1 (Jacobian norm)")
    sup0 = _sound_sup(t, d, sup1 * v, "h0 (policy error norm)")
    i0, i1 = int(np.argmax(d)), int(np.argmax(j))
    return TrajectoryH(
        float(sup0.max()),
        float(sup1.max()),
        float(d[i0]),
        float(j[i1]),
        float(t[i0]),
        float(t[i1]),
        True,
        How.SOUND,
    )


def h_from_functions(
    states,
    delta_fn: Callable[[np.ndarray], np.ndarray],
    jac_fn: Callable[[np.ndarray], np.ndarray],
    *,
    t=None,
    speed=None,
    L_Delta: float | None = None,
) -> TrajectoryH:
    """:func:`h_discrete` (``t is None``) or :func:`h_continuous` with ``Delta`` and its Jacobian
    evaluated by callables on the expert states ``(N, n)``: ``delta_fn(states) -> (N, m)``,
    ``jac_fn(states) -> (N, m, n)``. Works for any policy pair."""
    states = np.asarray(states, dtype=np.float64)
    d = np.asarray(delta_fn(states), dtype=np.float64)
    j = np.asarray(jac_fn(states), dtype=np.float64)
    if t is None:
        return h_discrete(d, j)
    if speed is None or L_Delta is None:
        raise SpecError(
            "continuous-time h needs speed and L_Delta (or pass t=None for the discrete max)",
            field="speed",
        )
    return h_continuous(t, d, j, speed, L_Delta)


# =============================================================================== the lemma


def eps_star(h0, h1, gamma0, L_Delta):
    """Smallest root ``eps*`` of ``h0 + gamma0 h1 e + (L/2) gamma0^2 e^2 = e``
    (docs/math/tasil.md 3.1).

    Cancellation-free form ``eps* = 2 h0 / ((1 - b) + sqrt((1 - b)^2 - 2 L gamma0^2 h0))``,
    ``b = gamma0 h1``; ``inf`` where ``b >= 1`` or the discriminant is negative. Vectorised; the
    result is rounded upward.
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
    bound_quarter
        ``2 gamma0 h0`` when the four quarter conditions hold, else ``inf``.
    eps_star
        Smallest root of ``h0 + gamma0 h1 e + (L/2) gamma0^2 e^2 = e`` (``inf`` if none).
    bound_sharp
        ``gamma0 eps*`` when the sharp conditions hold, else ``inf``.
    checks
        Every condition: ``tasil.quarter.*`` (the lemma) and ``tasil.sharp.*`` (its sharp form).
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
    def reason(self) -> str:
        """Empty when the lemma holds, else the failed sharp conditions and by how much."""
        if self.holds:
            return ""
        bad = [c for c in self.checks if c.id.startswith("tasil.sharp") and not c.holds]
        return "; ".join(f"{c.id}: {c.detail} (fails by {-c.margin:.4g})" for c in bad)


def _le(cid: str, lhs: float, rhs: float, text: str, source: str) -> Check:
    lhs, rhs = float(lhs), float(rhs)
    holds = bool(lhs <= rhs)
    margin = rhs - lhs if (math.isfinite(lhs) or math.isfinite(rhs)) else math.nan
    return Check(cid, holds, f"{text}: {lhs:.6g} <= {rhs:.6g}", lhs, rhs, margin, source, How.SOUND)


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

    Quarter form: if ``gamma0 h1 <= 1/4``, ``gamma0^2 L h0 <= 1/4``, ``2 h0 <= eta`` and
    ``2 gamma0 h0 <= R``, then ``max_t ||x_hat_t - x*_t|| <= 2 gamma0 h0``.
    Sharp form: with ``b = gamma0 h1 < 1`` and ``(1-b)^2 >= 2 L gamma0^2 h0``, if
    ``eps* <= eta`` and ``gamma0 eps* <= R`` then the gap is ``<= gamma0 eps*`` (and
    ``max_t ||Delta(x_hat_t)|| <= eps*``).
    The quarter conditions imply the sharp ones (``(1-b)^2 >= 9/16 >= 1/2``, ``eps* <= 2 h0``), so
    the sharp bound is the one reported as :attr:`GapLemma.bound`.

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
    """
    h0 = _pos("h0", h0, allow_zero=True)
    h1 = _pos("h1", h1, allow_zero=True)
    g = _pos("gamma0", gamma0)
    L = _pos("L_Delta", L_Delta, allow_zero=True)
    eta = _pos("eta", eta, allow_inf=True)
    R = _pos("R", R, allow_inf=True)
    src = "docs/math/tasil.md section 4" if continuous else "docs/math/tasil.md section 3.1"
    b = g * h1
    q = [
        _le("tasil.quarter.h1", b, 0.25, "gamma0 h1 <= 1/4", src),
        _le("tasil.quarter.L", g * g * L * h0, 0.25, "gamma0^2 L_Delta h0 <= 1/4", src),
        _le("tasil.quarter.eta", 2 * h0, eta, "2 h0 <= eta", src),
        _le("tasil.quarter.R", 2 * g * h0, R, "2 gamma0 h0 <= R", src),
    ]
    bound_q = _up(2 * g * h0) if all(c.holds for c in q) else math.inf
    es = float(eps_star(h0, h1, g, L))
    one_b = 1.0 - b
    s = [
        _le("tasil.sharp.b", b, 1.0, "b = gamma0 h1 < 1", src),
        _le(
            "tasil.sharp.disc",
            2 * L * g * g * h0,
            one_b * one_b if one_b > 0 else -math.inf,
            "2 L_Delta gamma0^2 h0 <= (1 - b)^2",
            src,
        ),
        _le("tasil.sharp.eta", es, eta, "eps* <= eta", src),
        _le("tasil.sharp.R", g * es, R, "gamma0 eps* <= R", src),
    ]
    if b >= 1.0:  # strict inequality needed
        s[0] = Check(s[0].id, False, s[0].detail, b, 1.0, 1.0 - b, src, How.SOUND)
    bound_s = _up(g * es) if all(c.holds for c in s) and math.isfinite(es) else math.inf
    return GapLemma(h0, h1, g, L, eta, R, bound_q, es, bound_s, tuple(q + s), continuous)


# =============================================================================== statistics


def clopper_pearson_upper(k: int, n: int, delta: float) -> float:
    """One-sided Clopper-Pearson upper confidence bound (docs/math/tasil.md 3.3 c).

    With probability ``>= 1 - delta`` over ``n`` i.i.d. Bernoulli(p) draws with ``k`` successes,
    ``p <= Beta^{-1}(1 - delta; k + 1, n - k)`` (``= 1`` when ``k = n``). At ``k = 0`` this is
    ``1 - delta^{1/n} <= log(1/delta)/n``.
    """
    if int(n) != n or n < 1:
        raise SpecError(f"n must be a positive integer, got {n!r}", field="n_val")
    if int(k) != k or not (0 <= k <= n):
        raise SpecError(f"k must be an integer in [0, n={n}], got {k!r}", field="k")
    delta = _delta_ok(delta)
    if k == n:
        return 1.0
    # scipy's numerical inverse gives a candidate; the bound is the smallest float p (searched
    # upward from it) at which Arb proves I_p(k + 1, n - k) >= 1 - delta: the regularized
    # incomplete beta is the Beta(k + 1, n - k) CDF, increasing in p, so every such p is >= the
    # exact Clopper-Pearson bound
    old_prec = ctx.prec
    ctx.prec = _CP_PREC
    try:
        if k == 0:  # closed form 1 - delta^(1/n), enclosed in Arb
            return min(1.0, arb_hi(1 - arb(delta) ** (arb(1) / n)))
        target = 1 - arb(delta)
        p = up(float(beta_dist.ppf(1.0 - delta, k + 1, n - k)))
        step = _CP_STEP0
        for _ in range(_CP_TRIES):
            if p >= 1.0:
                return 1.0
            if arb(p).beta_lower(k + 1, n - k, regularized=True) >= target:
                return p
            p = up(p * (1.0 + step))
            step *= 10.0
        return 1.0
    finally:
        ctx.prec = old_prec


@dataclass(frozen=True)
class ClassConstants:
    """Class constants of the parametric bounds (docs/math/tasil.md 3.3), fixed before the data.

    Attributes
    ----------
    q
        Number of parameters.
    B_theta
        Radius of the parameter ball ``||theta||_2 <= B_theta``.
    L_theta0, L_theta1
        ``sup_{x, theta} ||d_theta d_x^j pi(x; theta)||`` for ``j = 0, 1``.
    b0, b1
        Ranges ``0 <= h_j <= b_j``.
    theta_norm
        ``||theta_hat||_2`` of the trained policy, checked against ``B_theta`` when given.
    """

    q: int
    B_theta: float
    L_theta0: float
    L_theta1: float
    b0: float
    b1: float
    theta_norm: float | None = None

    def __post_init__(self) -> None:
        if int(self.q) != self.q or self.q < 1:
            raise SpecError(f"q must be a positive integer, got {self.q!r}", field="constants.q")
        for name in ("B_theta", "L_theta0", "L_theta1", "b0", "b1"):
            _pos(f"constants.{name}", getattr(self, name))
        if self.theta_norm is not None:
            _pos("constants.theta_norm", self.theta_norm, allow_zero=True)


def parametric_epsilon(
    n: int, delta: float, q: int, B_theta: float, L_theta: float, alpha: float, n_tau: int = 1
) -> float:
    """``eps_j = (q log(1 + 2 B L / alpha) + log(2/delta) + log K) / n`` (docs/math/tasil.md 3.3 a).

    With probability ``>= 1 - delta`` over ``n`` training trajectories, simultaneously for
    ``j = 0, 1``: ``P_xi[h_j > tau_j + 2 alpha_j] <= eps_j``. ``K = n_tau`` is the size of the grid
    ``tau_j`` was picked from after seeing the data (1 if fixed in advance).
    """
    delta = _delta_ok(delta)
    num = q * math.log1p(2.0 * B_theta * L_theta / alpha) + math.log(2.0 / delta)
    return _up((num + math.log(n_tau)) / n)


def parametric_expectation(
    n: int,
    delta: float,
    tau: float,
    b: float,
    q: int,
    B_theta: float,
    L_theta: float,
    n_tau: int = 1,
) -> float:
    """``R_j(n, delta) = tau_j + (b_j / n)(2 + q log(1 + 2 B L n / b_j) + log(2/delta) + log K)``:
    the bound ``E_xi h_j <= R_j`` of docs/math/tasil.md 3.3 (b), with ``alpha_j = b_j / n``."""
    delta = _delta_ok(delta)
    body = 2.0 + q * math.log1p(2.0 * B_theta * L_theta * n / b) + math.log(2.0 / delta)
    return _up(tau + (b / n) * (body + math.log(n_tau)))


def rho_tasil(
    delta: float, n: int, gamma0: float, tau0: float, constants: ClassConstants, n_tau: int = 1
) -> float:
    """DRIP-shaped ``rho_TaSIL(delta, n) = (6 gamma0 / delta) R_0(n, delta/3)``
    (docs/math/tasil.md 3.4).

    ``O(log n / n)`` as ``n -> inf`` (for ``tau0 = 0``) and ``O(log(1/delta) / delta)`` as
    ``delta -> 0``, the shape of DRIP Theorem ``thm:TaSIL``. Valid only under the conditions that
    :func:`tasil_certificate` checks; this function returns the number alone.
    """
    delta = _delta_ok(delta)
    c = constants
    R0 = parametric_expectation(n, delta / 3.0, tau0, c.b0, c.q, c.B_theta, c.L_theta0, n_tau)
    return _up(6.0 * gamma0 / delta * R0)


# =============================================================================== certificate


@dataclass(frozen=True)
class TasilForm:
    """One statistical form of the certificate.

    Attributes
    ----------
    name
        One of :data:`FORMS`.
    value
        A gap radius (``held_out``, ``threshold``, ``drip_shaped``) or, for ``expectation``, the
        bound on ``E_xi h_0`` (not a gap radius); ``inf`` when it cannot be computed.
    holds
        Every condition of the form holds (so ``value`` is certified at its stated level).
    vacuous
        The statement carries no information (e.g. an exceedance probability ``>= 1``).
    note
        The exact statement, its level and, when it fails, why.
    epsilon
        The exceedance probability ``P_xi[...]`` the form bounds (NaN where not applicable).
    checks
        The conditions.
    """

    name: str
    value: float
    holds: bool
    vacuous: bool
    note: str
    epsilon: float = math.nan
    checks: tuple[Check, ...] = ()

    def to_dict(self) -> dict[str, Any]:
        return {
            "name": self.name,
            "value": json_float(self.value),
            "holds": bool(self.holds),
            "vacuous": bool(self.vacuous),
            "epsilon": json_float(self.epsilon),
            "note": self.note,
            "checks": [c.to_dict() for c in self.checks],
        }


@dataclass(frozen=True)
class TasilCertificate:
    """The TaSIL certificate (docs/math/tasil.md sections 3-4), labelled :data:`LABEL`.

    Attributes
    ----------
    method
        Training method of the policy (free text, e.g. ``"tasil-1"``, ``"bc"``).
    h0, h1
        Maxima over all given (training and held-out) trajectories.
    gamma0, L_Delta, eta, R
        The constants of A1-A2.
    gap_bound, gap_reason
        Deterministic bound over the given initial states: the max over them of the per-state
        sharp lemma bound; ``inf`` with the reason when the lemma fails for some state.
    rho, rho_form
        The statistical gap radius used in ``rho_total`` (joint level ``1 - delta``), and the name
        of its form (chosen before looking at the values: ``use`` argument, or ``held_out`` when
        held-out data are given, else ``drip_shaped``). ``inf`` when that form fails.
    delta, n, n_val
        Confidence parameter and data sizes.
    tau0, tau1
        The thresholds of the held-out and threshold forms.
    forms
        Every statistical form, computed or with the reason it is not.
    vacuous_forms
        Names of the forms that are vacuous or whose conditions fail.
    continuous
        Whether h's are continuous-time sups (section 4).
    """

    method: str
    h0: float
    h1: float
    gamma0: float
    L_Delta: float
    eta: float
    R: float
    gap_bound: float
    gap_reason: str
    rho: float
    rho_form: str
    delta: float
    n: int
    n_val: int
    tau0: float
    tau1: float
    forms: tuple[TasilForm, ...]
    vacuous_forms: tuple[str, ...]
    continuous: bool = False
    gap_checks: tuple[Check, ...] = ()
    label: str = LABEL
    assumptions: tuple[str, ...] = field(default=ASSUMPTIONS)

    @property
    def certified(self) -> bool:
        """``rho`` is finite (its form holds and is not vacuous)."""
        return math.isfinite(self.rho)

    def form(self, name: str) -> TasilForm:
        """The form called ``name``."""
        for f in self.forms:
            if f.name == name:
                return f
        raise KeyError(name)

    def to_dict(self) -> dict[str, Any]:
        """JSON-ready dictionary; ``vacuous`` is true when ``rho`` is not certified."""
        return {
            "method": self.method,
            "label": self.label,
            "h0": json_float(self.h0),
            "h1": json_float(self.h1),
            "gamma0": json_float(self.gamma0),
            "L_Delta": json_float(self.L_Delta),
            "eta": json_float(self.eta),
            "R": json_float(self.R),
            "gap_bound": json_float(self.gap_bound),
            "gap_reason": self.gap_reason,
            "rho": json_float(self.rho),
            "rho_form": self.rho_form,
            "delta": self.delta,
            "n": self.n,
            "n_val": self.n_val,
            "tau0": json_float(self.tau0),
            "tau1": json_float(self.tau1),
            "vacuous": not self.certified,
            "vacuous_forms": list(self.vacuous_forms),
            "continuous": self.continuous,
            "forms": [f.to_dict() for f in self.forms],
            "gap_checks": [c.to_dict() for c in self.gap_checks],
            "assumptions": list(self.assumptions),
        }


def _h_array(name: str, values) -> np.ndarray:
    a = np.asarray(values, dtype=np.float64).reshape(-1)
    if not np.all(np.isfinite(a)) or np.any(a < 0):
        raise SpecError(f"{name} must be finite and >= 0", field=name)
    return a


def _grid_tau(observed: float, b: float) -> float:
    """Smallest ``b 2^{-k/2}`` (``k < K``) ``>= observed`` (docs/math/tasil.md 3.3, grid rule)."""
    grid = b * 2.0 ** (-0.5 * np.arange(_TAU_GRID_SIZE))
    ok = grid[grid >= observed]
    return float(ok.min()) if ok.size else math.inf


def _form_held_out(h0v, h1v, tau0, tau1, gamma0, L, eta, R, delta, cont) -> TasilForm:
    n_val = h0v.size
    k = int(np.sum((h0v > tau0) | (h1v > tau1)))
    eps = clopper_pearson_upper(k, n_val, delta / 2.0)
    lem = imitation_gap_lemma(tau0, tau1, gamma0, L, eta, R, continuous=cont)
    level = Check(
        "tasil.held_out.level",
        eps <= delta / 2.0,
        f"Clopper-Pearson P_xi[h0 > tau0 or h1 > tau1] <= {eps:.4g} must be <= delta/2",
        eps,
        delta / 2.0,
        delta / 2.0 - eps,
        "docs/math/tasil.md 3.3 (c)",
        How.SOUND,
    )
    checks = (level, *[c for c in lem.checks if c.id.startswith("tasil.sharp")])
    holds = level.holds and lem.holds
    note = (
        f"with prob >= 1 - delta/2 over {n_val} held-out trajectories ({k} exceed "
        f"tau=({tau0:.4g}, {tau1:.4g})): P_xi[gap > {lem.bound:.4g}] <= {eps:.4g}; joint level "
        f"1 - delta needs that <= delta/2"
    )
    if not lem.holds:
        note += f"; lemma fails at tau: {lem.reason}"
    return TasilForm("held_out", lem.bound, holds, eps >= 1.0 or not lem.holds, note, eps, checks)


def _tau_for(j: int, observed: float, tau, b: float) -> tuple[float, int]:
    if tau is not None:
        return float(tau[j]), 1
    return _grid_tau(observed, b), _TAU_GRID_SIZE


def _form_threshold(obs, tau, c, n, gamma0, L, eta, R, delta, cont) -> TasilForm:
    t0, K0 = _tau_for(0, obs[0], tau, c.b0)
    t1, K1 = _tau_for(1, obs[1], tau, c.b1)
    a0, a1 = c.b0 / n, c.b1 / n
    e0 = parametric_epsilon(n, delta / 2.0, c.q, c.B_theta, c.L_theta0, a0, K0)
    e1 = parametric_epsilon(n, delta / 2.0, c.q, c.B_theta, c.L_theta1, a1, K1)
    tp0, tp1 = t0 + 2 * a0, t1 + 2 * a1
    lem = imitation_gap_lemma(tp0, tp1, gamma0, L, eta, R, continuous=cont)
    eps = e0 + e1
    checks = [
        _le(
            "tasil.threshold.train0", obs[0], t0, "max_i h0(xi_i) <= tau0", "docs/math/tasil.md 3.3"
        ),
        _le(
            "tasil.threshold.train1", obs[1], t1, "max_i h1(xi_i) <= tau1", "docs/math/tasil.md 3.3"
        ),
        _le(
            "tasil.threshold.level",
            eps,
            delta / 2.0,
            "eps0 + eps1 <= delta/2",
            "docs/math/tasil.md 3.4",
        ),
        *_theta_check(c),
        *[x for x in lem.checks if x.id.startswith("tasil.sharp")],
    ]
    holds = all(x.holds for x in checks)
    note = (
        f"with prob >= 1 - delta/2 over {n} training trajectories: P_xi[gap > {lem.bound:.4g}] "
        f"<= eps0 + eps1 = {e0:.4g} + {e1:.4g} (alpha_j = b_j/n, tau+ = ({tp0:.4g}, {tp1:.4g}), "
        f"q = {c.q})"
    )
    if eps >= 1.0:
        note += "; VACUOUS: eps >= 1 (n too small for q parameters)"
    return TasilForm("threshold", lem.bound, holds, eps >= 1.0, note, eps, tuple(checks))


def _theta_check(c: ClassConstants) -> list[Check]:
    if c.theta_norm is None:
        return []
    return [_le("tasil.theta_ball", c.theta_norm, c.B_theta, "||theta_hat|| <= B_theta", _SOURCE)]


def _form_expectation(obs, tau, c, n, delta) -> TasilForm:
    t0, K0 = _tau_for(0, obs[0], tau, c.b0)
    t1, K1 = _tau_for(1, obs[1], tau, c.b1)
    R0 = parametric_expectation(n, delta, t0, c.b0, c.q, c.B_theta, c.L_theta0, K0)
    R1 = parametric_expectation(n, delta, t1, c.b1, c.q, c.B_theta, c.L_theta1, K1)
    checks = [
        _le(
            "tasil.expectation.train0",
            obs[0],
            t0,
            "max_i h0(xi_i) <= tau0",
            "docs/math/tasil.md 3.3",
        ),
        _le(
            "tasil.expectation.train1",
            obs[1],
            t1,
            "max_i h1(xi_i) <= tau1",
            "docs/math/tasil.md 3.3",
        ),
        *_theta_check(c),
    ]
    vac = R0 >= c.b0 and R1 >= c.b1
    note = (
        f"with prob >= 1 - delta: E_xi h0 <= R0 = {R0:.4g} and E_xi h1 <= R1 = {R1:.4g} "
        f"(ranges b = ({c.b0:.4g}, {c.b1:.4g})); a bound on E h0, not a gap radius"
    )
    if vac:
        note += "; VACUOUS: R_j >= b_j"
    return TasilForm(
        "expectation", R0, all(x.holds for x in checks), vac, note, math.nan, tuple(checks)
    )


def _form_drip(obs, tau, c, n, gamma0, L, eta, R, delta) -> TasilForm:
    t0, K0 = _tau_for(0, obs[0], tau, c.b0)
    t1, K1 = _tau_for(1, obs[1], tau, c.b1)
    d3 = delta / 3.0
    R0 = parametric_expectation(n, d3, t0, c.b0, c.q, c.B_theta, c.L_theta0, K0)
    R1 = parametric_expectation(n, d3, t1, c.b1, c.q, c.B_theta, c.L_theta1, K1)
    m0, m1 = 3.0 / delta * R0, 3.0 / delta * R1
    rho = rho_tasil(delta, n, gamma0, t0, c, K0)
    src = "docs/math/tasil.md 3.4"
    checks = [
        _le("tasil.drip.train0", obs[0], t0, "max_i h0(xi_i) <= tau0", "docs/math/tasil.md 3.3"),
        _le("tasil.drip.train1", obs[1], t1, "max_i h1(xi_i) <= tau1", "docs/math/tasil.md 3.3"),
        _le("tasil.drip.L", gamma0**2 * L * m0, 0.25, "gamma0^2 L_Delta (3/delta) R0 <= 1/4", src),
        _le("tasil.drip.h1", 4 * gamma0 * m1, 1.0, "4 gamma0 (3/delta) R1 <= 1", src),
        _le("tasil.drip.eta", 2 * m0, eta, "2 (3/delta) R0 <= eta", src),
        _le("tasil.drip.R", 2 * gamma0 * m0, R, "2 gamma0 (3/delta) R0 <= R", src),
        *_theta_check(c),
    ]
    holds = all(x.holds for x in checks)
    vac = m0 >= c.b0
    note = (
        f"with prob >= 1 - delta jointly over data and xi: gap <= (6 gamma0/delta) R0(n, delta/3) "
        f"= {rho:.4g} (R0 = {R0:.4g}, R1 = {R1:.4g}, q = {c.q}, n = {n})"
    )
    if vac:
        note += "; VACUOUS: the Markov level (3/delta) R0 >= b0 says nothing about h0"
    if not holds:
        bad = [x.id for x in checks if not x.holds]
        note += f"; conditions fail: {', '.join(bad)}"
    return TasilForm("drip_shaped", rho, holds, vac, note, math.nan, tuple(checks))


def tasil_certificate(
    train_h0: Sequence[float],
    train_h1: Sequence[float],
    *,
    gamma0: float,
    L_Delta: float,
    delta: float,
    eta: float = math.inf,
    R: float = math.inf,
    heldout_h0: Sequence[float] | None = None,
    heldout_h1: Sequence[float] | None = None,
    tau: tuple[float, float] | None = None,
    constants: ClassConstants | None = None,
    use: str | None = None,
    method: str = "tasil-1",
    continuous: bool = False,
) -> TasilCertificate:
    """Build the TaSIL certificate (docs/math/tasil.md sections 3-4; DRIP Theorem ``thm:TaSIL``
    shape).

    Parameters
    ----------
    train_h0, train_h1
        Per-trajectory ``h_0``, ``h_1`` of the ``n`` training trajectories (:class:`TrajectoryH`).
    gamma0, L_Delta, eta, R
        The constants of A1-A2 (``gamma0`` from the delta-ISS analysis).
    delta
        Joint failure probability of ``rho``.
    heldout_h0, heldout_h1
        Per-trajectory h's of ``n_val`` fresh expert trajectories not used in training (form 3.3 c).
    tau
        ``(tau0, tau1)`` fixed before seeing any data. When ``None``: the held-out form uses the
        training maxima (independent of the held-out data); the parametric forms round the
        training maxima up to a geometric grid of :data:`_TAU_GRID_SIZE` values and pay
        ``log K``.
    constants
        :class:`ClassConstants` for the parametric forms (3.3 a, b and 3.4); omitted forms are
        reported as not computed.
    use
        The form whose radius becomes ``rho``: ``"held_out"``, ``"threshold"`` or
        ``"drip_shaped"``. Default: ``"held_out"`` when held-out data are given, else
        ``"drip_shaped"``. It is fixed by the inputs, never by comparing values (taking the
        minimum over forms would need a union bound over them).
    method
        Name of the training method, recorded.
    continuous
        The h's are continuous-time sups (section 4).

    Returns
    -------
    TasilCertificate
    """
    h0t, h1t = _h_array("train_h0", train_h0), _h_array("train_h1", train_h1)
    if h0t.size != h1t.size or h0t.size == 0:
        raise SpecError(
            f"train_h0 and train_h1 need the same number (>= 1) of trajectories, got "
            f"{h0t.size} and {h1t.size}",
            field="train_h0",
        )
    have_val = heldout_h0 is not None or heldout_h1 is not None
    if have_val:
        if heldout_h0 is None or heldout_h1 is None:
            raise SpecError("give both heldout_h0 and heldout_h1", field="heldout_h0")
        h0v, h1v = _h_array("heldout_h0", heldout_h0), _h_array("heldout_h1", heldout_h1)
        if h0v.size != h1v.size or h0v.size == 0:
            raise SpecError(
                f"heldout_h0/heldout_h1 sizes differ or are empty: {h0v.size}, {h1v.size}",
                field="heldout_h0",
            )
    else:
        h0v = h1v = np.zeros(0)
    delta = _delta_ok(delta)
    gamma0 = _pos("gamma0", gamma0)
    L = _pos("L_Delta", L_Delta, allow_zero=True)
    eta = _pos("eta", eta, allow_inf=True)
    R = _pos("R", R, allow_inf=True)
    if tau is not None:
        if len(tau) != 2:
            raise SpecError(f"tau must be (tau0, tau1), got {tau!r}", field="tau")
        tau = (_pos("tau[0]", tau[0], allow_zero=True), _pos("tau[1]", tau[1], allow_zero=True))
    if use is None:
        use = "held_out" if have_val else "drip_shaped"
    if use not in ("held_out", "threshold", "drip_shaped"):
        raise SpecError(
            f"use={use!r}: rho must come from 'held_out', 'threshold' or 'drip_shaped'", field="use"
        )
    if use == "held_out" and not have_val:
        raise SpecError(
            "use='held_out' needs heldout_h0/heldout_h1 from fresh expert trajectories; give them "
            "or choose use='drip_shaped' with class constants",
            field="heldout_h0",
        )
    if use in ("threshold", "drip_shaped") and constants is None:
        raise SpecError(
            f"use={use!r} needs class constants (ClassConstants q, B_theta, L_theta, b); give them "
            "or held-out trajectories and use='held_out'",
            field="constants",
        )
    n, n_val = int(h0t.size), int(h0v.size)

    # deterministic lemma per given initial state
    all0, all1 = np.concatenate([h0t, h0v]), np.concatenate([h1t, h1v])
    bounds = eps_star(all0, all1, gamma0, L) * gamma0
    worst = int(np.argmax(bounds))
    lem = imitation_gap_lemma(all0[worst], all1[worst], gamma0, L, eta, R, continuous=continuous)
    n_fail = 0
    if not lem.holds:
        n_fail = sum(
            not imitation_gap_lemma(a, b, gamma0, L, eta, R).holds for a, b in zip(all0, all1)
        )
    gap_bound = lem.bound
    where = "training" if worst < n else "held-out"
    idx = worst if worst < n else worst - n
    gap_reason = (
        ""
        if lem.holds
        else f"lemma fails on {n_fail} of {all0.size} states; worst: {where} #{idx}: {lem.reason}"
    )

    obs = (float(h0t.max()), float(h1t.max()))
    forms: list[TasilForm] = []
    if have_val:
        t0, t1 = tau if tau is not None else obs
        forms.append(_form_held_out(h0v, h1v, t0, t1, gamma0, L, eta, R, delta, continuous))
    else:
        forms.append(TasilForm("held_out", math.inf, False, True, "not computed: no held-out data"))
    if constants is not None:
        forms.append(_form_threshold(obs, tau, constants, n, gamma0, L, eta, R, delta, continuous))
        forms.append(_form_expectation(obs, tau, constants, n, delta))
        forms.append(_form_drip(obs, tau, constants, n, gamma0, L, eta, R, delta))
    else:
        for name in ("threshold", "expectation", "drip_shaped"):
            forms.append(TasilForm(name, math.inf, False, True, "not computed: no class constants"))
    chosen = next(f for f in forms if f.name == use)
    ok = chosen.holds and not chosen.vacuous and math.isfinite(chosen.value)
    rho = chosen.value if ok else math.inf
    vac = tuple(f.name for f in forms if f.vacuous or not f.holds)
    if have_val:
        tau0, tau1 = tau if tau is not None else obs
    else:
        tau0, tau1 = tau if tau is not None else (math.nan, math.nan)
    return TasilCertificate(
        method=method,
        h0=float(all0.max()),
        h1=float(all1.max()),
        gamma0=gamma0,
        L_Delta=L,
        eta=eta,
        R=R,
        gap_bound=gap_bound,
        gap_reason=gap_reason,
        rho=rho,
        rho_form=use,
        delta=delta,
        n=n,
        n_val=n_val,
        tau0=float(tau0),
        tau1=float(tau1),
        forms=tuple(forms),
        vacuous_forms=vac,
        continuous=continuous,
        gap_checks=lem.checks,
    )
