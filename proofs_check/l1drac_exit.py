"""Box-only learned loops: the extension and the exit bound (docs/math/l1drac.md section 11).

* ``l1drac_exit.extension_rate``: Proposition 11.1. Random planar fields
  ``F(x) = A (x - x_e) + c |x|^2 e`` with a non-normal ``A``, contracting on a box only (sound
  closed-form ``lambda``, ``L``, ``M``); the extension ``F~(x) = F(Px) - k (x - Px)`` with ``k``
  of (11.1a) (``drip_cert.bounds.l1drac.exit``) is searched for pairs violating the global rate
  ``lambda'``, the Lipschitz bound ``L + k`` or the growth bound, by random pairs around the box
  and a local refinement. ``k_scale < 1`` claims a smaller slope (the tests show it fails).
* ``l1drac_exit.ou_grid_union``: Lemma 11.4 on the Ornstein-Uhlenbeck process
  ``de = -lam e dt + sig dW``, ``e_0 = 0``, whose moments are exact
  (``E e_t^{2p} <= (2p-1)!! (sig^2/(2 lam))^p``). The simulated frequency of
  ``sup_{t <= T} |e_t| >= r`` must not exceed the bound (11.4). ``union=False`` claims the
  fixed-time Markov bound ``(rho/r)^q`` for the supremum (no grid union): it fails on a long
  horizon.
* ``l1drac_exit.box_only_sde_1d``: Propositions 11.1-11.2 and Lemmas 11.3-11.4 together on the
  box-only drift ``x^3 - x`` (rate 1/4 on ``[-1/2, 1/2]`` only) with additive noise: the
  frequency of exits of the *true* process from the box must not exceed the bound computed for
  the extended process (moment radius by contraction.md Proposition 6.6).

Exits are monitored on the simulation grid with the Brownian-bridge crossing probability
between grid points added (``exp(-2 (r - x)(r - y) / (sig^2 dt))`` per level), which removes
most of the under-count of a discretely monitored supremum.
"""

from __future__ import annotations

import math

import numpy as np
from scipy.optimize import minimize

from proofs_check._core import CheckResult, Context, register, result

LABEL = "docs/math/l1drac.md section 11 (box-only loops: extension and exit probability)"
RATE_TOL = 1e-9  # relative float error of (x-y).(F~x - F~y)/|x-y|^2 at O(1) values
FREQ_Z = 4.0  # binomial standard errors allowed between the simulated frequency and the bound
P_MAX = 16  # largest moment order p tried for the bound (q = 2p)


def _double_factorial_odd(p: int) -> int:
    """``(2p - 1)!! = 1 * 3 * ... * (2p - 1)``."""
    return math.prod(range(1, 2 * p, 2))


def _planar(rng: np.random.Generator):
    a = float(rng.uniform(1.0, 2.0))
    w = float(rng.choice([-1.0, 1.0]) * rng.uniform(0.8, 1.6) * a)
    A = np.array([[-a, w], [0.0, -a]])
    if rng.random() < 0.5:
        A = A.T
    mu_a = float(np.linalg.eigvalsh(0.5 * (A + A.T)).max())
    h = float(rng.uniform(0.5, 1.0))
    c = float(rng.uniform(0.1, 0.4)) * (-mu_a) / (2.0 * h * math.sqrt(2.0))
    e = rng.normal(size=2)
    e /= np.linalg.norm(e)
    xe = rng.uniform(-0.1, 0.1, size=2)
    rmax = h * math.sqrt(2.0)
    lam = -(mu_a + 2.0 * c * rmax)  # mu_2(A + 2c e x^T) <= mu_2(A) + 2c|x|
    norm_a = float(np.linalg.norm(A, 2))
    lip = norm_a + 2.0 * c * rmax
    sup_f = norm_a * (rmax + float(np.linalg.norm(xe))) + c * rmax**2

    def F(x: np.ndarray) -> np.ndarray:  # x: (..., 2)
        return (x - xe) @ A.T + c * np.sum(x * x, axis=-1, keepdims=True) * e

    return F, h, lam, lip, sup_f


