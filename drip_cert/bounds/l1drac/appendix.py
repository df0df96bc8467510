"""Appendix A of L1-DRAC: every constant and map of the certificate, as pure functions.

Source: A. Gahlawat, S. H. Karumanchi, N. Hovakimyan, "L1-DRAC: Distributionally Robust Adaptive
Control -- Global Results", arXiv:2509.04619 (2025-09-04), Appendix A (printed pp. 43-46):
(A.1)-(A.19). Equation numbers are the paper's. The functions of Sec. 3.2 built on these
(Gamma_r, Gamma_a, Theta_r, Theta_a, the Upsilon_a maps and the two sides of every condition) are
in :mod:`drip_cert.bounds.l1drac.sides`.

Every function takes a constants object ``c`` (a
:class:`~drip_cert.bounds.l1drac.constants.L1Constants`,
read through its attributes only) and the moment order ``p``; the piecewise-constant-law
quantities (A.13)-(A.19) also take the control parameters ``omega``, ``Ts`` and ``lambda_s``.

ASCII names of the paper's symbol families (subscript ``i`` is the paper's index):

=================  =========================  ===========================================
paper              here                       order in ``(rho + Delta_star)`` (Sec. 3.2)
=================  =========================  ===========================================
Delta_{circ_i}     ``circ_i``                 0
Delta_{ocirc_i}    ``ocirc_i``  (circledcirc) 1/2
Delta_{odot_i}     ``odot_i``                 1
Delta_{otimes_i}   ``otimes_i``               3/2
Delta_{oast_i}     ``oast_i``   (circledast)  2
hat-Delta_i        ``hat_i``
=================  =========================  ===========================================

Known typos of the paper, fixed here (each also marked where the code fixes it):

* (A.10b), printed p. 45: Delta_{odot_4} contains hat-Delta_6, which is defined nowhere; the
  derivation (D.132b and D.150-D.151c) shows it is hat-Delta_5 (A.8c). We use hat-Delta_5.
* (D.142b), printed p. 137: a stray gamma'_sigma(omega, T_s), defined nowhere, in the bound of
  Delta_{tilde H_sigma}. Proposition D.11 has no such term and (A.17a) does not carry it; we
  implement (A.17a) as printed (no gamma'_sigma).

Numerics: every ``e^x - 1`` of the paper is :func:`math.expm1`, every ``1 - e^{-x}`` is
``-expm1(-x)``, and ``1 - (lambda_s/omega) (e^{omega Ts}-1)/(e^{lambda_s Ts}-1)`` in gamma'_2
(A.13c) is computed without cancellation (:func:`_one_minus_ratio`), so all quantities keep full
relative precision down to ``Ts = 1e-14`` and below.

One transcription, two arithmetics
----------------------------------
Every formula below is written once, generic over a small numeric backend
(:class:`~drip_cert.bounds.l1drac.backend.FloatOps`: ``const``, ``sqrt``, ``exp``, ``expm1``,
``max``, ``mid``, ``series_remainder``). The constants object carries its backend as the attribute
``num``: :class:`~drip_cert.bounds.l1drac.constants.L1Constants` carries
:data:`~drip_cert.bounds.l1drac.backend.FLOAT` (float64, :mod:`math`; the designer's fast
searches), and the Arb view of :mod:`drip_cert.bounds.l1drac.verify` carries
:data:`~drip_cert.bounds.l1drac.backend.ARB`, so the same code evaluates every
constant, map and condition in ball arithmetic from the same float inputs (the rigorous re-check
of a returned design). The result dataclasses carry the backend on to the maps that read them.
Rules that keep the Arb evaluation rigorous: every elementary function goes through ``num``,
every integer-derived constant through ``num.const``, and no two plain floats are combined before
one of them is a backend number (the verifier converts every input first). A branch chosen on
``num.mid`` (the ball's midpoint) only picks between two formulas that are both valid, and the
truncated series of :func:`_phi2` adds its remainder bound (``num.series_remainder``).
"""

from __future__ import annotations

import math
from dataclasses import dataclass

from drip_cert.bounds.l1drac.backend import FLOAT, Backend, Real
from drip_cert.bounds.l1drac.constants import L1ConstantsLike

