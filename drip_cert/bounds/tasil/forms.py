"""The statistical forms of the TaSIL certificate (docs/math/tasil.md sections 3.3-3.4): from the
``h_0, h_1`` of training (and held-out) trajectories to a statement about a fresh initial state
``xi ~ D``.

* held-out form (3.3 c): a Clopper-Pearson bound on how often fresh states exceed thresholds
  ``tau`` fixed from the training data, then the sharp lemma at ``tau``;
* threshold form (3.3 a, 3.4): a covering-number PAC bound :func:`parametric_epsilon`;
* expectation form (3.3 b): :func:`parametric_expectation`, a bound on ``E_xi h_j``;
* DRIP-shaped form (3.4): :func:`rho_tasil`, ``(6 gamma0 / delta) R_0(n, delta/3)`` through a
  Markov step.

Every form is **this project's construction**, not TaSIL's own constant.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Any

import numpy as np

from drip_cert.bounds.tasil._common import check_le, positive, probability, up_closed_form
from drip_cert.bounds.tasil.lemma import imitation_gap_lemma
from drip_cert.errors import SpecError
from drip_cert.numerics.stats import clopper_pearson_upper, min_trials_zero_failures
from drip_cert.provenance import Check, How, json_float

__all__ = [
    "FORMS",
    "ClassConstants",
    "TasilForm",
    "parametric_epsilon",
    "parametric_expectation",
    "rho_tasil",
]

FORMS = ("held_out", "threshold", "expectation", "drip_shaped", "uniform")
_SOURCE = "docs/math/tasil.md section 3 (this project's construction)"
# size of the geometric grid tau_j in {b_j 2^{-k/2}: k = 0..K-1} used when tau is data-chosen
_TAU_GRID_SIZE = 64


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
            positive(f"constants.{name}", getattr(self, name))
        if self.theta_norm is not None:
            positive("constants.theta_norm", self.theta_norm, allow_zero=True)


def parametric_epsilon(
    n: int, delta: float, q: int, B_theta: float, L_theta: float, alpha: float, n_tau: int = 1
) -> float:
    """``eps_j = (q log(1 + 2 B L / alpha) + log(2/delta) + log K) / n`` (docs/math/tasil.md 3.3 a).

    With probability ``>= 1 - delta`` over ``n`` training trajectories, simultaneously for
    ``j = 0, 1``: ``P_xi[h_j > tau_j + 2 alpha_j] <= eps_j``.

    Parameters
    ----------
    n, delta
        Number of training trajectories and failure probability.
    q, B_theta, L_theta
        Class constants (:class:`ClassConstants`; ``L_theta = L_theta_j``).
    alpha
        Resolution ``alpha_j`` of the net.
    n_tau
        ``K``, the size of the grid ``tau_j`` was picked from after seeing the data (1 if fixed
        in advance).

    Returns
    -------
    float
        ``eps_j``, rounded up.
    """
    delta = probability(delta)
    num = q * math.log1p(2.0 * B_theta * L_theta / alpha) + math.log(2.0 / delta)
    return up_closed_form((num + math.log(n_tau)) / n)


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
    the bound ``E_xi h_j <= R_j`` of docs/math/tasil.md 3.3 (b), with ``alpha_j = b_j / n``.

    Parameters
    ----------
    tau, b
        Threshold ``tau_j`` and range ``b_j`` of ``h_j``.
    n, delta, q, B_theta, L_theta, n_tau
        As in :func:`parametric_epsilon`.

    Returns
    -------
    float
        ``R_j``, rounded up.
    """
    delta = probability(delta)
    body = 2.0 + q * math.log1p(2.0 * B_theta * L_theta * n / b) + math.log(2.0 / delta)
    return up_closed_form(tau + (b / n) * (body + math.log(n_tau)))


def _drip_radius(gamma0: float, delta: float, R0: float) -> float:
    """``(6 gamma0 / delta) R_0`` rounded up: the DRIP-shaped radius from ``R_0(n, delta/3)``."""
    return up_closed_form(6.0 * gamma0 / delta * R0)


