"""The L1-DRAC design conditions (16a), (16b), (21a), (21b), (24), each with its verdict.

Source: A. Gahlawat, S. H. Karumanchi, N. Hovakimyan, "L1-DRAC: Distributionally Robust Adaptive
Control -- Global Results", arXiv:2509.04619 (2025-09-04), Sec. 3.2. The two sides of each
condition are :mod:`drip_cert.bounds.l1drac.sides`; this module compares them in float64 (the
searches' oracle) and attaches the Arb-verified margin of :mod:`drip_cert.bounds.l1drac.verify`.

Public surface
--------------
* :class:`ConditionResult` -- one condition in the paper's form, with a signed float margin and
  its Arb-verified enclosure.
* :func:`condition_16a`, :func:`condition_16b`, :func:`condition_21a`, :func:`condition_21b`,
  :func:`condition_24` -- one condition at one point.
* :func:`evaluate_conditions` -- all five at a fully specified point.
* :class:`DesignPoint` -- the keywords ``rho_r``, ``rho_a``, ``lambda_s``, ``Ts`` of a point.

The argument checks (:func:`check_p`, :func:`check_omega`, :func:`check_Ts`), the float64
conditions on precomputed constants (:func:`float_16a` ... :func:`float_24`,
:func:`float_conditions`) and :func:`with_arb_margins` are shared with the searches, the back-off
and the designer.
"""

from __future__ import annotations

import dataclasses
import math
from collections.abc import Callable
from dataclasses import dataclass
from typing import Any, TypedDict, Unpack

from drip_cert.bounds.l1drac.appendix import (
    RefConstants,
    SamplingConstants,
    TrueConstants,
    frak_p_prime,
    reference_constants,
    true_constants,
)
from drip_cert.bounds.l1drac.backend import FloatOps
from drip_cert.bounds.l1drac.constants import (
    L1Constants,
    check_int,
    is_real,
    unmatched_gain_a,
    unmatched_gain_r,
)
from drip_cert.bounds.l1drac.sides import (
    RELATIONS,
    margin_of,
    sides_16a,
    sides_16b,
    sides_21a,
    sides_21b,
    sides_24,
    sides_24_at,
)
from drip_cert.bounds.l1drac.verify import CONDITIONS, verify_conditions
from drip_cert.errors import SpecError
from drip_cert.provenance import json_float

__all__ = [
    "ConditionResult",
    "condition_16a",
    "condition_16b",
    "condition_21a",
    "condition_21b",
    "condition_24",
    "evaluate_conditions",
    "DesignPoint",
]

#: e^{x} overflows float64 beyond x = 709.78; omega*Ts and lambda_s*Ts are kept below this.
EXP_ARG_MAX = 700.0


class DesignPoint(TypedDict, total=False):
    """The design point beside ``(p, omega)``, as keywords of :func:`float_conditions`,
    :func:`with_arb_margins` and :func:`~drip_cert.bounds.l1drac.verify.verify_conditions`
    (a parameter left out or None is not given)."""

    rho_r: float | None
    rho_a: float | None
    lambda_s: float | None
    Ts: float | None


def _given(eq: str, name: str, value: float | None) -> float:
    """``value``, which condition ``eq`` needs (TypeError naming it when it is None)."""
    if value is None:
        raise TypeError(f"condition ({eq}) needs {name}, which was not given")
    return value