__all__ = [
    "frak_p",
    "frak_p_prime",
    "frak_p_dprime",
    "lip_indicator",
    "RefConstants",
    "TrueConstants",
    "SamplingConstants",
    "reference_hats",
    "reference_constants",
    "true_constants",
    "sampling_constants",
    "upsilon1_prime",
    "upsilon2_prime",
    "upsilon3_prime",
    "upsilon_minus_tilde",
    "upsilon_minus",
    "upsilon_ring",
]

#: Below this |x| the series of (e^x - 1 - x)/x^2 is summed (its 9th term is < 1e-16 relative).
_PHI2_SERIES_BELOW = 1e-2


# --------------------------------------------------------------------------------------------
# (A.1) global constants
# --------------------------------------------------------------------------------------------


def frak_p(p: int, num: Backend = FLOAT) -> Real:
    """Fraktur p(p) = (p (p - 1) / 2)^{1/2}; implements (A.1a) of L1-DRAC (zero at p = 1)."""
    return num.sqrt(num.const(p * (p - 1)) / 2.0)


def frak_p_prime(p: int, num: Backend = FLOAT) -> Real:
    """Fraktur p'(p) = (p (2p - 1) / 2)^{1/2}; implements (A.1a) of L1-DRAC."""
    return num.sqrt(num.const(p * (2 * p - 1)) / 2.0)


def frak_p_dprime(p: int, num: Backend = FLOAT) -> Real:
    """Fraktur p''(p) = (p (4p - 1))^{1/2}; implements (A.1a) of L1-DRAC."""
    return num.sqrt(num.const(p * (4 * p - 1)))


def lip_indicator(c: L1ConstantsLike) -> float:
    """1_Lip(f): 1.0 when Assumption 8 (global Lipschitz f) holds, else 0.0; (A.1b) of L1-DRAC."""
    return 1.0 if c.lip_f else 0.0


# --------------------------------------------------------------------------------------------
# A.1 Reference process, (A.2)-(A.7)
# --------------------------------------------------------------------------------------------


@dataclass(frozen=True)
class RefConstants:
    """The reference-process constants Delta^r of (A.2)-(A.7) of L1-DRAC at one moment order p.

    ``lam``, ``Delta_star`` and ``p`` are carried along because (18b) and (22) need them, and
    ``num`` (the backend of the constants they were computed from) because every map does.
    """

    p: int
    lam: Real
    Delta_star: Real
    hat_1: Real
    hat_2: Real
    hat_3: Real
    hat_4: Real
    circ_1: Real
    circ_2: Real
    circ_3: Real
    circ_4: Real
    ocirc_1: Real
    ocirc_2: Real
    ocirc_3: Real
    ocirc_4: Real
    odot_1: Real
    odot_2: Real
    odot_3: Real
    odot_4: Real
    odot_5: Real
    odot_6: Real
    odot_7: Real
    odot_8: Real
    otimes_1: Real
    otimes_2: Real
    otimes_3: Real
    otimes_4: Real
    otimes_5: Real
    oast_1: Real
    oast_2: Real
    oast_3: Real
    num: Backend = FLOAT


def reference_hats(c: L1ConstantsLike, p: int) -> tuple[Real, Real, Real, Real]:
    """hat-Delta^r_{1..4}(p); implements (A.2a) and (A.2b) of L1-DRAC.

    Returns
    -------
    tuple
        ``(hat_1(p), hat_2(p), hat_3, hat_4)``.
    """
    num = c.num
    sl = num.sqrt(c.lam)
    ind = lip_indicator(c)
    fp = frak_p(p, num)
    h1 = c.Delta_g * (
        (c.Delta_f * (2.0 + c.Delta_star) * (1.0 - ind) + c.Delta_mu) / sl
        + fp * (2.0 * c.Delta_p + c.Delta_sigma)
    )
    h2 = c.Delta_g * fp * c.Delta_sigma
    h3 = c.Delta_g * (c.Delta_f * (1.0 - ind) + c.Delta_mu) / sl
    h4 = (c.Delta_g * c.L_f * ind + c.Delta_g_dot) / sl
    return h1, h2, h3, h4


