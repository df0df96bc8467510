"""The three monotone root searches of the L1-DRAC designer: smallest rho_r, rho_a; largest Ts.

Source: A. Gahlawat, S. H. Karumanchi, N. Hovakimyan, "L1-DRAC: Distributionally Robust Adaptive
Control -- Global Results", arXiv:2509.04619 (2025-09-04), Sec. 3.2 (conditions (16), (21), (24)).

How and to what tolerance
-------------------------
Each unknown is the end of a feasible set that is an interval reaching to infinity (to zero for
Ts): :func:`smallest_rho_r`, :func:`smallest_rho_a` and :func:`largest_Ts` prove it. A search
asks a *probe* ``x -> (holds, margin)``: ``holds`` is the float64 verdict of the condition, the
same comparison of the same two float sides that the final re-check makes (NaN never holds), and
``margin`` a continuous measure of it, ``atanh(m / (|lhs| + |rhs|))`` with ``m`` the signed
margin of :func:`~drip_cert.bounds.l1drac.sides.margin_of` (>= 0 where the condition holds; for
positive sides ``+-log(lhs / rhs) / 2``, close to linear in ``log x``), used only to choose where
to probe next.

1. Bracketing (:func:`_bracket`): from the search's lower end (rho) or from ``T_cap`` (Ts), a
   first step of a factor 2 (rho) or 1/10 (Ts), then steps in ``log x`` from the secant
   extrapolation of the margin (times 1.1), at most doubling (galloping), until a probe holds;
   None when the cap (RHO_CAP; TINY for Ts) itself fails.
2. Closing (:func:`_close`): on ``[lo, hi]`` with one end satisfying and the other not, the
   secant zero of the margin through the last two probes in ``log x`` (else regula falsi through
   the ends, else the midpoint), projected as in the ITP method so that a bracket never needs
   more than bisection's count + ITP_N0 = 6 probes, and kept ``0.99 log1p(ROOT_RTOL)`` inside
   the ends so that a root estimated at an end is closed by the next probe. Every probed point
   replaces the end on its *verdict's* side, whatever its margin: the bracket invariant is that
   of a bisection.

The search stops when ``hi / lo - 1 <= ROOT_RTOL`` (or no float lies between the ends) and
returns the satisfying end: ``hi`` for rho (``lo`` for the largest Ts). That point was itself
probed, with the verdict the final re-check uses, so the certificate never rests on a point that
fails its own re-check; a point within a relative ROOT_RTOL below it (above it for Ts) fails, so
it is minimal (maximal) to ``ROOT_RTOL``, as with the bisection this replaced (issue 26), which
needed ~45 probes per root where this needs ~7 on the gallery examples (smooth margins converge
superlinearly; steps, NaN or misleading margins fall back to bisection's steps).

Public surface
--------------
* :data:`ROOT_RTOL` -- the relative tolerance of every search.
* :func:`smallest_rho_r`, :func:`smallest_rho_a`, :func:`largest_Ts` -- the searches, arguments
  checked.

:func:`min_rho_r`, :func:`min_rho_a` and :func:`max_Ts` are the same searches on precomputed
constants, unchecked (the designer's inner loops).
"""

from __future__ import annotations

import math
from collections.abc import Callable

from drip_cert.bounds.l1drac.appendix import (
    RefConstants,
    TrueConstants,
    reference_constants,
    sampling_constants,
    true_constants,
)
from drip_cert.bounds.l1drac.conditions import (
    EXP_ARG_MAX,
    check_omega,
    check_p,
    check_Ts,
    sides_24_oracle,
    sides_r_oracle,
)
from drip_cert.bounds.l1drac.constants import L1Constants
from drip_cert.bounds.l1drac.sides import (
    RELATIONS,
    budget_24,
    sides_16b,
    sides_21b,
    upsilon_sum,
)
from drip_cert.errors import SpecError

__all__ = ["ROOT_RTOL", "smallest_rho_r", "smallest_rho_a", "largest_Ts"]

