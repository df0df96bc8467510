"""The TaSIL sure bound on a finite horizon along the expert's tube (docs/math/tasil.md sections
3.7, 3.9, 3.10; ``drip_cert.bounds.tasil.tube``, ``drip_cert.analysis.contraction.learned_loop``).

Five claims, each falsified on random instances and attained on tight ones (one in three), so that
a bound 1 % smaller (``factor = 0.99``) fails:

* ``tasil.comparison_finite_horizon`` (3.7): ``max_{t <= T} gap <= ||g||_2 h0 (1 - e^{-lambda_IL T})
  / lambda_IL``. Tight: ``F_hat = -lambda x``, ``Delta`` constant along the top right singular
  vector of ``g``; then ``gap(T)`` equals the bound.
* ``tasil.tube_radius`` (3.10a): for an expert loop contracting at ``lambda*`` and any centre c,
  ``||x*(t, xi) - c|| <= e^{-lambda* t} ||xi - c|| + ||F*(c)|| (1 - e^{-lambda* t}) / lambda*``.
  Tight: ``F*(x) = -lambda (x - c) + v`` with ``xi - c`` parallel to ``v``.
* ``tasil.tube_gap`` (3.10b): the grid recursion of
  :func:`~drip_cert.bounds.tasil.tube.time_resolved_gap_up` with ``H_k`` the sup of
  ``||Delta(x*)||`` on ``[t_k, t_{k+1}]`` bounds the gap at every time; tight as the first claim.
* ``tasil.box_tube`` (3.11a): for an expert loop with ``mu_inf(W J W^{-1}) <= -lambda_W``,
  ``||W (x*(t, xi) - c)||_inf <= e^{-lambda_W t} ||W (xi - c)||_inf + ||W F*(c)||_inf (1 -
  e^{-lambda_W t}) / lambda_W``. Random: ``F*(x) = A x + a tanh(V x) + v`` with the rate
  ``-(mu_W(A) + |a| ||W V W^{-1}||_inf)``; tight: ``F*(x) = -lambda (x - c) + beta e_i``,
  ``xi - c = alpha e_i`` (alpha, beta >= 0).
* ``tasil.centred_form`` (3.9): ``sup_B ||Delta|| <= || |Delta(c)| + |[J](B)| r ||``, ``[J]`` the
  box's interval Jacobian. Random: ``Delta = W2 tanh(W1 x + b) + K x`` (``[J]`` from
  ``enclose_jacobian_centred``), sup by dense sampling and the corners; tight: ``Delta(x) = u (a +
  v . (x - c))`` (rank one), whose sup is attained at a corner.
"""

from __future__ import annotations

import numpy as np
from scipy.integrate import solve_ivp

from drip_cert.analysis.networks.mlp import enclose_jacobian_centred
from drip_cert.bounds.tasil.tube import (
    horizon_factor_up,
    time_resolved_gap_up,
    tube_radii_up,
)
from drip_cert.model.mlp import MLP
from proofs_check._core import CheckResult, Context, register, result

LABEL_FH = "docs/math/tasil.md Proposition 3.7 (finite-horizon comparison bound)"
LABEL_R = "docs/math/tasil.md Proposition 3.10 (a): the expert's contraction tube"
LABEL_G = "docs/math/tasil.md Proposition 3.10 (b): the time-resolved gap bound on a grid"
LABEL_C = "docs/math/tasil.md Proposition 3.9: the centred form over a box"
LABEL_B = "docs/math/tasil.md Proposition 3.11 (a): the expert's box tube in a weighted inf-norm"
ODE_RTOL = 1e-11  # solve_ivp relative tolerance
ODE_ATOL = 1e-13  # solve_ivp absolute tolerance
GRID = 2001  # points where sups along a trajectory and the gap are read off the dense output
RATIO_TOL = 1e-6
"""DOP853 at rtol 1e-11, and the grid's underestimate of the sup of a smooth ||Delta(x*_t)||
(relative (dt * speed)^2 ~ 1e-7 at this grid): both far below 1e-6."""
SAMPLES = 4000  # random points per box for the centred form's sampled sup (plus the corners)


def _g_and_direction(rng: np.random.Generator, n: int, m: int):
    g = rng.normal(size=(n, m))
    _, _, vt = np.linalg.svd(g)
    return g, vt[0]