@dataclass(frozen=True)
class ConditionResult:
    """One condition of L1-DRAC Sec. 3.2 in the paper's form ``lhs REL rhs``.

    ``lhs``, ``rhs``, ``margin`` and ``holds`` are the float64 evaluation: ``margin`` is signed,
    positive = satisfied: ``lhs - rhs`` for (16a, b) (``lhs >= rhs``), ``rhs - lhs`` for (21a, b)
    (``lhs < rhs``, strict) and (24) (``lhs <= rhs``); ``holds`` is the float comparison.

    ``verified``, ``margin_lo`` and ``margin_hi`` are the rigorous evaluation of the same margin
    in Arb ball arithmetic (:func:`drip_cert.bounds.l1drac.verify.verify_conditions`):
    ``[margin_lo, margin_hi]`` encloses the exact margin at the float inputs (lower end rounded
    down, upper end rounded up), and ``verified`` is ``margin_lo > 0`` (the ball's lower end is
    > 0). Only a verified condition counts for
    :attr:`drip_cert.bounds.l1drac.result.L1Design.feasible`. Results of the internal float-only
    searches carry ``verified=False`` and NaN ends.
    """

    eq: str
    lhs: float
    rhs: float
    margin: float
    holds: bool
    relation: str = ""
    verified: bool = False
    margin_lo: float = math.nan
    margin_hi: float = math.nan

    def to_dict(self) -> dict[str, Any]:
        """JSON-ready dictionary: eq, lhs, rhs, margin, holds, relation, verified, margin_lo,
        margin_hi."""
        return {
            "eq": self.eq,
            "lhs": json_float(self.lhs),
            "rhs": json_float(self.rhs),
            "margin": json_float(self.margin),
            "holds": bool(self.holds),
            "relation": self.relation,
            "verified": bool(self.verified),
            "margin_lo": json_float(self.margin_lo),
            "margin_hi": json_float(self.margin_hi),
        }


def _result(eq: str, lhs: float, rhs: float) -> ConditionResult:
    margin = margin_of(eq, lhs, rhs)
    return ConditionResult(eq, lhs, rhs, margin, _holds(eq, lhs, rhs, margin), RELATIONS[eq])


def _holds(eq: str, lhs: float, rhs: float, margin: float) -> bool:
    """Whether ``lhs REL rhs`` holds in floats (never with a NaN margin): the ``holds`` of
    :class:`ConditionResult`, without building one (the searches ask only this)."""
    relation = RELATIONS[eq]
    if relation == ">=":
        holds = lhs >= rhs
    elif relation == "<":
        holds = lhs < rhs
    else:  # "<="
        holds = lhs <= rhs
    if math.isnan(margin):
        holds = False
    return bool(holds)


def holds_of(eq: str, lhs: float, rhs: float) -> bool:
    """``_result(eq, lhs, rhs).holds`` without building the result (a search's oracle)."""
    return _holds(eq, lhs, rhs, margin_of(eq, lhs, rhs))


# --------------------------------------------------------------------------------------------
# Argument checks
# --------------------------------------------------------------------------------------------


def check_omega(c: L1Constants, omega: float) -> None:
    """SpecError unless omega is a finite number > 0 other than 2 lambda."""
    if not (is_real(omega) and math.isfinite(omega) and omega > 0):
        raise SpecError(f"{omega!r} must be a finite number > 0", field="omega")
    if omega == 2.0 * c.lam:
        raise SpecError(
            f"omega = {omega!r} equals 2*lambda: every bandwidth term of (18b), (18c), (21) and "
            "(24) divides by |2 lambda - omega|, which is zero there; choose another omega",
            field="omega",
        )


def check_p(c: L1Constants, p: Any) -> int:
    """p as an int in ``{1, ..., p_star}`` (SpecError otherwise)."""
    p = check_int("p", p, where="moment order", path=None)
    if p > c.p_star:
        raise SpecError(
            f"p = {p} exceeds p_star = {c.p_star}: the constants of Appendix A need the 2p-th "
            "moment bound Delta_star of Assumption 3; use p <= p_star",
            field="p",
        )
    return p