#: Relative tolerance of every root search (the returned root is within this of the true one).
ROOT_RTOL = 1e-12
#: Largest radius tried before a condition is declared infeasible for every rho.
RHO_CAP = 1e60
#: Smallest positive radius / sampling period tried.
TINY = 1e-200


#: A probe of a search: ``x -> (holds, m)``, the float64 verdict of the condition at ``x`` (the
#: comparison the final re-check makes) and a continuous margin used only to choose the next
#: probe: >= 0 where the condition holds with room, <= 0 where it fails (+-inf allowed), or NaN.
Probe = Callable[[float], tuple[bool, float]]

#: ITP slack n_0 over bisection: :func:`_close` never needs more than n_{1/2} + ITP_N0 probes,
#: where n_{1/2} = ceil(log2(w / (ITP_WIDTH log1p(ROOT_RTOL)))) is the count of plain bisection
#: on a bracket of width w in log x (a factor 2: n_{1/2} = 40).
ITP_N0 = 6
#: The ITP target width 2 eps in log x, as a fraction of log1p(ROOT_RTOL): a hair below it, so
#: that a bracket of that width in u = log(x / lo) passes the float test hi / lo - 1 <= ROOT_RTOL
#: despite the rounding of x = lo e^u.
ITP_WIDTH = 0.999
#: Factor on the secant's extrapolated step while bracketing an up-set: a little beyond the
#: estimated root, so that the next probe usually holds and brackets it tightly.
OVERSHOOT = 1.1
#: Smallest factor hi / lo of a bracketing step (an extrapolation closer than this is moved out).
MIN_FACTOR = 1.01
#: Distance, as a fraction of the target width log1p(ROOT_RTOL), from an end of the bracket inside
#: which no point is probed: a point estimated there is moved to this distance, so that when the
#: root is between it and the end the next bracket is within the tolerance (<1: float slack).
TOL_STEP = 0.99


def _relative_margin(m: float, lhs: float, rhs: float) -> float:
    """``atanh(m / (|lhs| + |rhs|))``: the margin on the scale of its terms, equal to
    ``log(lhs / rhs) / 2`` (its sign as ``m``) when both sides are positive, hence close to
    linear in log x where one power of x dominates each side (what the searches interpolate).
    +-inf where one side vanishes, has the other sign or is infinite (an overflow: ``m`` is then
    +-inf, a margin of definite sign); NaN when ``m`` is NaN or both sides are 0."""
    if math.isinf(m):
        return m
    scale = abs(lhs) + abs(rhs)
    if not 0.0 < scale < math.inf:
        return math.nan
    q = m / scale
    return math.atanh(q) if -1.0 < q < 1.0 else q * math.inf


def condition_probe(eq: str, sides: Callable[[float], tuple[float, float]]) -> Probe:
    """The probe of condition ``eq`` on its two float64 sides ``x -> (lhs, rhs)``: the verdict
    is ``holds_of(eq, lhs, rhs)`` (:func:`~drip_cert.bounds.l1drac.conditions.holds_of`, the
    ``holds`` of the final re-check: NaN never holds), written out for speed (the same booleans:
    tests/test_l1drac_roots.py), and the margin :func:`_relative_margin` of
    :func:`~drip_cert.bounds.l1drac.sides.margin_of`."""
    relation = RELATIONS[eq]
    atanh, inf, nan = math.atanh, math.inf, math.nan

    def probe(x: float) -> tuple[bool, float]:
        lhs, rhs = sides(x)
        if relation == ">=":
            m = lhs - rhs
            ok = lhs >= rhs
        elif relation == "<":
            m = rhs - lhs
            ok = lhs < rhs
        else:  # "<="
            m = rhs - lhs
            ok = lhs <= rhs
        if m != m:  # NaN: never holds (= holds_of), no margin
            return False, nan
        # _relative_margin, inlined (the searches' inner loop)
        if m == inf or m == -inf:
            return ok, m
        scale = abs(lhs) + abs(rhs)
        if not 0.0 < scale < inf:
            return ok, nan
        q = m / scale
        return ok, (atanh(q) if -1.0 < q < 1.0 else q * inf)

    return probe


