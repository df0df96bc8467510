"""The root searches of the L1-DRAC designer (:mod:`drip_cert.bounds.l1drac.searches`): the
contract of a bisection (the returned end was probed and satisfies, a failing point lies within
ROOT_RTOL of it, NaN never holds) on closed-form monotone functions, including steps, NaN regions
and brackets of adjacent floats; agreement with plain bisection on the real oracles of the
gallery constants (examples/l1drac_constants); and the far smaller number of probes.
"""

from __future__ import annotations

import math
import struct
from pathlib import Path

import numpy as np
import pytest

import drip_cert.bounds.l1drac.conditions as conditions
import drip_cert.bounds.l1drac.searches as searches
from drip_cert.bounds.l1drac.appendix import reference_constants, true_constants
from drip_cert.bounds.l1drac.conditions import holds_of
from drip_cert.bounds.l1drac.designer import design
from drip_cert.bounds.l1drac.sides import RELATIONS
from drip_cert.bounds.l1drac.toml import load_l1_constants
from tests.helpers import random_constants

RTOL = searches.ROOT_RTOL
#: two searches that each return a point within ROOT_RTOL above the same root (the float
#: oracle's boundary; its rounding noise there is ~1e-16 relative) differ by at most this
AGREE_RTOL = 2 * RTOL
#: one unit of float64 rounding, relative: the slack of comparing a float root with an exact one
ULP = 2.0**-52
#: probes of a whole search (bracketing from far below + closing) on a smooth function: plain
#: doubling + bisection needs > 40; the secant on a margin nearly linear in log x needs ~10
SMOOTH_MAX_PROBES = 20
#: probes of a whole search on the real oracles, as a fraction of plain bisection's (measured
#: ~0.15 on the gallery constants; bisection needs ~45 per root)
REAL_PROBE_FRACTION = 0.3
#: the gallery's design-l1 inputs: real L1-DRAC constants (docs/math/l1drac.md section 8, the
#: paper's 4-D example with the expert and the learned policy)
GALLERY = Path(__file__).resolve().parents[1] / "examples" / "l1drac_constants"
GALLERY_FILES = ("double_integrator.toml", "paper_4d_expert.toml", "paper_4d_learned.toml")


# ---------------------------------------------------------------- reference: plain bisection


def bisect_smallest(ok, lo):
    """The searches before issue 26: doubling from lo, bisection in log x on the verdict."""
    if ok(lo):
        return lo
    hi = max(2.0 * lo, lo + searches.TINY)
    while not ok(hi):
        lo = hi
        hi *= 2.0
        if hi > searches.RHO_CAP:
            return None
    while hi / lo - 1.0 > RTOL:
        mid = math.sqrt(lo * hi)  # as before issue 26 (bit for bit)
        if not lo < mid < hi:
            break
        if ok(mid):
            hi = mid
        else:
            lo = mid
    return hi


def bisect_close(probe, lo, hi, m_lo, m_hi, good_hi):
    """:func:`searches._close` as plain bisection on the verdicts (the margins unused)."""
    while hi / lo - 1.0 > RTOL:
        mid = math.sqrt(lo * hi)  # as before issue 26 (bit for bit)
        if not lo < mid < hi:
            break
        if probe(mid)[0] == good_hi:
            hi = mid
        else:
            lo = mid
    return lo, hi


def bisect_bracket(probe, x, m_x, first, limit):
    """:func:`searches._bracket` as before issue 26 (bit for bit): doubling up (rho), division
    by 10 down (Ts), the margins unused; None past ``limit``."""
    up = first > x
    nxt = first
    while True:
        ok, m = probe(nxt)
        if ok:
            return x, m_x, nxt, m
        x, m_x = nxt, m
        nxt = x * 2.0 if up else x / 10.0
        if nxt > limit if up else nxt < limit:
            return None


def use_bisection(m):
    """Every search of :mod:`searches` as doubling (or /10) + bisection on the same verdicts."""
    m.setattr(searches, "_bracket", bisect_bracket)
    m.setattr(searches, "_close", bisect_close)


class Counted:
    """A probe that records the points it was asked at."""

    def __init__(self, probe):
        self.probe = probe
        self.points: list[float] = []

    def __call__(self, x):
        self.points.append(x)
        return self.probe(x)


def power_probe(root, k=2.0, margin=None):
    """Up-set ``x^k >= root^k`` (closed form; root^k a normal float); margin ``log(x / root)``
    unless given."""

    def probe(x):
        ok = x**k >= root**k
        m = math.log(x / root) if margin is None else margin(x)
        return ok, m

    return probe


