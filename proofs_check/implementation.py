"""drip-cert's own implementation against the independent re-derivations of this package.

Each check imports a drip-cert module (``drip_cert.analysis.iss``, ``drip_cert.bounds.tasil``,
``drip_cert.bounds.l1drac.appendix``, ``.sides``, ``.radii``) and compares it with the
formulas re-derived here (two computations of the same number), plus the properties the
certificate relies on: the tighter delta-ISS bound is never looser than the paper's, the
Upsilon maps are non-decreasing (Prop. A.1), the Markov radius is valid. A module that cannot be
imported is a FAIL (drip-cert is expected to ship it).
"""

from __future__ import annotations

import dataclasses
import math

import numpy as np
import sympy as sp

from proofs_check._appendix_a import SYM, XI_MAPS, frak_p, ts_maps
from proofs_check._core import CheckResult, Context, register, result
from proofs_check.delta_iss import paper_bound, tight_bound
from proofs_check.tasil_gap import sharp_eps

ISS_REL_TOL = 1e-12  # closed forms evaluated two ways in double precision
RHO_REL_TOL = 1e-12  # drip-cert rounds rho upward by a few ulps; must not go below nor far above
MAP_REL_TOL = 1e-7  # naive numpy exp(x)-1 (here) vs drip-cert's expm1 forms at omega*T_s >= 1e-3
MONO_REL_TOL = 1e-12  # map(xi1) <= map(xi2) in double precision: rounding only
KAPPA_REL_TOL = 1e-12  # (rho/kappa)^{2p} vs delta through one pow: rounding only


@register("impl.iss_bounds", "drip_cert.analysis.iss vs DRIP Prop. 1 (both bounds)")
def check_impl_iss(ctx: Context) -> CheckResult:
    """drip-cert's paper/tight bounds equal the closed forms; tight <= paper for all theta, t."""
    name = "impl.iss_bounds"
    from drip_cert.analysis.iss import delta_iss

    rng = ctx.rng
    worst_eq = 0.0
    worst_order = -np.inf
    for _ in range(ctx.count(300, 40)):
        lam = float(np.exp(rng.uniform(-2, 2)))
        dg = float(np.exp(rng.uniform(-2, 2)))
        g2 = dg * float(rng.uniform(0.05, 1.0))
        res = delta_iss(lam, dg, g2)
        t = np.concatenate([[0.0], np.exp(np.linspace(-6, 4, 40))]) / lam
        e0, sv = float(rng.exponential()), float(rng.exponential())
        for frac in (0.5, *rng.uniform(0.01, 0.99, 3)):
            th = frac * 2 * lam / dg**2
            pb = res.paper_bound(t, e0, sv, th)
            mine = paper_bound(t, e0, sv, lam, dg, th)
            worst_eq = max(worst_eq, float(np.max(np.abs(pb - mine) / (mine + 1e-300))))
            tb = res.tight_bound(t, e0, sv)
            worst_order = max(worst_order, float(np.max((tb - pb) / (pb + 1e-300))))
        mine_t = tight_bound(t, e0, sv, lam, g2)
        worst_eq = max(
            worst_eq, float(np.max(np.abs(res.tight_bound(t, e0, sv) - mine_t) / (mine_t + 1e-300)))
        )
        worst_eq = max(
            worst_eq,
            abs(res.theta_star - lam / dg**2) / (lam / dg**2),
            abs(res.paper_gain_asymptotic - dg / lam) / (dg / lam),
        )
    ok = worst_eq <= ISS_REL_TOL and worst_order <= ISS_REL_TOL
    return result(
        name,
        "drip_cert.analysis.iss vs DRIP Prop. 1 (both bounds)",
        holds=bool(ok),
        residual=max(worst_eq, worst_order),
        detail=(
            f"max rel difference to the closed forms {worst_eq:.1e}; max (tight - paper)/paper"
            f" over t and admissible theta {worst_order:.1e}"
        ),
    )