def _mid(lo: float, hi: float) -> float:
    """The geometric midpoint of ``0 <= lo < hi`` without underflow of ``lo * hi``."""
    return math.sqrt(lo) * math.sqrt(hi)


def _close(
    probe: Probe, lo: float, hi: float, m_lo: float, m_hi: float, good_hi: bool
) -> tuple[float, float]:
    """Shrink a bracket ``0 < lo < hi`` with one satisfying end until ``hi / lo - 1 <= ROOT_RTOL``.

    ``good_hi``: ``hi`` satisfies and ``lo`` fails (an up-set); else the reverse (a down-set).
    ``m_lo``, ``m_hi``: the probe's margins at the ends. In ``u = log x``, each step probes

    1. the secant zero of the margin through the last two probes when it lies in the bracket,
       else the regula-falsi zero through the two ends, else the midpoint (NaN, infinite or
       equal margins); a margin whose sign disagrees with its verdict counts as 0;
    2. projected into the ball around the midpoint of radius
       ``r_j = eps 2^(n_max - j) - w / 2`` (the ITP method, Oliveira & Takahashi, ACM TOMS 47
       (1), 2020; ``2 eps = ITP_WIDTH log1p(ROOT_RTOL)``, ``n_max = n_{1/2} + ITP_N0``), which
       bounds the width after step j by ``2 eps 2^(n_max - j - 1)``: at most ``n_max`` probes
       whatever the margins are;
    3. kept ``TOL_STEP * 2 eps`` away from both ends (the midpoint once the bracket is narrower
       than twice that), so that a root estimated at an end is closed by the next probe.

    Every point is probed and replaces the end on its verdict's side, so the invariant (``hi``
    satisfies, ``lo`` fails, or the reverse) holds throughout, whatever the margins are; the
    margins only choose where to probe. Stops early when no float lies strictly between the ends
    (adjacent floats). Returns ``(lo, hi)``.
    """
    if not lo > 0.0:  # a bracket [0, hi]: no geometric midpoint lies inside (as bisection)
        return lo, hi
    m_lo, m_hi = _signed(not good_hi, m_lo), _signed(good_hi, m_hi)
    base = lo  # u = log(x / base): full relative precision at any scale of x
    eps2 = ITP_WIDTH * math.log1p(ROOT_RTOL)
    step = TOL_STEP * eps2
    ua, ub = 0.0, math.log(hi / lo)  # u of lo and hi
    n_max = max(math.ceil(math.log2(ub / eps2)), 0) + ITP_N0
    u0, z0, u1, z1 = ua, m_lo, ub, m_hi  # the last two probes (u, margin)
    j = 0
    while hi / lo - 1.0 > ROOT_RTOL:
        w = ub - ua
        half = ua + 0.5 * w
        u = _zero(u0, z0, u1, z1, ua, ub)
        if u is None:
            u = _zero(ua, m_lo, ub, m_hi, ua, ub)
        if u is None:
            u = half
        r = max(0.5 * eps2 * 2.0 ** (n_max - j) - 0.5 * w, 0.0)
        u = min(max(u, half - r), half + r)
        u = min(max(u, ua + step), ub - step) if w > 2.0 * step else half
        x = base * math.exp(u)
        if not lo < x < hi:
            x = _mid(lo, hi)
            u = half
            if not lo < x < hi:  # adjacent floats
                break
        ok, m = probe(x)
        m = _signed(ok, m)
        if ok == good_hi:
            hi, m_hi, ub = x, m, u
        else:
            lo, m_lo, ua = x, m, u
        u0, z0, u1, z1 = u1, z1, u, m
        j += 1
    return lo, hi


