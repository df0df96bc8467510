"""Sec. 3.2 of L1-DRAC: Gamma, Theta, the Upsilon_a maps and the two sides of each condition.

Source: A. Gahlawat, S. H. Karumanchi, N. Hovakimyan, "L1-DRAC: Distributionally Robust Adaptive
Control -- Global Results", arXiv:2509.04619 (2025-09-04), Sec. 3.2 (printed pp. 14-15):
Gamma_r, Gamma_a (18b, c), Theta_r, Theta_a (22, 23), the Upsilon maps (25a-c) and the design
conditions (16a), (16b), (21a), (21b), (24), built on the Appendix A constants of
:mod:`drip_cert.bounds.l1drac.appendix`.

Like the appendix, every function is written once, generic over the numeric backend that the
constants object carries (``c.num``, ``rc.num``, ``tc.num``, ``s.num``), so the designer's float64
searches and the Arb re-check of :mod:`drip_cert.bounds.l1drac.verify` run the same code.
"""

from __future__ import annotations

from drip_cert.bounds.l1drac.appendix import (
    RefConstants,
    SamplingConstants,
    TrueConstants,
    sampling_constants,
    upsilon1_prime,
    upsilon2_prime,
    upsilon3_prime,
    upsilon_minus,
    upsilon_minus_tilde,
    upsilon_ring,
)
from drip_cert.bounds.l1drac.backend import Real
from drip_cert.bounds.l1drac.constants import L1ConstantsLike, unmatched_gain_a, unmatched_gain_r

__all__ = [
    "gamma_r",
    "gamma_a",
    "theta_r",
    "theta_a",
    "upsilon_a1",
    "upsilon_a2",
    "upsilon_a3",
    "upsilon_sum",
    "RELATIONS",
    "margin_of",
    "sides_16a",
    "sides_16b",
    "sides_21a",
    "sides_21b",
    "sides_24",
    "sides_24_at",
    "budget_a",
    "budget_24",
]

# --------------------------------------------------------------------------------------------
# Sec. 3.2: Gamma_r, Gamma_a (18b, c), Theta_r, Theta_a (22, 23), Upsilon_a (25a-c)
# --------------------------------------------------------------------------------------------


def _abs_gap(lam: Real, omega: Real) -> Real:
    """|2 lambda - omega| (the caller guarantees omega != 2 lambda)."""
    return abs(2.0 * lam - omega)


def gamma_r(rho_r: Real, omega: Real, rc: RefConstants) -> Real:
    """Gamma_r(rho_r, p, omega); implements (18b) of L1-DRAC.

    Parameters
    ----------
    rho_r
        The reference-process radius varrho_r(p) >= 0.
    omega
        Filter bandwidth, ``omega != 2 lambda``.
    rc
        :func:`~drip_cert.bounds.l1drac.appendix.reference_constants` at the same p.
    """
    num = rc.num
    rho_r, omega = num.const(rho_r), num.const(omega)
    lam = rc.lam
    w = omega / _abs_gap(lam, omega)
    sl = num.sqrt(lam)
    r = rho_r + rc.Delta_star
    sr = num.sqrt(r)
    return (
        rc.circ_1 / (2 * lam)
        + w * rc.circ_4
        + (rc.ocirc_1 / (2 * lam) + w * rc.ocirc_4) * sr
        + (rc.odot_1 / (2 * lam) + w * rc.odot_8) * r
        + (rc.odot_2 / (2 * lam) + rc.odot_3 / (2 * sl) + rc.oast_1 * rc.Delta_star / (2 * lam))
        * rho_r
        + rc.otimes_1 / (2 * sl) * (r * sr)
    )


def gamma_a(rho_a: Real, omega: Real, tc: TrueConstants) -> Real:
    """Gamma_a(rho_a, p, omega); implements (18c) of L1-DRAC."""
    num = tc.num
    rho_a, omega = num.const(rho_a), num.const(omega)
    lam = tc.lam
    return (
        tc.odot_1 / (2 * lam)
        + omega * tc.odot_4 / _abs_gap(lam, omega)
        + tc.otimes_1 / (2 * num.sqrt(lam)) * num.sqrt(rho_a)
    ) * rho_a


def theta_r(rho_r: Real, omega: Real, rc: RefConstants) -> Real:
    """Theta_r(rho_r, p, omega); implements (22) of L1-DRAC (NOT divided by |2 lambda - omega|)."""
    num = rc.num
    rho_r, omega = num.const(rho_r), num.const(omega)
    sw = num.sqrt(omega)
    r = rho_r + rc.Delta_star
    sr = num.sqrt(r)
    return (
        rc.circ_2
        + sw * rc.circ_3
        + (rc.ocirc_2 + sw * rc.ocirc_3) * sr
        + (rc.odot_4 + sw * rc.odot_6) * r
        + (rc.odot_5 + sw * rc.odot_7) * rho_r
        + ((rc.otimes_2 + sw * rc.otimes_4) * r + (rc.otimes_3 + sw * rc.otimes_5) * rho_r) * sr
        + (rc.oast_2 * r + rc.oast_3 * rho_r) * r
    )


