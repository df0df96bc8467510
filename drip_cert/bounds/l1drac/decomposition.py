"""rho_L1 term by term: what each part of (16), (21), (24) of L1-DRAC costs at a design.

Source: A. Gahlawat, S. H. Karumanchi, N. Hovakimyan, "L1-DRAC: Distributionally Robust Adaptive
Control -- Global Results", arXiv:2509.04619 (2025-09-04), Sec. 3.2: (16a), (16b), (18b), (18c),
(21a), (21b), (22)-(25); docs/math/l1drac.md section 5.5.

At a design the smallest radii make their binding condition an equality (up to the back-off):
``(1 - k_r) rho_r^2 = alpha^2 + Gamma_r + eps_r + Theta_r / a_w (+ room)`` and, at
a given ``T_s``, ``(1 - k_a) rho_a^2 = Gamma_a + Theta_a / a_w + sum_i Upsilon_{a_i}
(+ room)``. Each term's share of the left side says what sets the radius: the left side is
quadratic in the radius and every right-side term grows more slowly (section 5.3), so removing a
term with share ``s`` shrinks the radius by a factor of about ``sqrt(1 - s)`` or more. The numbers
are float64 evaluations of the same functions the designer uses (:mod:`.sides`); they explain a
design and certify nothing (the design itself is verified in Arb, :mod:`.verify`).

Public surface
--------------
* :class:`Term`, :class:`RadiusDecomposition`, :class:`L1Decomposition`
* :func:`decompose` -- the decomposition of a feasible design.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Any

from drip_cert.bounds.l1drac.appendix import (
    reference_constants,
    sampling_constants,
    true_constants,
)
from drip_cert.bounds.l1drac.constants import L1Constants, unmatched_gain_a, unmatched_gain_r
from drip_cert.bounds.l1drac.mean import MeanGapBound, mean_gap_bound
from drip_cert.bounds.l1drac.result import L1Design
from drip_cert.bounds.l1drac.sides import (
    gamma_a,
    gamma_r,
    theta_a,
    theta_r,
    upsilon_a1,
    upsilon_a2,
    upsilon_a3,
)
from drip_cert.provenance import json_float

__all__ = ["Term", "RadiusDecomposition", "L1Decomposition", "decompose"]


@dataclass(frozen=True)
class Term:
    """One term of a radius's binding condition.

    ``name`` (the paper's symbol), ``value`` (its contribution to the right side), ``share``
    (``value`` over the left side ``(1 - k) rho^2``), ``condition`` (the equation it enters),
    ``ts_power`` (how it scales as ``T_s -> 0``: ``"T_s^0"``, or the leading power of a
    sampled-data term) and ``what`` (the constants it is made of, in words).
    """

    name: str
    value: float
    share: float
    condition: str
    ts_power: str
    what: str

    def to_dict(self) -> dict[str, Any]:
        """JSON-ready: every attribute."""
        return {
            "name": self.name,
            "value": json_float(self.value),
            "share": json_float(self.share),
            "condition": self.condition,
            "ts_power": self.ts_power,
            "what": self.what,
        }


@dataclass(frozen=True)
class RadiusDecomposition:
    """The terms of one radius (``rho_r`` or ``rho_a``): ``lhs = (1 - k) rho^2`` and its parts;
    ``room`` is ``lhs`` minus the sum of the terms (the back-off and, for a radius larger than its
    smallest value, the unused slack)."""

    radius: str
    value: float
    lhs: float
    terms: tuple[Term, ...]

    @property
    def room(self) -> float:
        """``lhs`` minus the sum of the terms."""
        return self.lhs - math.fsum(t.value for t in self.terms)

    def to_dict(self) -> dict[str, Any]:
        """JSON-ready: radius, value, lhs, room, terms (largest first)."""
        return {
            "radius": self.radius,
            "value": json_float(self.value),
            "lhs": json_float(self.lhs),
            "room": json_float(self.room),
            "terms": [t.to_dict() for t in sorted(self.terms, key=lambda t: -t.value)],
        }


@dataclass(frozen=True)
class L1Decomposition:
    """``rho_L1 = rho_r + rho_a`` term by term at a design (docs/math/l1drac.md section 5.5).

    ``rho_Ts0`` is the smallest verified ``rho`` on the design's front (the ``T_s -> 0`` end, a
    knife edge in general), ``None`` without a front; ``sampling_share`` is the part of
    ``(1 - k_a) rho_a^2`` the sampled-data terms (25a-c) take; ``rho_mean`` the bound of the mean
    gap ``max_t E||X_t - X*_t||`` at the same controller (:mod:`.mean`, section 5.6).
    """

    rho: float
    Ts: float
    rho_r: RadiusDecomposition
    rho_a: RadiusDecomposition
    rho_Ts0: float | None
    rho_mean: MeanGapBound | None = None

    @property
    def sampling_share(self) -> float:
        """Share of ``(1 - k_a) rho_a^2`` taken by the sampled-data terms (25a-c)."""
        return math.fsum(t.share for t in self.rho_a.terms if t.condition == "24")

    def binding(self) -> Term:
        """The term with the largest value in the larger radius's condition."""
        big = self.rho_a if self.rho_a.value >= self.rho_r.value else self.rho_r
        return max(big.terms, key=lambda t: t.value)

    def to_dict(self) -> dict[str, Any]:
        """JSON-ready: rho, Ts, rho_r, rho_a, rho_Ts0, rho_mean, sampling_share, binding, note."""
        b = self.binding()
        return {
            "rho": json_float(self.rho),
            "Ts": json_float(self.Ts),
            "rho_r": self.rho_r.to_dict(),
            "rho_a": self.rho_a.to_dict(),
            "rho_Ts0": None if self.rho_Ts0 is None else json_float(self.rho_Ts0),
            "rho_mean": None if self.rho_mean is None else self.rho_mean.to_dict(),
            "sampling_share": json_float(self.sampling_share),
            "binding": {"radius": b.condition, "name": b.name, "share": json_float(b.share)},
            "note": "float64 shares of (1 - k) rho^2 at the returned design, a_w = |2 lambda - "
            "omega| (docs/math/l1drac.md "
            "section 5.5); an explanation, not a claim: the design is verified in Arb",
        }