def _signed(ok: bool, m: float) -> float:
    """The margin ``m`` given the sign of the verdict ``ok`` (>= 0 where it holds, <= 0 where it
    fails): 0 where they disagree (a margin and a comparison rounded differently), NaN kept."""
    return max(m, 0.0) if ok else min(m, 0.0)


def _zero(u0: float, z0: float, u1: float, z1: float, a: float, b: float) -> float | None:
    """The zero of the line through ``(u0, z0)``, ``(u1, z1)`` when it lies in ``[a, b]`` (at an
    end: the root is there to the margin's rounding); None otherwise (NaN or infinite margins,
    equal margins)."""
    den = z1 - z0
    if not (den != 0.0 and math.isfinite(den) and math.isfinite(z1)):
        return None
    u = u1 - z1 * ((u1 - u0) / den)
    return u if a <= u <= b else None


def _bracket(
    probe: Probe, x: float, m_x: float, first: float, limit: float
) -> tuple[float, float, float, float] | None:
    """From a failing ``x > 0`` (margin ``m_x``), probe towards ``limit`` until a probe holds:
    ``(fail, m_fail, good, m_good)``, the last failing and the first satisfying probe; None when
    ``limit`` itself fails (the set being an up-set towards ``limit``: nowhere before it).

    The first probe is ``first`` (``2 x`` up, ``x / 10`` down: the bisection's first step
    ``s0``); each next step in log x is the secant extrapolation of the margin through the last
    two probes times ``OVERSHOOT`` (at least ``log MIN_FACTOR``), at most twice the last step
    (galloping: without a usable margin the exponent doubles per probe, about log2 log2 of the
    distance to the root in probes instead of log2 of it), clamped at ``limit``. A failing probe
    counts as failing whatever its margin, as in a bisection. A NaN margin after a finite one may
    be an overflow beyond the root, where the float oracle no longer follows the monotone set:
    from then on the search steps by ``s0`` from the last finite point, so that it probes no point
    the search of a bisection would not have probed. (NaN from the start -- the condition cannot
    be evaluated anywhere, e.g. e^(omega Ts) overflowed in the constants of (24) -- gallops to
    ``limit``: ~10 probes, not ~200.)
    """
    up = limit > x
    s0 = abs(math.log(first / x))
    finite = not math.isnan(m_x)  # a finite (or +-inf) margin was seen
    stepping = False  # steps of s0 only (after a NaN margin)
    nxt = first
    while True:
        ok, m = probe(nxt)
        if ok:
            return x, m_x, nxt, m
        if nxt == limit:
            return None
        d = abs(math.log(nxt / x))
        if math.isnan(m):
            if finite and not stepping:  # retreat to the last finite point, then step by s0
                stepping = True
                if d > s0 * (1.0 + 1e-9):
                    nxt = min(x * math.exp(s0), limit) if up else max(x * math.exp(-s0), limit)
                    continue
        else:
            finite = True
        step = s0 if stepping else 2.0 * d
        den = m - m_x  # > 0: the margin grows towards the root
        if not stepping and den > 0.0 and math.isfinite(den) and math.isfinite(m):
            est = -m * (d / den)  # the secant's zero, beyond nxt, in log x
            if est > 0.0:
                step = min(max(OVERSHOOT * est, math.log(MIN_FACTOR)), step)
        x, m_x = nxt, m
        nxt = min(x * math.exp(step), limit) if up else max(x * math.exp(-step), limit)


def _smallest(probe: Probe, lo: float) -> float | None:
    """Smallest x >= lo where the probe holds, for an up-set [x*, inf) or (x*, inf); None when
    it fails at RHO_CAP (then, the set being an up-set, everywhere below).

    :func:`_bracket` from ``lo`` upwards (first probe ``2 lo``), then :func:`_close` keeps the
    probe True at ``hi`` and False at ``lo`` until ``hi / lo - 1 <= ROOT_RTOL``; returns ``hi``.
    """
    ok, m_lo = probe(lo)
    if ok:
        return lo
    if not lo > 0.0:  # lo = 0: TINY is the next point, as in the bisection's doubling
        lo = TINY
        ok, m_lo = probe(lo)
        if ok:
            return lo
    if lo >= RHO_CAP:
        return None
    br = _bracket(probe, lo, m_lo, min(2.0 * lo, RHO_CAP), RHO_CAP)
    if br is None:
        return None
    lo, m_lo, hi, m_hi = br
    return _close(probe, lo, hi, m_lo, m_hi, True)[1]