def check_up(probe, x, root):
    """``x`` satisfies, ``x / (1 + RTOL)`` fails, and ``x`` is within ROOT_RTOL above root."""
    assert probe(x)[0]
    assert not probe(x / (1.0 + RTOL) * (1.0 - ULP))[0]
    assert root * (1.0 - 4 * ULP) <= x <= root * (1.0 + RTOL) * (1.0 + 4 * ULP)


def n_half(lo, hi):
    """Plain bisection's count on [lo, hi] in log x to the ITP target width."""
    return math.ceil(math.log2(math.log(hi / lo) / (searches.ITP_WIDTH * math.log1p(RTOL))))


# ---------------------------------------------------------------- closed-form monotone functions


@pytest.mark.parametrize("root", [1e-90, 3.3e-7, 1.0, math.sqrt(2.0), 7.77e5, 1e55])
@pytest.mark.parametrize("k", [0.5, 2.0, 3.0])
def test_smallest_on_smooth_power_laws(root, k):
    lo0 = root * 1e-3
    p = Counted(power_probe(root, k, margin=lambda x: k * math.log(x / root)))
    x = searches._smallest(p, lo0)
    assert x is not None and x in p.points  # the returned point was probed
    check_up(p.probe, x, root)
    assert len(p.points) <= SMOOTH_MAX_PROBES
    plain = Counted(lambda x: (p.probe(x)[0], math.nan))
    assert bisect_smallest(lambda x: plain(x)[0], lo0) is not None
    assert len(plain.points) > 2 * SMOOTH_MAX_PROBES  # what bisection needed


def test_smallest_on_a_condition_shaped_margin():
    """(16a)-like: (1 - k) x^2 >= a + b x^(3/2), through condition_probe (atanh margin)."""
    a, b, k = 3.0, 0.7, 0.2
    p = Counted(searches.condition_probe("16a", lambda x: ((1 - k) * x**2, a + b * x**1.5)))
    x = searches._smallest(p, 1e-3)
    assert x is not None and x in p.points
    root = _brent(lambda x: (1 - k) * x**2 - a - b * x**1.5, 1.0, 10.0)
    check_up(p.probe, x, root)
    assert len(p.points) <= SMOOTH_MAX_PROBES


def _brent(f, a, b):
    from scipy.optimize import brentq

    return brentq(f, a, b, xtol=1e-300, rtol=4 * ULP)


@pytest.mark.parametrize("margin", ["step", "nan", "nan below", "tiny below", "wild"])
def test_close_keeps_the_contract_for_any_margin(margin):
    """The margins only choose where to probe: with a step, NaN, misleading or random margins
    the bracket still ends with a satisfying hi, a failing lo, hi / lo - 1 <= ROOT_RTOL, in at
    most bisection's count + ITP_N0 probes."""
    root = 0.123456789
    rng = np.random.default_rng(7)
    noise = {}

    def m_of(x):
        if margin == "step":
            return 1.0 if x >= root else -1.0
        if margin == "nan":
            return math.nan
        if margin == "nan below":
            return math.log(x / root) if x >= root else math.nan
        if margin == "tiny below":  # pulls every interpolation onto the failing end
            return math.log(x / root) if x >= root else -1e-300
        # sign-consistent, random magnitude over 60 decades (a fixed function of x)
        v = noise.setdefault(x, float(10.0 ** rng.uniform(-30, 30)))
        return v if x >= root else -v

    p = Counted(power_probe(root, margin=m_of))
    lo, hi = 0.1, 0.2
    out_lo, out_hi = searches._close(p, lo, hi, m_of(lo), m_of(hi), True)
    assert p.probe(out_hi)[0] and not p.probe(out_lo)[0]
    assert out_hi / out_lo - 1.0 <= RTOL
    assert out_lo <= root <= out_hi
    assert len(p.points) <= n_half(lo, hi) + searches.ITP_N0


def test_close_on_a_down_set():
    """Ts orientation: T <= T* holds; lo is returned and satisfies, hi fails."""
    t_star = 2.345e-4

    def probe(t):
        return t <= t_star, math.log(t_star / t)

    p = Counted(probe)
    lo, hi = searches._close(p, 1e-5, 1e-3, probe(1e-5)[1], probe(1e-3)[1], False)
    assert probe(lo)[0] and not probe(hi)[0] and hi / lo - 1.0 <= RTOL
    assert lo in p.points and len(p.points) <= 12


def test_nan_never_holds_and_nan_everywhere_is_none():
    p = Counted(lambda x: (False, math.nan))
    assert searches._smallest(p, 1e-3) is None
    assert len(p.points) <= 15  # galloping to RHO_CAP, not ~210 doublings