def _pair(rng: np.random.Generator, tight: bool):
    """(F_hat, Delta, g, lambda_IL, T, x0) of a learned loop contracting on R^n."""
    n = int(rng.integers(2, 4))
    m = int(rng.integers(1, n + 1))
    g, top = _g_and_direction(rng, n, m)
    lam = float(rng.uniform(0.3, 2.0))
    T = float(rng.uniform(0.2, 2.0)) / lam  # lambda T of order 1: the finite horizon matters
    if tight:
        a0 = float(rng.uniform(0.1, 1.0)) * top

        def F_hat(x, lam=lam):
            return -lam * x

        def delta(x, a0=a0):
            return a0

        return F_hat, delta, g, lam, T, rng.normal(size=n)
    S = rng.normal(size=(n, n))
    W = rng.normal(size=(n, n))
    c = float(rng.uniform(-0.9, 0.9)) * lam / np.linalg.norm(W, 2)
    A = -lam * np.eye(n) + (S - S.T) / 2
    rate = lam - abs(c) * np.linalg.norm(W, 2)
    K, V = 0.3 * rng.normal(size=(m, n)), rng.normal(size=(m, n))
    a0, s = 0.3 * rng.normal(size=m), 0.3 * rng.normal(size=m)

    def F_hat2(x, A=A, c=c, W=W):
        return A @ x + c * np.tanh(W @ x)

    def delta2(x, a0=a0, K=K, s=s, V=V):
        return a0 + K @ x + s * np.sin(V @ x)

    return F_hat2, delta2, g, rate, T, rng.normal(size=n)


def _gap_run(F_hat, delta, g, T, x0):
    n = x0.size

    def rhs(_t, y):
        xs, xh = y[:n], y[n:]
        return np.concatenate([F_hat(xs) - g @ delta(xs), F_hat(xh)])

    sol = solve_ivp(
        rhs, (0.0, T), np.concatenate([x0, x0]), method="DOP853",
        rtol=ODE_RTOL, atol=ODE_ATOL, dense_output=True,
    )  # fmt: skip
    ts = np.linspace(0.0, T, GRID)
    Y = sol.sol(ts)
    gap = np.linalg.norm(Y[n:] - Y[:n], axis=0)
    dn = np.array([np.linalg.norm(delta(Y[:n, i])) for i in range(GRID)])
    return ts, gap, dn


@register("tasil.comparison_finite_horizon", LABEL_FH)
def check_finite_horizon(ctx: Context, factor: float = 1.0) -> CheckResult:
    """max_{t<=T} gap <= factor ||g||_2 h0 (1 - e^{-lambda_IL T}) / lambda_IL."""
    name = "tasil.comparison_finite_horizon"
    worst = worst_tight = 0.0
    n_inst = ctx.count(45, 9)
    for k in range(n_inst):
        tight = k % 3 == 0
        F_hat, delta, g, lam, T, x0 = _pair(ctx.rng, tight)
        _, gap, dn = _gap_run(F_hat, delta, g, T, x0)
        bound = factor * np.linalg.norm(g, 2) * dn.max() * horizon_factor_up(lam, T)
        r = float(gap.max() / bound) if bound > 0 else 0.0
        worst = max(worst, r)
        worst_tight = max(worst_tight, r) if tight else worst_tight
    return result(
        name,
        LABEL_FH,
        holds=bool(worst <= 1.0 + RATIO_TOL),
        residual=worst - 1.0,
        detail=f"{n_inst} instances (1/3 tight): max gap / bound = {worst:.8f} (tight "
        f"{worst_tight:.8f})",
    )


