"""``L_Delta`` on the difference ``pi_IL - pi*``, local to a box, and the box it must hold on
(docs/math/tasil.md section 3.12; ``drip_cert.analysis.networks.policy_regularity``,
``drip_cert.bounds.tasil.section``).

Two claims:

* ``tasil.difference_local`` (3.12, the bound): for ``Delta = pi_IL - pi*`` formed symbolically
  (a term both policies share cancels, networks included) and a box ``B``,
  :func:`~drip_cert.analysis.networks.policy_regularity.difference_jacobian_lipschitz` bounds
  ``||D Delta(x) - D Delta(y)||_2 / ||x - y||`` for every ``x, y`` in ``B``. Random instances:
  ``pi* = a sin(x_1) + K* x + v* tanh-network h(x)``, ``pi_IL = a sin(x_1) + K x + v* h(x) + q(x) +
  C N(x)`` (``h`` shared: it must cancel; ``N`` a second tanh MLP; ``q`` quadratic), the ratio
  sampled on random pairs, on pairs along the top eigenvector of the Hessian at sampled points,
  and after a local ascent. Tight (one in three): ``Delta = (c/2) x_1^2`` (the Hessian is the
  constant ``c e_1 e_1^T``, Frobenius norm = operator norm, enclosed exactly), whose ratio on a pair
  differing in ``x_1`` equals ``|c|``: a bound 1 % smaller (``factor = 0.99``) fails.
* ``tasil.which_box`` (3.12, "Which box"): the box of
  :func:`~drip_cert.bounds.tasil.section.l_delta_box`, the hull of the demonstrations' box and a
  set ``S`` proved to hold every expert trajectory from the support, enlarged by the tube radius
  ``R``, contains the tube of radius ``R`` (in the inf-norm, hence the Euclidean one) around the
  expert trajectory of every *new* initial state of the support. Instances: contracting expert
  loops ``F*(x) = A x + c tanh(W x)`` (``mu_2 <= -lambda``, ``F*(0) = 0``), so that the ball
  ``||x|| <= max_support ||x||`` is forward invariant and ``S`` is the box around it; two
  demonstrations, new initial states at the support's corners and at random. The wrong rule
  (``wrong = True``: the demonstrations' box alone, enlarged by ``R``) fails: new trajectories
  leave it.
"""

from __future__ import annotations

import numpy as np
import sympy as sp
from scipy.integrate import solve_ivp

from proofs_check._core import CheckResult, Context, register, result
from proofs_check._systems import random_contracting_system

LABEL_D = "docs/math/tasil.md section 3.12: L_Delta from the Hessian of pi_IL - pi* on a box"
LABEL_B = "docs/math/tasil.md section 3.12, Which box: the box holds every new expert tube"
PAIRS = 2000  # random pairs per instance (full run; a fifth under --quick)
ASCENT_STEPS = 40  # projected gradient-free ascent steps on the Hessian's operator norm
RATIO_TOL = 1e-9
"""The tight ratio |c| is computed in floats (a difference quotient of an exactly linear
derivative, relative error ~1e-15) against a bound rounded up by a few ulps: 1e-9 is far above
both and far below the 1 % of the wrong formula."""
ODE_RTOL = 1e-10  # solve_ivp relative tolerance of the expert trajectories
ODE_ATOL = 1e-12  # solve_ivp absolute tolerance
GRID = 401  # times at which a trajectory's distance to the box is read off
BOX_TOL = 1e-9
"""Containment is checked on ODE states accurate to ~1e-10 (rtol above): a violation smaller
than 1e-9 is integration error; the wrong rule misses by order 0.1."""


def _mlp(rng: np.random.Generator, sizes: list[int], scale: float):
    from drip_cert.model.mlp import MLP, init_mlp

    m = init_mlp(sizes, rng, activation="tanh", scale=scale)
    return MLP(m.weights, tuple(0.3 * rng.normal(size=b.shape) for b in m.biases), "tanh")


