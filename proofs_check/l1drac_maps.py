"""L1-DRAC Appendix A.2.1 maps: Proposition A.1, (A.21), Remarks 3.1-3.3 and the T_s rate.

Uses the independent transcription :mod:`proofs_check._appendix_a` (drip-cert's own maps, when
``drip_cert.bounds.l1drac`` exists, are checked in :mod:`proofs_check.implementation`).

* Prop. A.1 (A.20): every map is a polynomial in ``xi^{1/4}`` (resp. ``xi1^{1/4}``,
  ``xi2^{1/4}``) whose coefficients do not depend on xi (sympy ``Poly``); the coefficients are
  non-negative (falsification over random non-negative constants + Nelder-Mead), hence the
  maps are non-decreasing; the maps themselves are also compared at random ordered pairs.
* (A.21): ``lim_{T_s -> 0}`` of the maps is 0 (sympy ``limit``, max/|.| resolved by the sign of
  their series at T_s = 0, for omega above and below lambda_s).
* T_s rate (Sec. 4.3 claims ``sum Upsilon_ai in O(sqrt T_s)``): the leading exponent of
  ``sum Upsilon_ai`` is 1/4 when the diffusion has nonzero Hoelder constants, 1/2 when those
  vanish, 1 without diffusion (high-precision mpmath slopes; sympy limits of the blocks
  ``bar Delta_1 / sqrt(T_s)`` and ``Delta_sigma1 / T_s^{1/4}``). Erratum E8.
* Remarks 3.1-3.2: Gamma_r = O(rho_r^{3/2}), O(1) in omega; Theta/|2 lambda - omega| =
  O(1/sqrt(omega)), and O(1/omega) without diffusion (the sqrt(omega) coefficients of
  Appendix A.2 all carry a diffusion factor).
"""

from __future__ import annotations

import mpmath as mp
import numpy as np
import sympy as sp

from proofs_check._appendix_a import (
    CONSTANTS,
    DIFFUSION,
    HOLDER,
    SYM,
    XI_MAPS,
    frak_p,
    ts_maps,
)
from proofs_check._core import CheckResult, Context, register, result

LABEL = "L1-DRAC Prop. A.1 / (A.21) / Sec. 4.3"

COEF_REL_TOL = 1e-12  # coefficients are sums/products of non-negative floats: rounding only
MONO_REL_TOL = 1e-12  # map(xi1) - map(xi2) for xi1 <= xi2 in double precision: rounding only
SLOPE_TOL = 1e-3  # corrections to the leading power are O(T_s^{1/4}) <= 1e-7 at T_s <= 1e-30
MP_DPS = 120  # digits: exp(omega T_s) - 1 at T_s = 1e-40 keeps >= 70 significant digits


def _numpy(expr: sp.Expr, args: list[sp.Symbol]):
    return sp.lambdify(args, expr, modules=[{"Max": np.maximum, "Abs": np.abs}, "numpy"])


def _random_args(rng: np.random.Generator, size: int) -> dict[str, np.ndarray]:
    """Random admissible arguments: constants >= 0 (some exactly 0), rates > 0, T_s moderate."""
    vals: dict[str, np.ndarray] = {}
    for k in CONSTANTS:
        v = np.exp(rng.uniform(np.log(1e-3), np.log(1e3), size))
        v[rng.random(size) < 0.2] = 0.0
        vals[k] = v
    for k in ("lam", "lam_s", "omega"):
        vals[k] = np.exp(rng.uniform(np.log(1e-2), np.log(1e3), size))
    hi = 30.0 / np.maximum(np.maximum(vals["omega"], vals["lam_s"]), vals["lam"])
    vals["T_s"] = np.exp(rng.uniform(np.log(1e-9), np.log(hi)))
    # keep |2 lambda - omega| away from 0 (the paper excludes omega = 2 lambda)
    close = np.abs(2 * vals["lam"] - vals["omega"]) < 1e-3 * vals["omega"]
    vals["omega"][close] *= 1.5
    return vals


