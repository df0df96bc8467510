"""Rigorous verification of the L1-DRAC design conditions and the designer's back-off.

Mathematics first: the Arb balls enclose 50-digit mpmath values and the same balls at twice the
precision; the float64 and Arb evaluations of the one generic transcription of Appendix A agree;
a point with an exactly zero margin (closed form) and a point one ulp across the (24) boundary
(bisection with the Arb oracle) are rejected; the float roots of the old designer are
knife-edge and some of them provably fail, while every design returned now is verified with a
strictly positive margin, and fixed inputs are never changed.
"""

from __future__ import annotations

import dataclasses
import math

import mpmath
import numpy as np
import pytest
from flint import arb, ctx

from drip_cert.bounds.l1drac import appendix as A
from drip_cert.bounds.l1drac import backend, backoff, searches
from drip_cert.bounds.l1drac import conditions as C
from drip_cert.bounds.l1drac import sides as S
from drip_cert.bounds.l1drac import verify as V
from drip_cert.bounds.l1drac.constants import CONSTANT_NAMES, L1Constants
from drip_cert.bounds.l1drac.designer import design
from drip_cert.bounds.l1drac.request import DesignRequest
from drip_cert.provenance import How, Quantity
from tests.helpers import by_eq, di_constants, random_constants

#: float64 vs the Arb midpoint of one closed form of Appendix A (a few hundred roundings at most;
#: the expm1 / phi2 rewrites leave no cancellation), relative to the form's magnitude
REL_FLOAT_VS_ARB = 1e-12
#: a margin that cancels is compared relative to the sum of the magnitudes of its terms
REL_MARGIN_VS_TERMS = 1e-12
#: radius of a 128-bit Arb ball relative to its terms (~1e-38 per operation, a few hundred ops)
REL_ARB_RADIUS = 1e-30
#: digits of the mpmath references (far beyond the 128-bit balls they must fall into)
MP_DPS = 60
#: a bisection root is within ROOT_RTOL of its boundary and the margins have O(1)..O(10)
#: log-derivatives there, so its margin is below this, relative to its condition's sides (the
#: issue saw 1e-17 .. 1e-28 for (24))
KNIFE_EDGE_REL = 100 * searches.ROOT_RTOL
#: seeded random constant sets of the designer tests (enough to see sign flips: about 40% of
#: the float roots of (24) provably fail)
N_DESIGNS = 30
#: the largest relative back-off the designer may apply (BACKOFF_STEPS tries)
MAX_BACKOFF = backoff.BACKOFF_START * backoff.BACKOFF_GROWTH ** (backoff.BACKOFF_STEPS - 1)
#: floor of the scale a ball's radius is compared with, so that an exact zero (radius 0) passes
ZERO_SCALE = 1e-300
#: random omega this close (relatively) to 2 lambda is moved: |2 lambda - omega| divides Theta
POLE_DISTANCE = 1e-3


def random_request(rng: np.random.Generator) -> tuple[int, float, float]:
    """(p, omega, lambda_s) for a free design (Ts, rho_r, rho_a found)."""
    return int(rng.integers(1, 4)), float(10 ** rng.uniform(1.5, 4)), float(10 ** rng.uniform(0, 3))


def float_root_cases(seed: int, n: int):
    """Seeded free designs and the old designer's answer for each, the float roots as found:
    rho_r the smallest (16a, 21a) root, rho_a the smallest (16b, 21b) root, Ts the largest
    (24) root. Cases without roots (omega too small for (21)) are skipped; yields
    ``(c, p, omega, lambda_s, rho_r, rho_a, Ts)``."""
    rng = np.random.default_rng(seed)
    for _ in range(n):
        c = random_constants(rng)
        p, omega, ls = random_request(rng)
        rr = searches.smallest_rho_r(c, p, omega)
        ra = None if rr is None else searches.smallest_rho_a(c, p, omega, rr, which=("16b", "21b"))
        Ts = None if ra is None else searches.largest_Ts(c, p, omega, ls, rr, ra)
        if Ts is not None:
            yield c, p, omega, ls, rr, ra, Ts