def _instance(rng: np.random.Generator, tight: bool):
    """(System, box, jax Hessian of Delta, exact Lipschitz constant or None) of one instance."""
    from drip_cert.model.blocks import mlp_block
    from drip_cert.model.system import System

    n = int(rng.integers(2, 4))
    m = 1 if tight else int(rng.integers(1, 3))
    xs = sp.symbols(f"x1:{n + 1}", real=True)
    X = sp.Matrix(xs)
    h = mlp_block("h", _mlp(rng, [n, 5, m], 1.0))
    N = mlp_block("N", _mlp(rng, [n, 6, 6, m], float(rng.uniform(0.5, 2.0))))
    hx = sp.Matrix([h.component(j)(*xs) for j in range(m)])
    Nx = sp.Matrix([N.component(j)(*xs) for j in range(m)])
    a = float(rng.uniform(-10.0, 10.0))
    shared = sp.Matrix([a * sp.sin(xs[0])] * m) + sp.Matrix(rng.normal(size=(m, n))) * X + hx
    expert = shared + sp.Matrix(rng.normal(size=(m, n))) * X
    c = float(rng.uniform(0.5, 3.0)) * (1 if rng.random() < 0.5 else -1)
    if tight:
        learned = shared + sp.Matrix([c / 2 * xs[0] ** 2])
        exact = abs(c)
    else:
        Q = rng.normal(size=(m, n, n)) * 0.3
        quad = sp.Matrix([(X.T * sp.Matrix(Q[j]) * X)[0, 0] for j in range(m)])
        learned = shared + sp.Matrix(rng.normal(size=(m, n))) * X + quad
        learned = learned + sp.Matrix(rng.normal(size=(m, m))) * Nx
        exact = None
    lo = rng.uniform(-2.0, 0.0, size=n)
    box = np.stack([lo, lo + rng.uniform(0.3, 2.0, size=n)], axis=1)
    s = System(
        name="difference",
        states=xs,
        f=sp.zeros(n, 1),
        g=sp.Matrix(rng.normal(size=(n, m))),
        expert=expert,
        learned=learned,
        support=tuple(map(tuple, box)),
        horizon=1.0,
        blocks={"h": h, "N": N},
    )
    return s, box, exact


def _jacobian_fn(s):
    from drip_cert._jax import jax, jnp

    fn = s.lower(list(sp.Matrix(s.learned) - sp.Matrix(s.expert)))
    jac = jax.jit(jax.vmap(jax.jacfwd(lambda z: jnp.ravel(fn(0.0, z)))))
    hess = jax.jit(jax.vmap(jax.hessian(lambda z: jnp.ravel(fn(0.0, z)))))
    return (lambda P: np.asarray(jac(jnp.asarray(P)))), (lambda P: np.asarray(hess(jnp.asarray(P))))


def _worst_ratio(rng: np.random.Generator, s, box: np.ndarray, pairs: int) -> float:
    """Largest ``||D Delta(x) - D Delta(y)|| / ||x - y||`` found on pairs in ``box``."""
    jac, hess = _jacobian_fn(s)
    n = box.shape[0]
    lo, hi = box[:, 0], box[:, 1]
    Xp = rng.uniform(lo, hi, size=(pairs, n))
    Yp = rng.uniform(lo, hi, size=(pairs, n))
    # pairs along the direction of largest curvature at random points (short secants)
    C = rng.uniform(lo, hi, size=(pairs, n))
    H = hess(C)  # (N, m, n, n)
    dirs = []
    for k in range(pairs):
        # the top right singular vector of v -> H[v] (an (m, n) matrix per v): of the stacked H
        M = H[k].transpose(1, 0, 2).reshape(n, -1)  # rows: one per v coordinate
        _, _, vt = np.linalg.svd(M.T)
        dirs.append(vt[0])
    D = np.array(dirs) * 1e-3 * (hi - lo).min()
    Xs = np.clip(C + D, lo, hi)
    Ys = np.clip(C - D, lo, hi)
    P1, P2 = np.concatenate([Xp, Xs]), np.concatenate([Yp, Ys])

    def ratios(A, B):
        d = np.linalg.norm((A - B), axis=1)
        ok = d > 0
        J1, J2 = jac(A[ok]), jac(B[ok])
        num = np.linalg.norm(J1 - J2, ord=2, axis=(1, 2))
        return num / d[ok], ok

    r, ok = ratios(P1, P2)
    best = float(r.max())
    # a short random local ascent from the ten best pairs
    order = np.argsort(-r)[:10]
    A, B = P1[ok][order], P2[ok][order]
    cur = r[order]
    scale = 0.05 * (hi - lo)
    for _ in range(ASCENT_STEPS):
        A2 = np.clip(A + rng.normal(size=A.shape) * scale, lo, hi)
        B2 = np.clip(B + rng.normal(size=B.shape) * scale, lo, hi)
        r2, ok2 = ratios(A2, B2)
        full = np.full(A.shape[0], -np.inf)
        full[ok2] = r2
        better = full > cur
        A[better], B[better], cur[better] = A2[better], B2[better], full[better]
    return max(best, float(cur.max()))


