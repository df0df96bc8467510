"""DRIP decomposition of the total imitation gap (drip_paper.tex ~l.637-720).

``Upsilon_T(D~; pi) <= policy-IG(D; pi_hat) + uncertainty-IG(D~; pi, pi_hat)`` by Minkowski
(triangle inequality inside the expectation, then ``max_t (a + b) <= max_t a + max_t b``) and
the marginal property of couplings (an expectation over the coupling of a function of ``xi``
only is the expectation over ``D``). Checked on random empirical laws with random couplings
built exactly (convex combinations of the product coupling and north-west-corner couplings of
random orderings, so both marginals hold to rounding), random linear flows for the expert and
learner, and a noisy true process (several noise paths per initial state).
"""

from __future__ import annotations

import numpy as np
from scipy.linalg import expm

from proofs_check._core import CheckResult, Context, register, result

LABEL = "DRIP eq. (Decomposition:IG:1)-(Final)"

MARGINAL_TOL = 1e-12  # marginals and the marginal identity: rounding of sums of <= 400 terms
MINKOWSKI_TOL = 1e-12  # triangle inequality in floating point: rounding only


def north_west_coupling(a: np.ndarray, b: np.ndarray) -> np.ndarray:
    """The north-west-corner coupling of weight vectors ``a`` and ``b`` (same total mass)."""
    P = np.zeros((a.size, b.size))
    ra, rb = a.astype(float).copy(), b.astype(float).copy()
    i = j = 0
    while i < a.size and j < b.size:
        q = min(ra[i], rb[j])
        P[i, j] += q
        ra[i] -= q
        rb[j] -= q
        if ra[i] <= rb[j]:
            i += 1
        else:
            j += 1
    return P


def random_coupling(rng: np.random.Generator, a: np.ndarray, b: np.ndarray) -> np.ndarray:
    """A random coupling of ``a`` and ``b``: mixture of the product and permuted NW couplings."""
    parts = [np.outer(a, b)]
    for _ in range(3):
        pa, pb = rng.permutation(a.size), rng.permutation(b.size)
        Q = north_west_coupling(a[pa], b[pb])
        P = np.zeros_like(Q)
        P[np.ix_(pa, pb)] = Q
        parts.append(P)
    w = rng.dirichlet(np.ones(len(parts)))
    return sum(wi * Pi for wi, Pi in zip(w, parts))


@register("decomposition.tig", LABEL + ", Minkowski + marginal property")
def check_decomposition(ctx: Context) -> CheckResult:
    """TIG <= policy-IG + uncertainty-IG, and the marginal identity, on random couplings."""
    name = "decomposition.tig"
    rng = ctx.rng
    n_inst = ctx.count(200, 25)
    worst_marg = 0.0
    worst_mink = -np.inf
    tightest = 0.0
    for _ in range(n_inst):
        d = int(rng.integers(1, 5))
        na, nb = int(rng.integers(1, 20)), int(rng.integers(1, 20))
        a = rng.dirichlet(np.ones(na))
        b = rng.dirichlet(np.ones(nb))
        xi = rng.normal(size=(na, d))
        xib = xi[rng.integers(0, na, size=nb)] + rng.normal(size=(nb, d)) * rng.uniform(0, 1)
        P = random_coupling(rng, a, b)
        worst_marg = max(
            worst_marg, float(np.max(np.abs(P.sum(1) - a))), float(np.max(np.abs(P.sum(0) - b)))
        )
        ts = np.linspace(0.0, float(rng.uniform(1, 5)), 30)
        As = [rng.normal(size=(d, d)) * 0.5 - np.eye(d) * rng.uniform(0, 1) for _ in range(3)]
        Es = [np.stack([expm(A * t) for t in ts]) for A in As]  # (T, d, d)
        x_star = np.einsum("tij,nj->tni", Es[0], xi)  # expert from xi
        x_hat = np.einsum("tij,nj->tni", Es[1], xi)  # learner from xi
        n_noise = int(rng.integers(1, 6))
        noise = np.cumsum(rng.normal(size=(n_noise, ts.size, nb, d)) * 0.3, axis=1)
        X = np.einsum("tij,nj->tni", Es[2], xib)[None] + noise  # true, (noise, T, nb, d)
        # (T, na, nb) pairwise distances, averaged over the noise paths
        tig_t = np.mean(
            np.linalg.norm(X[:, :, None, :, :] - x_star[None, :, :, None, :], axis=-1), axis=0
        )
        unc_t = np.mean(
            np.linalg.norm(X[:, :, None, :, :] - x_hat[None, :, :, None, :], axis=-1), axis=0
        )
        pol_pair = np.linalg.norm(x_hat - x_star, axis=-1)  # (T, na)
        TIG = np.max(np.einsum("tij,ij->t", tig_t, P))
        UNC = np.max(np.einsum("tij,ij->t", unc_t, P))
        pol_coupled = np.einsum("ti,ij->t", pol_pair, P)
        pol_marg = pol_pair @ a
        worst_marg = max(
            worst_marg, float(np.max(np.abs(pol_coupled - pol_marg) / (1 + np.abs(pol_marg))))
        )
        POL = np.max(pol_marg)
        worst_mink = max(worst_mink, float((TIG - POL - UNC) / (POL + UNC + 1e-300)))
        tightest = max(tightest, float(TIG / (POL + UNC + 1e-300)))
    ok = worst_marg <= MARGINAL_TOL and worst_mink <= MINKOWSKI_TOL
    return result(
        name,
        LABEL + ", Minkowski + marginal property",
        holds=bool(ok),
        residual=max(worst_mink, worst_marg),
        detail=(
            f"{n_inst} random couplings: max marginal error {worst_marg:.1e}, max "
            f"(TIG - policy-IG - uncertainty-IG)/rhs = {worst_mink:.2e}, max TIG/rhs {tightest:.3f}"
        ),
    )