def boundary_constants() -> L1Constants:
    """Constants for which (16a) and (16b) have closed-form roots with an exactly zero margin.

    p = 1 (so fraktur p = 0), no diffusion, no unmatched and no matched-parallel uncertainty:
    Gamma_r = Gamma_a = Theta_r = Theta_a = 0 and k_r = k_a = 0, so (16a) is
    ``rho_r^2 >= alpha^2 + eps_r = 0.25 + 0.75 = 1`` and (16b) is ``rho_a^2 >= eps_a = 0.25``:
    at rho_r = 1, rho_a = 0.5 both margins are exactly 0 (every number is a dyadic rational).
    Delta_f, Delta_mu, L_mu, Delta_Theta > 0 keep the left side of (24) positive, so Ts is finite.
    """
    d = {n: 0.0 for n in CONSTANT_NAMES}
    d.update(
        {
            "lambda": 10.0,
            "Delta_f": 1.0,
            "Delta_g": 1.0,
            "Delta_Theta": 1.0,
            "Delta_mu": 1.0,
            "L_mu": 1.0,
            "alpha": 0.5,
            "eps_r": 0.75,
            "eps_a": 0.25,
            "p_star": 8,
            "m": 1,
            "lip_f": False,
        }
    )
    return L1Constants.from_mapping(d)


def _mp(ball: arb) -> tuple[mpmath.mpf, mpmath.mpf]:
    """(midpoint, radius) of a ball as mpmath numbers."""
    return mpmath.mpf(ball.mid().str(MP_DPS, radius=False)), mpmath.mpf(
        ball.rad().str(MP_DPS, radius=False)
    )


def _contains(ball: arb, exact: mpmath.mpf) -> bool:
    """The ball contains a 60-digit reference (up to that reference's own last digits)."""
    m, r = _mp(ball)
    return abs(m - exact) <= r + abs(exact) * mpmath.mpf(10) ** (5 - MP_DPS)


# ------------------------------------------------------------------ the Arb balls are honest


@pytest.mark.parametrize("x", [1e-14, -1e-9, 3e-3, -9e-3, 0.0125, 0.5, -2.0])
def test_phi2_ball_encloses_mpmath(x: float) -> None:
    """(e^x - 1 - x)/x^2: the truncated series (|x| < 1e-2) carries its remainder as a radius,
    so the ball contains the 60-digit value on both branches."""
    with ctx.workprec(V.ARB_PREC):
        ball = A._phi2(arb(x), backend.ARB)
    with mpmath.workdps(MP_DPS):
        xm = mpmath.mpf(x)
        exact = (mpmath.expm1(xm) - xm) / xm**2
        assert _contains(ball, exact)
    assert float(ball.rad()) <= REL_ARB_RADIUS * abs(float(ball.mid()))
    assert abs(A._phi2(x, backend.FLOAT) / float(ball.mid()) - 1.0) < REL_FLOAT_VS_ARB


@pytest.mark.parametrize("Ts", [1e-14, 1e-9, 1e-4])
@pytest.mark.parametrize(("omega", "ls"), [(1e3, 100.0), (50.0, 300.0)])
def test_sampling_balls_enclose_mpmath(Ts: float, omega: float, ls: float) -> None:
    """(A.13) in Arb contains the printed formulas evaluated with 60 digits (gamma'_2 is the
    cancellation-prone one: 1 - R with R -> 1 as Ts -> 0)."""
    c = di_constants()
    with ctx.workprec(V.ARB_PREC):
        s = A.sampling_constants(V.ArbConstants(c), 2, arb(omega), arb(Ts), arb(ls))
    with mpmath.workdps(MP_DPS):
        w, T, sl = mpmath.mpf(omega), mpmath.mpf(Ts), mpmath.mpf(ls)
        R = sl / w * mpmath.expm1(w * T) / mpmath.expm1(sl * T)
        ref = {
            "gamma_1": mpmath.sqrt(sl * (mpmath.exp(sl * T) + 1) / mpmath.expm1(sl * T)),
            "gamma_2": max(mpmath.exp((w - sl) * T), 1) * R,
            "gamma_2p": max(abs(1 - mpmath.exp((w - sl) * T) * R), abs(1 - R)),
            "expm1_omega_Ts": mpmath.expm1(w * T),
        }
        for k, v in ref.items():
            assert _contains(getattr(s, k), v), k