def reference_constants(c: L1ConstantsLike, p: int) -> RefConstants:
    """All reference-process constants at moment order p; implements (A.2)-(A.7) of L1-DRAC.

    Parameters
    ----------
    c
        The paper's constants (Assumptions 1-8).
    p
        Moment order, an integer in ``{1, ..., p_star}`` (not re-checked here).

    Returns
    -------
    RefConstants
        hat-Delta^r (A.2), Delta^r_circ (A.3), Delta^r_ocirc (A.4), Delta^r_odot (A.5),
        Delta^r_otimes (A.6), Delta^r_oast (A.7).
    """
    num = c.num
    lam = c.lam
    sl = num.sqrt(lam)
    sm = num.sqrt(num.const(c.m))
    fp = frak_p(p, num)
    fp1 = frak_p_prime(p, num)
    h1, h2, h3, h4 = reference_hats(c, p)
    dg = c.Delta_g
    dmp = c.Delta_mu_par
    par = c.Delta_p_par + c.Delta_sigma_par  # (Delta_p^par + Delta_sigma^par), everywhere below
    g2m = dg * dg * dmp / sl  # Delta_g^2 Delta_mu^par / sqrt(lambda)
    return RefConstants(
        p=p,
        lam=lam,
        Delta_star=c.Delta_star,
        hat_1=h1,
        hat_2=h2,
        hat_3=h3,
        hat_4=h4,
        # (A.3a)-(A.3c)
        circ_1=c.Delta_p**2 + (c.Delta_p + c.Delta_sigma) ** 2,
        circ_2=dmp / sl * (h1 + g2m),
        circ_3=fp1 / sl * par * (h1 + 2.0 * g2m),
        circ_4=par * dg / lam * (fp1**2 * dg * par + sm * (2.0 * c.Delta_p + c.Delta_sigma)),
        # (A.4a)-(A.4c)
        ocirc_1=2.0 * c.Delta_sigma * (c.Delta_p + c.Delta_sigma),
        ocirc_2=dmp / sl * h2,
        ocirc_3=fp1 / sl * (par * h2 + c.Delta_sigma_par * (h1 + 2.0 * g2m)),
        ocirc_4=(
            dg
            / lam
            * (
                par * (2.0 * fp1**2 * dg * c.Delta_sigma_par + sm * c.Delta_sigma)
                + sm * c.Delta_sigma_par * (2.0 * c.Delta_p + c.Delta_sigma)
            )
        ),
        # (A.5a)-(A.5d)
        odot_1=c.Delta_sigma**2,
        odot_2=2.0 * c.Delta_g_perp * c.Delta_mu_perp,
        odot_3=2.0 * fp * (c.Delta_g_perp * (c.Delta_p_perp + c.Delta_sigma_perp) + c.Delta_p),
        odot_4=dmp / sl * (h1 + h3 + 2.0 * g2m),
        odot_5=dmp * (h4 / sl + 4.0 * dg) + 2.0 * sl * dg * fp * par,
        odot_6=fp1 / sl * (par * (h3 + 2.0 * g2m) + c.Delta_sigma_par * h2),
        odot_7=fp1 * par * (h4 / sl + 2.0 * dg),
        odot_8=(
            c.Delta_sigma_par * dg / lam * (fp1**2 * dg * c.Delta_sigma_par + sm * c.Delta_sigma)
        ),
        # (A.6a)-(A.6b)
        otimes_1=2.0 * fp * c.Delta_g_perp * c.Delta_sigma_perp,
        otimes_2=dmp * h2 / sl,
        otimes_3=2.0 * fp * sl * dg * c.Delta_sigma_par,
        otimes_4=fp1 * c.Delta_sigma_par * (h3 + 2.0 * g2m) / sl,
        otimes_5=fp1 * c.Delta_sigma_par * (h4 / sl + 2.0 * dg),
        # (A.7a)
        oast_1=2.0 * c.Delta_g_perp * c.Delta_mu_perp,
        oast_2=dmp * (h3 + g2m) / sl,
        oast_3=dmp * (h4 / sl + 4.0 * dg),
        num=num,
    )


# --------------------------------------------------------------------------------------------
# A.2 True process, (A.8)-(A.12)
# --------------------------------------------------------------------------------------------