def theta_a(rho_a: Real, rho_r: Real, omega: Real, tc: TrueConstants, Delta_star: Real) -> Real:
    """Theta_a(rho_a, rho_r, p, omega); implements (23) of L1-DRAC (NOT divided by |2lambda-omega|).

    ``rho'' = rho_a + 2 (rho_r + Delta_star)`` as defined below (23).
    """
    num = tc.num
    rho_a, rho_r, omega = num.const(rho_a), num.const(rho_r), num.const(omega)
    sw = num.sqrt(omega)
    rpp = rho_a + 2.0 * (rho_r + Delta_star)
    return (
        sw * tc.ocirc_1 + sw * tc.otimes_3 * rpp + (tc.otimes_2 + sw * tc.otimes_4) * rho_a
    ) * num.sqrt(rho_a) + (tc.odot_2 + sw * tc.odot_3 + tc.oast_2 * rpp + tc.oast_3 * rho_a) * rho_a


def _with_ring(xi2: Real, s: SamplingConstants) -> tuple[Real, Real]:
    """``xi2`` as a backend number and ring-Upsilon(xi2; p, omega) (A.19c), as (25a-c) use them."""
    xi2 = s.num.const(xi2)
    return xi2, upsilon_ring(xi2, s.consts, s.p, s.omega)


def upsilon_a1(xi1: Real, xi2: Real, s: SamplingConstants) -> Real:
    """Upsilon_{a_1}(xi1, xi2; p, omega, Ts); implements (25a) of L1-DRAC."""
    lam = s.consts.lam
    xi2, ring = _with_ring(xi2, s)
    return upsilon_minus_tilde(xi1, s) * xi2 + s.omega / (
        lam * _abs_gap(lam, s.omega)
    ) * ring * upsilon_minus(xi1, s)


def upsilon_a2(xi1: Real, xi2: Real, s: SamplingConstants) -> Real:
    """Upsilon_{a_2}(xi1, xi2; p, omega, Ts); implements (25b) of L1-DRAC."""
    c, lam, sw = s.consts, s.consts.lam, s.num.sqrt(s.omega)
    xi2, ring = _with_ring(xi2, s)
    return (
        (c.Delta_g * xi2 + sw / _abs_gap(lam, s.omega) * ring)
        * (upsilon1_prime(xi1, s) + sw * upsilon2_prime(xi1, s))
        / lam
    )


def upsilon_a3(xi1: Real, xi2: Real, s: SamplingConstants) -> Real:
    """Upsilon_{a_3}(xi1, xi2; p, omega, Ts); implements (25c) of L1-DRAC."""
    c, lam, sw = s.consts, s.consts.lam, s.num.sqrt(s.omega)
    xi2, ring = _with_ring(xi2, s)
    return (
        (2.0 * c.Delta_g * xi2 + sw / lam * ring) * upsilon3_prime(xi1, s) / _abs_gap(lam, s.omega)
    )


def upsilon_sum(xi1: Real, xi2: Real, s: SamplingConstants) -> Real:
    """sum_{i=1}^3 Upsilon_{a_i}(xi1, xi2); the left side of (24) of L1-DRAC.

    (24) evaluates it at ``xi1 = rho'(p) = rho_a + rho_r + Delta_star`` and ``xi2 = rho_a``.
    """
    return upsilon_a1(xi1, xi2, s) + upsilon_a2(xi1, xi2, s) + upsilon_a3(xi1, xi2, s)


# --------------------------------------------------------------------------------------------
# Sec. 3.2: the two sides of the design conditions (16a), (16b), (21a), (21b), (24)
# --------------------------------------------------------------------------------------------

#: Each condition in the paper's form ``lhs REL rhs`` (Sec. 3.2).
RELATIONS: dict[str, str] = {"16a": ">=", "16b": ">=", "21a": "<", "21b": "<", "24": "<="}


def margin_of(eq: str, lhs: Real, rhs: Real) -> Real:
    """The signed margin of condition ``eq``, positive when it holds with room.

    ``lhs - rhs`` for (16a, b) (``lhs >= rhs``); ``rhs - lhs`` for (21a, b) (``lhs < rhs``)
    and (24) (``lhs <= rhs``).
    """
    return lhs - rhs if RELATIONS[eq] == ">=" else rhs - lhs