@pytest.mark.parametrize("seed", range(4))
def test_margin_balls_at_two_precisions_overlap(seed: int) -> None:
    """Two enclosures of one exact margin must intersect; the 256-bit one is the narrower."""
    rng = np.random.default_rng(seed)
    c = random_constants(rng)
    p, omega, ls = random_request(rng)
    kw = {"lambda_s": ls, "Ts": 1e-9, "rho_r": 3.0, "rho_a": 2.0}
    b128 = V.verify_conditions(c, p, omega, **kw, prec=128)
    b256 = V.verify_conditions(c, p, omega, **kw, prec=256)
    assert set(b128) == set(V.CONDITIONS)
    for eq in V.CONDITIONS:
        assert b128[eq].ball.overlaps(b256[eq].ball), eq
        assert b256[eq].ball.rad() <= b128[eq].ball.rad(), eq


# ------------------------------------------------------------------ one code, two arithmetics


def _fields(obj) -> dict:
    return {
        f.name: getattr(obj, f.name)
        for f in dataclasses.fields(obj)
        if f.name not in ("consts", "num", "p", "envelope")
    }


def _close(f: float, ball: arb, scale: float) -> bool:
    mid = float(ball.mid())
    return abs(f - mid) <= REL_FLOAT_VS_ARB * max(abs(mid), scale) and float(
        ball.rad()
    ) <= REL_ARB_RADIUS * max(abs(mid), scale, ZERO_SCALE)