@dataclass(frozen=True)
class TrueConstants:
    """The true-process constants of (A.8)-(A.12) of L1-DRAC at one moment order p."""

    p: int
    lam: Real
    hat_1: Real
    hat_2: Real
    hat_3: Real
    hat_4: Real
    hat_5: Real
    ocirc_1: Real
    odot_1: Real
    odot_2: Real
    odot_3: Real
    odot_4: Real
    otimes_1: Real
    otimes_2: Real
    otimes_3: Real
    otimes_4: Real
    oast_1: Real
    oast_2: Real
    oast_3: Real
    num: Backend = FLOAT


def true_constants(c: L1ConstantsLike, p: int) -> TrueConstants:
    """All true-process constants at moment order p; implements (A.8)-(A.12) of L1-DRAC.

    The paper's (A.10b) prints hat-Delta_6 in Delta_{odot_4}; it is hat-Delta_5 (see the module
    docstring), and hat-Delta_5 is used.
    """
    num = c.num
    lam = c.lam
    sl = num.sqrt(lam)
    ind = lip_indicator(c)
    fp = frak_p(p, num)
    fp1 = frak_p_prime(p, num)
    dg = c.Delta_g
    lmp = c.L_mu_par
    lpar = c.L_p_par + c.L_sigma_par  # (L_p^par + L_sigma^par)
    # (A.8a)-(A.8c)
    h1 = 2.0 / sl * dg * c.Delta_f * (1.0 - ind)
    h2 = dg * fp * (c.L_p + c.L_sigma)
    h3 = dg * c.Delta_f * (1.0 - ind) / sl
    h4 = (dg * (c.L_mu + c.L_f * ind) + c.Delta_g_dot) / sl
    h5 = num.sqrt(num.const(c.m)) * dg * (c.L_p + c.L_sigma)
    return TrueConstants(
        p=p,
        lam=lam,
        hat_1=h1,
        hat_2=h2,
        hat_3=h3,
        hat_4=h4,
        hat_5=h5,
        # (A.9)
        ocirc_1=fp1 * lpar * h1 / sl,
        # (A.10a)
        odot_1=(c.L_p + c.L_sigma) ** 2,
        odot_2=lmp * h1 / sl,
        odot_3=fp1 * lpar * h2 / sl,
        # (A.10b) -- ERRATUM: the paper prints hat-Delta_6 (undefined); it is hat-Delta_5 (D.132b).
        odot_4=lpar * (h5 + dg * dg * fp1**2 * lpar) / lam,
        # (A.11a)-(A.11c)
        otimes_1=2.0 * c.Delta_g_perp * fp * (c.L_p_perp + c.L_sigma_perp),
        otimes_2=2.0 * sl * dg * fp * lpar + lmp * h2 / sl,
        otimes_3=fp1 * lpar * h3 / sl,
        otimes_4=fp1 * lpar * (h4 / sl + 2.0 * dg * (1.0 + dg / lam * lmp)),
        # (A.12)
        oast_1=2.0 * c.Delta_g_perp * c.L_mu_perp,
        oast_2=lmp * h3 / sl,
        oast_3=lmp * (h4 / sl + dg * (4.0 + dg / lam * lmp)),
        num=num,
    )


# --------------------------------------------------------------------------------------------
# A.2.1 Piecewise-constant adaptation law, (A.13)-(A.19)
# --------------------------------------------------------------------------------------------


def _phi2(x: Real, num: Backend) -> Real:
    """(e^x - 1 - x) / x^2 to full relative precision (series for small |x|).

    For ``|x| < 1e-2`` the series ``sum_{k>=0} x^k / (k+2)!`` is summed to ``k = n - 1`` with
    ``n = num.series_terms``; its remainder is at most ``|x|^n / ((n+2)! (1 - |x|))`` (a
    geometric tail, ``(k+2)! >= (n+2)!`` for k >= n), which the Arb backend adds as a radius
    (float64: n = 9, a remainder below 1e-16 / 3.6e6 relative).
    """
    if abs(num.mid(x)) < _PHI2_SERIES_BELOW:
        n = num.series_terms
        term = num.const(0.5)
        total = term
        for k in range(1, n):
            term = term * (x / (k + 2))
            total = total + term
        return num.series_remainder(total, x, n, math.factorial(n + 2))
    return (num.expm1(x) - x) / (x * x)


