"""An independent sympy transcription of L1-DRAC Appendix A.2.1 (A.13)-(A.19) and (25).

Read off the rendered PDF (arXiv:2509.04619, pp. 15, 45-46), not from drip-cert's
implementation. Every map is built as a sympy expression in the symbols of :data:`SYM`, so
the checks can differentiate, take limits and series, or lambdify it for numbers.

``branch`` selects how ``max`` and ``|.|`` are written: ``"exact"`` keeps ``Max``/``Abs``;
a callable ``branch(kind, args)`` may resolve them (used for series as T_s -> 0, where the
branch is fixed by the sign of ``omega - lambda_s``).
"""

from __future__ import annotations

import sympy as sp

_NAMES = (
    "lam lam_s omega T_s xi xi1 xi2 pp ppp Delta_f Delta_g Delta_Theta Delta_mu Delta_mu_par "
    "Delta_p Delta_sigma Delta_p_par Delta_sigma_par L_mu Lh_mu L_mu_par Lh_mu_par L_p L_sigma "
    "Lh_p Lh_sigma L_p_par L_sigma_par Lh_p_par Lh_sigma_par"
)
SYM: dict[str, sp.Symbol] = {s.name: s for s in sp.symbols(_NAMES, nonnegative=True)}
"""All symbols; ``pp`` = frak p'(p), ``ppp`` = frak p''(p) (A.1); ``Lh_*`` = hat L_*."""

CONSTANTS = tuple(k for k in SYM if k not in {"lam", "lam_s", "omega", "T_s", "xi", "xi1", "xi2"})

HOLDER = ("L_p", "L_sigma", "L_p_par", "L_sigma_par")
"""1/2-Hoelder constants of the diffusion (Assumptions 1, 5, 6)."""

DIFFUSION = (
    "Delta_p",
    "Delta_sigma",
    "Delta_p_par",
    "Delta_sigma_par",
    *HOLDER,
    "Lh_p",
    "Lh_sigma",
    "Lh_p_par",
    "Lh_sigma_par",
)
"""Every constant that is zero when there is no diffusion at all."""


def frak_p(p: int) -> tuple[sp.Expr, sp.Expr, sp.Expr]:
    """(A.1): ``(p (p-1)/2)^{1/2}``, ``(p (2p-1)/2)^{1/2}``, ``(p (4p-1))^{1/2}``."""
    p_ = sp.Integer(p)
    return (sp.sqrt(p_ * (p_ - 1) / 2), sp.sqrt(p_ * (2 * p_ - 1) / 2), sp.sqrt(p_ * (4 * p_ - 1)))


def _exact(kind: str, args: tuple[sp.Expr, ...]) -> sp.Expr:
    return sp.Max(*args) if kind == "max" else sp.Abs(args[0])


