"""The moment bound of a contracting SDE (docs/math/contraction.md Proposition 6.5; L1-DRAC
Assumption 3 with a known diffusion; ``drip_cert.analysis.growth.closed_loop.sde_moment_bound``).

The proposition: if ``(x - y)^T (F(t, x) - F(t, y)) <= -lambda ||x - y||^2``, ``||F(t, 0)|| <= b``,
``||p(t, x)||_F^2 <= a0 + a1 ||x|| + a2 ||x||^2`` and ``||X_0|| <= r0``, then with
``k = (2q - 1)/2``, ``kappa = lambda - k a2 > 0``, ``B = b + k a1``, ``A = k a0``

    sup_t ||X_t||_{L_2q} <= max(r0, u*),  u* = B / (2 kappa) + sqrt((B / (2 kappa))^2 + A / kappa).

Checked two ways: against the closed-form moments of the Ornstein-Uhlenbeck process (the bound
must cover them, and is attained for ``q = 1``: a bound 1 % smaller fails), and against a
seeded Euler-Maruyama simulation of a nonlinear contracting SDE with a state-dependent diffusion
(the lower confidence limit of the empirical moment must stay below the bound; the deterministic
bound of Proposition 6.4, which ignores the diffusion, fails). The formula is re-implemented here
in plain floats; drip-cert's outward-rounded implementation is compared with it.
"""

from __future__ import annotations

import math

import numpy as np

from proofs_check._core import CheckResult, Context, register, result

LABEL = "docs/math/contraction.md Prop. 6.5 (moments of the contracting nominal SDE)"
OU_REL_TOL = 1e-12  # closed-form Gaussian moments vs a closed-form bound: rounding only
IMPL_REL_TOL = 1e-12  # drip-cert rounds each operation outward: a few ulps above, never below
OU_TIGHT_FACTOR = math.sqrt(math.e) * (1.0 + 1e-12)
"""bound / OU moment <= sqrt(2q - 1) / ((2q - 1)!!)^{1/2q} < sqrt(e) (Stirling) when the
stationary part dominates; the largest ratio over all instances must stay below it."""
SIM_Z = 3.29  # one-sided 99.95 % per comparison; Bonferroni over 80 (40 times, q = 1, 2): >= 96 %
SIM_DT = 2e-3  # Euler-Maruyama step: weak error O(dt) ~ 1e-3 relative, far below the margins tested
SIM_T = 4.0  # horizon: 6 time constants 1/lambda, the moments have reached stationarity


def moment_bound(r0, b, lam, q, a0, a1=0.0, a2=0.0) -> float:
    """(6.5b) in plain floats (independent of drip-cert)."""
    k = (2 * q - 1) / 2
    kappa = lam - k * a2
    if kappa <= 0:
        return math.inf
    B, A = b + k * a1, k * a0
    h = B / (2 * kappa)
    return max(r0, h + math.sqrt(h * h + A / kappa))


def ou_moment(x0: float, lam: float, sigma: float, q: int, t) -> np.ndarray:
    """``E X_t^{2q}`` for the 1-D OU process ``dX = -lam X dt + sigma dW``, ``X_0 = x0``: the
    Gaussian ``N(m, v)``, ``m = x0 e^{-lam t}``, ``v = sigma^2 (1 - e^{-2 lam t}) / (2 lam)``,
    has ``E X^{2q} = sum_j C(2q, 2j) m^{2q - 2j} v^j (2j - 1)!!``."""
    t = np.asarray(t, dtype=float)
    m = x0 * np.exp(-lam * t)
    v = sigma**2 * (-np.expm1(-2 * lam * t)) / (2 * lam)
    return sum(
        math.comb(2 * q, 2 * j) * m ** (2 * q - 2 * j) * v**j * math.prod(range(1, 2 * j, 2))
        for j in range(q + 1)
    )


@register("sde.ou_closed_form", LABEL + ", OU closed form")
def check_ou(ctx: Context, factor: float = 1.0, ignore_diffusion: bool = False) -> CheckResult:
    """The bound covers ``sup_t (E|X_t|^{2q})^{1/2q}`` of the OU process, within
    :data:`OU_TIGHT_FACTOR`, attained for ``q = 1``; drip-cert's implementation agrees.

    ``factor`` multiplies the bound and ``ignore_diffusion`` sets ``a0 = 0`` (the deterministic
    bound): the tests use them to show the check fails on a wrong formula.
    """
    from drip_cert.analysis.growth.closed_loop import sde_moment_bound

    name = "sde.ou_closed_form"
    rng = ctx.rng
    ts = np.linspace(0.0, 1.0, 4001)
    worst = -np.inf  # max (true / bound - 1): positive is a violation
    tight = 0.0  # max bound / true over the instances
    impl = 0.0  # max |drip-cert / here - 1|, and drip-cert below the formula counts as inf
    n_inst = ctx.count(400, 60)
    for i in range(n_inst):
        lam = float(rng.uniform(0.2, 5.0))
        sigma = float(rng.uniform(0.05, 3.0))
        q = int(rng.integers(1, 6))
        s = sigma / math.sqrt(2 * lam)
        # half the instances start inside the stationary spread, half far outside it
        x0 = float(
            rng.uniform(-s, s) if i % 2 == 0 else rng.choice([-1, 1]) * rng.uniform(s, 5 * s)
        )
        true = float(np.max(ou_moment(x0, lam, sigma, q, ts * 12.0 / lam) ** (1 / (2 * q))))
        a0 = 0.0 if ignore_diffusion else sigma**2
        bound = factor * moment_bound(abs(x0), 0.0, lam, q, a0)
        worst = max(worst, true / bound - 1.0)
        tight = max(tight, bound / true)
        dc = sde_moment_bound(abs(x0), 0.0, lam, q, sigma**2)
        ref = moment_bound(abs(x0), 0.0, lam, q, sigma**2)
        impl = max(impl, math.inf if dc < ref else dc / ref - 1.0)
    holds = worst <= OU_REL_TOL and tight <= OU_TIGHT_FACTOR and impl <= IMPL_REL_TOL
    return result(
        name,
        LABEL + ", OU closed form",
        holds=holds,
        residual=worst,
        detail=f"{n_inst} OU instances (lambda, sigma, x0, q <= 5): max true/bound - 1 = "
        f"{worst:.3g}, max bound/true = {tight:.4g} (<= sqrt(e)), drip-cert vs formula "
        f"{impl:.3g}",
    )