@register("l1drac.propA1_monotone", "L1-DRAC Prop. A.1 (A.20) and (25): maps non-decreasing")
def check_monotone(ctx: Context) -> CheckResult:
    """Polynomial structure in xi^{1/4} with non-negative coefficients; random ordered pairs."""
    name = "l1drac.propA1_monotone"
    maps = ts_maps()
    z = sp.symbols("z", nonnegative=True)
    rng = ctx.rng
    size = ctx.count(20000, 2000)
    vals = _random_args(rng, size)
    others = [SYM[k] for k in CONSTANTS] + [SYM[k] for k in ("lam", "lam_s", "omega", "T_s")]
    worst = -np.inf
    n_coef = 0
    structure_ok = True
    for key in (*XI_MAPS, "Ua1", "Ua2", "Ua3"):
        # (25) maps are sums of products of A.1 maps with non-negative weights: they are
        # checked at ordered pairs only (expanding them symbolically costs minutes)
        coefs = []
        if key in XI_MAPS:
            e = maps[key].subs(SYM["xi"], z**4)
            poly = sp.Poly(sp.expand(sp.powdenest(e, force=True)), z)
            coefs = list(zip(poly.monoms(), poly.coeffs()))
        for monom, coef in coefs:
            gens = (z,)
            if any(g in coef.free_symbols for g in (SYM["xi"], SYM["xi1"], SYM["xi2"], *gens)):
                structure_ok = False
            if sum(monom) == 0:
                continue  # constant term does not affect monotonicity
            f = _numpy(coef, others)
            c = np.asarray(f(*[vals[s.name] for s in others]), dtype=float)
            c = np.broadcast_to(c, (size,))
            finite = np.isfinite(c)
            scale = np.max(np.abs(c[finite])) + 1e-300 if finite.any() else 1.0
            worst = max(worst, float(np.max(-c[finite] / scale)) if finite.any() else -np.inf)
            n_coef += 1
        # direct comparison at random ordered pairs
        args = others + ([SYM["xi"]] if key in XI_MAPS else [SYM["xi1"], SYM["xi2"]])
        fmap = _numpy(maps[key], args)
        a = np.exp(rng.uniform(-8, 8, size))
        b = a * np.exp(rng.uniform(0, 4, size))
        base = [vals[s.name] for s in others]
        if key in XI_MAPS:
            lo, hi_ = fmap(*base, a), fmap(*base, b)
        else:
            c2 = np.exp(rng.uniform(-8, 8, size))
            lo = fmap(*base, a, c2)
            hi_ = np.minimum(fmap(*base, b, c2), fmap(*base, a, c2 * np.exp(rng.uniform(0, 4))))
        lo, hi_ = np.broadcast_to(lo, (size,)), np.broadcast_to(hi_, (size,))
        ok = np.isfinite(lo) & np.isfinite(hi_)
        worst = max(worst, float(np.max((lo[ok] - hi_[ok]) / (np.abs(hi_[ok]) + 1e-300))))
    holds = structure_ok and worst <= max(COEF_REL_TOL, MONO_REL_TOL)
    return result(
        name,
        "L1-DRAC Prop. A.1 (A.20) and (25): maps non-decreasing",
        holds=bool(holds),
        residual=worst,
        detail=(
            f"6 maps of (A.20) are polynomials in xi^(1/4) with xi-free coefficients: "
            f"{structure_ok}; "
            f"{n_coef} non-constant coefficients x {size} random constant sets, and the maps at "
            f"{size} ordered pairs each: max relative negativity {worst:.2e}"
        ),
    )


def _constants(omega: int, lam_s: int, p: int = 2, zero: tuple[str, ...] = ()):
    vals = {SYM[k]: sp.Rational(i % 5 + 1, 3) for i, k in enumerate(CONSTANTS)}
    _, pp, ppp = frak_p(p)
    vals.update(
        {
            SYM["pp"]: pp,
            SYM["ppp"]: ppp,
            SYM["lam"]: sp.Integer(2),
            SYM["lam_s"]: sp.Integer(lam_s),
            SYM["omega"]: sp.Integer(omega),
            SYM["xi"]: sp.Integer(3),
            SYM["xi1"]: sp.Integer(3),
            SYM["xi2"]: sp.Integer(1),
        }
    )
    vals.update({SYM[k]: sp.Integer(0) for k in zero})
    return vals