def _one_minus_ratio(omega: Real, lambda_s: Real, Ts: Real, num: Backend) -> Real:
    """1 - (lambda_s/omega) (e^{omega Ts} - 1)/(e^{lambda_s Ts} - 1), without cancellation.

    With e(x) = x + x^2 phi2(x): omega e(lambda_s T) - lambda_s e(omega T)
    = omega lambda_s T^2 (lambda_s phi2(lambda_s T) - omega phi2(omega T)).
    """
    u = lambda_s * Ts
    return (
        lambda_s
        * Ts
        * Ts
        * (lambda_s * _phi2(u, num) - omega * _phi2(omega * Ts, num))
        / num.expm1(u)
    )


@dataclass(frozen=True)
class SamplingConstants:
    """The piecewise-constant-law constants (A.13)-(A.17) of L1-DRAC at (p, omega, Ts, lambda_s).

    ``envelope`` is True when the constants are the monotone envelope of
    :func:`sampling_constants` (``e^{-lambda_s Ts} -> 1`` in (A.15), ``gamma_2 -> max(gamma_2, 1)``
    in (A.13d), (A.14), (A.17)), which bounds the paper's values from above.
    """

    consts: L1ConstantsLike
    p: int
    omega: Real
    Ts: Real
    lambda_s: Real
    envelope: bool
    gamma_1: Real
    gamma_1p: Real
    gamma_2: Real
    gamma_2p: Real
    gamma_pp: Real
    gamma_mu: Real
    gamma_mu_hat: Real
    gamma_sigma: Real
    gamma_sigma_hat: Real
    bar_1: Real
    bar_2: Real
    bar_3: Real
    mu_1: Real
    mu_2: Real
    mu_3: Real
    sigma_1: Real
    sigma_2: Real
    sigma_3: Real
    expm1_omega_Ts: Real  # e^{omega Ts} - 1, used by (A.18c)
    one_m_e2lam: Real  # 1 - e^{-2 lambda Ts}, used by (A.19a)
    one_m_e2omega: Real  # 1 - e^{-2 omega Ts}, used by (A.13d), (A.19a)
    num: Backend = FLOAT  # the backend of ``consts``