@pytest.mark.parametrize("seed", range(6))
def test_float_and_arb_evaluations_agree(seed: int) -> None:
    """Every constant of (A.2)-(A.17), every map of (A.18)-(A.19), (18b, c), (22), (23), (25)
    and both sides of every condition: float64 == Arb midpoint to REL_FLOAT_VS_ARB, on random
    constant sets and design points (including tiny Ts, where expm1 / phi2 matter)."""
    rng = np.random.default_rng(100 + seed)
    for _ in range(8):
        c = random_constants(rng)
        p = int(rng.integers(1, 9))
        omega = float(10 ** rng.uniform(-1, 6))
        if abs(omega - 2 * c.lam) < POLE_DISTANCE * omega:
            omega *= 1.5
        ls = float(10 ** rng.uniform(-1, 4))
        Ts = float(10 ** rng.uniform(-14, -1)) / max(omega, ls, 1.0)
        rr, ra = float(rng.uniform(0.1, 20.0)), float(rng.uniform(0.1, 20.0))
        xi = float(10 ** rng.uniform(-3, 3))
        fl = {
            "rc": A.reference_constants(c, p),
            "tc": A.true_constants(c, p),
            "s": A.sampling_constants(c, p, omega, Ts, ls),
            "se": A.sampling_constants(c, p, omega, Ts, ls, envelope=True),
        }
        with ctx.workprec(V.ARB_PREC):
            ac = V.ArbConstants(c)
            w, T, la = arb(omega), arb(Ts), arb(ls)
            ab = {
                "rc": A.reference_constants(ac, p),
                "tc": A.true_constants(ac, p),
                "s": A.sampling_constants(ac, p, w, T, la),
                "se": A.sampling_constants(ac, p, w, T, la, envelope=True),
            }
            for key in fl:
                fa, aa = _fields(fl[key]), _fields(ab[key])
                for name, v in fa.items():
                    assert _close(float(v), backend.ARB.const(aa[name]), 0.0), (key, name)
            maps = (
                A.upsilon1_prime,
                A.upsilon2_prime,
                A.upsilon3_prime,
                A.upsilon_minus_tilde,
                A.upsilon_minus,
            )
            for f in maps:
                assert _close(f(xi, fl["s"]), f(arb(xi), ab["s"]), 0.0), f.__name__
            assert _close(A.upsilon_ring(xi, c, p, omega), A.upsilon_ring(arb(xi), ac, p, w), 0.0)
            for f in (S.upsilon_a1, S.upsilon_a2, S.upsilon_a3, S.upsilon_sum):
                assert _close(f(xi, ra, fl["s"]), f(arb(xi), arb(ra), ab["s"]), 0.0), f.__name__
            for f, k in ((S.gamma_r, "rc"), (S.theta_r, "rc"), (S.gamma_a, "tc")):
                assert _close(f(rr, omega, fl[k]), f(arb(rr), w, ab[k]), 0.0), f.__name__
            th = S.theta_a(ra, rr, omega, fl["tc"], c.Delta_star)
            assert _close(th, S.theta_a(arb(ra), arb(rr), w, ab["tc"], ac.Delta_star), 0.0)
            # the conditions: each side, and the margin relative to the sum of its terms
            b, tha, ga = S.budget_a(c, fl["tc"], omega, rr, ra)
            l16a, r16a = S.sides_16a(c, fl["rc"], omega, rr)
            l16b, r16b = S.sides_16b(c, fl["tc"], omega, ra)
            scale = {
                "16a": abs(l16a) + abs(r16a),
                "16b": abs(l16b) + abs(r16b),
                "21a": abs(l16a) + abs(r16a) + S.theta_r(rr, omega, fl["rc"]),
                "21b": abs(b) + 2 * ga + tha,
                "24": abs(b) + 2 * ga + tha,
            }
            sides_f = {
                "16a": (l16a, r16a),
                "16b": (l16b, r16b),
                "21a": S.sides_21a(c, fl["rc"], omega, rr),
                "21b": S.sides_21b(c, fl["tc"], omega, rr, ra),
                "24": S.sides_24(c, fl["tc"], p, omega, ls, Ts, rr, ra),
            }
            sides_a = {
                "16a": S.sides_16a(ac, ab["rc"], w, arb(rr)),
                "16b": S.sides_16b(ac, ab["tc"], w, arb(ra)),
                "21a": S.sides_21a(ac, ab["rc"], w, arb(rr)),
                "21b": S.sides_21b(ac, ab["tc"], w, arb(rr), arb(ra)),
                "24": S.sides_24(ac, ab["tc"], p, w, la, T, arb(rr), arb(ra)),
            }
            margins_a = {eq: S.margin_of(eq, *sides_a[eq]) for eq in V.CONDITIONS}
        for eq in V.CONDITIONS:
            mf = S.margin_of(eq, *sides_f[eq])
            ma = margins_a[eq]
            assert abs(mf - float(ma.mid())) <= REL_MARGIN_VS_TERMS * scale[eq], eq
            assert float(ma.rad()) <= REL_ARB_RADIUS * scale[eq], eq


# ------------------------------------------------------------------ points on the boundary


def test_exact_zero_margin_is_not_verified() -> None:
    """A condition that holds with equality (margin exactly 0, closed form) is not verified:
    the float comparison ``>=`` says it holds, the Arb margin is the exact ball 0."""
    c = boundary_constants()
    res = by_eq(C.evaluate_conditions(c, 1, 1e3, 100.0, 1e-9, 1.0, 0.5))
    for eq in ("16a", "16b"):
        assert res[eq].margin == 0.0 and res[eq].holds, eq
        assert res[eq].margin_lo == 0.0 == res[eq].margin_hi, eq
        assert not res[eq].verified, eq
    # the old designer's roots sit exactly there: the searches start at the closed-form bound
    assert searches.smallest_rho_r(c, 1, 1e3, ("16a",)) == 1.0
    assert searches.smallest_rho_a(c, 1, 1e3, 1.0, which=("16b",)) == 0.5
    d = design(c, DesignRequest(p=1, omega=1e3, lambda_s=100.0))
    assert d.feasible and d.verified
    assert d.rho_r == 1.0 * (1.0 + backoff.BACKOFF_START) and d.rho_a == 0.5 * (
        1.0 + backoff.BACKOFF_START
    )
    assert all(r.margin_lo > 0.0 and r.holds for r in d.conditions)