def _resolver(vals):
    """Branch of max/|.| valid for small T_s > 0, from the sign of the series at 0."""
    s = sp.symbols("s", positive=True)

    def lead_sign(e):
        ser = sp.expand(sp.series(e.subs(vals).subs(SYM["T_s"], s), s, 0, 4).removeO())
        return 0 if ser == 0 else sp.sign(ser.as_leading_term(s))

    def branch(kind, args):
        if kind == "max":
            return args[0] if lead_sign(args[0] - args[1]) >= 0 else args[1]
        return args[0] if lead_sign(args[0]) >= 0 else -args[0]

    return branch


@register("l1drac.A21_limits", "L1-DRAC (A.21) and Remark 3.3: maps -> 0 as T_s -> 0")
def check_A21(ctx: Context) -> CheckResult:
    """sympy limits as T_s -> 0+ of the maps of (A.21) (and of the blocks of Upsilon'_1)."""
    name = "l1drac.A21_limits"
    Ts = SYM["T_s"]
    cases = [(50, 10), (5, 30)] if not ctx.quick else [(5, 30)]
    lims: dict[str, sp.Expr] = {}
    for omega, lam_s in cases:
        vals = _constants(omega, lam_s)
        maps = ts_maps(_resolver(vals))
        keys = [
            "U2p",
            "U3p",
            "Utilde_minus",
            "U_minus",
            "Delta_mu1",
            "Delta_mu2",
            "Delta_mu3",
            "Delta_sigma2",
            "Delta_sigma3",
        ]
        if not ctx.quick:  # the slow ones (tens of seconds each), full run only
            keys += ["Delta_sigma1", "U1p"]
        for key in keys:
            lims[f"{key}@w={omega},ls={lam_s}"] = sp.limit(maps[key].subs(vals), Ts, 0, "+")
    bad = {k: v for k, v in lims.items() if v != 0}
    return result(
        name,
        "L1-DRAC (A.21) and Remark 3.3: maps -> 0 as T_s -> 0",
        holds=not bad,
        residual=0.0 if not bad else float("nan"),
        detail=(
            f"{len(lims)} limits at T_s -> 0+ (omega > lambda_s and omega < lambda_s); Upsilon'_1"
            " is a sum of sqrt(omega) p' Delta_sigma_i xi^k and Delta_mu_i xi^k, whose blocks are"
            f" all checked; nonzero: {bad or 'none'}"
        ),
    )


def _slope(expr: sp.Expr, k1: int, k2: int) -> float:
    """d log(expr) / d log(T_s) between T_s = 10^-k1 and 10^-k2 (mpmath, MP_DPS digits)."""
    with mp.workdps(MP_DPS):
        f = sp.lambdify(SYM["T_s"], expr, modules="mpmath")
        y1, y2 = f(mp.mpf(10) ** (-k1)), f(mp.mpf(10) ** (-k2))
        return float((mp.log(y2) - mp.log(y1)) / ((k1 - k2) * mp.log(10)))