def _expectation_bounds(n: int, delta: float, taus, c: ClassConstants) -> tuple[float, float]:
    """``(R_0, R_1)`` of :func:`parametric_expectation` at ``taus = ((tau0, K0), (tau1, K1))``."""
    (t0, K0), (t1, K1) = taus
    R0 = parametric_expectation(n, delta, t0, c.b0, c.q, c.B_theta, c.L_theta0, K0)
    R1 = parametric_expectation(n, delta, t1, c.b1, c.q, c.B_theta, c.L_theta1, K1)
    return R0, R1


def rho_tasil(
    delta: float, n: int, gamma0: float, tau0: float, constants: ClassConstants, n_tau: int = 1
) -> float:
    """DRIP-shaped ``rho_TaSIL(delta, n) = (6 gamma0 / delta) R_0(n, delta/3)``
    (docs/math/tasil.md 3.4).

    ``O(log n / n)`` as ``n -> inf`` (for ``tau0 = 0``) and ``O(log(1/delta) / delta)`` as
    ``delta -> 0``, the shape of DRIP Theorem ``thm:TaSIL``. Valid only under the conditions that
    :func:`~drip_cert.bounds.tasil.certificate.tasil_certificate` checks; this function returns the
    number alone.

    Parameters
    ----------
    delta, n
        Joint failure probability and number of training trajectories.
    gamma0
        Linear delta-ISS gain (A1).
    tau0, constants, n_tau
        Threshold of ``h_0``, class constants and the size ``K`` of its grid.

    Returns
    -------
    float
        The radius, rounded up.
    """
    delta = probability(delta)
    c = constants
    R0 = parametric_expectation(n, delta / 3.0, tau0, c.b0, c.q, c.B_theta, c.L_theta0, n_tau)
    return _drip_radius(gamma0, delta, R0)


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
        """JSON-ready dictionary."""
        return {
            "name": self.name,
            "value": json_float(self.value),
            "holds": bool(self.holds),
            "vacuous": bool(self.vacuous),
            "epsilon": json_float(self.epsilon),
            "note": self.note,
            "checks": [c.to_dict() for c in self.checks],
        }


def _grid_tau(observed: float, b: float) -> float:
    """Smallest ``b 2^{-k/2}`` (``k < K``) ``>= observed`` (docs/math/tasil.md 3.3, grid rule)."""
    grid = b * 2.0 ** (-0.5 * np.arange(_TAU_GRID_SIZE))
    ok = grid[grid >= observed]
    return float(ok.min()) if ok.size else math.inf


def _thresholds(obs, tau, c: ClassConstants) -> tuple[tuple[float, int], tuple[float, int]]:
    """``((tau0, K0), (tau1, K1))``: the given ``tau`` (``K = 1``), or the training maxima ``obs``
    rounded up to the grid of :data:`_TAU_GRID_SIZE` values (docs/math/tasil.md 3.3)."""
    if tau is not None:
        return (float(tau[0]), 1), (float(tau[1]), 1)
    return (_grid_tau(obs[0], c.b0), _TAU_GRID_SIZE), (_grid_tau(obs[1], c.b1), _TAU_GRID_SIZE)


def _train_checks(form: str, obs, t0: float, t1: float) -> list[Check]:
    """``max_i h_j(xi_i) <= tau_j`` on the training data, ``j = 0, 1`` (docs/math/tasil.md 3.3)."""
    src = "docs/math/tasil.md 3.3"
    return [
        check_le(f"tasil.{form}.train0", obs[0], t0, "max_i h0(xi_i) <= tau0", src),
        check_le(f"tasil.{form}.train1", obs[1], t1, "max_i h1(xi_i) <= tau1", src),
    ]


def _theta_check(c: ClassConstants) -> list[Check]:
    if c.theta_norm is None:
        return []
    return [
        check_le("tasil.theta_ball", c.theta_norm, c.B_theta, "||theta_hat|| <= B_theta", _SOURCE)
    ]


def form_uniform(rho: float, how: str, remark: str = "") -> TasilForm:
    """The sure form ``uniform`` (docs/math/tasil.md 3.8): ``gap <= rho`` for every initial state
    of the support with probability one; ``how`` says which product gives ``rho``, ``remark`` is
    appended inside the parenthesis."""
    note = f"every initial state of the support: gap <= {how} (probability 1{remark})"
    return TasilForm("uniform", rho, True, False, note)