def ts_maps(branch=_exact, s: dict[str, sp.Expr] | None = None) -> dict[str, sp.Expr]:
    """The maps of (A.18), (A.19) in ``xi`` and (25) in ``(xi1, xi2)``, with their building blocks.

    ``s`` optionally substitutes expressions for symbols (e.g. ``T_s -> s**4``).
    """
    S = dict(SYM)
    if s:
        S.update(s)
    lam, ls, w, Ts = S["lam"], S["lam_s"], S["omega"], S["T_s"]
    pp, ppp = S["pp"], S["ppp"]
    Dg, DT = S["Delta_g"], S["Delta_Theta"]
    Dmu, Dmup = S["Delta_mu"], S["Delta_mu_par"]
    Dp, Ds, Dpp, Dsp = S["Delta_p"], S["Delta_sigma"], S["Delta_p_par"], S["Delta_sigma_par"]
    out: dict[str, sp.Expr] = {}
    g1 = sp.sqrt(ls * (sp.exp(ls * Ts) + 1) / (sp.exp(ls * Ts) - 1))  # (A.13a)
    g1p = (1 - sp.exp(-2 * lam * Ts)) * (1 - sp.exp(-w * Ts))  # (A.13a)
    r = ls / w * (sp.exp(w * Ts) - 1) / (sp.exp(ls * Ts) - 1)
    g2 = branch("max", (sp.exp((w - ls) * Ts), sp.Integer(1))) * r  # (A.13b)
    g2p = branch(
        "max", (branch("abs", (1 - sp.exp((w - ls) * Ts) * r,)), branch("abs", (1 - r,)))
    )  # (A.13c)
    gpp = pp * g2p + ppp * sp.sqrt(1 - sp.exp(-2 * w * Ts)) * (2 + g2)  # (A.13d)
    gmu = S["L_mu_par"] + S["L_mu"] * g2 * DT  # (A.14a)
    ghmu = S["Lh_mu_par"] + S["Lh_mu"] * g2 * DT
    Lpar = S["L_p_par"] + S["L_sigma_par"]
    Lhpar = S["Lh_p_par"] + S["Lh_sigma_par"]
    gsig = Lpar + g2 * DT * (S["L_p"] + S["L_sigma"])  # (A.14b)
    ghsig = Lhpar + g2 * DT * (S["Lh_p"] + S["Lh_sigma"])  # (A.14c)
    E = Dg * DT * sp.exp(-ls * Ts)
    D1 = 2 * Ts * (S["Delta_f"] + (1 + E) * Dmu + pp * E * g1 * (Dp + Ds)) + 2 * sp.sqrt(
        2
    ) * sp.sqrt(Ts) * pp * (Dp + Ds)  # (A.15a)
    D2 = 2 * pp * Ds * (sp.sqrt(2) * sp.sqrt(Ts) + Ts * E * g1)  # (A.15b)
    D3 = 2 * Ts * (S["Delta_f"] + (1 + E) * Dmu)  # (A.15c)
    one_m = 1 - sp.exp(-ls * Ts)
    Dmu1 = Ts * ghmu + D1 * gmu + Dmup * one_m  # (A.16a)
    Dmu2 = D2 * gmu  # (A.16b)
    Dmu3 = Ts * gmu * D3 + Dmup * one_m  # (A.16c)
    Dsig1 = (Lpar * sp.sqrt(D1) + Ts * Lhpar) * (1 + g2) + gsig * sp.sqrt(D1) + Ts * ghsig
    Dsig2 = sp.sqrt(D2) * (gsig + (1 + g2) * Lpar)  # (A.17b)
    Dsig3 = sp.sqrt(D3) * (gsig + (1 + g2) * Lpar)
    out.update(
        gamma1=g1,
        gamma1p=g1p,
        gamma2=g2,
        gamma2p=g2p,
        gammapp=gpp,
        gamma_mu=gmu,
        gammah_mu=ghmu,
        gamma_sigma=gsig,
        gammah_sigma=ghsig,
        Dbar1=D1,
        Dbar2=D2,
        Dbar3=D3,
        Delta_mu1=Dmu1,
        Delta_mu2=Dmu2,
        Delta_mu3=Dmu3,
        Delta_sigma1=Dsig1,
        Delta_sigma2=Dsig2,
        Delta_sigma3=Dsig3,
    )

    def ups1(x):  # (A.18a)
        return (
            Dmu1
            + sp.sqrt(w) * pp * Dsig1
            + sp.sqrt(w) * pp * Dsig2 * x ** sp.Rational(1, 4)
            + (Dmu2 + sp.sqrt(w) * pp * Dsig3) * sp.sqrt(x)
            + Dmu3 * x
        )

    def ups2(x):  # (A.18b)
        return gpp * (Dpp + Dsp * (1 + sp.sqrt(x)))

    def ups3(x):  # (A.18c)
        return Dmup * (sp.exp(w * Ts) - 1) * (1 + x)

    def ups_tilde(x):  # (A.19a)
        return (
            (1 / lam)
            * (1 - sp.exp(-2 * lam * Ts))
            * Dg
            * (
                sp.sqrt(w) * pp * sp.sqrt(1 - sp.exp(-2 * w * Ts)) * (Dpp + Dsp * (1 + sp.sqrt(x)))
                + Dmup * (1 + x)
            )
        )

    def ups_minus(x):  # (A.19b)
        return g1p * (2 * pp * (Dpp + Dsp * (1 + sp.sqrt(x))) + Dmup / sp.sqrt(w) * (1 + x))

    def ups_ring(x):  # (A.19c)
        return Dg**2 * (pp * Lpar * sp.sqrt(x) + S["L_mu_par"] * x / sp.sqrt(w))

    xi, x1, x2 = S["xi"], S["xi1"], S["xi2"]
    out.update(
        U1p=ups1(xi),
        U2p=ups2(xi),
        U3p=ups3(xi),
        Utilde_minus=ups_tilde(xi),
        U_minus=ups_minus(xi),
        U_ring=ups_ring(xi),
    )
    den = branch("abs", (2 * lam - w,))
    out["Ua1"] = ups_tilde(x1) * x2 + w / (lam * den) * ups_ring(x2) * ups_minus(x1)  # (25a)
    out["Ua2"] = (
        (1 / lam) * (Dg * x2 + sp.sqrt(w) / den * ups_ring(x2)) * (ups1(x1) + sp.sqrt(w) * ups2(x1))
    )  # (25b)
    out["Ua3"] = (1 / den) * (2 * Dg * x2 + sp.sqrt(w) / lam * ups_ring(x2)) * ups3(x1)  # (25c)
    out["Ua_sum"] = out["Ua1"] + out["Ua2"] + out["Ua3"]
    return out


XI_MAPS = ("U1p", "U2p", "U3p", "Utilde_minus", "U_minus", "U_ring")
"""The maps of Proposition A.1 (functions of one xi)."""