@register("l1drac.Ts_rate", "L1-DRAC Sec. 4.3: rate at which the T_s terms vanish")
def check_ts_rate(ctx: Context) -> CheckResult:
    """Leading exponent of sum Upsilon_ai in T_s: 1/4 (Hoelder diffusion), 1/2, 1 (no diffusion)."""
    name = "l1drac.Ts_rate"
    expected = {"general": 0.25, "no Hoelder constants": 0.5, "no diffusion": 1.0}
    zeros = {"general": (), "no Hoelder constants": HOLDER, "no diffusion": DIFFUSION}
    slopes: dict[str, float] = {}
    worst = 0.0
    for omega, lam_s in [(50, 10), (5, 30)] if not ctx.quick else [(50, 10)]:
        for regime, zero in zeros.items():
            vals = _constants(omega, lam_s, zero=zero)
            e = ts_maps()["Ua_sum"].subs(vals)
            sl = _slope(e, 30, 40)
            slopes[f"{regime}@w={omega}"] = round(sl, 6)
            worst = max(worst, abs(sl - expected[regime]))
    # the source of T_s^{1/4}: bar Delta_1 ~ sqrt(T_s), Delta_sigma1 ~ T_s^{1/4} (sympy)
    s = sp.symbols("s", positive=True)
    vals = _constants(50, 10)
    maps = ts_maps(_resolver(vals))
    l1 = sp.limit(maps["Dbar1"].subs(vals).subs(SYM["T_s"], s**4) / s**2, s, 0, "+")
    if ctx.quick:  # ~10 s of sympy: full run only
        l2 = sp.nan
        sym_ok = bool(l1.is_positive and l1.is_finite)
    else:
        l2 = sp.limit(maps["Delta_sigma1"].subs(vals).subs(SYM["T_s"], s**4) / s, s, 0, "+")
        sym_ok = bool(l1.is_positive and l1.is_finite and l2.is_positive and l2.is_finite)
    holds = sym_ok and worst <= SLOPE_TOL
    return result(
        name,
        "L1-DRAC Sec. 4.3: rate at which the T_s terms vanish",
        holds=bool(holds),
        residual=worst,
        detail=(
            f"slopes d log(sum Upsilon_ai)/d log T_s at T_s in [1e-40, 1e-30]: {slopes}; "
            f"lim bar Delta_1/T_s^(1/2) = {sp.N(l1, 6)}, lim Delta_sigma1/T_s^(1/4) = "
            f"{sp.N(l2, 6)}: with Hoelder diffusion the rate is T_s^(1/4), not sqrt(T_s)"
        ),
        erratum="E8",
    )


