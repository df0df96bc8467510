"""A lower bound on the radius ``rho = rho_r + rho_a`` of every feasible L1-DRAC design.

Source: A. Gahlawat, S. H. Karumanchi, N. Hovakimyan, "L1-DRAC: Distributionally Robust Adaptive
Control -- Global Results", arXiv:2509.04619 (2025-09-04), Sec. 3.2, conditions (16a), (16b),
(21a) with Gamma_r, Gamma_a (18b, c) and Theta_r (22) of :mod:`drip_cert.bounds.l1drac.sides`.

``certify`` uses it to rank the metric coordinate candidates before their (costly) designs:
a candidate whose radius cannot beat the best certificate found is not designed
(:func:`drip_cert.bounds.certificate.certify`). The bound holds for any omega, lambda_s and
T_s, so it is loose where (24) (the sampling condition at the given T_s) binds; it is only ever
used to skip work, never as a radius of a certificate.

Public surface
--------------
* :func:`rho_lower_bound` -- ``rho_r + rho_a >= this`` for every design satisfying (16a),
  (16b) and (21a) at moment order ``p``.
"""

from __future__ import annotations

import math
from collections.abc import Callable

from drip_cert.bounds.l1drac.appendix import reference_constants, true_constants
from drip_cert.bounds.l1drac.constants import L1Constants, unmatched_gain_a, unmatched_gain_r

__all__ = ["rho_lower_bound", "LOWER_DEFLATE", "LOWER_ITERATIONS"]

LOWER_DEFLATE = 1.0 - 1e-12
"""Each iterate of the bound is multiplied by this: it covers the float64 rounding of one
evaluation (< 200 operations on non-negative numbers, each with relative error <= 2^-53, so
< 2.3e-14 relative) with room, so that each float iterate stays below the exact one."""

LOWER_ITERATIONS = 2000  #: at most this many fixed-point steps (a count of work, not time)


def _smallest_root_below(c0: float, k: float, stuff: Callable[[float], float]) -> float:
    """A lower bound on every ``rho >= 0`` with ``(1 - k) rho^2 >= c0 + stuff(rho)``.

    ``stuff`` is non-negative and non-decreasing. The iteration ``rho_{j+1} = sqrt((c0 +
    stuff(rho_j)) / (1 - k))`` from ``rho_0 = 0`` stays below every such rho: if ``rho_j <=
    rho`` then ``rho_{j+1} <= sqrt((c0 + stuff(rho)) / (1 - k)) <= rho``. It increases, and
    stops when it no longer does (or after :data:`LOWER_ITERATIONS` steps). ``inf`` when
    ``k >= 1`` (no rho satisfies the inequality when ``c0 > 0``); 0 when an input is not a
    non-negative number (no claim).
    """
    if not (math.isfinite(c0) and c0 >= 0.0 and math.isfinite(k) and k >= 0.0):
        return 0.0
    if k >= 1.0:
        return math.inf if c0 + stuff(0.0) > 0.0 else 0.0
    rho = 0.0
    for _ in range(LOWER_ITERATIONS):
        s = stuff(rho)
        if not (math.isfinite(s) and s >= 0.0):
            return rho
        nxt = math.sqrt((c0 + s) / (1.0 - k)) * LOWER_DEFLATE
        if not nxt > rho:
            break
        rho = nxt
    return rho


