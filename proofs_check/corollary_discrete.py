"""DRIP Corollary "DiscreteDeltaISS" (drip_paper.tex ~l.866): sampled trajectories.

The corollary (stated without proof) applies Prop. 1 to inputs that are piecewise constant on
the uniform partition ``{0, t_1, ..., t_k = T}`` and evaluates the bound at the partition
points with ``max_i ||v_{t_i}||``. Prop. 1 is stated for continuous inputs; the comparison
argument holds verbatim for piecewise-continuous ones (Caratheodory solutions), which is what
this check exercises: exact flows between partition points (solve_ivp restarted at every
``t_i``), the bound checked at every partition point, for admissible theta and for the
tighter comparison bound.
"""

from __future__ import annotations

import numpy as np
from scipy.integrate import solve_ivp

from proofs_check._core import CheckResult, Context, register, result
from proofs_check._systems import random_contracting_system
from proofs_check.delta_iss import ODE_ATOL, ODE_RTOL, paper_bound, tight_bound

LABEL = "DRIP Cor. 1 (corol:DiscreteDeltaISS)"

BOUND_REL_TOL = 1e-7  # restarted DOP853 at rtol 1e-10 over <= 40 intervals: error << 1e-7


def sampled_gap(sys_, xi1, xi2, v_samples, T):
    """||y_{t_i} - x_{t_i}|| at the partition points, y driven by the piecewise-constant v."""
    n = xi1.size
    k = v_samples.shape[0]
    ts = np.linspace(0.0, T, k + 1)
    zero = np.zeros(sys_.g.shape[1])
    z = np.concatenate([xi1, xi2])
    gaps = [float(np.linalg.norm(xi1 - xi2))]
    for i in range(k):
        vi = v_samples[i]

        def rhs(t, z, vi=vi):
            return np.concatenate([sys_.drift(z[:n], vi), sys_.drift(z[n:], zero)])

        sol = solve_ivp(rhs, (ts[i], ts[i + 1]), z, method="DOP853", rtol=ODE_RTOL, atol=ODE_ATOL)
        if not sol.success:
            raise RuntimeError(f"solve_ivp failed: {sol.message}")
        z = sol.y[:, -1]
        gaps.append(float(np.linalg.norm(z[:n] - z[n:])))
    return ts, np.array(gaps)


@register("iss.corollary_discrete", LABEL + ", sampled trajectories")
def check_corollary(ctx: Context) -> CheckResult:
    """The corollary's bound at every partition point, piecewise-constant perturbations."""
    name = "iss.corollary_discrete"
    rng = ctx.rng
    n_sys = ctx.count(80, 12)
    worst = -np.inf
    tightest = 0.0
    for j in range(n_sys):
        sys_ = random_contracting_system(rng, linear=(j % 2 == 0))
        n, m = sys_.g.shape
        lam = sys_.lam
        k = int(rng.integers(3, 41))
        T = float(rng.uniform(1.0, 10.0)) / lam
        _, s, Vt = np.linalg.svd(sys_.g)
        if j % 4 == 0:  # the same worst-case direction on every interval: near-tight case
            v_samples = np.tile(Vt[0] * rng.uniform(0.1, 3.0), (k, 1))
        else:
            v_samples = rng.normal(size=(k, m)) * rng.uniform(0.1, 3.0)
        vmax = float(np.max(np.linalg.norm(v_samples, axis=1)))
        xi2 = rng.normal(size=n) * 2.0
        xi1 = xi2 + rng.normal(size=n) * float(rng.choice([0.0, 0.3, 2.0]))
        ts, gaps = sampled_gap(sys_, xi1, xi2, v_samples, T)
        d = gaps[0]
        delta_g = float(np.linalg.norm(sys_.g, "fro"))
        scale = d + vmax * s[0] / lam + 1e-300
        tb = tight_bound(ts, d, vmax, lam, s[0])
        worst = max(worst, float(np.max((gaps - tb) / scale)))
        tightest = max(tightest, float(np.max(gaps[1:] / tb[1:])))
        for frac in (0.5, *rng.uniform(0.02, 0.98, size=2)):
            th = frac * 2 * lam / delta_g**2
            pb = paper_bound(ts, d, vmax, lam, delta_g, th)
            worst = max(worst, float(np.max((gaps - pb) / scale)))
    return result(
        name,
        LABEL + ", sampled trajectories",
        holds=bool(worst <= BOUND_REL_TOL),
        residual=worst,
        detail=(
            f"{n_sys} systems, k in [3,40] intervals, paper bound (3 thetas) and tight bound at "
            f"every partition point: max rel violation {worst:.2e}; max gap/tight bound "
            f"{tightest:.6f}"
        ),
    )