def check_Ts(c: L1Constants, omega: float, lambda_s: float | None, Ts: float | None) -> None:
    """SpecError unless lambda_s and Ts are finite numbers > 0 with no overflow of e^{x Ts}."""
    for name, v in (("lambda_s", lambda_s), ("Ts", Ts)):
        if v is None or not (is_real(v) and math.isfinite(v) and v > 0):
            raise SpecError(f"{v!r} must be a finite number > 0", field=name)
    assert lambda_s is not None and Ts is not None  # each was checked in the loop above
    if max(omega, lambda_s, 2.0 * c.lam) * Ts > EXP_ARG_MAX:
        raise SpecError(
            f"Ts = {Ts!r} is so long that e^(max(omega, lambda_s, 2 lambda) Ts) overflows; such a "
            "sampling period can never satisfy (24): use a Ts several orders smaller",
            field="Ts",
        )


# --------------------------------------------------------------------------------------------
# The float64 conditions on precomputed constants (the searches' oracle): the two sides come
# from the generic transcription of :mod:`drip_cert.bounds.l1drac.sides` (the Arb verifier
# evaluates the same code).
# --------------------------------------------------------------------------------------------


def float_16a(c: L1Constants, rc: RefConstants, omega: float, rho_r: float) -> ConditionResult:
    """(16a) in float64."""
    return _result("16a", *sides_16a(c, rc, omega, rho_r))


def float_16b(c: L1Constants, tc: TrueConstants, omega: float, rho_a: float) -> ConditionResult:
    """(16b) in float64."""
    return _result("16b", *sides_16b(c, tc, omega, rho_a))


def float_21a(c: L1Constants, rc: RefConstants, omega: float, rho_r: float) -> ConditionResult:
    """(21a) in float64; Theta_r is divided by |2 lambda - omega| exactly once (the authors'
    Julia code: twice)."""
    return _result("21a", *sides_21a(c, rc, omega, rho_r))


def float_21b(
    c: L1Constants, tc: TrueConstants, omega: float, rho_r: float, rho_a: float
) -> ConditionResult:
    """(21b) in float64."""
    return _result("21b", *sides_21b(c, tc, omega, rho_r, rho_a))


def float_24(
    c: L1Constants,
    tc: TrueConstants,
    p: int,
    omega: float,
    lambda_s: float,
    Ts: float,
    rho_r: float,
    rho_a: float,
    *,
    envelope: bool = False,
) -> ConditionResult:
    """(24) in float64 (on the monotone envelope of (A.13)-(A.17) when ``envelope``)."""
    return _result("24", *sides_24(c, tc, p, omega, lambda_s, Ts, rho_r, rho_a, envelope=envelope))


def holds_24_at(
    c: L1Constants,
    tc: TrueConstants,
    s: SamplingConstants,
    omega: float,
    rho_r: float,
    rho_a: float,
) -> bool:
    """``float_24(...).holds`` on sampling constants computed once (``s``), without building the
    result: the oracle of the search over rho_a, asked ~10^5 times per design."""
    lhs, rhs = sides_24_at(c, tc, s, omega, rho_r, rho_a)
    return _holds("24", lhs, rhs, margin_of("24", lhs, rhs))


def sides_24_oracle(
    c: L1Constants,
    tc: TrueConstants,
    s: SamplingConstants,
    omega: float,
    rho_r: float,
) -> Callable[[float], tuple[float, float]]:
    """``y -> sides_24_at(c, tc, s, omega, rho_r, y)``, the same two floats bit for bit, faster
    (:func:`_oracle_24`)."""
    return _oracle_24(c, tc, s, omega, rho_r, False)