def rho_lower_bound(c: L1Constants, p: int) -> float:
    """``L <= rho_r + rho_a`` for every ``(omega, lambda_s, T_s, rho_r, rho_a)`` that satisfies
    (16a), (16b) and (21a) at moment order ``p`` (so for every feasible design, whose
    ``rho = rho_r + rho_a`` (17)).

    With ``r = rho_r + Delta_star``, ``w = omega / |2 lambda - omega|`` and every appendix
    constant >= 0, (16a) and (21a) together ask

    .. math::  (1 - k_r) \\rho_r^2 \\ge \\alpha^2 + \\Gamma_r(\\rho_r, \\omega)
               + \\max(\\epsilon_r, \\Theta_r(\\rho_r, \\omega) / |2\\lambda - \\omega|).   (L.1)

    ``Gamma_r = G_0 + w W`` (18b) with ``W = circ_4 + ocirc_4 r^{1/2} + odot_8 r``, and
    ``Theta_r(omega) >= Theta_r(0) = T_0`` (22) (its omega terms are ``sqrt(omega)`` times
    non-negative numbers). For ``omega < 2 lambda``: ``w >= 0`` and ``|2 lambda - omega| <=
    2 lambda``, so the right side of (L.1) is ``>= alpha^2 + G_0 + max(eps_r, T_0 / (2
    lambda))``; for ``omega > 2 lambda``: ``w > 1``, so it is ``>= alpha^2 + G_0 + W + eps_r``.
    Hence (L.1) implies, for every omega,

    .. math::  (1 - k_r) \\rho_r^2 \\ge \\alpha^2 + G_0(\\rho_r)
               + \\min(\\max(\\epsilon_r, T_0 / (2\\lambda)), W + \\epsilon_r).      (L.2)

    and likewise (16b) with ``Gamma_a >= (odot_1 / (2 lambda) + otimes_1 / (2 sqrt(lambda))
    rho_a^{1/2}) rho_a`` (18c) gives ``(1 - k_a) rho_a^2 >= eps_a + that``. Both right sides
    are non-decreasing in the radius: :func:`_smallest_root_below` bounds each radius from
    below. 0 (no claim) when a constant is negative or not finite.
    """
    rc, tc = reference_constants(c, p), true_constants(c, p)
    lam = float(c.lam)
    names_r = (
        "circ_1 circ_2 circ_4 ocirc_1 ocirc_2 ocirc_4 odot_1 odot_2 odot_3 odot_4 odot_5 odot_8 "
        "otimes_1 otimes_2 otimes_3 oast_1 oast_2 oast_3 Delta_star"
    ).split()
    vr = {n: float(getattr(rc, n)) for n in names_r}
    va = {n: float(getattr(tc, n)) for n in ("odot_1", "otimes_1")}
    if not (math.isfinite(lam) and lam > 0.0) or not all(
        math.isfinite(v) and v >= 0.0 for v in (*vr.values(), *va.values())
    ):
        return 0.0
    sl, ds = math.sqrt(lam), vr["Delta_star"]
    eps_r = float(c.eps_r)

    def stuff_r(rho: float) -> float:
        r = rho + ds
        sr = math.sqrt(r)
        g0 = (
            vr["circ_1"] / (2 * lam)
            + vr["ocirc_1"] / (2 * lam) * sr
            + vr["odot_1"] / (2 * lam) * r
            + (vr["odot_2"] / (2 * lam) + vr["odot_3"] / (2 * sl) + vr["oast_1"] * ds / (2 * lam))
            * rho
            + vr["otimes_1"] / (2 * sl) * (r * sr)
        )
        t0 = (
            vr["circ_2"]
            + vr["ocirc_2"] * sr
            + vr["odot_4"] * r
            + vr["odot_5"] * rho
            + (vr["otimes_2"] * r + vr["otimes_3"] * rho) * sr
            + (vr["oast_2"] * r + vr["oast_3"] * rho) * r
        )
        w = vr["circ_4"] + vr["ocirc_4"] * sr + vr["odot_8"] * r
        return g0 + min(max(eps_r, t0 / (2 * lam)), w + eps_r)

    def stuff_a(rho: float) -> float:
        return (va["odot_1"] / (2 * lam) + va["otimes_1"] / (2 * sl) * math.sqrt(rho)) * rho

    lo_r = _smallest_root_below(float(c.alpha) ** 2, float(unmatched_gain_r(c)), stuff_r)
    lo_a = _smallest_root_below(float(c.eps_a), float(unmatched_gain_a(c)), stuff_a)
    return (lo_r + lo_a) * LOWER_DEFLATE