def _shares(terms: list[tuple[str, float, str, str, str]], lhs: float) -> tuple[Term, ...]:
    return tuple(
        Term(n, float(v), float(v) / lhs if lhs > 0 else math.nan, cond, pw, what)
        for n, v, cond, pw, what in terms
    )


def decompose(c: L1Constants, d: L1Design) -> L1Decomposition | None:
    """The term-by-term decomposition of the feasible design ``d`` (``None`` when infeasible)."""
    if not d.feasible or None in (d.omega, d.lambda_s, d.Ts, d.rho_r, d.rho_a, d.rho):
        return None
    w, ls, Ts = float(d.omega), float(d.lambda_s), float(d.Ts)  # type: ignore[arg-type]
    rr, ra = float(d.rho_r), float(d.rho_a)  # type: ignore[arg-type]
    rc, tc = reference_constants(c, d.p), true_constants(c, d.p)
    lam, a_w = c.lam, abs(2.0 * c.lam - w)
    y = rr + rc.Delta_star
    sl = math.sqrt(lam)
    rw = w / a_w
    g_r = [
        ("Delta_circ1/(2 lam) + omega Delta_circ4/a_w", rc.circ_1 / (2 * lam)
         + rw * rc.circ_4, "16a", "T_s^0", "Gamma_r, order y_r^0: drift/diffusion growth at 0"),
        ("(Delta_ocirc1/(2 lam) + omega Delta_ocirc4/a_w) y_r^1/2", (rc.ocirc_1 / (2 * lam)
         + rw * rc.ocirc_4) * math.sqrt(y), "16a", "T_s^0", "Gamma_r, order y_r^1/2: diffusion"),
        ("(Delta_odot1/(2 lam) + omega Delta_odot8/a_w) y_r", (rc.odot_1 / (2 * lam)
         + rw * rc.odot_8) * y, "16a", "T_s^0", "Gamma_r, order y_r: linear growth"),
        ("(Delta_odot2/(2 lam) + Delta_odot3/(2 sqrt lam) + Delta_oast1 Delta_star/(2 lam)) rho_r",
         (rc.odot_2 / (2 * lam) + rc.odot_3 / (2 * sl) + rc.oast_1 * rc.Delta_star / (2 * lam))
         * rr, "16a", "T_s^0", "Gamma_r, order rho_r: Lipschitz constants"),
        ("Delta_otimes1/(2 sqrt lam) y_r^3/2", rc.otimes_1 / (2 * sl) * y * math.sqrt(y), "16a",
         "T_s^0", "Gamma_r, order y_r^3/2: diffusion growth"),
    ]  # fmt: skip
    assert math.isclose(sum(v for _, v, *_ in g_r), float(gamma_r(rr, w, rc)), rel_tol=1e-9)
    terms_r = [
        ("alpha^2", c.alpha**2, "16a", "T_s^0", "initial distance W_2p(xi_0, xi_0*)"),
        *g_r,
        ("eps_r", c.eps_r, "16a", "T_s^0", "design slack of (16a)"),
        ("Theta_r/a_w", float(theta_r(rr, w, rc)) / a_w, "21a", "T_s^0",
         "filter-bandwidth terms (22), O(omega^-1/2)"),
    ]  # fmt: skip
    lhs_r = (1.0 - float(unmatched_gain_r(c))) * rr**2
    ga = float(gamma_a(ra, w, tc))
    g_a = [
        ("Delta_odot1/(2 lam) rho_a", tc.odot_1 / (2 * lam) * ra, "16b", "T_s^0",
         "Gamma_a: Lipschitz constants of the uncertainty"),
        ("omega Delta_odot4/a_w rho_a", w * tc.odot_4 / a_w * ra, "16b", "T_s^0",
         "Gamma_a: filtered uncertainty"),
        ("Delta_otimes1/(2 sqrt lam) rho_a^3/2", tc.otimes_1 / (2 * sl) * ra * math.sqrt(ra),
         "16b", "T_s^0", "Gamma_a: diffusion Hoelder constants"),
    ]  # fmt: skip
    assert math.isclose(sum(v for _, v, *_ in g_a), ga, rel_tol=1e-9)
    s = sampling_constants(c, d.p, w, Ts, ls)
    xi1 = ra + rr + c.Delta_star
    terms_a = [
        *g_a,
        ("Theta_a/a_w", float(theta_a(ra, rr, w, tc, c.Delta_star)) / a_w, "21b",
         "T_s^0", "filter-bandwidth terms (23)"),
        ("Upsilon_a1", float(upsilon_a1(xi1, ra, s)), "24", "T_s^1/4 (diffusion) .. T_s^1/2",
         "sampled-data error (25a): the predictor between samples"),
        ("Upsilon_a2", float(upsilon_a2(xi1, ra, s)), "24", "T_s^1/4 (diffusion) .. T_s^1/2",
         "sampled-data error (25b)"),
        ("Upsilon_a3", float(upsilon_a3(xi1, ra, s)), "24", "T_s^1/4 (diffusion) .. T_s^1/2",
         "sampled-data error (25c)"),
    ]  # fmt: skip
    lhs_a = (1.0 - float(unmatched_gain_a(c))) * ra**2
    # at a given T_s, (24) binds rho_a: its right side holds Gamma_a and Theta_a, not eps_a
    ts0 = min((p.rho for p in d.front if p.verified), default=None)
    return L1Decomposition(
        rho=float(d.rho),  # type: ignore[arg-type]
        Ts=Ts,
        rho_r=RadiusDecomposition("rho_r", rr, lhs_r, _shares(terms_r, lhs_r)),
        rho_a=RadiusDecomposition("rho_a", ra, lhs_a, _shares(terms_a, lhs_a)),
        rho_Ts0=ts0,
        rho_mean=mean_gap_bound(c, d),
    )