@register("l1drac_exit.extension_rate", LABEL)
def check_extension_rate(ctx: Context, k_scale: float = 1.0) -> CheckResult:
    """Proposition 11.1: the extension contracts at lambda' everywhere, with L + k and Delta_f~."""
    from drip_cert.bounds.l1drac.exit import extension_constants

    name = "l1drac_exit.extension_rate"
    rng = ctx.rng
    worst_rate = -np.inf
    worst_other = -np.inf
    n_pairs = ctx.count(20000, 4000)
    for _ in range(ctx.count(12, 4)):
        F, h, lam, lip, sup_f = _planar(rng)
        lam_p = float(rng.uniform(0.3, 0.7)) * lam
        k0, lf0, df = extension_constants(lam, lam_p, lip, sup_f, 0.0)
        k = k_scale * k0

        def Ft(x: np.ndarray, F=F, h=h, k=k) -> np.ndarray:
            px = np.clip(x, -h, h)
            return F(px) - k * (x - px)

        def rate(z: np.ndarray, Ft=Ft) -> np.ndarray:
            x, y = z[..., :2], z[..., 2:]
            v = x - y
            nv = np.sum(v * v, axis=-1)
            return np.sum(v * (Ft(x) - Ft(y)), axis=-1) / np.maximum(nv, 1e-300)

        z = rng.uniform(-3 * h, 3 * h, size=(n_pairs, 4))
        r = rate(z)
        ratio = (r + lam_p) / lam_p
        for i in np.argsort(ratio)[-5:]:
            res = minimize(lambda zz, rate=rate: -rate(zz[None, :])[0], z[i], method="Nelder-Mead")
            ratio = np.append(ratio, (rate(res.x[None, :])[0] + lam_p) / lam_p)
        worst_rate = max(worst_rate, float(ratio.max()))
        x, y = z[:, :2], z[:, 2:]
        dl = np.linalg.norm(Ft(x) - Ft(y), axis=-1) / np.linalg.norm(x - y, axis=-1)
        lf = lip + k  # (ii) for the slope actually used
        gr = np.linalg.norm(Ft(x), axis=-1) / np.sqrt(1.0 + np.sum(x * x, axis=-1))
        dfk = math.sqrt(sup_f**2 + k**2)  # (iii) with d0 = 0 (the origin is in the box)
        worst_other = max(worst_other, float((dl / lf - 1).max()), float((gr / dfk - 1).max()))
        assert lf0 >= lip + k0 and df >= math.sqrt(sup_f**2 + k0**2)
    holds = worst_rate <= RATE_TOL and worst_other <= RATE_TOL
    return result(
        name,
        LABEL,
        holds=holds,
        residual=max(worst_rate, worst_other),
        detail=(
            f"k_scale={k_scale}: worst (rate + lambda')/lambda' = {worst_rate:.3e}, worst "
            f"Lipschitz/growth excess {worst_other:.3e} (<= {RATE_TOL} holds)"
        ),
    )


def _exit_frequency(
    drift, x0: np.ndarray, sig: float, T: float, n_steps: int, lo: float, hi: float, rng
) -> float:
    """Mean over paths of P(exit of [lo, hi] before T), Euler-Maruyama + bridge crossings."""
    dt = T / n_steps
    x = x0.astype(float).copy()
    survive = np.ones_like(x)
    out = np.zeros(x.shape, dtype=bool)
    for _ in range(n_steps):
        y = x + drift(x) * dt + sig * math.sqrt(dt) * rng.normal(size=x.shape)
        out |= (y <= lo) | (y >= hi)
        inside = ~out
        du = np.clip((hi - x) * (hi - y), 0.0, None)
        dl = np.clip((x - lo) * (y - lo), 0.0, None)
        p = np.exp(-2 * du / (sig**2 * dt)) + np.exp(-2 * dl / (sig**2 * dt))
        survive = np.where(inside, survive * np.clip(1.0 - p, 0.0, 1.0), 0.0)
        x = np.where(inside, y, x)
    return float(np.mean(1.0 - survive))


