"""Certificates in metric coordinates: the mapping of bounds between ``z = Theta x`` and ``x``
(docs/math/contraction.md section 5; ``drip_cert.model.system.System.transformed``,
``drip_cert.analysis.contraction.coordinates``).

* ``coordinates.delta_iss_maps_back`` (Proposition 5.3 with section 6.2): for a linear closed loop
  ``x' = A x + B w`` with ``||w|| <= 1``, contracting in the metric ``P`` at rate ``lambda``, the
  gap from ``x(0) = 0`` satisfies ``||x(t)|| <= factor_to_x * ||B_z||_2 / lambda`` where
  ``B_z = Theta B`` and ``lambda = -mu_2(Theta A Theta^{-1})``. Checked by falsification: random
  ``A`` (Hurwitz, far from normal, so that ``mu_2(A) > 0`` is common), its LMI-free metric from
  the Lyapunov equation, drip-cert's coordinate change and rigorous factor, and the
  disturbance ``w = sign(B^T P x)`` (smoothed) that drives the P-norm up fastest, from rest,
  integrated by DOP853. The norm step itself is tight (the ratio
  ``||x|| / ||Theta x||`` along the top singular direction of ``Theta^{-1}``), so ``factor``, which
  multiplies the mapped bound, fails the check for any value noticeably below 1 (the tests use
  it to show the check can fail).
* ``coordinates.matched_split_consistent`` (Proposition 5.2): in ``z`` the adaptation projection
  is ``Theta_ad,z Theta = (g^T P g)^{-1} g^T P``, and a matched uncertainty ``g a`` keeps its
  matched part ``a``; exact rational identity on random instances, computed through
  ``System.transformed``.
"""

from __future__ import annotations

import numpy as np
import sympy as sp
from scipy.integrate import solve_ivp
from scipy.linalg import solve_continuous_lyapunov

from proofs_check._core import CheckResult, Context, register, result

LABEL = "docs/math/contraction.md section 5 (metric coordinates: mapping bounds back)"
ODE_RTOL = 1e-10  # solve_ivp relative tolerance
ODE_ATOL = 1e-12  # solve_ivp absolute tolerance
GAP_TOL = 1e-7  # DOP853 error at rtol 1e-10 over the horizon, relative to the bound
SEED_STATE = 1e-9  # start (almost) at rest: negligible next to any bound here
SMOOTH = 200.0  # tanh(SMOOTH s) stands in for sign(s): |w| <= 1 and a smooth right-hand side


def _random_loop(rng: np.random.Generator) -> tuple[np.ndarray, np.ndarray]:
    """A 2-state Hurwitz ``A`` with a large off-diagonal term and an input column ``B``."""
    a, b = rng.uniform(0.3, 1.5, size=2)
    c = rng.uniform(2.0, 8.0) * rng.choice([-1.0, 1.0])
    A = np.array([[-a, c], [0.0, -b]])
    B = rng.normal(size=(2, 1))
    return A, B