def form_held_out(
    h0v, h1v, tau0, tau1, gamma0, L, eta, R, delta, cont, comparison_gain=None
) -> TasilForm:
    """The held-out form (docs/math/tasil.md 3.3 c, 3.4): ``k`` of the held-out h's exceed
    ``tau``; the sound Clopper-Pearson bound at confidence ``1 - delta/2`` must be
    ``<= delta/2``, and the sharp lemma at ``tau`` gives the radius. With a
    ``comparison_gain`` (a learned loop contracting on all of ``R^n``, docs/math/tasil.md
    Proposition 3.7) the radius is the smaller of that and ``comparison_gain * tau0``: on the
    event ``h0 <= tau0`` (which contains the event the level bounds) that bound holds too."""
    n_val = h0v.size
    k = int(np.sum((h0v > tau0) | (h1v > tau1)))
    eps = float(clopper_pearson_upper(k, n_val, alpha=delta / 2.0, sound=True))
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
    value, route_checks, route = lem.bound, lem.sharp_checks, "lemma"
    if comparison_gain is not None:
        cmp = up_closed_form(comparison_gain * tau0)
        if cmp < value:
            value, route = cmp, "comparison"
            route_checks = (
                check_le(
                    "tasil.comparison",
                    cmp,
                    math.inf,
                    f"learned loop contracting on R^n: gap <= sup||g||_2 / lambda_IL * tau0 = "
                    f"{comparison_gain:.6g} * {tau0:.6g}",
                    "docs/math/tasil.md section 3.7",
                ),
            )
    checks = (level, *route_checks)
    finite = math.isfinite(value)
    holds = level.holds and finite
    note = (
        f"with prob >= 1 - delta/2 over {n_val} held-out trajectories ({k} exceed "
        f"tau=({tau0:.4g}, {tau1:.4g})): P_xi[gap > {value:.4g}] <= {eps:.4g}; joint level "
        f"1 - delta needs that <= delta/2"
    )
    if route == "comparison":
        note += f" (comparison bound of the learned loop; the lemma gives {lem.bound:.4g})"
    elif not lem.holds:
        note += f"; lemma fails at tau: {lem.reason}"
    need = min_trials_zero_failures(delta / 2.0, delta / 2.0)
    if n_val < need:
        note += (
            f"; with {n_val} held-out trajectories this form can never pass at delta = "
            f"{delta:g} (even with none exceeding tau the bound stays above delta/2): set "
            f"[tasil] heldout >= {need}"
        )
    return TasilForm("held_out", value, holds, eps >= 1.0 or not finite, note, eps, checks)


def form_held_out_comparison(h0v, tau0: float, comparison_gain: float, delta: float) -> TasilForm:
    """The held-out form through the comparison bound alone (docs/math/tasil.md 3.3 c with
    Proposition 3.7), for a policy whose Jacobian is not Lipschitz (no lemma, no ``h_1``).

    With the learned loop contracting on all of ``R^n``, every initial state's gap is at most
    ``comparison_gain * h_0(xi)``, so ``P_xi[gap > comparison_gain * tau0] <=
    P_xi[h_0 > tau0]``, which the sound Clopper-Pearson bound on the ``k`` held-out ``h_0`` above
    ``tau0`` bounds at confidence ``1 - delta/2``; that must be ``<= delta/2``."""
    h0v = np.asarray(h0v, dtype=np.float64)
    n_val = h0v.size
    k = int(np.sum(h0v > tau0))
    eps = float(clopper_pearson_upper(k, n_val, alpha=delta / 2.0, sound=True))
    level = Check(
        "tasil.held_out.level",
        eps <= delta / 2.0,
        f"Clopper-Pearson P_xi[h0 > tau0] <= {eps:.4g} must be <= delta/2",
        eps,
        delta / 2.0,
        delta / 2.0 - eps,
        "docs/math/tasil.md 3.3 (c)",
        How.SOUND,
    )
    value = up_closed_form(comparison_gain * tau0)
    route = check_le(
        "tasil.comparison",
        value,
        math.inf,
        f"learned loop contracting on R^n: gap <= gamma_IL * tau0 = {comparison_gain:.6g} * "
        f"{tau0:.6g} (no Jacobian-Lipschitz constant needed)",
        "docs/math/tasil.md section 3.7",
    )
    finite = math.isfinite(value)
    note = (
        f"with prob >= 1 - delta/2 over {n_val} held-out trajectories ({k} exceed "
        f"tau0={tau0:.4g}): P_xi[gap > {value:.4g}] <= {eps:.4g} (comparison bound of the "
        f"learned loop; the lemma route is not applicable: the policy's Jacobian is not "
        f"Lipschitz); joint level 1 - delta needs that <= delta/2"
    )
    need = min_trials_zero_failures(delta / 2.0, delta / 2.0)
    if n_val < need:
        note += f"; set [tasil] heldout >= {need} for this form to be able to pass"
    return TasilForm(
        "held_out",
        value,
        level.holds and finite,
        eps >= 1.0 or not finite,
        note,
        eps,
        (level, route),
    )