def test_designer_gives_up_when_no_back_off_is_allowed(monkeypatch) -> None:
    """With a zero back-off the exact boundary point can never be verified: the designer stops
    after BACKOFF_STEPS tries and reports the design infeasible with the reason."""
    monkeypatch.setattr(backoff, "BACKOFF_START", 0.0)
    d = design(boundary_constants(), DesignRequest(p=1, omega=1e3, lambda_s=100.0))
    assert not d.feasible and not d.verified
    assert "(16a) is not verified" in d.reason and "rho_r" in d.reason
    assert dict(d.backoff) == {"rho_r": 1.0}


def _arb_boundary_of_24(c, p, omega, ls, rr, ra) -> tuple[float, float]:
    """Adjacent doubles T_in < T_out with the exact (24) margin > 0 at T_in and < 0 at T_out,
    by bisection on Ts with the Arb verdict as the oracle."""

    def verdict(T: float) -> int:
        m = V.verify_conditions(c, p, omega, lambda_s=ls, Ts=T, rho_r=rr, rho_a=ra, which=("24",))
        m = m["24"]
        assert m.verified or m.hi < 0.0, "a 128-bit ball straddles 0: refine the precision"
        return 1 if m.verified else -1

    t = searches.largest_Ts(c, p, omega, ls, rr, ra)
    lo, hi = t / 2.0, t * 2.0
    while verdict(lo) < 0:
        lo /= 2.0
    while verdict(hi) > 0:
        hi *= 2.0
    while math.nextafter(lo, math.inf) < hi:
        mid = 0.5 * (lo + hi)
        if verdict(mid) > 0:
            lo = mid
        else:
            hi = mid
    return lo, hi


def test_arb_rejects_the_double_just_across_the_24_boundary() -> None:
    """One ulp across the exact boundary of (24) the Arb verification proves failure (the
    ball's upper end is < 0) and one ulp inside it proves success; in float64 both margins are
    rounding noise (below KNIFE_EDGE_REL of the right side), and on these seeded constant sets
    the float comparison says "holds" at a point that provably fails, at least once."""
    flipped = 0
    for c, p, omega, ls, rr, ra_min, _ in float_root_cases(200, 8):
        ra = 2.0 * ra_min
        t_in, t_out = _arb_boundary_of_24(c, p, omega, ls, rr, ra)
        assert t_out == math.nextafter(t_in, math.inf)
        inside = C.condition_24(c, p, omega, ls, t_in, rr, ra)
        across = C.condition_24(c, p, omega, ls, t_out, rr, ra)
        assert inside.verified and inside.margin_lo > 0.0
        assert not across.verified and across.margin_hi < 0.0
        for r in (inside, across):
            assert abs(r.margin) < KNIFE_EDGE_REL * abs(r.rhs)
        flipped += across.holds
    assert flipped >= 1


# ------------------------------------------------------------------ the designer


def test_float_roots_are_knife_edge_and_some_provably_fail() -> None:
    """The old designer returned the float roots as found (omega, lambda_s given: rho_r, rho_a
    the smallest roots, Ts the largest). Their smallest float margin is below KNIFE_EDGE_REL of
    its condition, and Arb proves some of them wrong (the sign flips the issue reports)."""
    flipped = 0
    for c, p, omega, ls, rr, ra, Ts in float_root_cases(7, N_DESIGNS):
        res = C.evaluate_conditions(c, p, omega, ls, Ts, rr, ra)
        assert all(r.holds for r in res)
        assert min(r.margin / max(abs(r.lhs), abs(r.rhs)) for r in res) < KNIFE_EDGE_REL
        flipped += any(r.margin_hi < 0.0 for r in res)
    assert flipped >= 1