def _oracle_24(
    c: L1Constants,
    tc: TrueConstants,
    s: SamplingConstants,
    omega: float,
    rho_r: float,
    compare: bool,
) -> Any:
    """``y -> sides_24_at(c, tc, s, omega, rho_r, y)`` (``compare``: ``y -> holds_24_at(...)``),
    the same floats (booleans) bit for bit, faster.

    The search over ``rho_a`` asks (24) ~40 times per root at fixed ``(c, tc, s, omega,
    rho_r)``. This computes once every subexpression of (25a-c), (18c) and (23) that does not
    involve ``rho_a`` and evaluates the rest with the float operations of
    :func:`~drip_cert.bounds.l1drac.sides.sides_24_at`, in the same order: every hoisted factor
    is a left-most operand of its product or sum there (Python evaluates ``a * b * y`` as
    ``(a * b) * y``), so each float is the same (tested against :func:`sides_24_at` in
    tests/test_l1drac_oracle.py). Float backend only (the searches'); another backend gets
    :func:`sides_24_at` itself.
    """
    if not all(isinstance(o.num, FloatOps) for o in (c, tc, s)):
        if compare:
            return lambda y: holds_24_at(c, tc, s, omega, rho_r, y)
        return lambda y: sides_24_at(c, tc, s, omega, rho_r, y)
    sq = math.sqrt
    rho_r = float(rho_r)
    D = c.Delta_star
    sc = s.consts
    fp1 = frak_p_prime(s.p)
    # (A.19c) ring-Upsilon(xi2) = Delta_g^2 (fp1 (L_p_par + L_sigma_par) xi2^(1/2)
    #                                        + L_mu_par xi2 / omega^(1/2))
    ring_a = sc.Delta_g**2
    ring_r1 = fp1 * (sc.L_p_par + sc.L_sigma_par)
    ring_lmu = sc.L_mu_par
    s_sw = sq(s.omega)
    # (A.18a-c), (A.19a, b) in xi1 and the factors of (25a-c)
    d_p_par, d_s_par, d_mu_par = sc.Delta_p_par, sc.Delta_sigma_par, sc.Delta_mu_par
    k_tilde = s_sw * fp1 * sq(s.one_m_e2omega)
    k_tilde_out = s.one_m_e2lam * sc.Delta_g
    lam_s = sc.lam
    gap_s = abs(2.0 * lam_s - s.omega)
    k_a1 = s.omega / (lam_s * gap_s)
    g1p = s.gamma_1p
    two_fp1 = 2.0 * fp1
    swfp1 = s_sw * fp1
    u1_0 = s.mu_1 + swfp1 * s.sigma_1
    u1_1 = swfp1 * s.sigma_2
    u1_2 = s.mu_2 + swfp1 * s.sigma_3
    mu_3, gamma_pp, dg = s.mu_3, s.gamma_pp, sc.Delta_g
    sw_gap = s_sw / gap_s
    two_dg = 2.0 * sc.Delta_g
    sw_lam = s_sw / lam_s
    u3_k = sc.Delta_mu_par * s.expm1_omega_Ts
    # the right side (budget_24): Gamma_a (18c) and Theta_a (23) / |2 lambda - omega|
    om = float(omega)
    lam_t = tc.lam
    gap_c = abs(2.0 * c.lam - om)
    g0 = tc.odot_1 / (2 * lam_t) + om * tc.odot_4 / abs(2.0 * lam_t - om)
    g1 = tc.otimes_1 / (2 * sq(lam_t))
    t_sw = sq(om)
    q_rpp = 2.0 * (rho_r + D)
    t_0 = t_sw * tc.ocirc_1
    t_1 = t_sw * tc.otimes_3
    t_2 = tc.otimes_2 + t_sw * tc.otimes_4
    t_3 = tc.odot_2 + t_sw * tc.odot_3
    oast_2, oast_3 = tc.oast_2, tc.oast_3
    one_m_ka = 1.0 - unmatched_gain_a(c)
    isnan = math.isnan

    def sides(y: float) -> Any:
        y = float(y)
        xi1 = y + rho_r + D
        ring = ring_a * (ring_r1 * sq(y) + ring_lmu * y / s_sw)
        sx = sq(xi1)
        par = d_p_par + d_s_par * (1.0 + sx)
        one_xi = 1.0 + xi1
        umt = k_tilde_out * (k_tilde * par + d_mu_par * one_xi) / lam_s
        um = g1p * (two_fp1 * par + d_mu_par * one_xi / s_sw)
        a1 = umt * y + k_a1 * ring * um
        u1p = u1_0 + u1_1 * sq(sx) + u1_2 * sx + mu_3 * xi1
        a2 = (dg * y + sw_gap * ring) * (u1p + s_sw * (gamma_pp * par)) / lam_s
        a3 = (two_dg * y + sw_lam * ring) * (u3_k * one_xi) / gap_s
        ga = (g0 + g1 * sq(y)) * y
        rpp = y + q_rpp
        th = (t_0 + t_1 * rpp + t_2 * y) * sq(y) + (t_3 + oast_2 * rpp + oast_3 * y) * y
        lhs, rhs = a1 + a2 + a3, one_m_ka * y**2 - ga - th / gap_c
        if compare:  # holds_24_at: _holds("24", lhs, rhs, rhs - lhs)
            return lhs <= rhs and not isnan(rhs - lhs)
        return lhs, rhs

    return sides