def sampling_constants(
    c: L1ConstantsLike,
    p: int,
    omega: Real,
    Ts: Real,
    lambda_s: Real,
    *,
    envelope: bool = False,
) -> SamplingConstants:
    """gamma's, bar-Delta's, Delta_mu's and Delta_sigma's; implements (A.13)-(A.17) of L1-DRAC.

    Parameters
    ----------
    c
        The paper's constants.
    p
        Moment order.
    omega, Ts, lambda_s
        Filter bandwidth, sampling period, predictor pole (all > 0).
    envelope
        If True, return the monotone upper envelope used by the T_s search of the designer:
        ``e^{-lambda_s Ts}`` is replaced by 1 in (A.15) and gamma_2 by ``max(gamma_2, 1)`` in
        (A.13d), (A.14) and (A.17). Every Upsilon map is a sum of products of non-negative factors,
        each non-decreasing in these two replaced quantities, so the envelope maps are >= the
        paper's maps; and every factor of the envelope is non-decreasing in Ts (proof in
        :func:`drip_cert.bounds.l1drac.searches.largest_Ts`).

    Returns
    -------
    SamplingConstants
    """
    num = c.num
    omega, Ts, lambda_s = num.const(omega), num.const(Ts), num.const(lambda_s)
    lam = c.lam
    u = lambda_s * Ts
    em1_u = num.expm1(u)  # e^{lambda_s Ts} - 1
    em1_w = num.expm1(omega * Ts)  # e^{omega Ts} - 1
    fp1 = frak_p_prime(p, num)
    fp2 = frak_p_dprime(p, num)
    # (A.13a): gamma_1 = (lambda_s (e^u + 1)/(e^u - 1))^{1/2};  Ts*gamma_1 kept separately
    gamma_1 = num.sqrt(lambda_s * (2.0 + em1_u) / em1_u)
    Ts_gamma_1 = num.sqrt(Ts * (2.0 + em1_u) * (u / em1_u))  # = Ts gamma_1, no overflow
    one_m_e2lam = -num.expm1(-2.0 * lam * Ts)
    one_m_ew = -num.expm1(-omega * Ts)
    gamma_1p = one_m_e2lam * one_m_ew
    # (A.13b): gamma_2 = max(e^{(omega-lambda_s)Ts}, 1) * R,  R = (ls/w)(e^{w Ts}-1)/(e^{ls Ts}-1)
    one_m_R = _one_minus_ratio(omega, lambda_s, Ts, num)
    R = 1.0 - one_m_R
    e_diff = num.exp((omega - lambda_s) * Ts)
    gamma_2 = num.max(e_diff, 1.0) * R
    # (A.13c): |1 - e^{(w-ls)Ts} R| = |-(e^{(w-ls)Ts} - 1) + e^{(w-ls)Ts}(1 - R)|, both terms of
    # one sign, so no cancellation
    gamma_2p = num.max(
        abs(-num.expm1((omega - lambda_s) * Ts) + e_diff * one_m_R),
        abs(one_m_R),
    )
    g2 = num.max(gamma_2, 1.0) if envelope else gamma_2
    one_m_e2omega = -num.expm1(-2.0 * omega * Ts)
    # (A.13d)
    gamma_pp = fp1 * gamma_2p + fp2 * num.sqrt(one_m_e2omega) * (2.0 + g2)
    # (A.14a)-(A.14c)
    gamma_mu = c.L_mu_par + c.L_mu * g2 * c.Delta_Theta
    gamma_mu_hat = c.L_mu_par_hat + c.L_mu_hat * g2 * c.Delta_Theta
    gamma_sigma = c.L_p_par + c.L_sigma_par + g2 * c.Delta_Theta * (c.L_p + c.L_sigma)
    gamma_sigma_hat = (
        c.L_p_par_hat + c.L_sigma_par_hat + g2 * c.Delta_Theta * (c.L_p_hat + c.L_sigma_hat)
    )
    # (A.15a)-(A.15c)
    e_mu = num.const(1.0) if envelope else num.exp(-u)  # e^{-lambda_s Ts}
    gt = c.Delta_g * c.Delta_Theta * e_mu
    ps = c.Delta_p + c.Delta_sigma
    s2T = num.sqrt(2.0 * Ts)  # sqrt(2) sqrt(Ts)
    bar_1 = (
        2.0 * (Ts * (c.Delta_f + (1.0 + gt) * c.Delta_mu) + fp1 * gt * Ts_gamma_1 * ps)
        + 2.0 * s2T * fp1 * ps
    )
    bar_2 = 2.0 * fp1 * c.Delta_sigma * (s2T + gt * Ts_gamma_1)
    bar_3 = 2.0 * Ts * (c.Delta_f + (1.0 + gt) * c.Delta_mu)
    one_m_eu = -num.expm1(-u)  # 1 - e^{-lambda_s Ts}, in (A.16a), (A.16c)
    lpar = c.L_p_par + c.L_sigma_par
    lhat_par = c.L_p_par_hat + c.L_sigma_par_hat
    sq_b1 = num.sqrt(bar_1)
    bracket = gamma_sigma + (1.0 + g2) * lpar  # of (A.17b)
    return SamplingConstants(
        consts=c,
        p=p,
        omega=omega,
        Ts=Ts,
        lambda_s=lambda_s,
        envelope=envelope,
        gamma_1=gamma_1,
        gamma_1p=gamma_1p,
        gamma_2=g2,
        gamma_2p=gamma_2p,
        gamma_pp=gamma_pp,
        gamma_mu=gamma_mu,
        gamma_mu_hat=gamma_mu_hat,
        gamma_sigma=gamma_sigma,
        gamma_sigma_hat=gamma_sigma_hat,
        bar_1=bar_1,
        bar_2=bar_2,
        bar_3=bar_3,
        # (A.16a)-(A.16c)
        mu_1=Ts * gamma_mu_hat + bar_1 * gamma_mu + c.Delta_mu_par * one_m_eu,
        mu_2=bar_2 * gamma_mu,
        mu_3=Ts * gamma_mu * bar_3 + c.Delta_mu_par * one_m_eu,
        # (A.17a) -- ERRATUM note: (D.142b) carries a stray gamma'_sigma(omega, Ts), defined
        # nowhere; Prop. D.11 has no such term, so (A.17a) is implemented as printed, without it.
        sigma_1=(lpar * sq_b1 + Ts * lhat_par) * (1.0 + g2)
        + (gamma_sigma * sq_b1 + Ts * gamma_sigma_hat),
        # (A.17b)
        sigma_2=num.sqrt(bar_2) * bracket,
        sigma_3=num.sqrt(bar_3) * bracket,
        expm1_omega_Ts=em1_w,
        one_m_e2lam=one_m_e2lam,
        one_m_e2omega=one_m_e2omega,
        num=num,
    )


