"""The forward-invariant sets drip-cert proves inside a box where a contraction rate holds
(docs/math/contraction.md section 7; ``drip_cert.analysis.contraction.invariance``).

Proposition (ball): ``mu_2(D F) <= -lambda`` on a convex box ``B``, ``||F(x_0)|| <= eps`` and
``r >= max(eps / lambda, max_{y in D} ||y - x_0||)`` with the ball ``S = {||x - x_0|| <= r}``
inside ``B``: every solution from the support ``D`` stays in ``S``.

Proposition (box, Nagumo): ``F_i <= 0`` on the face ``x_i = hi_i`` and ``>= 0`` on ``x_i = lo_i``:
the box is forward invariant.

Checked by falsification: random planar fields ``F(x) = A (x - x_e) + c |x|^2 e`` that contract
near the origin only (the quadratic term), drip-cert's sound rate on a random box, its proved
set, and trajectories from the support (corners and random points) integrated by DOP853. The
residual is the largest excursion outside the proved set, relative to its size. ``radius_factor``
shrinks the claimed ball (a value < 1 claims a set too small; the tests use it to show the check
can fail).
"""

from __future__ import annotations

import numpy as np
import sympy as sp
from scipy.integrate import solve_ivp

from proofs_check._core import CheckResult, Context, register, result

LABEL = "docs/math/contraction.md section 7 (forward-invariant ball and box)"
ODE_RTOL = 1e-10  # solve_ivp relative tolerance
ODE_ATOL = 1e-12  # solve_ivp absolute tolerance
EXCURSION_TOL = 1e-7  # DOP853 error at rtol 1e-10 over the horizon, relative to the set's size


def _system(rng: np.random.Generator):
    x1, x2 = sp.symbols("x1 x2", real=True)
    a = float(rng.uniform(0.5, 2.0))
    w = float(rng.uniform(-1.0, 1.0))
    A = sp.Matrix([[-a, w], [-w, -a]])  # mu_2(A) = -a exactly
    xe = sp.Matrix([float(rng.uniform(-0.2, 0.2)), float(rng.uniform(-0.2, 0.2))])
    c = float(rng.uniform(0.05, 0.3))
    e = sp.Matrix([float(v) for v in rng.normal(size=2)]).normalized()
    X = sp.Matrix([x1, x2])
    F = A * (X - xe) + c * (x1**2 + x2**2) * e
    return (x1, x2), sp.ImmutableMatrix(F)


@register("invariance.sets_random_systems", LABEL)
def check_invariant_sets(ctx: Context, radius_factor: float = 1.0) -> CheckResult:
    """Trajectories from the support never leave the set drip-cert proves invariant."""
    from drip_cert import contraction_rate
    from drip_cert.analysis.contraction.invariance import invariant_ball, invariant_box

    name = "invariance.sets_random_systems"
    rng = ctx.rng
    n_sys = ctx.count(12, 3)
    worst = -np.inf
    proved = 0
    for _ in range(n_sys):
        (x1, x2), F = _system(rng)
        t = sp.Symbol("t", real=True)
        half = float(rng.uniform(0.8, 1.5))
        B = np.array([[-half, half], [-half, half]])
        s = float(rng.uniform(0.1, 0.4))
        D = np.array([[-s, s], [-s, s]])
        r = contraction_rate(F.jacobian([x1, x2]), (x1, x2), B, max_boxes=2000)
        if not r.holds:
            continue
        fn = sp.lambdify((x1, x2), list(F), "numpy")

        def F_num(z, fn=fn):
            return np.array(fn(*z), dtype=float)

        ball = invariant_ball(F, (x1, x2), t, r.rate, r.scope, D, 5.0, F_num)
        box_ok = invariant_box(F, (x1, x2), t, D, 5.0)
        starts = [np.array([a, b]) for a in D[0] for b in D[1]]
        starts += list(rng.uniform(D[:, 0], D[:, 1], size=(4, 2)))
        T = 5.0
        for x0 in starts:
            sol = solve_ivp(
                lambda _t, z, fn=fn: np.array(fn(*z), dtype=float),
                (0.0, T),
                x0,
                method="DOP853",
                rtol=ODE_RTOL,
                atol=ODE_ATOL,
                t_eval=np.linspace(0.0, T, 401),
            )
            X = sol.y.T
            if ball.proved:
                rad = radius_factor * ball.radius
                dist = np.linalg.norm(X - np.array(ball.centre), axis=1)
                worst = max(worst, float(np.max(dist - rad)) / ball.radius)
            if box_ok:
                lo, hi = D[:, 0], D[:, 1]
                mid, half_w = 0.5 * (lo + hi), 0.5 * (hi - lo) * radius_factor
                out = np.max(np.abs(X - mid) - half_w, axis=1) / np.max(0.5 * (hi - lo))
                worst = max(worst, float(np.max(out)))
        proved += int(ball.proved) + int(box_ok)
    holds = proved > 0 and worst <= EXCURSION_TOL
    return result(
        name,
        LABEL,
        holds=holds,
        residual=worst,
        detail=f"{proved} sets proved on {n_sys} random systems; largest relative excursion "
        f"outside a proved set {worst:.3g} (tolerance {EXCURSION_TOL:g})"
        + ("" if proved else "; no set was proved: nothing was checked"),
    )