@register("tasil.tube_radius", LABEL_R)
def check_tube_radius(ctx: Context, factor: float = 1.0) -> CheckResult:
    """||x*(t, xi) - c|| <= factor * r(t) of (3.10a) at every grid time."""
    name = "tasil.tube_radius"
    rng = ctx.rng
    worst = worst_tight = 0.0
    n_inst = ctx.count(45, 9)
    for k in range(n_inst):
        tight = k % 3 == 0
        n = int(rng.integers(2, 4))
        lam = float(rng.uniform(0.3, 2.0))
        c = rng.normal(size=n)
        v = rng.normal(size=n)
        if tight:
            xi = c + float(rng.uniform(0.1, 2.0)) * v / np.linalg.norm(v)

            def F(x, lam=lam, c=c, v=v):
                return -lam * (x - c) + v

            rate = lam
        else:
            xi = c + rng.normal(size=n) * 2.0
            S, W = rng.normal(size=(n, n)), rng.normal(size=(n, n))
            a = float(rng.uniform(-0.9, 0.9)) * lam / np.linalg.norm(W, 2)
            A = -lam * np.eye(n) + (S - S.T) / 2
            rate = lam - abs(a) * np.linalg.norm(W, 2)

            def F(x, A=A, a=a, W=W, v=v):
                return A @ x + a * np.tanh(W @ x) + v

        T = 3.0 / rate
        sol = solve_ivp(
            lambda _t, x, F=F: F(x), (0.0, T), xi, method="DOP853",
            rtol=ODE_RTOL, atol=ODE_ATOL, dense_output=True,
        )  # fmt: skip
        ts = np.linspace(0.0, T, 200)
        dist = np.linalg.norm(sol.sol(ts) - c[:, None], axis=0)
        phi = float(np.linalg.norm(F(c)))
        r = factor * tube_radii_up(float(np.linalg.norm(xi - c)), phi, rate, ts)
        ratio = float(np.max(dist / r))
        worst = max(worst, ratio)
        worst_tight = max(worst_tight, ratio) if tight else worst_tight
    return result(
        name,
        LABEL_R,
        holds=bool(worst <= 1.0 + RATIO_TOL),
        residual=worst - 1.0,
        detail=f"{n_inst} instances (1/3 tight): max ||x* - c|| / r(t) = {worst:.8f} (tight "
        f"{worst_tight:.8f})",
    )


@register("tasil.tube_gap", LABEL_G)
def check_tube_gap(ctx: Context, factor: float = 1.0) -> CheckResult:
    """gap(t) <= factor * b(t) at the grid and max gap <= factor * max b (3.10b)."""
    name = "tasil.tube_gap"
    worst = worst_tight = 0.0
    n_inst = ctx.count(45, 9)
    K = 8  # grid intervals; GRID - 1 = 2000 is a multiple of K: grid times are sample times
    for k in range(n_inst):
        tight = k % 3 == 0
        F_hat, delta, g, lam, T, x0 = _pair(ctx.rng, tight)
        ts, gap, dn = _gap_run(F_hat, delta, g, T, x0)
        step = (GRID - 1) // K
        H = [float(dn[i * step : (i + 1) * step + 1].max()) for i in range(K)]
        b = factor * time_resolved_gap_up(ts[::step], H, lam, float(np.linalg.norm(g, 2)))
        at_grid = gap[::step]
        ratio = max(
            float(np.max(np.where(b > 0, at_grid / np.where(b > 0, b, 1.0), 0.0))),
            float(gap.max() / b.max()) if b.max() > 0 else 0.0,
        )
        worst = max(worst, ratio)
        worst_tight = max(worst_tight, ratio) if tight else worst_tight
    return result(
        name,
        LABEL_G,
        holds=bool(worst <= 1.0 + RATIO_TOL),
        residual=worst - 1.0,
        detail=f"{n_inst} instances (1/3 tight), {K} intervals: max gap / b = {worst:.8f} (tight "
        f"{worst_tight:.8f})",
    )


@register("tasil.centred_form", LABEL_C)
def check_centred_form(ctx: Context, factor: float = 1.0) -> CheckResult:
    """sampled sup_B ||Delta|| <= factor * || |Delta(c)| + |[J](B)| r || (3.9)."""
    name = "tasil.centred_form"
    rng = ctx.rng
    worst = worst_tight = 0.0
    n_inst = ctx.count(45, 9)
    for k in range(n_inst):
        tight = k % 3 == 0
        n = int(rng.integers(2, 4))
        c = rng.normal(size=n)
        r = rng.uniform(0.05, 1.0, size=n)
        lo, hi = c - r, c + r
        if tight:
            u, v = rng.normal(size=n), rng.normal(size=n)
            a = float(rng.uniform(0.0, 1.0))

            def delta(X, u=u, v=v, a=a, c=c):
                return (a + (X - c) @ v)[:, None] * u[None, :]

            Jm = np.abs(np.outer(u, v))
        else:
            h = int(rng.integers(3, 9))
            W1, b1, W2 = rng.normal(size=(h, n)), rng.normal(size=h), rng.normal(size=(n, h))
            Km = 0.5 * rng.normal(size=(n, n))
            net = MLP(weights=(W1, W2), biases=(b1, np.zeros(n)))

            def delta(X, net=net, Km=Km):
                return net.apply_np(X) + X @ Km.T

            jl, jh = enclose_jacobian_centred(net, lo, hi)
            Jm = np.maximum(np.abs(jl + Km), np.abs(jh + Km))
        corners = np.array(np.meshgrid(*[[-1.0, 1.0]] * n)).reshape(n, -1).T * r + c
        X = np.concatenate([rng.uniform(lo, hi, size=(SAMPLES, n)), corners])
        sampled = float(np.max(np.linalg.norm(delta(X), axis=1)))
        bound = factor * float(np.linalg.norm(np.abs(delta(c[None, :])[0]) + Jm @ r))
        ratio = sampled / bound if bound > 0 else 0.0
        worst = max(worst, ratio)
        worst_tight = max(worst_tight, ratio) if tight else worst_tight
    return result(
        name,
        LABEL_C,
        holds=bool(worst <= 1.0 + RATIO_TOL),
        residual=worst - 1.0,
        detail=f"{n_inst} boxes (1/3 tight): max sampled sup / centred form = {worst:.8f} (tight "
        f"{worst_tight:.8f})",
    )