def form_threshold(obs, tau, c, n, gamma0, L, eta, R, delta, cont) -> TasilForm:
    """The threshold form (docs/math/tasil.md 3.3 a, 3.4): ``eps_0 + eps_1 <= delta/2`` at
    confidence ``1 - delta/2`` and the sharp lemma at ``tau + 2 alpha``, ``alpha_j = b_j / n``."""
    (t0, K0), (t1, K1) = _thresholds(obs, tau, c)
    a0, a1 = c.b0 / n, c.b1 / n
    e0 = parametric_epsilon(n, delta / 2.0, c.q, c.B_theta, c.L_theta0, a0, K0)
    e1 = parametric_epsilon(n, delta / 2.0, c.q, c.B_theta, c.L_theta1, a1, K1)
    tp0, tp1 = t0 + 2 * a0, t1 + 2 * a1
    lem = imitation_gap_lemma(tp0, tp1, gamma0, L, eta, R, continuous=cont)
    eps = e0 + e1
    checks = [
        *_train_checks("threshold", obs, t0, t1),
        check_le(
            "tasil.threshold.level",
            eps,
            delta / 2.0,
            "eps0 + eps1 <= delta/2",
            "docs/math/tasil.md 3.4",
        ),
        *_theta_check(c),
        *lem.sharp_checks,
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


def form_expectation(obs, tau, c, n, delta) -> TasilForm:
    """The expectation form (docs/math/tasil.md 3.3 b): ``E_xi h_j <= R_j(n, delta)``, a bound on
    ``E h_0`` reported for information, not a gap radius."""
    taus = _thresholds(obs, tau, c)
    R0, R1 = _expectation_bounds(n, delta, taus, c)
    checks = [*_train_checks("expectation", obs, taus[0][0], taus[1][0]), *_theta_check(c)]
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


def form_drip(obs, tau, c, n, gamma0, L, eta, R, delta) -> TasilForm:
    """The DRIP-shaped form (docs/math/tasil.md 3.4): ``delta`` split in three (data, Markov for
    ``h_0``, Markov for ``h_1``); the quarter conditions at ``m_j = (3/delta) R_j(n, delta/3)``
    give the radius ``2 gamma0 m_0 = rho_TaSIL``."""
    taus = _thresholds(obs, tau, c)
    t0, t1 = taus[0][0], taus[1][0]
    R0, R1 = _expectation_bounds(n, delta / 3.0, taus, c)
    m0, m1 = 3.0 / delta * R0, 3.0 / delta * R1
    rho = _drip_radius(gamma0, delta, R0)
    src = "docs/math/tasil.md 3.4"
    checks = [
        *_train_checks("drip", obs, t0, t1),
        check_le(
            "tasil.drip.L", gamma0**2 * L * m0, 0.25, "gamma0^2 L_Delta (3/delta) R0 <= 1/4", src
        ),
        check_le("tasil.drip.h1", 4 * gamma0 * m1, 1.0, "4 gamma0 (3/delta) R1 <= 1", src),
        check_le("tasil.drip.eta", 2 * m0, eta, "2 (3/delta) R0 <= eta", src),
        check_le("tasil.drip.R", 2 * gamma0 * m0, R, "2 gamma0 (3/delta) R0 <= R", src),
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