def smallest_rho_r(
    c: L1Constants, p: int, omega: float, which: tuple[str, ...] = ("16a", "21a")
) -> float | None:
    """The smallest rho_r satisfying (16a) and/or (21a) at (p, omega); None if none does.

    Monotonicity (why the search finds *the* smallest). Write ``x = rho_r > 0``,
    ``k = Delta_g_perp Delta_mu_perp / lambda in (0, 1)`` (Assumption 7), ``D = Delta_star >= 0``.
    (16a) holds iff ``psi(x) = (1 - k) - (alpha^2 + eps_r + Gamma_r(x)) / x^2 >= 0``. By (18b),
    ``Gamma_r(x)`` is a non-negative combination of ``1, (x+D)^{1/2}, (x+D), x, (x+D)^{3/2}``, and
    each of these divided by ``x^2`` is non-increasing in x (for ``(x+D)^q / x^2`` with ``q < 2``:
    ``d/dx log = q/(x+D) - 2/x < 0``). Hence psi is non-decreasing, -> -inf as x -> 0
    (``eps_r > 0``), -> 1 - k > 0 as x -> inf: the feasible set is ``[x*, inf)`` with a single
    root x*. For (21a), ``x^2 psi`` is the rhs - lhs of (21a); (22) adds the non-negative terms
    ``(x+D)^{1/2} x``, ``(x+D)^2`` and ``(x+D) x``, whose quotients by x^2,
    ``(x+D)^{1/2}/x``, ``(1 + D/x)^2``, ``1 + D/x``, are non-increasing too; so again psi is
    non-decreasing and the strict set ``{psi > 0}`` is an interval ``(x*, inf)``, non-empty iff
    ``lim psi = 1 - k - (Delta^r_oast2 + Delta^r_oast3) / |2 lambda - omega| > 0``.
    Checked on grids in tests/test_l1drac_design.py.

    The lower end of the bracket is ``sqrt((alpha^2 + eps_r) / (1 - k))`` (below it (16a) fails
    because Gamma_r >= 0) for (16a), and ``max(alpha / sqrt(1-k), 1e-200)`` for (21a) alone.
    """
    p = check_p(c, p)
    check_omega(c, omega)
    return min_rho_r(c, reference_constants(c, p), omega, which)


def min_rho_r(
    c: L1Constants, rc: RefConstants, omega: float, which: tuple[str, ...]
) -> float | None:
    """:func:`smallest_rho_r` on precomputed constants, arguments unchecked."""
    out = 0.0
    if "16a" in which:
        lo = math.sqrt((c.alpha**2 + c.eps_r) / (1.0 - c.k_r))
        r = _smallest(condition_probe("16a", sides_r_oracle(c, rc, omega, "16a")), lo)
        if r is None:
            return None
        out = max(out, r)
    if "21a" in which:
        lo = max(c.alpha / math.sqrt(1.0 - c.k_r), TINY)
        lo = max(lo, out)  # the joint set is an up-set: start at the (16a) root when known
        r = _smallest(condition_probe("21a", sides_r_oracle(c, rc, omega, "21a")), lo)
        if r is None:
            return None
        out = max(out, r)
    return out


