"""The imitation-gap lemma that drip-cert uses for DRIP Theorem "TaSIL"
(docs/math/tasil.md Sec. 3.1).

Lemma (p = 1, linear delta-ISS gain gamma_0, eta = R = infinity here): with
``h0 = max_t ||Delta(x*_t)||``, ``h1 = max_t ||d Delta(x*_t)||_op``, ``L`` the Lipschitz
constant of ``d Delta``,

* basic: if ``gamma0 h1 <= 1/4`` and ``gamma0^2 L h0 <= 1/4`` then
  ``max_t ||x_hat_t - x*_t|| <= 2 gamma0 h0`` and ``max_t ||Delta(x_hat_t)|| <= 2 h0``;
* sharp: if ``b = gamma0 h1 < 1`` and ``(1-b)^2 >= 2 L gamma0^2 h0`` then the gap is at most
  ``gamma0 eps*`` with ``eps* = ((1-b) - sqrt((1-b)^2 - 2 L gamma0^2 h0)) / (L gamma0^2)``.

Falsification on discrete systems ``x_{t+1} = F(x_t) + B Delta(x_t)`` with a contraction
``F(x) = A x + c sin(W x)`` (Lipschitz rho < 1, so gamma0 = ||B||_2 / (1 - rho) is a valid
linear gain) and TaSIL's ``dummy2`` system (``F = a x``, ``B = c(1-a) I``, gamma0 = c), and
``Delta(x) = a0 + K x + s * sin(V x)`` (``L = max|s| ||V||_2^2``), scaled up to the lemma's
conditions; then an adversarial search (Nelder-Mead over the instance parameters) maximising
gap / bound on the boundary of the conditions.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np
from scipy.optimize import minimize

from proofs_check._core import CheckResult, Context, register, result

LABEL = "DRIP Thm. TaSIL (thm:TaSIL) via docs/math/tasil.md Lemma 3.1"

RATIO_TOL = 1e-9  # gap/bound is computed from <= 60 steps of O(1) arithmetic: rounding only


@dataclass(frozen=True)
class GapInstance:
    """A learner/expert pair on a contracting discrete system (see module docstring)."""

    A: np.ndarray
    c: float
    W: np.ndarray
    B: np.ndarray
    a0: np.ndarray
    K: np.ndarray
    s: np.ndarray
    V: np.ndarray
    gamma0: float
    L: float

    def F(self, x: np.ndarray) -> np.ndarray:
        return self.A @ x + self.c * np.sin(self.W @ x)

    def delta(self, x: np.ndarray) -> np.ndarray:
        return self.a0 + self.K @ x + self.s * np.sin(self.V @ x)

    def ddelta(self, x: np.ndarray) -> np.ndarray:
        return self.K + (self.s * np.cos(self.V @ x))[:, None] * self.V

    def scaled(self, k: float) -> GapInstance:
        """Delta multiplied by k (h0, h1, L all scale by k)."""
        return GapInstance(
            self.A,
            self.c,
            self.W,
            self.B,
            k * self.a0,
            k * self.K,
            k * self.s,
            self.V,
            self.gamma0,
            k * self.L,
        )


def rollout(inst: GapInstance, x0: np.ndarray, T: int):
    """Expert trajectory and learner error; returns (gap, h0, h1, max ||Delta(x_hat)||).

    The learner is tracked through its error ``e = x_hat - x*`` with the increment of ``F``
    written without cancellation (``sin p - sin q = 2 cos((p+q)/2) sin((p-q)/2)``), so that
    a tiny gap next to a large state is not lost to rounding.
    """
    xs = x0.copy()
    e = np.zeros_like(x0)
    h0 = h1 = gap = dmax = 0.0
    for _ in range(T):
        h0 = max(h0, float(np.linalg.norm(inst.delta(xs))))
        h1 = max(h1, float(np.linalg.norm(inst.ddelta(xs), 2)))
        dh = inst.delta(xs + e)
        dmax = max(dmax, float(np.linalg.norm(dh)))
        we = inst.W @ e
        dF = inst.A @ e + 2 * inst.c * np.cos(inst.W @ xs + we / 2) * np.sin(we / 2)
        e = dF + inst.B @ dh
        xs = inst.F(xs)
        gap = max(gap, float(np.linalg.norm(e)))
    return gap, h0, h1, dmax


def sharp_eps(gamma0: float, h0: float, h1: float, L: float) -> float:
    """``eps*`` of the sharp lemma (nan when its conditions fail).

    Evaluated as ``2 h0 / ((1-b) + sqrt((1-b)^2 - 2 L gamma0^2 h0))``, the same number as the
    lemma's ``((1-b) - sqrt(.)) / (L gamma0^2)`` without its cancellation for small ``L``.
    """
    b = gamma0 * h1
    disc = (1 - b) ** 2 - 2 * L * gamma0**2 * h0
    if b >= 1 or disc < 0:
        return float("nan")
    return float(2 * h0 / ((1 - b) + math.sqrt(disc)))


def random_instance(rng: np.random.Generator, *, dummy2: bool) -> GapInstance:
    """Random contracting system and error function (unscaled)."""
    n = int(rng.integers(1, 5))
    if dummy2:  # TaSIL reference system, r = 1: x+ = a x + c (1 - a) Delta
        a, cc = 0.95, float(rng.uniform(1.0, 6.0))
        A, c, W, B, m = a * np.eye(n), 0.0, np.zeros((n, n)), cc * (1 - a) * np.eye(n), n
        gamma0 = cc
    else:
        m = int(rng.integers(1, n + 1))
        A = rng.normal(size=(n, n))
        W = rng.normal(size=(n, n))
        c = float(rng.uniform(-1, 1))
        rho_target = float(rng.uniform(0.3, 0.97))
        scale = rho_target / (np.linalg.norm(A, 2) + abs(c) * np.linalg.norm(W, 2))
        A, c = A * scale, c * scale
        rho = np.linalg.norm(A, 2) + abs(c) * np.linalg.norm(W, 2)
        B = rng.normal(size=(n, m))
        gamma0 = float(np.linalg.norm(B, 2) / (1 - rho))
    V = rng.normal(size=(m, n)) * rng.uniform(0.2, 2.0)
    s = rng.normal(size=m) * float(rng.choice([0.0, 1.0]))
    L = float(np.max(np.abs(s)) * np.linalg.norm(V, 2) ** 2) if s.any() else 0.0
    return GapInstance(
        A=A,
        c=c,
        W=W,
        B=B,
        a0=rng.normal(size=m),
        K=rng.normal(size=(m, n)),
        s=s,
        V=V,
        gamma0=gamma0,
        L=L,
    )


def _ratios(inst: GapInstance, x0: np.ndarray, T: int, u: float, sharp_factor: float):
    """Scale Delta to a fraction u of the conditions' boundary; return (basic, sharp) ratios."""
    _, h0, h1, _ = rollout(inst, x0, T)
    g = inst.gamma0
    if h0 == 0 and h1 == 0:
        return 0.0, 0.0
    # basic: k g h1 <= 1/4 and k^2 g^2 L h0 <= 1/4
    kb = min(
        1 / (4 * g * h1) if h1 > 0 else np.inf,
        1 / (2 * g * np.sqrt(inst.L * h0)) if inst.L * h0 > 0 else np.inf,
    )
    # sharp: k b <= 1 - k sqrt(2 L g^2 h0)
    ks = 1.0 / (g * h1 + np.sqrt(2 * inst.L * g**2 * h0))
    out = []
    for k, sharp in ((kb, False), (ks, True)):
        if not np.isfinite(k):
            k = 1.0 / max(h0, 1e-300)
        sc = inst.scaled(u * k)
        gap, h0s, h1s, dmax = rollout(sc, x0, T)
        if sharp:
            eps = sharp_eps(g, h0s, h1s, sc.L)
            bound = sharp_factor * g * eps
            r = max(gap / bound, dmax / eps) if bound > 0 else 0.0
        else:
            r = max(gap / (2 * g * h0s), dmax / (2 * h0s)) if h0s > 0 else 0.0
        out.append(float(r))
    return out[0], out[1]


