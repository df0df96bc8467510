"""The slope-restricted LMI of docs/math/contraction.md section 11
(analysis/contraction/slope_lmi.py).

Proposition 11.2: a verified ``(P, t, lambda)`` of (11.3) gives
``(x - y)^T P (F(x) - F(y)) <= -lambda ||x - y||_P^2`` for every pair. Checked by falsification:
random loops ``F(x) = A x + C h(x)`` with small tanh / relu / leaky-relu networks (one neuron
included, where the S-procedure is exact and the rate is attained), drip-cert's verified rate
and metric, and random pairs of states near and far; the residual is the largest
``(x - y)^T P (F(x) - F(y)) / ||x - y||_P^2 + lambda`` (positive = a violation), relative to
``1 + |lambda|``. ``slope_scale`` multiplies the upper end of every slope range before the LMI is
built (a value < 1 is a wrong constraint (11.2); the tests use it to show the check can fail).

Proposition 11.3: ``mu_P(J) >= tr(J) / n`` for every ``J`` and ``P > 0``. Checked on random
matrices and metrics; ``divisor`` replaces ``n`` (``1`` is a wrong formula that fails).
"""

from __future__ import annotations

import dataclasses

import numpy as np

from proofs_check._core import CheckResult, Context, register, result

LABEL = "docs/math/contraction.md section 11 (slope-restricted LMI, trace condition)"
#: float evaluation of the increments of O(1) networks at states up to 1e2: a few 1e-14 relative,
#: far below the 1e-9 back-off of the verified rate
PAIR_TOL = 1e-9
#: eigenvalues of random 2..6 dimensional symmetric matrices: LAPACK's backward error
EIG_TOL = 1e-10


def _loop(rng: np.random.Generator, act: str, one: bool):
    from drip_cert.analysis.growth.closed_loop import AffineBlocks
    from drip_cert.model.mlp import MLP

    if one:
        w1, w2 = rng.uniform(0.5, 2.0), rng.uniform(-2.0, 0.4)
        mlp = MLP(
            weights=(np.array([[w1]]), np.array([[w2]])),
            biases=(np.array([rng.uniform(-0.5, 0.5)]), np.zeros(1)),
            activation=act,
        )
        return AffineBlocks(np.array([[-1.0]]), np.zeros(1), {"h": np.eye(1)}), {"h": mlp}
    n, m = 2, 5
    mlp = MLP(
        weights=(0.7 * rng.standard_normal((m, n)), 0.7 * rng.standard_normal((n, m))),
        biases=(0.3 * rng.standard_normal(m), np.zeros(n)),
        activation=act,
    )
    a = rng.uniform(1.0, 2.0)
    w = rng.uniform(-1.0, 1.0)
    A = np.array([[-a, w], [-w, -a]])
    return AffineBlocks(A, np.zeros(n), {"h": 0.5 * np.eye(n)}), {"h": mlp}


@register("slope_lmi.incremental_contraction", LABEL)
def check_incremental_contraction(ctx: Context, slope_scale: float = 1.0) -> CheckResult:
    """No pair of states violates the rate of a verified slope-restricted LMI."""
    from drip_cert.analysis.contraction.slope_lmi import slope_lmi_rate, slope_structure

    name = "slope_lmi.incremental_contraction"
    rng = ctx.rng
    worst = -np.inf
    proved = 0
    n_sys = ctx.count(12, 4)
    for k in range(n_sys):
        act = ("tanh", "relu", "leaky_relu(0.1)")[k % 3]
        dec, mlps = _loop(rng, act, one=k % 2 == 0)
        st = slope_structure(dec, mlps)
        if slope_scale != 1.0:
            st = dataclasses.replace(st, beta=st.alpha + slope_scale * (st.beta - st.alpha))
        res = slope_lmi_rate(st, metric=k % 4 == 3, obstruct=False)
        if res.rate is None:
            continue
        proved += 1
        mlp = mlps["h"]
        C = dec.C["h"]
        n = st.n

        def F(X, mlp=mlp, A=dec.A, C=C):
            return X @ A.T + mlp.apply_np(X) @ C.T

        scale = rng.choice([0.05, 1.0, 30.0], size=(ctx.count(4000, 800), 1))
        X = scale * rng.standard_normal((len(scale), n))
        Y = X + scale * rng.standard_normal((len(scale), n)) * rng.choice([1e-3, 1.0], (len(X), 1))
        V, D = X - Y, F(X) - F(Y)
        num = np.einsum("ij,jk,ik->i", V, res.P, D)
        den = np.einsum("ij,jk,ik->i", V, res.P, V)
        ok = den > 0
        viol = (num[ok] / den[ok] + res.rate) / (1.0 + abs(res.rate))
        worst = max(worst, float(np.max(viol)))
    holds = proved > 0 and worst <= PAIR_TOL
    return result(
        name,
        LABEL,
        holds=holds,
        residual=worst,
        detail=f"{proved} verified rates on {n_sys} random loops; largest relative excess of "
        f"(x - y)^T P (F(x) - F(y)) / ||x - y||_P^2 over -lambda: {worst:.3g} "
        f"(tolerance {PAIR_TOL:g})" + ("" if proved else "; nothing verified: nothing checked"),
    )


@register("slope_lmi.trace_condition", LABEL)
def check_trace_condition(ctx: Context, divisor: float | None = None) -> CheckResult:
    """``mu_P(J) >= tr(J) / n`` on random matrices and metrics."""
    name = "slope_lmi.trace_condition"
    rng = ctx.rng
    worst = -np.inf
    for _ in range(ctx.count(2000, 300)):
        n = int(rng.integers(2, 7))
        J = rng.standard_normal((n, n)) + rng.uniform(-3, 3) * np.eye(n)
        R = rng.standard_normal((n, n))
        P = R @ R.T + 0.1 * np.eye(n)
        w, U = np.linalg.eigh(P)
        Ph, Pih = U @ np.diag(np.sqrt(w)) @ U.T, U @ np.diag(1 / np.sqrt(w)) @ U.T
        K = Ph @ J @ Pih
        mu = float(np.linalg.eigvalsh(0.5 * (K + K.T))[-1])
        claim = float(np.trace(J)) / (n if divisor is None else divisor)
        worst = max(worst, (claim - mu) / (1.0 + abs(mu)))
    return result(
        name,
        LABEL,
        holds=worst <= EIG_TOL,
        residual=worst,
        detail=f"largest relative excess of tr(J)/n over mu_P(J): {worst:.3g} "
        f"(tolerance {EIG_TOL:g})",
    )