def smallest_rho_a(
    c: L1Constants,
    p: int,
    omega: float,
    rho_r: float,
    *,
    lambda_s: float | None = None,
    Ts: float | None = None,
    which: tuple[str, ...] = ("16b", "21b", "24"),
) -> float | None:
    """The smallest rho_a satisfying (16b), (21b) and, when Ts is given, (24); None if none does.

    Monotonicity. With ``y = rho_a``, ``k = Delta_g_perp L_mu_perp / lambda in (0, 1)``:
    (16b) is ``psi(y) = (1-k) - Delta_odot1/(2 lambda y) - omega Delta_odot4/(|2l-w| y)
    - Delta_otimes1/(2 sqrt(lambda) sqrt(y)) - eps_a / y^2 >= 0`` with psi increasing, -> -inf at
    0, -> 1 - k > 0 at inf: one root. (21b): (23) is a non-negative combination of ``y^{1/2}``,
    ``rho'' y^{1/2}``, ``y^{3/2}``, ``y``, ``rho'' y``, ``y^2`` with ``rho'' = y + 2(rho_r + D)``;
    divided by y^2 each is non-increasing, so (rhs - lhs)/y^2 is non-decreasing and the feasible
    set is an interval (y*, inf). (24) at fixed Ts: with ``xi1 = y + rho_r + D``, ``xi2 = y``,
    every term of (25a-c) is a non-negative multiple of ``xi2^a xi1^b`` with ``a in {1/2, 1}``,
    ``b in {0, 1/4, 1/2, 1}`` and ``a + b <= 2`` (ring-Upsilon is ``O(xi2^{1/2} + xi2)``, the
    primed maps are ``O(1 + xi1^{1/4} + xi1^{1/2} + xi1)``), and
    ``xi2^a xi1^b / y^2 = y^{a-2} (y + rho_r + D)^b`` is non-increasing in y when
    ``a + b <= 2`` (log-derivative ``(a-2)/y + b/(y + r) <= (a + b - 2)/y <= 0``). So
    ``(rhs - lhs)/y^2`` of (24) is non-decreasing too: an interval [y*, inf).
    The joint set is the intersection of up-sets, an up-set: its left end is the largest root.
    """
    p = check_p(c, p)
    check_omega(c, omega)
    if Ts is not None:
        if lambda_s is None:
            raise SpecError("lambda_s is needed to evaluate (24) at a given Ts", field="lambda_s")
        check_Ts(c, omega, lambda_s, Ts)
    return min_rho_a(c, true_constants(c, p), p, omega, rho_r, lambda_s, Ts, which)


def min_rho_a(
    c: L1Constants,
    tc: TrueConstants,
    p: int,
    omega: float,
    rho_r: float,
    lambda_s: float | None,
    Ts: float | None,
    which: tuple[str, ...],
    start: float | None = None,
) -> float | None:
    """:func:`smallest_rho_a` on precomputed constants, arguments unchecked. ``start``: the
    result of the same call with ``which`` = ``("16b", "21b")``, where the search of (24) starts
    (pass ``which = ("24",)`` with it: the same result as all three, without repeating the
    first two searches)."""
    out = TINY if start is None else start
    if "16b" in which:
        lo = math.sqrt(c.eps_a / (1.0 - c.k_a))
        r = _smallest(condition_probe("16b", lambda y: sides_16b(c, tc, omega, y)), lo)
        if r is None:
            return None
        out = max(out, r)
    if "21b" in which:
        r = _smallest(condition_probe("21b", lambda y: sides_21b(c, tc, omega, rho_r, y)), out)
        if r is None:
            return None
        out = max(out, r)
    if "24" in which and Ts is not None and lambda_s is not None:
        # the sampling constants do not depend on rho_a: computed once for the whole search
        s = sampling_constants(c, p, omega, Ts, lambda_s)
        r = _smallest(condition_probe("24", sides_24_oracle(c, tc, s, omega, rho_r)), out)
        if r is None:
            return None
        out = max(out, r)
    return out