def _best_bound(rho_of_p, b_of_rho, sig: float, room: float, T: float, union: bool) -> float:
    from drip_cert.bounds.l1drac.exit import grid_exit_bound

    best = math.inf
    for p in range(1, P_MAX + 1):
        rho = rho_of_p(p)
        if union:
            d = grid_exit_bound(rho=rho, b=b_of_rho(rho), s=sig, q=2 * p, room=room, horizon=T)
            best = min(best, d.delta)
        else:
            best = min(best, (rho / room) ** (2 * p))
    return best


def _compare(name: str, rows: list[tuple[str, float, float, int]], union: bool) -> CheckResult:
    worst = -np.inf
    parts = []
    for tag, freq, bound, n in rows:
        se = math.sqrt(max(freq * (1 - freq), 1.0 / n) / n)
        worst = max(worst, freq - bound - FREQ_Z * se)
        parts.append(f"{tag}: freq {freq:.4f} bound {bound:.4g}")
    return result(
        name,
        LABEL,
        holds=worst <= 0.0,
        residual=worst,
        detail=f"union={union}; " + "; ".join(parts),
    )


@register("l1drac_exit.ou_grid_union", LABEL)
def check_ou_grid_union(ctx: Context, union: bool = True) -> CheckResult:
    """Lemma 11.4: the simulated frequency of sup|e| >= r stays below (11.4) for OU."""
    name = "l1drac_exit.ou_grid_union"
    rng = ctx.rng
    n_paths = ctx.count(4000, 1500)
    rows = []
    regimes = ((1.0, 1.0, 20.0, 2.0), (1.0, 1.0, 1.0, 5.0), (2.0, 0.5, 1.0, 6.0))
    for lam, sig, T, r_over_s in regimes:
        s = sig / math.sqrt(2 * lam)
        room = r_over_s * s

        def rho_of_p(p: int, s=s) -> float:
            return s * _double_factorial_odd(p) ** (1.0 / (2 * p))

        bound = _best_bound(rho_of_p, lambda rho, lam=lam: lam * rho, sig, room, T, union)
        freq = _exit_frequency(
            lambda x, lam=lam: -lam * x,
            np.zeros(n_paths),
            sig,
            T,
            ctx.count(2000, 800),
            -room,
            room,
            rng,
        )
        rows.append((f"lam={lam} sig={sig} T={T} r={room:.3g}", freq, bound, n_paths))
    return _compare(name, rows, union)


@register("l1drac_exit.box_only_sde_1d", LABEL)
def check_box_only_sde_1d(ctx: Context) -> CheckResult:
    """Section 11 end to end on dx = (x^3 - x) dt + sig dW, rate 1/4 on [-1/2, 1/2] only."""
    name = "l1drac_exit.box_only_sde_1d"
    rng = ctx.rng
    n_paths = ctx.count(4000, 1500)
    lam, lip, half, support = 0.25, 1.0, 0.5, 0.2  # mu = 3x^2 - 1 <= -1/4, |3x^2 - 1| <= 1
    k = lam  # one dimension: k = lambda' = lambda (Proposition 11.1)
    lf = lip + k
    room = half - support  # |x'| is non-increasing (x F(x) <= 0 on |x| <= 1): S' = [-0.2, 0.2]
    T = 4.0
    rows = []
    for sig in (0.02, 0.03, 0.2):

        def rho_of_p(p: int, sig=sig) -> float:  # contraction.md Proposition 6.6, a0 = sig^2
            return math.sqrt((2 * p - 1) * sig**2 / (2 * lam))

        bound = _best_bound(rho_of_p, lambda rho: lf * rho, sig, room, T, True)
        x0 = rng.uniform(-support, support, size=n_paths)
        freq = _exit_frequency(
            lambda x: x**3 - x, x0, sig, T, ctx.count(2000, 800), -half, half, rng
        )
        rows.append((f"sig={sig}", freq, bound, n_paths))
    return _compare(name, rows, True)
