"""Theorem 4.1 of L1-DRAC: the moment order for a probability, the Markov radius kappa and the
ultimate bound.

Source: A. Gahlawat, S. H. Karumanchi, N. Hovakimyan, "L1-DRAC: Distributionally Robust Adaptive
Control -- Global Results", arXiv:2509.04619 (2025-09-04), Sec. 4 (Lemma 4.4, (85); Theorem 4.1,
(129b), (130a)); ``docs/math/l1drac.md`` section 7 and erratum E9 of section 8.

Public surface
--------------
* :func:`p_for_delta` -- the integer moment order Theorem 4.1 needs for a probability delta.
* :func:`kappa_markov` -- the high-probability radius ``rho(p) delta^{-1/(2p)}`` (130a).
* :func:`ultimate_bound` -- the ultimate bound (129b) of a feasible design.
"""

from __future__ import annotations

import math

from drip_cert.bounds.l1drac.appendix import reference_constants
from drip_cert.bounds.l1drac.constants import L1Constants, is_real
from drip_cert.bounds.l1drac.result import L1Design
from drip_cert.bounds.l1drac.sides import gamma_r, theta_r
from drip_cert.errors import SpecError

__all__ = ["p_for_delta", "kappa_markov", "ultimate_bound"]


def _check_probability(delta: float) -> None:
    if not (is_real(delta) and 0.0 < delta < 1.0):
        raise SpecError(f"{delta!r} is not a probability in (0, 1)", field="delta")


def p_for_delta(delta: float, p_star: int) -> int:
    """The integer moment order Theorem 4.1 needs for a violation probability delta.

    The paper sets ``p = log sqrt(1/delta)``, an integer only for ``delta = e^{-2p}``. The valid
    integer variant (docs/math/l1drac.md section 7; erratum E9 in section 8) is
    ``p = max(1, ceil(0.5 log(1/delta)))``, for
    which ``kappa_markov(rho, p, delta) <= e rho(p)``.

    Raises
    ------
    SpecError
        delta not in (0, 1), or the p it needs exceeds p_star.
    """
    _check_probability(delta)
    p = max(1, math.ceil(0.5 * math.log(1.0 / delta)))
    if p > 1 and delta >= math.exp(-2.0 * (p - 1)):  # rounding of the log at delta = e^{-2k}
        p -= 1
    if p > p_star:
        raise SpecError(
            f"delta = {delta!r} needs p = ceil(0.5 log(1/delta)) = {p} > p_star = {p_star}: the "
            "nominal process has no bounded moment of that order (Assumption 3); use a larger "
            f"delta (>= {math.exp(-2 * p_star):.3g}) or raise p_star",
            field="delta",
        )
    return p


def kappa_markov(rho: float, p: int, delta: float) -> float:
    """kappa = rho(p) delta^{-1/(2p)}: P(||X_t - X*_t|| >= kappa) < delta (Theorem 4.1, (130a)).

    This is the Markov step of the proof of Theorem 4.1 at an integer p, valid for every delta in
    (0, 1) (``P(|Z| >= k) <= E|Z|^{2p} / k^{2p} < (rho/k)^{2p} = delta``). The paper's
    ``e * rho(log sqrt(1/delta))`` is the case ``p = log sqrt(1/delta)``; with
    ``p = p_for_delta(delta, .)`` this value is ``<= e rho(p)``. Requires the hypotheses with
    ``alpha = ||X0 - X0*||_{L_2p}`` (a coupling), as Theorem 4.1 states.
    """
    _check_probability(delta)
    return rho * delta ** (-1.0 / (2 * p))


def ultimate_bound(c: L1Constants, d: L1Design, t_hat: float) -> float:
    """hat-rho(p, omega, t_hat) = hat-rho_r + rho_a, the ultimate bound (129b) on [t_hat, T].

    hat-rho_r is (85) of Lemma 4.4: ``(e^{-2 lambda t_hat} alpha^2 + Dgp Dmup/lambda rho_r^2 +
    Gamma_r(rho_r) + Theta_r(rho_r)/|2 lambda - omega|)^{1/2}`` (alpha in the role of
    W_2p(xi_0, xi_0*)). Strictly below rho(p) for a feasible design (Lemma 4.4).
    """
    if not d.feasible:
        raise SpecError("the ultimate bound needs a feasible design", field="design")
    if not (is_real(t_hat) and t_hat >= 0.0 and math.isfinite(t_hat)):
        raise SpecError(f"{t_hat!r} must be a finite time >= 0", field="t_hat")
    w, rho_r, rho_a = d.omega, d.rho_r, d.rho_a
    if w is None or rho_r is None or rho_a is None:
        raise SpecError(
            "the ultimate bound needs omega, rho_r and rho_a; this design marked feasible lacks "
            f"one (omega = {w!r}, rho_r = {rho_r!r}, rho_a = {rho_a!r})",
            field="design",
        )
    rc = reference_constants(c, d.p)
    inner = (
        math.exp(-2.0 * c.lam * t_hat) * c.alpha**2
        + c.k_r * rho_r**2
        + gamma_r(rho_r, w, rc)
        + theta_r(rho_r, w, rc) / abs(2.0 * c.lam - w)
    )
    return math.sqrt(inner) + rho_a