@register("coordinates.delta_iss_maps_back", LABEL)
def check_delta_iss_maps_back(ctx: Context, factor: float = 1.0) -> CheckResult:
    """Simulated gaps in x never exceed the z-bound mapped back by drip-cert's factor."""
    from drip_cert.analysis.contraction.coordinates import coordinates_from_metric
    from drip_cert.analysis.contraction.lognorm import mu2_constant_bounds

    name = "coordinates.delta_iss_maps_back"
    rng = ctx.rng
    worst = -np.inf
    positive_mu2 = 0
    n_sys = ctx.count(16, 4)
    for _ in range(n_sys):
        A, B = _random_loop(rng)
        P = solve_continuous_lyapunov(A.T, -np.eye(2))  # A^T P + P A = -I
        ch = coordinates_from_metric(P, "Lyapunov")
        Th = ch.theta
        _, mu_z = mu2_constant_bounds(Th @ A @ np.linalg.inv(Th))
        lo_x, _ = mu2_constant_bounds(A)
        positive_mu2 += int(lo_x > 0)
        if mu_z >= 0:
            continue
        lam = -mu_z
        # the norm step of Proposition 5.3 is tight: ||x|| / ||Theta x|| reaches ||Theta^{-1}||_2
        # along the top singular direction, so the factor may not be smaller
        Ti = np.linalg.inv(Th)
        u = np.linalg.svd(Ti)[2][0]
        worst = max(worst, np.linalg.norm(Ti @ u) / np.linalg.norm(u) / (factor * ch.to_x) - 1.0)
        bound = factor * ch.to_x * np.linalg.norm(Th @ B, 2) / lam
        T = 8.0 / lam
        # the disturbance that pushes the P-norm up fastest, w = sign(B^T P x), smoothed
        Pz = Th.T @ Th
        bp = (B[:, 0] @ Pz) / np.linalg.norm(B[:, 0] @ Pz)
        sol = solve_ivp(
            lambda t, x, A=A, B=B, bp=bp: A @ x + B[:, 0] * np.tanh(SMOOTH * (bp @ x)),
            (0.0, T),
            SEED_STATE * B[:, 0] / np.linalg.norm(B[:, 0]),  # at 0 exactly, w would stay 0
            method="DOP853",
            rtol=ODE_RTOL,
            atol=ODE_ATOL,
            t_eval=np.linspace(0.0, T, 801),
        )
        gap = float(np.max(np.linalg.norm(sol.y, axis=0)))
        worst = max(worst, (gap - bound) / bound)
    holds = worst <= GAP_TOL and positive_mu2 > 0
    return result(
        name,
        LABEL,
        holds=holds,
        residual=worst,
        detail=f"{n_sys} random loops ({positive_mu2} with mu_2(A) > 0 in x); largest simulated "
        f"gap relative to the mapped-back bound minus 1: {worst:.3g} (tolerance {GAP_TOL:g})",
    )


@register("coordinates.matched_split_consistent", LABEL)
def check_matched_split(ctx: Context) -> CheckResult:
    """Theta_ad in z is the P-orthogonal projection; a matched uncertainty keeps its part."""
    from drip_cert.model.system import System

    name = "coordinates.matched_split_consistent"
    rng = ctx.rng
    x1, x2, x3 = sp.symbols("x1 x2 x3", real=True)
    worst = 0
    n = ctx.count(6, 2)
    for _ in range(n):
        g = sp.Matrix(3, 1, [sp.Rational(int(v), 4) for v in rng.integers(1, 9, size=3)])
        L = sp.Matrix(3, 3, lambda i, j: 0 if j > i else sp.Rational(int(rng.integers(1, 9)), 4))
        Th = L.T  # upper triangular, invertible
        a = sp.sin(x1) + x2 * x3 / 7
        s = System(
            name="random",
            states=(x1, x2, x3),
            f=[0, 0, 0],
            g=g,
            expert=[0],
            lambda_mu=list(g * a),
            support=[(-1.0, 1.0)] * 3,
            horizon=1.0,
        )
        z = s.transformed(np.array(Th.tolist(), dtype=float))
        P = Th.T * Th
        lhs = sp.Matrix(z.theta_ad) * Th
        rhs = (g.T * P * g).inv() * g.T * P
        worst = max(worst, int(sp.simplify(lhs - rhs) != sp.zeros(1, 3)))
        back = dict(zip(z.states, list(Th * sp.Matrix([x1, x2, x3])), strict=True))
        matched = (sp.Matrix(z.theta_ad) * sp.Matrix(z.lambda_mu)).xreplace(back)
        worst = max(worst, int(sp.simplify(matched[0] - a) != 0))
    return result(
        name,
        LABEL,
        holds=worst == 0,
        residual=float(worst),
        detail=f"{n} random rational instances: Theta_ad,z Theta == (g^T P g)^-1 g^T P and the "
        "matched part of g a(x) is a(x) in z" + ("" if worst == 0 else ": a mismatch"),
    )