def largest_Ts(
    c: L1Constants, p: int, omega: float, lambda_s: float, rho_r: float, rho_a: float
) -> float | None:
    """The largest Ts for which the monotone envelope of (24) holds; None if (24) cannot hold.

    The paper's left side of (24) is *not* monotone in Ts for every parameter value: gamma_2
    (A.13b) decreases in Ts when omega < lambda_s, and the factors ``Ts e^{-lambda_s Ts}`` and
    ``Ts gamma_1(Ts) e^{-lambda_s Ts}`` of (A.15) rise and then fall. We therefore search on the
    *envelope* (``sampling_constants(..., envelope=True)``): ``e^{-lambda_s Ts} -> 1`` in (A.15),
    ``gamma_2 -> max(gamma_2, 1)``. Proof that the envelope's left side is non-decreasing in Ts:
    it is a sum of products of non-negative factors, each non-decreasing in Ts -- ``Ts``,
    ``sqrt(Ts)``, ``1 - e^{-x Ts}``, ``e^{omega Ts} - 1``; ``Ts gamma_1(Ts)`` (with
    ``u = lambda_s Ts``, ``(Ts gamma_1)^2 = u^2 coth(u/2) / lambda_s`` and
    ``d/du [u^2 coth(u/2)] = u (sinh u - u/2) / sinh^2(u/2) > 0``); ``max(gamma_2, 1)``
    (equal to 1 when omega < lambda_s; when omega >= lambda_s, ``(e^{a T}-1)/(e^{b T}-1)``
    increases for a >= b because ``a / (1 - e^{-a T})`` increases in a, and
    ``e^{(omega - lambda_s) Ts}`` increases);
    gamma'_2 (both arguments of its max are ``1 - (decreasing)`` or ``(increasing) - 1`` around
    the value 1 at Ts = 0); gamma'_1 and the square roots of these. The right side does not
    depend on Ts. So the feasible set of the envelope is an interval ``(0, T*]`` and the search
    finds T*. Because the envelope bounds the paper's left side from above, (24) itself holds at
    the returned Ts (re-checked in :func:`~drip_cert.bounds.l1drac.designer.design`); the true
    largest Ts can be larger by a relative ``O(lambda_s Ts)``, negligible in the regime (24)
    forces (Ts << 1/lambda_s).

    The search starts at ``T_cap = min(1e3, 700 / max(omega, lambda_s, 2 lambda))`` (returned
    as is when (24) holds there) and brackets downwards (:func:`_bracket`, first step 1/10) down
    to 1e-200.
    """
    p = check_p(c, p)
    check_omega(c, omega)
    check_Ts(c, omega, lambda_s, 1e-12 / max(omega, lambda_s, 1.0))
    return max_Ts(c, true_constants(c, p), p, omega, lambda_s, rho_r, rho_a)


def max_Ts(
    c: L1Constants,
    tc: TrueConstants,
    p: int,
    omega: float,
    lambda_s: float,
    rho_r: float,
    rho_a: float,
    budget: float | None = None,
) -> float | None:
    """:func:`largest_Ts` on precomputed constants, arguments unchecked; ``budget`` replaces
    the float64 right side of (24) when given (the back-off passes its rigorous lower bound)."""
    if budget is None:
        budget = budget_24(c, tc, omega, rho_r, rho_a)
    if not budget > 0.0:
        return None
    xi1 = rho_a + rho_r + c.Delta_star

    def env_probe(T: float) -> tuple[bool, float]:
        s = sampling_constants(c, p, omega, T, lambda_s, envelope=True)
        lhs = upsilon_sum(xi1, rho_a, s)
        return lhs <= budget, _relative_margin(budget - lhs, lhs, budget)  # NaN: False

    t_cap = min(1e3, EXP_ARG_MAX / max(omega, lambda_s, 2.0 * c.lam))
    ok, m_hi = env_probe(t_cap)
    if ok:
        return t_cap
    if t_cap / 10.0 < TINY:
        return None
    br = _bracket(env_probe, t_cap, m_hi, t_cap / 10.0, TINY)
    if br is None:
        return None
    hi, m_hi, lo, m_lo = br
    return _close(env_probe, lo, hi, m_lo, m_hi, False)[0]