def upsilon1_prime(xi: Real, s: SamplingConstants) -> Real:
    """Upsilon'_1(xi; p, omega, Ts); implements (A.18a) of L1-DRAC."""
    num = s.num
    xi = num.const(xi)
    sw = num.sqrt(s.omega)
    fp1 = frak_p_prime(s.p, num)
    sq = num.sqrt(xi)
    return (
        s.mu_1
        + sw * fp1 * s.sigma_1
        + sw * fp1 * s.sigma_2 * num.sqrt(sq)
        + (s.mu_2 + sw * fp1 * s.sigma_3) * sq
        + s.mu_3 * xi
    )


def _par_diffusion(xi: Real, s: SamplingConstants) -> Real:
    """Delta_p^par + Delta_sigma^par (1 + xi^{1/2}): the matched-diffusion factor of (A.18b),
    (A.19a) and (A.19b)."""
    c = s.consts
    return c.Delta_p_par + c.Delta_sigma_par * (1.0 + s.num.sqrt(xi))


def upsilon2_prime(xi: Real, s: SamplingConstants) -> Real:
    """Upsilon'_2(xi; p, omega, Ts); implements (A.18b) of L1-DRAC."""
    return s.gamma_pp * _par_diffusion(s.num.const(xi), s)


def upsilon3_prime(xi: Real, s: SamplingConstants) -> Real:
    """Upsilon'_3(xi) = Delta_mu^par (e^{omega Ts} - 1)(1 + xi); implements (A.18c) of L1-DRAC."""
    return s.consts.Delta_mu_par * s.expm1_omega_Ts * (1.0 + s.num.const(xi))


def upsilon_minus_tilde(xi: Real, s: SamplingConstants) -> Real:
    """tilde-Upsilon^-(xi; p, omega, Ts); implements (A.19a) of L1-DRAC."""
    c = s.consts
    num = s.num
    xi = num.const(xi)
    fp1 = frak_p_prime(s.p, num)
    par = _par_diffusion(xi, s)
    inner = num.sqrt(s.omega) * fp1 * num.sqrt(s.one_m_e2omega) * par + c.Delta_mu_par * (1.0 + xi)
    return s.one_m_e2lam * c.Delta_g * inner / c.lam


def upsilon_minus(xi: Real, s: SamplingConstants) -> Real:
    """Upsilon^-(xi; p, omega, Ts); implements (A.19b) of L1-DRAC."""
    c = s.consts
    num = s.num
    xi = num.const(xi)
    fp1 = frak_p_prime(s.p, num)
    return s.gamma_1p * (
        2.0 * fp1 * _par_diffusion(xi, s) + c.Delta_mu_par * (1.0 + xi) / num.sqrt(s.omega)
    )


def upsilon_ring(xi: Real, c: L1ConstantsLike, p: int, omega: Real) -> Real:
    """ring-Upsilon(xi; p, omega); implements (A.19c) of L1-DRAC (independent of Ts)."""
    num = c.num
    xi, omega = num.const(xi), num.const(omega)
    fp1 = frak_p_prime(p, num)
    return c.Delta_g**2 * (
        fp1 * (c.L_p_par + c.L_sigma_par) * num.sqrt(xi) + c.L_mu_par * xi / num.sqrt(omega)
    )