def _nonlinear(x: np.ndarray) -> np.ndarray:
    """``F(x) = A x + 0.5 sin(x) + c``: ``mu_2(A) = -2`` (skew coupling), ``|0.5 cos| <= 0.5``,
    so the rate is ``lambda = 1.5`` on all of ``R^2``; ``F(0) = c``."""
    A = np.array([[-2.0, 1.0], [-1.0, -2.0]])
    return x @ A.T + 0.5 * np.sin(x) + np.array([0.3, -0.2])


def _diffusion(x: np.ndarray) -> np.ndarray:
    """``p(x) = diag(0.5 + 0.3 cos x1, 0.4)``: ``||p||_F^2 <= 0.8^2 + 0.4^2 = 0.8``."""
    out = np.zeros((x.shape[0], 2, 2))
    out[:, 0, 0] = 0.5 + 0.3 * np.cos(x[:, 0])
    out[:, 1, 1] = 0.4
    return out


NL_LAM, NL_B, NL_A0 = 1.5, math.hypot(0.3, 0.2), 0.8
NL_BOX = 0.1  #: X_0 uniform on [-0.1, 0.1]^2, so r0 = 0.1 sqrt(2)


@register("sde.simulated_nonlinear", LABEL + ", simulated nonlinear SDE")
def check_simulated(ctx: Context, ignore_diffusion: bool = False) -> CheckResult:
    """Seeded Euler-Maruyama paths of ``dX = F(X) dt + p(X) dW`` (:func:`_nonlinear`,
    :func:`_diffusion`): at every recorded time the lower confidence limit (z = :data:`SIM_Z`)
    of ``E||X_t||^{2q}`` stays below the bound's ``2q``-th power, ``q = 1, 2``.
    ``ignore_diffusion`` uses ``a0 = 0`` (the bound of an ODE) and must fail."""
    name = "sde.simulated_nonlinear"
    rng = ctx.rng
    n_paths = ctx.count(20_000, 8_000)
    n_steps = int(round(SIM_T / SIM_DT))
    record = n_steps // 40
    x = rng.uniform(-NL_BOX, NL_BOX, size=(n_paths, 2))
    r0 = NL_BOX * math.sqrt(2.0)
    a0 = 0.0 if ignore_diffusion else NL_A0
    bounds = {q: moment_bound(r0, NL_B, NL_LAM, q, a0) for q in (1, 2)}
    worst = -np.inf  # max over times and q of (lower CL / bound^{2q} - 1)
    ratio = 0.0  # max of (mean moment)^{1/2q} / bound
    sq = math.sqrt(SIM_DT)
    for j in range(1, n_steps + 1):
        dw = sq * rng.standard_normal(size=(n_paths, 2))
        x = x + SIM_DT * _nonlinear(x) + np.einsum("bij,bj->bi", _diffusion(x), dw)
        if j % record:
            continue
        r2 = np.sum(x * x, axis=1)
        for q, bound in bounds.items():
            v = r2**q
            mean = float(np.mean(v))
            lcl = mean - SIM_Z * float(np.std(v, ddof=1)) / math.sqrt(n_paths)
            worst = max(worst, lcl / bound ** (2 * q) - 1.0)
            ratio = max(ratio, mean ** (1 / (2 * q)) / bound)
    return result(
        name,
        LABEL + ", simulated nonlinear SDE",
        holds=worst <= 0.0,
        residual=worst,
        detail=f"{n_paths} paths, dt = {SIM_DT}, T = {SIM_T}, q = 1, 2: max (lower "
        f"{SIM_Z}-sigma confidence limit of E||X_t||^2q) / bound^2q - 1 = {worst:.3g}; "
        f"max empirical L_2q norm / bound = {ratio:.3f} (bounds "
        + ", ".join(f"q={q}: {b:.4g}" for q, b in bounds.items())
        + ")",
    )