@register("tasil.gap_lemma_random", LABEL + ", random instances")
def check_gap_random(ctx: Context, sharp_factor: float = 1.0) -> CheckResult:
    """Gap <= 2 gamma0 h0 and <= gamma0 eps* on random instances inside the conditions."""
    name = "tasil.gap_lemma_random"
    rng = ctx.rng
    n_inst = ctx.count(1500, 150)
    worst_b = worst_s = 0.0
    for k in range(n_inst):
        inst = random_instance(rng, dummy2=(k % 3 == 0))
        x0 = rng.normal(size=inst.A.shape[0]) * rng.uniform(0, 3)
        u = float(rng.choice([1.0, rng.uniform(0.3, 1.0)]))
        rb, rs = _ratios(inst, x0, int(rng.integers(5, 61)), u, sharp_factor)
        worst_b, worst_s = max(worst_b, rb), max(worst_s, rs)
    ok = worst_b <= 1 + RATIO_TOL and worst_s <= 1 + RATIO_TOL
    return result(
        name,
        LABEL + ", random instances",
        holds=bool(ok),
        residual=max(worst_b, worst_s) - 1.0,
        detail=(
            f"{n_inst} instances (1/3 dummy2), Delta scaled to [0.3,1] x the conditions' "
            f"boundary: max gap/(2 g0 h0) = {worst_b:.4f}, max gap/(g0 eps*) = {worst_s:.4f}"
        ),
    )