@register("l1drac.remarks_scalings", "L1-DRAC Remarks 3.1-3.2 (18b-c), (22)-(23)")
def check_remarks(ctx: Context) -> CheckResult:
    """Gamma_r = O(rho^{3/2}) and O(1) in omega; Theta/|2l-w| = O(w^-1/2), O(1/w) w/o diffusion."""
    name = "l1drac.remarks_scalings"
    lam, w, rho, Ds, rho_a = sp.symbols("lambda omega rho_r Delta_star rho_a", positive=True)
    D = {
        k: sp.Symbol(k, positive=True)
        for k in (
            "c1 c2 c3 c4 cc1 cc2 cc3 cc4 o1 o2 o3 o4 o5 o6 o7 o8 x1 x2 x3 x4 x5 a1 a2 a3 "
            "A_cc1 A_o1 A_o2 A_o3 A_o4 A_x1 A_x2 A_x3 A_x4 A_a2 A_a3"
        ).split()
    }
    den = w - 2 * lam  # omega -> oo: |2 lambda - omega| = omega - 2 lambda
    R = rho + Ds
    gamma_r = (
        D["c1"] / (2 * lam)
        + w * D["c4"] / den
        + (D["cc1"] / (2 * lam) + w * D["cc4"] / den) * sp.sqrt(R)
        + (D["o1"] / (2 * lam) + w * D["o8"] / den) * R
        + (D["o2"] / (2 * lam) + D["o3"] / (2 * sp.sqrt(lam)) + D["a1"] * Ds / (2 * lam)) * rho
        + D["x1"] / (2 * sp.sqrt(lam)) * R ** sp.Rational(3, 2)
    )  # (18b)
    theta_r = (
        D["c2"]
        + sp.sqrt(w) * D["c3"]
        + (D["cc2"] + sp.sqrt(w) * D["cc3"]) * sp.sqrt(R)
        + (D["o4"] + sp.sqrt(w) * D["o6"]) * R
        + (D["o5"] + sp.sqrt(w) * D["o7"]) * rho
        + ((D["x2"] + sp.sqrt(w) * D["x4"]) * R + (D["x3"] + sp.sqrt(w) * D["x5"]) * rho)
        * sp.sqrt(R)
        + (D["a2"] * R + D["a3"] * rho) * R
    )  # (22)
    rpp = rho_a + 2 * R
    theta_a = (
        sp.sqrt(w) * D["A_cc1"]
        + sp.sqrt(w) * D["A_x3"] * rpp
        + (D["A_x2"] + sp.sqrt(w) * D["A_x4"]) * rho_a
    ) * sp.sqrt(rho_a) + (
        D["A_o2"] + sp.sqrt(w) * D["A_o3"] + D["A_a2"] * rpp + D["A_a3"] * rho_a
    ) * rho_a  # (23)
    l_rho = sp.limit(gamma_r / rho ** sp.Rational(3, 2), rho, sp.oo)
    l_w = sp.limit(gamma_r, w, sp.oo)
    l_tr = sp.limit(sp.sqrt(w) * theta_r / den, w, sp.oo)
    l_ta = sp.limit(sp.sqrt(w) * theta_a / den, w, sp.oo)
    # without diffusion, the sqrt(omega) coefficients of Appendix A.2 vanish (A.3)-(A.11):
    pp = sp.Symbol("pp", positive=True)
    S = {
        k: sp.Symbol(k, nonnegative=True)
        for k in ("Dpp Dsp Dg Dmup h1 h2 h3 h4 Lpp Lsp h2t h3t h4t Lmup".split())
    }
    sl = sp.sqrt(lam)
    sqrt_w_coeffs = [
        pp / sl * (S["Dpp"] + S["Dsp"]) * (S["h1"] + 2 * S["Dg"] ** 2 * S["Dmup"] / sl),  # o3
        pp
        / sl
        * (
            (S["Dpp"] + S["Dsp"]) * S["h2"]
            + S["Dsp"] * (S["h1"] + 2 * S["Dg"] ** 2 * S["Dmup"] / sl)
        ),  # cc3
        pp
        / sl
        * (
            (S["Dpp"] + S["Dsp"]) * (S["h3"] + 2 * S["Dg"] ** 2 * S["Dmup"] / sl)
            + S["Dsp"] * S["h2"]
        ),  # odot6
        pp * (S["Dpp"] + S["Dsp"]) * (S["h4"] / sl + 2 * S["Dg"]),  # odot7
        pp * S["Dsp"] / sl * (S["h3"] + 2 * S["Dg"] ** 2 * S["Dmup"] / sl),  # otimes4
        pp * S["Dsp"] * (S["h4"] / sl + 2 * S["Dg"]),  # otimes5
        pp / sl * (S["Lpp"] + S["Lsp"]) * S["h2t"],  # true: circledcirc1 (hat Delta_1)
        pp / sl * (S["Lpp"] + S["Lsp"]) * S["h2t"],  # true: odot3 (hat Delta_2)
        pp / sl * (S["Lpp"] + S["Lsp"]) * S["h3t"],  # true: otimes3
        pp
        * (S["Lpp"] + S["Lsp"])
        * (S["h4t"] / sl + 2 * S["Dg"] * (1 + S["Dg"] / lam * S["Lmup"])),  # otimes4
    ]
    nodiff = {S[k]: 0 for k in ("Dpp", "Dsp", "Lpp", "Lsp")}
    vanish = all(sp.simplify(c.subs(nodiff)) == 0 for c in sqrt_w_coeffs)
    finite_pos = all(bool(v.is_positive) and bool(v.is_finite) for v in (l_rho, l_tr, l_ta))
    ok = finite_pos and bool(l_w.is_finite) and vanish
    return result(
        name,
        "L1-DRAC Remarks 3.1-3.2 (18b-c), (22)-(23)",
        holds=bool(ok),
        residual=0.0 if ok else float("nan"),
        detail=(
            f"lim Gamma_r/rho_r^(3/2) = {l_rho}; lim_(w->oo) Gamma_r = {sp.simplify(l_w)}; "
            f"lim sqrt(w) Theta_r/|2l-w| = {l_tr}; lim sqrt(w) Theta_a/|2l-w| = {l_ta}; "
            f"sqrt(omega) coefficients vanish without diffusion: {vanish}"
        ),
    )