@register("tasil.difference_local", LABEL_D)
def check_difference_local(ctx: Context, factor: float = 1.0) -> CheckResult:
    """``||D Delta(x) - D Delta(y)|| <= factor L_dDelta ||x - y||`` on the box (docstring)."""
    from drip_cert.analysis.networks.policy_regularity import difference_jacobian_lipschitz

    name = "tasil.difference_local"
    n_inst = ctx.count(12, 6)
    pairs = ctx.count(PAIRS, PAIRS // 5)
    worst = worst_tight = worst_random = -np.inf
    for k in range(n_inst):
        tight = k % 3 == 0
        s, box, exact = _instance(ctx.rng, tight)
        L = difference_jacobian_lipschitz(s, box)
        if L is None or not L.how.proved or not np.isfinite(L.value):
            return result(
                name, LABEL_D, holds=False, residual=np.inf,
                detail=f"instance {k}: no sound finite bound on the difference ({L})",
            )  # fmt: skip
        bound = factor * L.value
        if tight:
            assert exact is not None
            # the pair x, x + e_1 t: D Delta differs by c t e_1 e_1^T, ratio |c| exactly
            r = exact / bound
            worst_tight = max(worst_tight, r)
        else:
            r = _worst_ratio(ctx.rng, s, box, pairs) / bound
            worst_random = max(worst_random, r)
        worst = max(worst, r)
    return result(
        name,
        LABEL_D,
        holds=bool(worst <= 1.0 + RATIO_TOL),
        residual=worst - 1.0,
        detail=f"{n_inst} instances (1/3 tight), {pairs} random + {pairs} curvature pairs each: "
        f"max ratio / L_dDelta = {worst:.8f} (tight {worst_tight:.8f}, random "
        f"{worst_random:.4f})",
    )


def _expert_trajectories(sysm, X0: np.ndarray, T: float) -> np.ndarray:
    """States ``(len(X0), GRID, n)`` of ``x' = A x + c tanh(W x)`` from each row of ``X0``."""
    out = []
    ts = np.linspace(0.0, T, GRID)
    zero = np.zeros(sysm.g.shape[1])
    for x0 in X0:
        sol = solve_ivp(
            lambda _t, x: sysm.drift(x, zero), (0.0, T), x0, method="DOP853",
            rtol=ODE_RTOL, atol=ODE_ATOL, t_eval=ts,
        )  # fmt: skip
        out.append(sol.y.T)
    return np.array(out)


@register("tasil.which_box", LABEL_B)
def check_which_box(ctx: Context, wrong: bool = False) -> CheckResult:
    """Every new expert tube lies in ``l_delta_box`` (module docstring); ``wrong``: the
    demonstrations' box alone."""
    from drip_cert.bounds.tasil.section import l_delta_box

    name = "tasil.which_box"
    rng = ctx.rng
    n_inst = ctx.count(30, 8)
    worst = -np.inf
    for _ in range(n_inst):
        sysm = random_contracting_system(rng, linear=bool(rng.random() < 0.3))
        n = sysm.A.shape[0]
        lo = rng.uniform(-1.5, -0.2, size=n)
        support = np.stack([lo, lo + rng.uniform(0.4, 2.0, size=n)], axis=1)
        T = float(rng.uniform(0.5, 3.0)) / sysm.lam
        R = float(rng.uniform(0.01, 0.2))
        # S: the box around the forward-invariant ball ||x|| <= max_support ||x|| (F*(0) = 0 and
        # mu_2 <= -lambda < 0: ||x(t)|| does not increase), contraction.md section 7
        rad = float(np.linalg.norm(np.maximum(np.abs(support[:, 0]), np.abs(support[:, 1]))))
        S = None if wrong else np.stack([-np.full(n, rad), np.full(n, rad)], axis=1)
        demos = _expert_trajectories(sysm, rng.uniform(support[:, 0], support[:, 1], (2, n)), T)
        B = l_delta_box(demos.reshape(-1, n), S, R)
        corners = np.array(np.meshgrid(*support.tolist(), indexing="ij")).reshape(n, -1).T
        new = np.concatenate([corners, rng.uniform(support[:, 0], support[:, 1], (20, n))])
        traj = _expert_trajectories(sysm, new, T).reshape(-1, n)
        # the inf-norm tube [-R, R]^n around each state must lie in B: excess over the faces
        excess = np.maximum(B[:, 0] - (traj - R), (traj + R) - B[:, 1])
        worst = max(worst, float(excess.max()))
    return result(
        name,
        LABEL_B,
        holds=bool(worst <= BOX_TOL),
        residual=worst,
        detail=f"{n_inst} contracting expert loops, 2 demonstrations, corners + 20 new initial "
        f"states each: largest excess of a tube of radius R over the box = {worst:.3g}"
        + (" (wrong rule: the demonstrations' box only)" if wrong else ""),
    )