def _scalar_ratio(z, T: int, sharp_factor: float) -> float:
    """gap / (gamma0 eps*) for the scalar instance x+ = a x + beta Delta(x), pure Python.

    ``Delta(x) = a0 + k x + s sin(x)`` is scaled onto the boundary of the sharp conditions;
    ``gamma0 = beta / (1 - a)`` is the exact linear gain of the scalar contraction.
    """
    a = 0.995 / (1.0 + math.exp(-z[0]))
    beta = math.exp(max(min(z[1], 5.0), -5.0))
    a0, k, s, x0 = z[2], z[3], z[4], z[5]
    g0 = beta / (1.0 - a)
    xs, h0, h1 = x0, 0.0, 0.0
    for _ in range(T):
        h0 = max(h0, abs(a0 + k * xs + s * math.sin(xs)))
        h1 = max(h1, abs(k + s * math.cos(xs)))
        xs = a * xs
    L = abs(s)
    if h0 == 0.0:
        return 0.0
    u = 1.0 / (1.0 + math.exp(-z[6]))  # fraction of the conditions' boundary
    kk = u / (g0 * h1 + math.sqrt(2.0 * L * g0**2 * h0))
    a0, k, s, L, h0, h1 = kk * a0, kk * k, kk * s, kk * L, kk * h0, kk * h1
    eps = sharp_eps(g0, h0, h1, L)
    if not eps > 0:
        return 0.0
    xs, e, gap, dmax = x0, 0.0, 0.0, 0.0  # track the error e = x_hat - x* (no cancellation)
    for _ in range(T):
        dh = a0 + k * (xs + e) + s * math.sin(xs + e)
        dmax = max(dmax, abs(dh))
        e = a * e + beta * dh
        xs = a * xs
        gap = max(gap, abs(e))
    return max(gap / (sharp_factor * g0 * eps), dmax / eps)


@register("tasil.gap_lemma_adversarial", LABEL + ", adversarial search")
def check_gap_adversarial(ctx: Context, sharp_factor: float = 1.0) -> CheckResult:
    """Nelder-Mead maximisation of gap / sharp bound over scalar instance parameters.

    Parameters ``(a, beta, a0, k, s, x0, u)``, Delta scaled to the fraction ``u`` of the
    boundary of the sharp conditions.
    One start is the known near-worst case (constant error, positive feedback, x0 = 0), the
    others random; ``sharp_factor`` < 1 (a wrong constant) must make the check fail.
    """
    name = "tasil.gap_lemma_adversarial"
    rng = ctx.rng
    T = 200
    n_starts = ctx.count(16, 4)
    best = 0.0
    starts = [np.array([4.0, -2.0, 1.0, 0.5, 0.0, 0.0, 3.0])]
    starts += [rng.normal(size=7) * [2, 1, 1, 1, 1, 2, 2] for _ in range(n_starts - 1)]
    for z0 in starts:
        r = minimize(
            lambda z: -_scalar_ratio(z, T, sharp_factor),
            z0,
            method="Nelder-Mead",
            options={"maxiter": 800, "xatol": 1e-9, "fatol": 1e-12},
        )
        best = max(best, -float(r.fun))
    return result(
        name,
        LABEL + ", adversarial search",
        holds=bool(best <= 1 + RATIO_TOL),
        residual=best - 1.0,
        detail=f"{n_starts} Nelder-Mead starts, T={T}: max gap/(gamma0 eps*) found = {best:.6f}",
    )