def test_designer_returns_verified_interior_points() -> None:
    """On the same seeded constant sets, every design is feasible, every condition is verified
    with a strictly positive Arb margin and holds in float64, and the back-off factors are the
    stated ones: each in 1 + BACKOFF_START * BACKOFF_GROWTH^k, k < BACKOFF_STEPS."""
    allowed = set(backoff.backoff_factors())
    n = 0
    for c, p, omega, ls, rr, ra, _ in float_root_cases(7, N_DESIGNS):
        # objective "min_rho": Ts found (the largest (24) allows) and backed off, as tested here
        d = design(c, DesignRequest(p=p, omega=omega, lambda_s=ls, objective="min_rho"))
        assert d.feasible and d.verified, d.reason
        assert [r.eq for r in d.conditions] == list(V.CONDITIONS)
        assert all(r.verified and r.margin_lo > 0.0 and r.holds for r in d.conditions)
        assert set(dict(d.backoff)) == {"rho_r", "rho_a", "Ts"}
        assert set(dict(d.backoff).values()) <= allowed
        assert dict(d.backoff)["rho_r"] == 1.0 + backoff.BACKOFF_START  # no rounding issue in (16a)
        # the returned point re-checks to the same verdicts, a hair inside the float roots
        assert C.evaluate_conditions(c, p, omega, ls, d.Ts, d.rho_r, d.rho_a) == d.conditions
        assert d.rho_r == rr * dict(d.backoff)["rho_r"] and d.rho_a >= ra
        assert d.rho <= (rr + ra) * (1.0 + MAX_BACKOFF)
        n += 1
    assert n >= N_DESIGNS * 0.9


def test_fixed_inputs_are_never_changed() -> None:
    """Given omega, lambda_s, Ts, rho_r, rho_a: only evaluated, never moved; the verdict is the
    Arb-verified one, both for a comfortable point and for a point just across (24)."""
    c = di_constants()
    req = DesignRequest(p=1, lambda_s=100.0, omega=1e3, Ts=1e-9, rho_r=3.0, rho_a=1.0)
    d = design(c, req)
    assert d.feasible and d.verified and d.backoff == ()
    assert (d.omega, d.lambda_s, d.Ts, d.rho_r, d.rho_a) == (1e3, 100.0, 1e-9, 3.0, 1.0)
    rr = searches.smallest_rho_r(c, 1, 1e3)
    _, t_out = _arb_boundary_of_24(c, 1, 1e3, 100.0, rr, 1.0)
    edge = design(c, dataclasses.replace(req, Ts=t_out, rho_r=rr))
    assert (edge.Ts, edge.rho_r, edge.rho_a) == (t_out, rr, 1.0) and edge.backoff == ()
    assert not edge.feasible and "(24)" in edge.reason
    assert edge.conditions[-1].margin_hi < 0.0


def test_design_label_is_computed_from_inputs() -> None:
    """The provenance of a design's verdict is weakest(VERIFY_METHOD, inputs), never a literal."""
    d = design(di_constants(), DesignRequest(p=1, lambda_s=100.0, omega=1e3))
    assert V.VERIFY_METHOD == How.EXACT and d.label() == How.EXACT
    assert d.label([How.SOUND, How.GIVEN]) == How.GIVEN
    assert d.label([Quantity("lambda", 10.0, How.ESTIMATE)]) == How.ESTIMATE


def test_json_keeps_old_keys_and_adds_the_verified_margins() -> None:
    req = DesignRequest(p=2, lambda_s=100.0, omega=1e3, delta=0.01, objective="min_rho")
    d = design(di_constants(), req)  # "min_rho": Ts found, so backed off too
    js = d.to_dict()
    old = ("feasible", "p", "omega", "lambda_s", "Ts", "rho_r", "rho_a", "rho", "kappa", "delta")
    for k in (*old, "conditions", "reason", "notes", "how", "tolerance", "seconds"):
        assert k in js
    assert js["verified"] is True and js["feasible"] is True
    assert set(js["backoff"]) == {"rho_r", "rho_a", "Ts"}
    assert js["verification"]["min_margin_lo"] > 0.0
    for r in js["conditions"]:
        for k in ("eq", "lhs", "rhs", "margin", "holds", "relation"):
            assert k in r
        assert r["verified"] is True and 0.0 < r["margin_lo"] <= r["margin_hi"]


def test_arb_view_is_read_only_and_exact() -> None:
    c = di_constants()
    ac = V.ArbConstants(c)
    assert ac.num is backend.ARB and ac.m == c.m and ac.lip_f is c.lip_f
    assert ac.lam.is_exact() and ac.lam == arb(c.lam)
    with pytest.raises(AttributeError):
        ac.lam = arb(1.0)