def _mu_w(M: np.ndarray, w: np.ndarray) -> float:
    """``mu_inf(W M W^{-1}) = max_i (M_ii + sum_{j != i} |M_ij| w_i / w_j)``."""
    Mw = M * (w[:, None] / w[None, :])
    d = np.diag(Mw)
    return float(np.max(d + np.sum(np.abs(Mw), axis=1) - np.abs(d)))


@register("tasil.box_tube", LABEL_B)
def check_box_tube(ctx: Context, factor: float = 1.0) -> CheckResult:
    """||W (x*(t, xi) - c)||_inf <= factor * r_W(t) of (3.11a) at every grid time."""
    name = "tasil.box_tube"
    rng = ctx.rng
    worst = worst_tight = 0.0
    n_inst = ctx.count(45, 9)
    for k in range(n_inst):
        tight = k % 3 == 0
        n = int(rng.integers(2, 4))
        w = rng.uniform(0.3, 3.0, size=n)
        c = rng.normal(size=n)
        lam = float(rng.uniform(0.3, 2.0))
        if tight:
            i = int(rng.integers(n))
            e = np.zeros(n)
            e[i] = 1.0
            xi = c + float(rng.uniform(0.1, 2.0)) * e
            v = float(rng.uniform(0.0, 2.0)) * e

            def F(x, lam=lam, c=c, v=v):
                return -lam * (x - c) + v

            rate = lam
        else:
            xi = c + rng.normal(size=n) * 2.0
            v = rng.normal(size=n)
            A = -lam * np.eye(n) + 0.2 * rng.normal(size=(n, n))
            V = rng.normal(size=(n, n))
            Vw = V * (w[:, None] / w[None, :])
            room = -_mu_w(A, w)
            if room <= 0.1:
                A = A - (0.1 - room + 0.1) * np.eye(n)
                room = -_mu_w(A, w)
            # the tanh term's Jacobian a diag(sech^2) V has weighted inf-norm <= |a| ||W V W^-1||
            a = float(rng.uniform(-0.9, 0.9)) * room / float(np.max(np.sum(np.abs(Vw), axis=1)))
            rate = room - abs(a) * float(np.max(np.sum(np.abs(Vw), axis=1)))

            def F(x, A=A, a=a, V=V, v=v):
                return A @ x + a * np.tanh(V @ x) + v

        T = 3.0 / rate
        sol = solve_ivp(
            lambda _t, x, F=F: F(x), (0.0, T), xi, method="DOP853",
            rtol=ODE_RTOL, atol=ODE_ATOL, dense_output=True,
        )  # fmt: skip
        ts = np.linspace(0.0, T, 200)
        dist = np.max(np.abs(sol.sol(ts) - c[:, None]) * w[:, None], axis=0)
        R0 = float(np.max(np.abs(xi - c) * w))
        phi = float(np.max(np.abs(F(c)) * w))
        r = factor * tube_radii_up(R0, phi, rate, ts)
        ratio = float(np.max(dist / r))
        worst = max(worst, ratio)
        worst_tight = max(worst_tight, ratio) if tight else worst_tight
    return result(
        name,
        LABEL_B,
        holds=bool(worst <= 1.0 + RATIO_TOL),
        residual=worst - 1.0,
        detail=f"{n_inst} instances (1/3 tight): max ||W (x* - c)||_inf / r_W(t) = {worst:.8f} "
        f"(tight {worst_tight:.8f})",
    )
