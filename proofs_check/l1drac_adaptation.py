"""L1-DRAC (15b) / DRIP (L1DRAC:...:AdaptationLaw): the piecewise-constant adaptation gain.

The gain ``lambda_s (1 - e^{lambda_s T_s})^{-1}`` is the Hovakimyan-Cao piecewise-constant law
``sigma_hat(iT) = -Phi(T)^{-1} e^{A_s T} x_tilde(iT)``, ``Phi(T) = A_s^{-1}(e^{A_s T} - I)``,
with ``A_s = -lambda_s I`` (symbolic; numeric with ``scipy.linalg.expm``). The defining property
is also checked by integration: over one period the prediction error obeys
``x_tilde' = A_s x_tilde + sigma_hat - sigma``, and the law gives ``x_tilde(T) = -Phi(T) sigma``
(zero when the uncertainty is zero), for general Hurwitz ``A_s`` and for ``-lambda_s I``.
"""

from __future__ import annotations

import numpy as np
import sympy as sp
from scipy.integrate import solve_ivp
from scipy.linalg import expm

from proofs_check._core import CheckResult, Context, register, result

LABEL = "L1-DRAC (15b), DRIP eq. (L1DRAC:Definition:FeedbackOperator:AdaptationLaw)"

MATRIX_REL_TOL = 1e-10  # expm + solve, <= 6x6, lambda_s T in [1e-3, 10]: well conditioned
ODE_REL_TOL = 1e-8  # solve_ivp at rtol 1e-11 over one sampling period, relative to |x_tilde(0)|


def gain(lam_s: float, Ts: float) -> float:
    """``lambda_s (1 - e^{lambda_s T_s})^{-1}`` written with expm1 (no cancellation)."""
    return -lam_s / np.expm1(lam_s * Ts)


@register("l1drac.adaptation_gain", LABEL)
def check_adaptation_gain(ctx: Context) -> CheckResult:
    """Scalar gain == Hovakimyan-Cao law with A_s = -lambda_s I; one-period error property."""
    name = "l1drac.adaptation_gain"
    ls, T = sp.symbols("lambda_s T_s", positive=True)
    As = -ls
    Phi = (sp.exp(As * T) - 1) / As
    hc = -sp.exp(As * T) / Phi
    sym_res = sp.simplify(hc - ls / (1 - sp.exp(ls * T)))
    sym_ok = sym_res == 0
    rng = ctx.rng
    worst_mat = 0.0
    worst_ode = 0.0
    for k in range(ctx.count(200, 20)):
        n = int(rng.integers(1, 7))
        lam_s = float(np.exp(rng.uniform(-2, 4)))
        Ts = float(np.exp(rng.uniform(np.log(1e-3), np.log(10.0)))) / lam_s
        A = -lam_s * np.eye(n)
        E = expm(A * Ts)
        Phi_m = np.linalg.solve(A, E - np.eye(n))
        law = -np.linalg.solve(Phi_m, E)
        worst_mat = max(
            worst_mat,
            float(np.max(np.abs(law - gain(lam_s, Ts) * np.eye(n)))) / abs(gain(lam_s, Ts)),
        )
        # one period of x_tilde' = A x_tilde + sigma_hat - sigma, general Hurwitz A half the time
        if k % 2 == 1:
            M = rng.normal(size=(n, n))
            A = M - M.T - (lam_s + np.abs(np.linalg.eigvals(M + M.T)).max()) * np.eye(n)
            E = expm(A * Ts)
            Phi_m = np.linalg.solve(A, E - np.eye(n))
        x0 = rng.normal(size=n)
        sigma = rng.normal(size=n) * float(rng.choice([0.0, 1.0]))
        sig_hat = -np.linalg.solve(Phi_m, E @ x0)
        sol = solve_ivp(
            lambda t, x, A=A, s=sig_hat - sigma: A @ x + s,
            (0.0, Ts),
            x0,
            method="DOP853",
            rtol=1e-11,
            atol=1e-14,
        )
        target = -Phi_m @ sigma
        worst_ode = max(
            worst_ode,
            float(np.linalg.norm(sol.y[:, -1] - target))
            / (np.linalg.norm(x0) + np.linalg.norm(target)),
        )
    ok = sym_ok and worst_mat <= MATRIX_REL_TOL and worst_ode <= ODE_REL_TOL
    return result(
        name,
        LABEL,
        holds=bool(ok),
        residual=max(worst_mat, worst_ode),
        detail=(
            f"symbolic: -Phi^-1 e^(A_s T) - lambda_s/(1-e^(lambda_s T)) = {sym_res}; expm law vs "
            f"scalar gain: max rel diff {worst_mat:.1e}; one-period error vs -Phi sigma: "
            f"{worst_ode:.1e}"
        ),
    )