def holds_24_oracle(
    c: L1Constants,
    tc: TrueConstants,
    s: SamplingConstants,
    omega: float,
    rho_r: float,
) -> Callable[[float], bool]:
    """``y -> holds_24_at(c, tc, s, omega, rho_r, y)`` on the floats of :func:`sides_24_oracle`
    (the same booleans): the oracle of the search over ``rho_a``."""
    return _oracle_24(c, tc, s, omega, rho_r, True)


def holds_r_oracle(
    c: L1Constants, rc: RefConstants, omega: float, eq: str
) -> Callable[[float], bool]:
    """``x -> holds_of(eq, *sides_<eq>(c, rc, omega, x))`` for ``eq`` in ``("16a", "21a")``:
    the oracles of the search over ``rho_r``, with every subexpression of Gamma_r (18b) and
    Theta_r (22) that does not involve ``rho_r`` computed once, and the rest in the float
    operations of :func:`~drip_cert.bounds.l1drac.sides.sides_16a` /
    :func:`~drip_cert.bounds.l1drac.sides.sides_21a` in their order (the same booleans; tested
    in tests/test_l1drac_oracle.py). Float backend only; otherwise the generic form."""
    return _oracle_r(c, rc, omega, eq, True)


def sides_r_oracle(
    c: L1Constants, rc: RefConstants, omega: float, eq: str
) -> Callable[[float], tuple[float, float]]:
    """``x -> sides_<eq>(c, rc, omega, x)`` for ``eq`` in ``("16a", "21a")``, the same two
    floats bit for bit, faster (the floats :func:`holds_r_oracle` compares): what the search
    over ``rho_r`` evaluates, to compare them and to interpolate on their margin."""
    return _oracle_r(c, rc, omega, eq, False)