@register("impl.tasil", "drip_cert.bounds.tasil vs docs/math/tasil.md (eps*, rho_TaSIL)")
def check_impl_tasil(ctx: Context) -> CheckResult:
    """eps_star and rho_tasil of drip-cert vs the formulas of tasil_gap / tasil_rates."""
    name = "impl.tasil"
    from drip_cert.bounds.tasil import ClassConstants, eps_star, rho_tasil
    from proofs_check import tasil_rates as tr

    rng = ctx.rng
    rho_expr = tr.rho_tasil(tr.n, tr.delta)
    f = sp.lambdify((tr.g0, tr.b0, tr.q, tr.B, tr.L, tr.n, tr.delta), rho_expr, "mpmath")
    worst = 0.0
    for _ in range(ctx.count(300, 40)):
        g0 = float(np.exp(rng.uniform(-2, 3)))
        h1 = float(rng.uniform(0, 0.9)) / g0
        L = float(np.exp(rng.uniform(-5, 3)))
        h0 = float(rng.uniform(0, 1)) * (1 - g0 * h1) ** 2 / (2 * L * g0**2)
        a, b = eps_star(h0, h1, g0, L), sharp_eps(g0, h0, h1, L)
        if b > 0:
            worst = max(worst, abs(a - b) / b)
        c = ClassConstants(
            q=int(rng.integers(1, 10_000)),
            B_theta=float(rng.uniform(0.1, 10)),
            L_theta0=float(rng.uniform(0.1, 10)),
            L_theta1=1.0,
            b0=float(rng.uniform(0.1, 10)),
            b1=1.0,
        )
        nn, dl = int(rng.integers(1, 10**7)), float(np.exp(rng.uniform(-20, -0.01)))
        theirs = rho_tasil(dl, nn, g0, 0.0, c)
        mine = float(f(g0, c.b0, c.q, c.B_theta, c.L_theta0, nn, dl))
        worst = max(worst, abs(theirs - mine) / mine)
    return result(
        name,
        "drip_cert.bounds.tasil vs docs/math/tasil.md (eps*, rho_TaSIL)",
        holds=bool(worst <= RHO_REL_TOL),
        residual=worst,
        detail=f"max rel difference (eps*, rho_TaSIL at tau0=0) {worst:.1e}",
    )


def _random_l1_constants(rng: np.random.Generator):
    """A random valid ``L1Constants`` (Assumption 7 satisfied) and the matching symbol values."""
    from drip_cert.bounds.l1drac.constants import L1Constants

    vals: dict[str, object] = {}
    for fld in dataclasses.fields(L1Constants):
        if fld.name in ("p_star", "m"):
            vals[fld.name] = int(rng.integers(1, 9))
        elif fld.name == "lip_f":
            vals[fld.name] = bool(rng.integers(0, 2))
        else:
            v = float(np.exp(rng.uniform(np.log(1e-2), np.log(1e2))))
            vals[fld.name] = 0.0 if rng.random() < 0.15 else v
    for k in ("lam", "eps_r", "eps_a"):
        vals[k] = float(np.exp(rng.uniform(np.log(1e-1), np.log(1e2))))
    vals["Delta_g_perp"] = 0.5 * vals["lam"] / (1 + max(vals["Delta_mu_perp"], vals["L_mu_perp"]))
    return L1Constants(**vals), vals


_MAP = {
    "Lh_mu": "L_mu_hat",
    "Lh_mu_par": "L_mu_par_hat",
    "Lh_p": "L_p_hat",
    "Lh_sigma": "L_sigma_hat",
    "Lh_p_par": "L_p_par_hat",
    "Lh_sigma_par": "L_sigma_par_hat",
}