def test_no_root_below_the_cap_is_none_in_few_probes():
    p = Counted(power_probe(1e70))
    assert searches._smallest(p, 1.0) is None
    assert max(p.points) == searches.RHO_CAP and len(p.points) <= 12


def test_nan_after_finite_margins_falls_back_to_doubling():
    """A NaN margin above finite ones may be an overflow above the root: from there the search
    doubles, never probing beyond twice the root (as the doubling of a bisection)."""
    root = 1000.0

    def probe(x):
        return x >= root, (math.log(x / root) if x < 10.0 else math.nan)

    p = Counted(probe)
    x = searches._smallest(p, 1.0)
    assert x is not None
    check_up(probe, x, root)
    assert max(p.points) <= 2.0 * root


def test_adjacent_floats_end_the_search():
    """A bracket of adjacent (subnormal) floats wider than ROOT_RTOL: no point inside to probe."""
    lo, hi = 3 * 5e-324, 4 * 5e-324
    assert math.nextafter(lo, 1.0) == hi and hi / lo - 1.0 > RTOL
    p = Counted(lambda x: (x >= hi, math.nan))
    assert searches._close(p, lo, hi, math.nan, math.nan, True) == (lo, hi)
    assert p.points == []


def test_root_at_a_float_boundary():
    """A verdict that flips between two adjacent normal floats: the bracket is those two."""
    root = 0.7
    below = math.nextafter(root, 0.0)
    p = Counted(lambda x: (x >= root, math.log(x / root)))
    x = searches._smallest(p, 0.1)
    assert x is not None and p.probe(x)[0] and not p.probe(below)[0]
    assert root <= x <= root * (1.0 + RTOL)


def _bits(x):
    return struct.unpack("<q", struct.pack("<d", x))[0]


@pytest.mark.parametrize("eq", sorted(RELATIONS))
def test_condition_probe_verdict_is_holds_of(eq):
    """The verdict written out in condition_probe is holds_of (the final re-check's holds)."""
    special = [0.0, -0.0, 1.0, -1.0, 1e300, -1e300, math.inf, -math.inf, math.nan, 5e-324]
    rng = np.random.default_rng(11)
    values = special + [float(v) for v in rng.normal(size=20)]
    for lhs in values:
        for rhs in values + [lhs]:
            ok, m = searches.condition_probe(eq, lambda x, a=lhs, b=rhs: (a, b))(1.0)
            assert ok == holds_of(eq, lhs, rhs)
            if ok:
                assert m >= 0.0 or (math.isnan(m) and lhs == rhs == 0.0)
            elif not math.isnan(m):
                assert m <= 0.0


# ---------------------------------------------------------------- the real oracles


def _gallery():
    return [load_l1_constants(GALLERY / f)[0] for f in GALLERY_FILES] + [
        random_constants(np.random.default_rng(seed)) for seed in (1, 2)
    ]


#: (omega, lambda_s, Ts) in multiples of (lambda, lambda, 1/lambda): omega below and above
#: 2 lambda, up to the paper example's designs (omega ~ 85 and 270 lambda, Ts = 1e-4 / lambda)
POINTS = (
    (0.01, 0.1, 1e-4),
    (0.5, 3.0, 1e-3),
    (5.0, 50.0, 1e-5),
    (100.0, 1e3, 1e-6),
    (85.0, 100.0, 1e-4),
    (270.0, 100.0, 1e-4),
)


def _all_searches(c, inputs=None):
    """Every search at every point: (rho_r, rho_a floor, rho_a with (24), Ts max) per point.

    ``inputs``: the (rho_r, rho_a floor) per point that the later searches take (those of a
    reference run), so that two runs compare each search on the same arguments: a rho_r that
    differs by 1e-13 would move the Ts root by more (the right side of (24) is a difference).
    """
    p = 1
    rc, tc = reference_constants(c, p), true_constants(c, p)
    lam = float(c.lam)
    out = []
    for i, (kw, kl, kt) in enumerate(POINTS):
        w, ls, Ts = kw * lam, kl * lam, kt / lam
        r = searches.min_rho_r(c, rc, w, ("16a", "21a"))
        r_in = (1.5 if r is None else r) if inputs is None else inputs[i][0]
        a0 = searches.min_rho_a(c, tc, p, w, r_in, None, None, ("16b", "21b"))
        a0_in = a0 if inputs is None else inputs[i][1]
        a = searches.min_rho_a(c, tc, p, w, r_in, ls, Ts, ("16b", "21b", "24"))
        t = searches.max_Ts(c, tc, p, w, ls, r_in, 2.0 * a0_in) if a0_in is not None else None
        out.append((r, a0, a, t, r_in, a0_in))
    return out


