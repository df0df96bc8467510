"""The comparison bound of the imitation gap through the learned loop's own contraction
(docs/math/tasil.md Proposition 3.7; ``drip_cert.bounds.tasil.certificate``, ``comparison_gain``).

Claim (``C = R^n``): if ``mu_2(d F_hat / dx) <= -lambda_IL < 0`` everywhere, the expert loop is
``F* = F_hat - g Delta`` and both start at the same state, then
``max_t ||x_hat_t - x*_t|| <= ||g||_2 sup_t ||Delta(x*_t)|| / lambda_IL``.

Falsification in continuous time: ``F_hat(x) = A x + c tanh(W x)`` with ``A`` a negative
multiple of the identity plus a skew part and ``|c| ||W||_2`` below ``-mu_2(A)``, so
``lambda_IL = -mu_2(A) - |c| ||W||_2`` is a valid rate (``tanh' in [0, 1]``); ``g`` a random
``n x m`` matrix; ``Delta(x) = a0 + K x + s sin(V x)``. The pair ``(x*, x_hat)`` is integrated by
DOP853 and the sup of ``||Delta(x*_t)||`` is taken on a fine grid. One instance in three is the
tight one (``F_hat = -lambda x``, constant ``Delta`` along the top singular direction of ``g``,
``lambda T`` large), where the ratio gap / bound tends to 1: a ``factor`` below 1 on the bound
makes the check fail (the tests use it to show the check can fail).
"""

from __future__ import annotations

import numpy as np
from scipy.integrate import solve_ivp

from proofs_check._core import CheckResult, Context, register, result

LABEL = "docs/math/tasil.md Proposition 3.7 (comparison bound through the learned loop)"
ODE_RTOL = 1e-10  # solve_ivp relative tolerance
ODE_ATOL = 1e-12  # solve_ivp absolute tolerance
GRID = 4001  # points where sup ||Delta(x*_t)|| and the gap are read off the dense output
RATIO_TOL = 1e-6
"""DOP853 at rtol 1e-10 over the horizon, and the grid's underestimate of the sup of a smooth
||Delta(x*_t)|| (relative (dt * speed)^2 ~ 1e-7 at this grid): both far below 1e-6."""


def _instance(rng: np.random.Generator, tight: bool):
    n = int(rng.integers(2, 4))
    m = int(rng.integers(1, n + 1))
    g = rng.normal(size=(n, m))
    if tight:
        lam = float(rng.uniform(0.5, 2.0))
        A, c, W = -lam * np.eye(n), 0.0, np.zeros((n, n))
        u, _, vt = np.linalg.svd(g)
        a0 = float(rng.uniform(0.1, 1.0)) * vt[0]  # the input direction ||g||_2 is attained on
        K, s, V = np.zeros((m, n)), np.zeros(m), np.zeros((m, n))
        T = 25.0 / lam  # e^{-lambda T} ~ 1e-11: the ratio reaches 1 to that accuracy
        return A, c, W, g, a0, K, s, V, lam, T
    S = rng.normal(size=(n, n))
    base = float(rng.uniform(0.5, 2.0))
    A = -base * np.eye(n) + (S - S.T) / 2
    W = rng.normal(size=(n, n))
    c = float(rng.uniform(-0.9, 0.9)) * base / np.linalg.norm(W, 2)
    lam = base - abs(c) * np.linalg.norm(W, 2)  # mu_2(A) = -base (skew part adds nothing)
    a0 = rng.normal(size=m) * 0.3
    K = rng.normal(size=(m, n)) * 0.3
    s = rng.normal(size=m) * 0.3
    V = rng.normal(size=(m, n))
    return A, c, W, g, a0, K, s, V, lam, float(rng.uniform(3.0, 10.0))


@register("tasil.comparison_bound", LABEL)
def check_comparison_bound(ctx: Context, factor: float = 1.0) -> CheckResult:
    """max_t gap <= factor * ||g||_2 sup||Delta(x*)|| / lambda_IL on random and tight instances."""
    name = "tasil.comparison_bound"
    rng = ctx.rng
    n_inst = ctx.count(60, 12)
    worst = 0.0
    worst_tight = 0.0
    for k in range(n_inst):
        tight = k % 3 == 0
        A, c, W, g, a0, K, s, V, lam, T = _instance(rng, tight)
        n = A.shape[0]

        def delta(x, a0=a0, K=K, s=s, V=V):
            return a0 + K @ x + s * np.sin(V @ x)

        def F_hat(x, A=A, c=c, W=W):
            return A @ x + c * np.tanh(W @ x)

        def rhs(_t, y, g=g, n=n):
            xs, xh = y[:n], y[n:]
            return np.concatenate([F_hat(xs) - g @ delta(xs), F_hat(xh)])

        x0 = rng.normal(size=n) * float(rng.uniform(0.0, 2.0))
        sol = solve_ivp(
            rhs, (0.0, T), np.concatenate([x0, x0]), method="DOP853",
            rtol=ODE_RTOL, atol=ODE_ATOL, dense_output=True,
        )  # fmt: skip
        ts = np.linspace(0.0, T, GRID)
        Y = sol.sol(ts)
        gap = float(np.max(np.linalg.norm(Y[n:] - Y[:n], axis=0)))
        h0 = float(max(np.linalg.norm(delta(Y[:n, i])) for i in range(GRID)))
        bound = factor * np.linalg.norm(g, 2) * h0 / lam
        r = gap / bound if bound > 0 else 0.0
        worst = max(worst, r)
        if tight:
            worst_tight = max(worst_tight, r)
    return result(
        name,
        LABEL,
        holds=bool(worst <= 1.0 + RATIO_TOL),
        residual=worst - 1.0,
        detail=(
            f"{n_inst} instances (1/3 tight): max gap / (||g||_2 h0 / lambda_IL) = {worst:.8f} "
            f"(tight instances {worst_tight:.8f}: the bound is attained)"
        ),
    )