def sides_16a(c: L1ConstantsLike, rc: RefConstants, omega: Real, rho_r: Real) -> tuple[Real, Real]:
    """(16a): ``lhs = (1 - k_r) rho_r^2``, ``rhs = alpha^2 + Gamma_r(rho_r, p, omega) + eps_r``."""
    rho_r = c.num.const(rho_r)
    lhs = (1.0 - unmatched_gain_r(c)) * rho_r**2
    rhs = c.alpha**2 + gamma_r(rho_r, omega, rc) + c.eps_r
    return lhs, rhs


def sides_16b(c: L1ConstantsLike, tc: TrueConstants, omega: Real, rho_a: Real) -> tuple[Real, Real]:
    """(16b): ``lhs = (1 - k_a) rho_a^2``, ``rhs = Gamma_a(rho_a, p, omega) + eps_a``."""
    rho_a = c.num.const(rho_a)
    lhs = (1.0 - unmatched_gain_a(c)) * rho_a**2
    rhs = gamma_a(rho_a, omega, tc) + c.eps_a
    return lhs, rhs


def sides_21a(c: L1ConstantsLike, rc: RefConstants, omega: Real, rho_r: Real) -> tuple[Real, Real]:
    """(21a): ``lhs = Theta_r / |2 lambda - omega|``,
    ``rhs = (1 - k_r) rho_r^2 - alpha^2 - Gamma_r``.

    Theta_r is divided by |2 lambda - omega| exactly once (the authors' Julia code: twice).
    """
    rho_r, omega = c.num.const(rho_r), c.num.const(omega)
    lhs = theta_r(rho_r, omega, rc) / _abs_gap(c.lam, omega)
    rhs = (1.0 - unmatched_gain_r(c)) * rho_r**2 - c.alpha**2 - gamma_r(rho_r, omega, rc)
    return lhs, rhs


def budget_a(
    c: L1ConstantsLike, tc: TrueConstants, omega: Real, rho_r: Real, rho_a: Real
) -> tuple[Real, Real, Real]:
    """``((1 - k_a) rho_a^2 - Gamma_a, Theta_a / |2 lambda - omega|, Gamma_a)``; (21b) and (24)."""
    num = c.num
    omega, rho_r, rho_a = num.const(omega), num.const(rho_r), num.const(rho_a)
    ga = gamma_a(rho_a, omega, tc)
    th = theta_a(rho_a, rho_r, omega, tc, c.Delta_star) / _abs_gap(c.lam, omega)
    return (1.0 - unmatched_gain_a(c)) * rho_a**2 - ga, th, ga


def budget_24(c: L1ConstantsLike, tc: TrueConstants, omega: Real, rho_r: Real, rho_a: Real) -> Real:
    """The right side of (24): ``(1 - k_a) rho_a^2 - Gamma_a - Theta_a / |2 lambda - omega|``."""
    b, th, _ = budget_a(c, tc, omega, rho_r, rho_a)
    return b - th


def sides_21b(
    c: L1ConstantsLike, tc: TrueConstants, omega: Real, rho_r: Real, rho_a: Real
) -> tuple[Real, Real]:
    """(21b): ``lhs = Theta_a / |2 lambda - omega|``, ``rhs = (1 - k_a) rho_a^2 - Gamma_a``."""
    rhs, lhs, _ = budget_a(c, tc, omega, rho_r, rho_a)
    return lhs, rhs


def sides_24(
    c: L1ConstantsLike,
    tc: TrueConstants,
    p: int,
    omega: Real,
    lambda_s: Real,
    Ts: Real,
    rho_r: Real,
    rho_a: Real,
    *,
    envelope: bool = False,
) -> tuple[Real, Real]:
    """(24): ``lhs = sum_i Upsilon_{a_i}(rho', rho_a)`` (25a-c), ``rhs = (1 - k_a) rho_a^2 -
    Gamma_a - Theta_a / |2 lambda - omega|`` with ``rho' = rho_a + rho_r + Delta_star``.

    ``envelope=True`` evaluates the left side on the monotone envelope of
    :func:`~drip_cert.bounds.l1drac.appendix.sampling_constants` (the designer's Ts search).
    """
    s = sampling_constants(c, p, omega, Ts, lambda_s, envelope=envelope)
    return sides_24_at(c, tc, s, omega, rho_r, rho_a)


def sides_24_at(
    c: L1ConstantsLike,
    tc: TrueConstants,
    s: SamplingConstants,
    omega: Real,
    rho_r: Real,
    rho_a: Real,
) -> tuple[Real, Real]:
    """:func:`sides_24` on sampling constants computed once (``s``: they depend on ``(p, omega,
    lambda_s, Ts)`` only, not on the radii a search varies); the same operations in the same
    order, so the same numbers."""
    num = c.num
    rho_r, rho_a = num.const(rho_r), num.const(rho_a)
    lhs = upsilon_sum(rho_a + rho_r + c.Delta_star, rho_a, s)
    return lhs, budget_24(c, tc, omega, rho_r, rho_a)