@register(
    "impl.l1drac_maps", "drip_cert.bounds.l1drac.appendix, .sides vs (A.13)-(A.19), (25); Prop. A.1"
)
def check_impl_l1drac_maps(ctx: Context) -> CheckResult:
    """drip-cert's Upsilon maps equal this package's transcription and are non-decreasing."""
    name = "impl.l1drac_maps"
    from drip_cert.bounds.l1drac import appendix as ap
    from drip_cert.bounds.l1drac import sides

    maps = ts_maps()
    syms = [SYM[k] for k in SYM]
    fns = {
        k: sp.lambdify(syms, maps[k], modules=[{"Max": max, "Abs": abs}, "math"])
        for k in (*XI_MAPS, "Ua1", "Ua2", "Ua3")
    }
    theirs_xi = {
        "U1p": ap.upsilon1_prime,
        "U2p": ap.upsilon2_prime,
        "U3p": ap.upsilon3_prime,
        "Utilde_minus": ap.upsilon_minus_tilde,
        "U_minus": ap.upsilon_minus,
    }
    theirs_a = {"Ua1": sides.upsilon_a1, "Ua2": sides.upsilon_a2, "Ua3": sides.upsilon_a3}
    rng = ctx.rng
    worst_eq = 0.0
    worst_mono = -np.inf
    for _ in range(ctx.count(300, 30)):
        c, vals = _random_l1_constants(rng)
        p = int(rng.integers(1, 6))
        omega = float(np.exp(rng.uniform(np.log(0.1), np.log(1e3))))
        if abs(2 * c.lam - omega) < 1e-3 * omega:
            omega *= 1.5
        lam_s = float(np.exp(rng.uniform(np.log(0.1), np.log(1e3))))
        Ts = float(np.exp(rng.uniform(np.log(1e-3), np.log(20.0)))) / max(omega, lam_s)
        s = ap.sampling_constants(c, p, omega, Ts, lam_s)
        _, pp, ppp = frak_p(p)
        env = {k: float(vals[_MAP.get(k, k)]) for k in SYM if _MAP.get(k, k) in vals}
        env.update(pp=float(pp), ppp=float(ppp), lam_s=lam_s, omega=omega, T_s=Ts)
        x1, x2 = float(np.exp(rng.uniform(-5, 5))), float(np.exp(rng.uniform(-5, 5)))
        for key in XI_MAPS:
            mine = fns[key](**{**env, "xi": x1, "xi1": 0.0, "xi2": 0.0})
            th = ap.upsilon_ring(x1, c, p, omega) if key == "U_ring" else theirs_xi[key](x1, s)
            worst_eq = max(worst_eq, abs(th - mine) / (abs(mine) + 1e-300))
            th_hi = (
                ap.upsilon_ring(2 * x1, c, p, omega)
                if key == "U_ring"
                else theirs_xi[key](2 * x1, s)
            )
            worst_mono = max(worst_mono, (th - th_hi) / (abs(th_hi) + 1e-300))
        for key, fn in theirs_a.items():
            mine = fns[key](**{**env, "xi": 0.0, "xi1": x1, "xi2": x2})
            th = fn(x1, x2, s)
            worst_eq = max(worst_eq, abs(th - mine) / (abs(mine) + 1e-300))
            worst_mono = max(
                worst_mono,
                (th - fn(2 * x1, x2, s)) / (abs(th) + 1e-300),
                (th - fn(x1, 2 * x2, s)) / (abs(th) + 1e-300),
            )
    ok = worst_eq <= MAP_REL_TOL and worst_mono <= MONO_REL_TOL
    return result(
        name,
        "drip_cert.bounds.l1drac.appendix, .sides vs (A.13)-(A.19), (25); Prop. A.1",
        holds=bool(ok),
        residual=max(worst_eq, worst_mono),
        detail=(
            f"max rel difference to the independent transcription {worst_eq:.1e}; max "
            f"relative decrease when xi doubles {worst_mono:.1e}"
        ),
    )


@register("impl.l1drac_markov", "drip_cert.bounds.l1drac.radii p_for_delta / kappa_markov")
def check_impl_markov(ctx: Context) -> CheckResult:
    """kappa <= e rho and (rho/kappa)^{2p} = delta for drip-cert's integer p, any delta."""
    name = "impl.l1drac_markov"
    from drip_cert.bounds.l1drac.radii import kappa_markov, p_for_delta

    rng = ctx.rng
    deltas = np.concatenate(
        [np.exp(-rng.uniform(0, 30, ctx.count(5000, 500))), np.exp(-2.0 * np.arange(1, 15))]
    )
    worst = -np.inf
    for d in deltas:
        if not 0 < d < 1:
            continue
        p = p_for_delta(float(d), 20)
        k = kappa_markov(1.0, p, float(d))
        worst = max(worst, (k - math.e) / math.e, abs(k ** (-2 * p) - d) / d - KAPPA_REL_TOL)
    return result(
        name,
        "drip_cert.bounds.l1drac.radii p_for_delta / kappa_markov",
        holds=bool(worst <= KAPPA_REL_TOL),
        residual=worst,
        detail=f"{deltas.size} deltas: max of (kappa - e rho)/(e rho) and tail error {worst:.1e}",
    )