def _oracle_r(c: L1Constants, rc: RefConstants, omega: float, eq: str, compare: bool) -> Any:
    """:func:`holds_r_oracle` (``compare``) or :func:`sides_r_oracle`."""
    side = {"16a": sides_16a, "21a": sides_21a}[eq]
    if not all(isinstance(o.num, FloatOps) for o in (c, rc)):
        if compare:
            return lambda x: holds_of(eq, *side(c, rc, omega, x))
        return lambda x: side(c, rc, omega, x)
    sq, isnan = math.sqrt, math.isnan
    om = float(omega)
    lam, D = rc.lam, rc.Delta_star
    w = om / abs(2.0 * lam - om)
    sl = sq(lam)
    # (18b) Gamma_r = A0 + A1 r^(1/2) + A2 r + A3 rho_r + A4 r^(3/2), r = rho_r + Delta_star
    a0 = rc.circ_1 / (2 * lam) + w * rc.circ_4
    a1 = rc.ocirc_1 / (2 * lam) + w * rc.ocirc_4
    a2 = rc.odot_1 / (2 * lam) + w * rc.odot_8
    a3 = rc.odot_2 / (2 * lam) + rc.odot_3 / (2 * sl) + rc.oast_1 * D / (2 * lam)
    a4 = rc.otimes_1 / (2 * sl)
    one_m_kr = 1.0 - unmatched_gain_r(c)
    alpha2, eps_r = c.alpha**2, c.eps_r
    if eq == "16a":

        def holds_16a(x: float) -> Any:
            x = float(x)
            r = x + D
            sr = sq(r)
            lhs = one_m_kr * x**2
            rhs = alpha2 + (a0 + a1 * sr + a2 * r + a3 * x + a4 * (r * sr)) + eps_r
            if compare:
                return lhs >= rhs and not isnan(lhs - rhs)
            return lhs, rhs

        holds_16a.__name__ = "holds_16a" if compare else "sides_16a"
        return holds_16a
    # (22) Theta_r, divided by |2 lambda - omega| (c's lambda, as sides_21a)
    sw = sq(om)
    b0 = rc.circ_2 + sw * rc.circ_3
    b1 = rc.ocirc_2 + sw * rc.ocirc_3
    b2 = rc.odot_4 + sw * rc.odot_6
    b3 = rc.odot_5 + sw * rc.odot_7
    b4 = rc.otimes_2 + sw * rc.otimes_4
    b5 = rc.otimes_3 + sw * rc.otimes_5
    oast_2, oast_3 = rc.oast_2, rc.oast_3
    gap = abs(2.0 * c.lam - om)

    def holds_21a(x: float) -> Any:
        x = float(x)
        r = x + D
        sr = sq(r)
        th = b0 + b1 * sr + b2 * r + b3 * x + (b4 * r + b5 * x) * sr + (oast_2 * r + oast_3 * x) * r
        lhs = th / gap
        rhs = one_m_kr * x**2 - alpha2 - (a0 + a1 * sr + a2 * r + a3 * x + a4 * (r * sr))
        if compare:
            return lhs < rhs and not isnan(rhs - lhs)
        return lhs, rhs

    holds_21a.__name__ = "holds_21a" if compare else "sides_21a"
    return holds_21a


def float_conditions(
    c: L1Constants,
    rc: RefConstants,
    tc: TrueConstants,
    p: int,
    omega: float,
    which: tuple[str, ...],
    *,
    rho_r: float | None = None,
    rho_a: float | None = None,
    lambda_s: float | None = None,
    Ts: float | None = None,
) -> tuple[ConditionResult, ...]:
    """The float64 results of the conditions ``which``, in that order, at one point."""
    make = {
        "16a": lambda: float_16a(c, rc, omega, _given("16a", "rho_r", rho_r)),
        "21a": lambda: float_21a(c, rc, omega, _given("21a", "rho_r", rho_r)),
        "16b": lambda: float_16b(c, tc, omega, _given("16b", "rho_a", rho_a)),
        "21b": lambda: float_21b(
            c, tc, omega, _given("21b", "rho_r", rho_r), _given("21b", "rho_a", rho_a)
        ),
        "24": lambda: float_24(
            c,
            tc,
            p,
            omega,
            _given("24", "lambda_s", lambda_s),
            _given("24", "Ts", Ts),
            _given("24", "rho_r", rho_r),
            _given("24", "rho_a", rho_a),
        ),
    }
    return tuple(make[eq]() for eq in which)


def with_arb_margins(
    c: L1Constants,
    p: int,
    results: tuple[ConditionResult, ...],
    omega: float,
    **point: Unpack[DesignPoint],
) -> tuple[ConditionResult, ...]:
    """``results`` with their Arb-verified margins (one Arb evaluation for all of them).

    ``point`` is the rest of the design point (``lambda_s``, ``Ts``, ``rho_r``, ``rho_a``) as
    :func:`~drip_cert.bounds.l1drac.verify.verify_conditions` takes it.
    """
    v = verify_conditions(c, p, omega, which=tuple(r.eq for r in results), **point)
    out = []
    for r in results:
        m = v[r.eq]
        out.append(dataclasses.replace(r, verified=m.verified, margin_lo=m.lo, margin_hi=m.hi))
    return tuple(out)