def _agree(x, y):
    if x is None or y is None:
        return x is None and y is None
    return abs(x / y - 1.0) <= AGREE_RTOL


@pytest.mark.parametrize("i", range(len(GALLERY_FILES) + 2))
def test_searches_agree_with_bisection_on_the_real_oracles(i, monkeypatch):
    c = _gallery()[i]
    with monkeypatch.context() as m:
        use_bisection(m)
        ref = _all_searches(c)
    new = _all_searches(c, [row[4:] for row in ref])
    found = 0
    for a, b in zip(new, ref, strict=True):
        for x, y in zip(a[:4], b[:4], strict=True):
            assert _agree(x, y), (x, y)
            found += x is not None
    assert found >= 8


def test_far_fewer_probes_on_the_real_oracles(monkeypatch):
    """Probes of the (24) oracle and of the envelope of (24), counted where the searches make
    them (conditions._oracle_24, searches.sampling_constants), new against plain bisection."""
    counts = {"24": 0, "Ts": 0}
    real_oracle, real_sc = conditions._oracle_24, searches.sampling_constants

    def oracle(*a):
        f = real_oracle(*a)

        def counted(y):
            counts["24"] += 1
            return f(y)

        return counted

    def sc(*a, **k):
        counts["Ts"] += bool(k.get("envelope"))
        return real_sc(*a, **k)

    monkeypatch.setattr(conditions, "_oracle_24", oracle)
    monkeypatch.setattr(searches, "sampling_constants", sc)
    for c in _gallery():
        _all_searches(c)
    new = dict(counts)
    counts.update({"24": 0, "Ts": 0})
    use_bisection(monkeypatch)
    for c in _gallery():
        _all_searches(c)
    for k in counts:
        assert 0 < new[k] <= REAL_PROBE_FRACTION * counts[k], (k, new[k], counts[k])


@pytest.mark.parametrize("name", GALLERY_FILES)
def test_design_agrees_with_bisection(name, monkeypatch):
    """The verified design of a gallery input with the new searches and with bisection: the same
    omega, lambda_s and (the grid) Ts, radii within AGREE_RTOL, both verified in Arb."""
    c, req = load_l1_constants(GALLERY / name)
    new = design(c, req)
    with monkeypatch.context() as m:
        use_bisection(m)
        import drip_cert.bounds.l1drac.solve as solve

        solve._rho_r_at.cache_clear()
        solve._rho_a_floor.cache_clear()
        ref = design(c, req)
        solve._rho_r_at.cache_clear()
        solve._rho_a_floor.cache_clear()
    assert new.feasible and ref.feasible
    assert all(r.verified and r.margin_lo > 0.0 for r in new.conditions)
    assert (new.omega, new.lambda_s) == (ref.omega, ref.lambda_s)
    for x, y in ((new.rho_r, ref.rho_r), (new.rho_a, ref.rho_a), (new.Ts, ref.Ts)):
        assert _agree(x, y), (x, y)


#: probes of one public search on the double integrator (measured 6-12; bisection: 40-50)
PUBLIC_MAX_PROBES = 20


def test_public_searches_need_few_probes(monkeypatch):
    """smallest_rho_a with (24) and largest_Ts, through the public API: the probes of (24) and of
    its envelope per search (bisection needed > 40 each)."""
    counts = {"24": 0, "Ts": 0}
    real_oracle, real_sc = conditions._oracle_24, searches.sampling_constants

    def oracle(*a):
        f = real_oracle(*a)

        def counted(y):
            counts["24"] += 1
            return f(y)

        return counted

    def sc(*a, **k):
        counts["Ts"] += bool(k.get("envelope"))
        return real_sc(*a, **k)

    monkeypatch.setattr(conditions, "_oracle_24", oracle)
    monkeypatch.setattr(searches, "sampling_constants", sc)
    c = load_l1_constants(GALLERY / "double_integrator.toml")[0]
    lam = float(c.lam)
    n = 0
    for kw, kl, kt in POINTS[:4]:
        w, ls, Ts = kw * lam, kl * lam, kt / lam
        r = searches.smallest_rho_r(c, 1, w)
        if r is None:
            continue
        counts.update({"24": 0, "Ts": 0})
        a = searches.smallest_rho_a(c, 1, w, r, lambda_s=ls, Ts=Ts)
        a0 = searches.smallest_rho_a(c, 1, w, r, which=("16b", "21b"))
        t = searches.largest_Ts(c, 1, w, ls, r, 2.0 * a0)
        assert a is not None and t is not None
        assert 0 < counts["24"] <= PUBLIC_MAX_PROBES and 0 < counts["Ts"] <= PUBLIC_MAX_PROBES
        n += 1
    assert n >= 3