# --------------------------------------------------------------------------------------------
# The conditions at one point, checked and verified
# --------------------------------------------------------------------------------------------


def _evaluate(
    c: L1Constants, p: int, which: tuple[str, ...], omega: float, **point: Unpack[DesignPoint]
) -> tuple[ConditionResult, ...]:
    """The conditions ``which`` at one point: arguments checked, float64 verdicts, Arb margins."""
    p = check_p(c, p)
    check_omega(c, omega)
    if "24" in which:
        check_Ts(c, omega, point["lambda_s"], point["Ts"])
    rc = reference_constants(c, p)
    tc = true_constants(c, p)
    floats = float_conditions(c, rc, tc, p, omega, which, **point)
    return with_arb_margins(c, p, floats, omega, **point)


def condition_16a(c: L1Constants, p: int, omega: float, rho_r: float) -> ConditionResult:
    """(16a): ``(1 - Dgp Dmup / lambda) rho_r^2 >= alpha^2 + Gamma_r(rho_r, p, omega) + eps_r``.

    Float64 verdict plus the Arb-verified margin (:class:`ConditionResult`).
    """
    return _evaluate(c, p, ("16a",), omega, rho_r=rho_r)[0]


def condition_16b(c: L1Constants, p: int, omega: float, rho_a: float) -> ConditionResult:
    """(16b): ``(1 - Dgp Lmup / lambda) rho_a^2 >= Gamma_a(rho_a, p, omega) + eps_a``.

    Float64 verdict plus the Arb-verified margin (:class:`ConditionResult`).
    """
    return _evaluate(c, p, ("16b",), omega, rho_a=rho_a)[0]


def condition_21a(c: L1Constants, p: int, omega: float, rho_r: float) -> ConditionResult:
    """(21a): ``Theta_r / |2 lambda - omega| < (1 - k_r) rho_r^2 - alpha^2 - Gamma_r``.

    Float64 verdict plus the Arb-verified margin (:class:`ConditionResult`).
    """
    return _evaluate(c, p, ("21a",), omega, rho_r=rho_r)[0]


def condition_21b(
    c: L1Constants, p: int, omega: float, rho_r: float, rho_a: float
) -> ConditionResult:
    """(21b): ``Theta_a / |2 lambda - omega| < (1 - Dgp Lmup / lambda) rho_a^2 - Gamma_a``.

    Float64 verdict plus the Arb-verified margin (:class:`ConditionResult`).
    """
    return _evaluate(c, p, ("21b",), omega, rho_r=rho_r, rho_a=rho_a)[0]


def condition_24(
    c: L1Constants,
    p: int,
    omega: float,
    lambda_s: float,
    Ts: float,
    rho_r: float,
    rho_a: float,
) -> ConditionResult:
    """(24): ``sum_i Upsilon_{a_i}(rho', rho_a) <= (1 - k_a) rho_a^2 - Gamma_a - Theta_a/|2l - w|``.

    ``rho' = rho_a + rho_r + Delta_star``; the Upsilon maps are (25a-c) with (A.13)-(A.19).
    Float64 verdict plus the Arb-verified margin (:class:`ConditionResult`).
    """
    return _evaluate(c, p, ("24",), omega, lambda_s=lambda_s, Ts=Ts, rho_r=rho_r, rho_a=rho_a)[0]


def evaluate_conditions(
    c: L1Constants,
    p: int,
    omega: float,
    lambda_s: float,
    Ts: float,
    rho_r: float,
    rho_a: float,
) -> tuple[ConditionResult, ...]:
    """(16a), (16b), (21a), (21b), (24) at one fully specified point, in that order.

    Each result carries the float64 verdict and the Arb-verified margin (:class:`ConditionResult`).
    """
    return _evaluate(c, p, CONDITIONS, omega, lambda_s=lambda_s, Ts=Ts, rho_r=rho_r, rho_a=rho_a)
