"""Contraction of a closed loop affine in MLP blocks by a slope-restricted LMI (the LipSDP idea
applied to the closed loop's Jacobian), verified in Arb. docs/math/contraction.md section 11.

Setting. ``F(x) = A x + c + sum_k C_k h_k(x)`` (constant ``A, c, C_k``, :func:`~drip_cert.
analysis.closed_loop.affine_in_blocks`), every ``h_k`` an MLP ``z_{l+1} = s_l(W_l z_l + b_l)``.
For two states ``x, y`` write ``v = x - y``, ``a`` for the stacked increments of the
pre-activations of every neuron (hidden neurons, and output neurons when the output activation is
not the identity) and ``u`` for the increments of their outputs. Then ``a = E xi`` and
``F(x) - F(y) = G xi`` with ``xi = (v, u)`` and constant ``E``, ``G`` (11.1), and every neuron
satisfies the incremental quadratic constraint (11.2)

``q_i(xi) = (u_i - alpha_i a_i) (beta_i a_i - u_i) >= 0``,

``[alpha_i, beta_i]`` the activation's slope range (for a piecewise-C1 activation the secant
slope ``u_i / a_i`` is an average of its a.e. derivative, hence in the range). With multipliers
``t_i >= 0`` (S-procedure), the LMI (11.3)

``M(P, t, lambda) = Ev^T P G + G^T P Ev + 2 lambda Ev^T P Ev + sum_i t_i Q_i <= 0``

(``Ev xi = v``, ``Q_i`` the matrix of ``q_i``) gives ``2 v^T P (F(x) - F(y)) <= -2 lambda
||v||_P^2`` for every pair, i.e. the loop contracts at rate ``lambda`` in ``||.||_P``; with
``P = I`` it is ``mu_2(DF(x)) <= -lambda`` for every x (and every Clarke Jacobian), DRIP
Assumption 2 / L1-DRAC Assumption 2 on all of ``R^n``. On a box the ranges
``[alpha_i, beta_i]`` shrink to the slopes over each neuron's pre-activation interval on the box
(interval bounds through the layers), and the rate holds on the box.

Solve, re-check, verify (as :mod:`drip_cert.analysis.contraction.lmi`): cvxpy (Clarabel for small
LMIs,
SCS above), only ``OPTIMAL`` accepted; the multipliers ``t`` (and ``P``) are kept and the best
``lambda`` for them is recomputed by a Schur complement in floats; the LMI at a slightly smaller
``lambda`` is then assembled in Arb (the coefficient conversion radius of ``A``, ``C_k`` as ball
radii) and its largest eigenvalue bounded rigorously
(:func:`~drip_cert.analysis.contraction.lognorm.
lambda_max_upper`): strictly negative or no certificate.

Necessary condition (:func:`trace_obstruction`). For every ``P > 0``,
``mu_P(J) >= tr(J) / n`` (the mean eigenvalue of the symmetric part of ``P^{1/2} J P^{-1/2}``),
and the LMI covers every ``J(s) = A + sum_k C_k W_L S_{L-1} ... S_0 W_0`` with each slope
``s_i`` chosen independently in its range. So if ``max_s tr J(s) / n > -lambda``, no LMI of this
form proves the rate ``lambda`` (none proves contraction when it is ``>= 0``): the reason a loop
that contracts only by cancelling a plant nonlinearity with the policy (the paper's plain MLP)
cannot be certified this way. The maximum over the slope box is attained at a vertex; it is
approached by exact per-layer maximisation (``tr`` is linear in one layer's slopes).
"""

from __future__ import annotations

import math
import time
import warnings
from dataclasses import dataclass, field

import numpy as np
from flint import arb, arb_mat

from drip_cert.analysis.contraction.lognorm import lambda_max_upper
from drip_cert.analysis.growth.closed_loop import CONVERSION_ULPS, AffineBlocks
from drip_cert.errors import SpecError
from drip_cert.model.activations import Identity
from drip_cert.model.blocks import MappedMLP
from drip_cert.model.mlp import MLP
from drip_cert.numerics.interval_np import affine_enclosure_rad
from drip_cert.numerics.rounding import arb_hi

__all__ = [
    "DEFAULT_MAX_DIM",
    "SlopeLMIResult",
    "SlopeStructure",
    "TraceObstruction",
    "slope_lmi_rate",
    "BoxSlopeResult",
    "box_slope_bnb",
    "lmi_matrix",
    "sampled_slopes",
    "slope_structure",
    "trace_obstruction",
    "verify_slope_lmi",
]

#: above this LMI size (states + neurons) no SDP is attempted: SCS took 3 s at d = 66, 49-95 s at
#: d = 148 and did not converge in its iteration cap (409 s) on another d = 148 instance (2 loaded
#: cores); the trace condition is checked at any size
DEFAULT_MAX_DIM = 100
#: LMI size up to which Clarabel (interior point, most accurate) is used; SCS (first order) above.
#: Measured (2 loaded cores, P = I): d = 34: Clarabel 7.4 s, SCS 1.0 s; d = 66: 33 s vs 3.3 s, the
#: same verified rate to 2e-5 (the Schur-complement rate repairs SCS's lower accuracy)
_CLARABEL_MAX_DIM = 16
#: SCS iteration cap: a count of work (never wall time), so the same inputs give the same answer
_SCS_MAX_ITERS = 20_000
#: strictness of the SDP constraint ``M <= -margin * scale * I`` (room for the rigorous check;
#: NOT a soundness pad: the Arb check alone decides)
_MARGIN = 1e-7
#: the verified rate is this much (relative) below the Schur-complement rate of the multipliers
_RATE_BACKOFF = (1e-9, 1e-6, 1e-4)
#: rounds of per-layer maximisation of tr J(s) (exact per layer; a few rounds reach a fixed point)
_TRACE_ROUNDS = 8
#: bisection steps on lambda for a free metric P (each a feasibility SDP)
_METRIC_BISECTIONS = 12


@dataclass(frozen=True)
class SlopeStructure:
    """The increments of a loop affine in MLP blocks (module docstring, (11.1)).

    ``xi = (v, u)`` with ``v`` in ``R^n`` and ``u`` the ``N`` neuron output increments;
    ``a = E xi`` (``(N, n + N)``) the pre-activation increments; ``F(x) - F(y) = G xi``, whose
    columns are ``A`` (for ``v``) and ``C_k W_L`` (or ``C_k`` for output neurons), kept as the
    parts ``A``, ``C_k``, ``W`` so that the Arb check forms the products itself.
    ``alpha``, ``beta`` are the slope ranges (global unless :func:`slope_structure` got a box).
    ``E_rad`` (``None``: exact) bounds ``|E - E_exact|`` entrywise and ``cout_rad[k]`` the same
    for the ``W`` of ``couts[k]``: a network read through an input map ``N(S x)`` enters with its
    first layer ``W_0 S`` folded (:class:`~drip_cert.model.blocks.MappedMLP`), a float midpoint and
    a rigorous radius, and the Arb check takes both as balls.
    """

    n: int
    E: np.ndarray
    A: np.ndarray
    couts: tuple[tuple[np.ndarray, np.ndarray, int], ...]
    alpha: np.ndarray
    beta: np.ndarray
    layers: tuple[tuple[str, int, int, int], ...] = field(default=())
    E_rad: np.ndarray | None = None
    cout_rad: tuple[np.ndarray | None, ...] = ()

    @property
    def N(self) -> int:
        """Number of neurons."""
        return int(self.E.shape[0])

    @property
    def dim(self) -> int:
        """Size ``n + N`` of the LMI."""
        return self.n + self.N

    def G(self) -> np.ndarray:
        """Float ``G`` (``(n, n + N)``); the Arb check rebuilds it from its parts."""
        G = np.zeros((self.n, self.dim))
        G[:, : self.n] = self.A
        for C, W, col in self.couts:
            G[:, col : col + W.shape[1]] += C @ W
        return G

    def jacobian(self, slopes: np.ndarray) -> np.ndarray:
        """``J(s) = A + sum_k C_k W_L S ... S W_0`` for one choice of all slopes (floats)."""
        # d xi / d v: solve the layered recursion u = S a, a = E xi (E strictly "lower")
        n = self.n
        U = np.zeros((self.N, n))
        V = np.eye(n)
        for _, r0, r1, _ in self.layers:
            a = self.E[r0:r1, :n] @ V + self.E[r0:r1, n:] @ U
            U[r0:r1] = slopes[r0:r1, None] * a
        return self.G() @ np.vstack([V, U])


def _neuron_layers(mlp: MLP) -> list[int]:
    """Indices of the layers whose outputs are neurons (all hidden, the output if not affine)."""
    last = len(mlp.weights) - 1
    return [
        i
        for i in range(len(mlp.weights))
        if i < last or not isinstance(mlp.activations[i], Identity)
    ]


def slope_structure(
    dec: AffineBlocks, mlps: dict[str, MLP], box: np.ndarray | None = None
) -> SlopeStructure:
    """:class:`SlopeStructure` of ``F = A x + c + sum_k C_k h_k(S_k x)``; with ``box`` each
    neuron's slope range is that over its pre-activation interval on the box (interval bound
    propagation, :func:`~drip_cert.numerics.interval_np.affine_enclosure_rad` and the activations'
    enclosures), else the activation's global range. A block with an input map ``S_k``
    (:attr:`~drip_cert.analysis.growth.closed_loop.AffineBlocks.S`, e.g. ``N(Theta^{-1} z)``)
    enters as its folded network, first weight ``W_0 S_k`` as a midpoint and a rigorous radius
    (:class:`~drip_cert.model.blocks.MappedMLP`), kept in ``E_rad`` / ``cout_rad``."""
    n = int(dec.A.shape[0])
    rows: list[np.ndarray] = []
    rad_rows: list[np.ndarray] = []
    alpha: list[np.ndarray] = []
    beta: list[np.ndarray] = []
    couts = []
    cout_rad: list[np.ndarray | None] = []
    layers = []
    nets: dict[str, tuple[MLP, np.ndarray | None]] = {}
    for name in dec.C:
        if name in dec.S:
            mm = MappedMLP(mlps[name], dec.S[name])
            nets[name] = (mm.folded, None if mm.exact else np.asarray(mm.rad0))
        else:
            nets[name] = (mlps[name], None)
    N = sum(nets[k][0].weights[i].shape[0] for k in dec.C for i in _neuron_layers(nets[k][0]))
    r = 0
    for name, C in dec.C.items():
        mlp, rad0 = nets[name]
        neur = _neuron_layers(mlp)
        prev_col: int | None = None  # column of the previous layer's neurons in xi (None: v)
        lo = hi = None
        if box is not None:
            lo, hi = np.asarray(box, float)[:, 0], np.asarray(box, float)[:, 1]
        for i in neur:
            W, b, act = mlp.weights[i], mlp.biases[i], mlp.activations[i]
            m = W.shape[0]
            Ei = np.zeros((m, n + N))
            Ri = np.zeros((m, n + N))
            if prev_col is None:
                Ei[:, :n] = W
                if rad0 is not None:
                    Ri[:, :n] = rad0
            else:
                Ei[:, prev_col : prev_col + W.shape[1]] = W
            rows.append(Ei)
            rad_rows.append(Ri)
            if box is None:
                bnd = act.bounds
                alpha.append(np.full(m, bnd.slope_lo))
                beta.append(np.full(m, bnd.slope_hi))
            else:
                assert lo is not None and hi is not None
                plo, phi = affine_enclosure_rad(W, rad0 if i == 0 else None, b, lo, hi)
                slo, shi = act.slope_range(plo, phi)
                alpha.append(np.asarray(slo, float))
                beta.append(np.asarray(shi, float))
                lo, hi = act.enclose(plo, phi)
                lo, hi = np.asarray(lo, float), np.asarray(hi, float)
            layers.append((name, r, r + m, i))
            prev_col = n + r
            r += m
        if not neur:  # one affine layer: C_k W_0 acts on v
            couts.append((np.asarray(C, float), mlp.weights[0], 0))
            cout_rad.append(rad0)
        elif neur[-1] == len(mlp.weights) - 1:  # output neurons: F picks C_k u_out
            couts.append((np.asarray(C, float), np.eye(mlp.out_dim), int(prev_col or 0)))
            cout_rad.append(None)
        else:
            couts.append((np.asarray(C, float), mlp.weights[-1], int(prev_col or 0)))
            cout_rad.append(None)
    E = np.vstack(rows) if rows else np.zeros((0, n))
    E_rad = np.vstack(rad_rows) if rad_rows else np.zeros((0, n))
    return SlopeStructure(
        n,
        E,
        np.asarray(dec.A, float),
        tuple((C, W, int(col)) for C, W, col in couts),
        np.concatenate(alpha) if alpha else np.zeros(0),
        np.concatenate(beta) if beta else np.zeros(0),
        tuple(layers),
        E_rad if np.any(E_rad) else None,
        tuple(cout_rad),
    )


# ------------------------------------------------------------------ necessary condition


@dataclass(frozen=True)
class TraceObstruction:
    """``max_s tr J(s) / n`` over the slope box (a vertex found by per-layer maximisation) and the
    log norm and spectral abscissa of ``J`` at that vertex (floats: a reason, not a bound)."""

    mean_eigenvalue: float
    mu2: float
    abscissa: float
    slopes: np.ndarray
    at_upper: int = -1  #: neurons at the top of their slope range at that vertex (-1: unknown)

    def to_dict(self) -> dict[str, float | int]:
        """The condition's numbers (JSON-ready floats; a reason, not a bound)."""
        return {
            "trace_over_n": self.mean_eigenvalue,
            "mu2": self.mu2,
            "abscissa": self.abscissa,
            "neurons": int(self.slopes.size),
            "at_upper": self.at_upper,
        }

    def short(self) -> str:
        """The binding number in one clause: ``tr J(s)/n = ... > 0 at s = (the vertex)``."""
        where = (
            f"{self.at_upper} of {self.slopes.size} neurons at the top of their slope range, "
            "the rest at the bottom"
            if self.at_upper >= 0
            else f"a vertex of the {self.slopes.size} slope ranges"
        )
        return (
            f"tr J(s)/n = {self.mean_eigenvalue:.4g} > 0 at s = ({where}), and mu_P(J) >= "
            "tr J/n for every metric P"
        )

    def blocks(self, rate: float = 0.0) -> bool:
        """Whether no LMI of the form (11.3) can prove the rate ``rate``."""
        return self.mean_eigenvalue > -rate or self.abscissa > -rate

    def reason(self) -> str:
        """The number that makes the LMI impossible, as text."""
        return (
            f"with every neuron's slope chosen independently in its range, tr J(s)/n = "
            f"{self.mean_eigenvalue:.4g} (at a slope vertex; spectral abscissa "
            f"{self.abscissa:.4g}, mu_2 {self.mu2:.4g} there) and mu_P(J) >= tr(J)/n for "
            "every metric P: no "
            "slope-restricted LMI can prove contraction (this Jacobian is in the slope set; if "
            "the loop contracts, it is by correlations between slopes, e.g. a policy cancelling "
            "a plant nonlinearity, that independent slope ranges do not see)"
        )


def trace_obstruction(st: SlopeStructure) -> TraceObstruction:
    """Largest ``tr J(s) / n`` over slope vertices (module docstring), by per-layer maximisation
    from the midpoint slopes; then ``mu_2`` and the spectral abscissa at that vertex."""
    s = 0.5 * (st.alpha + st.beta)
    n = st.n
    for _ in range(_TRACE_ROUNDS):
        changed = False
        for _, r0, r1, _ in st.layers:
            # tr J(s) is affine in this layer's slopes: coefficient i = d tr J / d s_i
            coef = _trace_coefficients(st, s, r0, r1)
            new = np.where(coef > 0, st.beta[r0:r1], st.alpha[r0:r1])
            if not np.array_equal(new, s[r0:r1]):
                s[r0:r1] = new
                changed = True
        if not changed:
            break
    J = st.jacobian(s)
    sym = 0.5 * (J + J.T)
    return TraceObstruction(
        float(np.trace(J)) / n,
        float(np.linalg.eigvalsh(sym)[-1]),
        float(np.max(np.linalg.eigvals(J).real)),
        s.copy(),
        int(np.sum(s == st.beta)),
    )


def _trace_coefficients(st: SlopeStructure, s: np.ndarray, r0: int, r1: int) -> np.ndarray:
    """``d tr J(s) / d s_i`` for the neurons ``r0..r1`` (finite differences of an affine map are
    exact up to rounding: unit steps)."""
    base = np.trace(st.jacobian(s))
    out = np.empty(r1 - r0)
    for j in range(r0, r1):
        e = s.copy()
        e[j] += 1.0
        out[j - r0] = np.trace(st.jacobian(e)) - base
    return out


# ------------------------------------------------------------------ the LMI


def _neuron_terms(st: SlopeStructure, t: np.ndarray) -> np.ndarray:
    """``sum_i t_i Q_i`` (float), ``Q_i`` the matrix of ``q_i = (u - alpha a)(beta a - u)``."""
    E, a, b = st.E, st.alpha, st.beta
    n = st.n
    M = -(E.T * (t * a * b)) @ E
    K = E.T * (0.5 * t * (a + b))  # (d, N): E^T diag(t (a + b) / 2)
    M[:, n:] += K
    M[n:, :] += K.T
    M[n:, n:] -= np.diag(t)
    return M


def lmi_matrix(st: SlopeStructure, P: np.ndarray, t: np.ndarray, lam: float) -> np.ndarray:
    """The float ``M(P, t, lam)`` of (11.3) (symmetrised; the certificate uses the Arb one)."""
    n = st.n
    M = _neuron_terms(st, t)
    PG = P @ st.G()
    M[:n, :] += PG
    M[:, :n] += PG.T
    M[:n, :n] += 2.0 * lam * P
    return 0.5 * (M + M.T)


def _best_rate(st: SlopeStructure, P: np.ndarray, t: np.ndarray) -> float | None:
    """Largest ``lambda`` with ``M(P, t, lambda) <= 0`` (Schur complement on the neuron block;
    ``None`` when that block is not negative definite): ``-lambda_max(L^-1 S L^-T) / 2`` with
    ``P = L L^T`` and ``S`` the Schur complement of ``M(P, t, 0)``."""
    n = st.n
    M = lmi_matrix(st, P, t, 0.0)
    top, off, bot = M[:n, :n], M[:n, n:], M[n:, n:]
    if st.N:
        if float(np.linalg.eigvalsh(bot)[-1]) >= 0.0:
            return None
        S = top - off @ np.linalg.solve(bot, off.T)
    else:
        S = top
    L = np.linalg.cholesky(P)
    Li = np.linalg.inv(L)
    X = Li @ S @ Li.T
    return -0.5 * float(np.linalg.eigvalsh(0.5 * (X + X.T))[-1])


def _arb_ball(M: np.ndarray, rad: np.ndarray | None = None) -> arb_mat:
    r, c = M.shape
    if rad is None:
        return arb_mat([[arb(float(M[i, j])) for j in range(c)] for i in range(r)])
    return arb_mat([[arb(float(M[i, j]), float(rad[i, j])) for j in range(c)] for i in range(r)])


def verify_slope_lmi(st: SlopeStructure, P: np.ndarray, t: np.ndarray, lam: float) -> bool:
    """Rigorously check ``P > 0``, ``t >= 0`` and ``M(P, t, lam) < 0`` (11.3).

    ``M`` is assembled in Arb: ``A`` and ``C_k`` as balls of their conversion radius
    (:data:`~drip_cert.analysis.growth.closed_loop.CONVERSION_ULPS` spacings), a folded first layer
    ``W_0 S`` as balls of its radius (``E_rad``, ``cout_rad``), the other weights, slopes,
    ``P``, ``t`` and ``lam`` as the exact floats they are; ``lambda_max`` of the ball matrix is
    bounded by :func:`~drip_cert.analysis.contraction.lognorm.lambda_max_upper` (midpoint + radius).
    """
    P = np.asarray(P, float)
    t = np.asarray(t, float)
    if not np.array_equal(P, P.T) or np.any(t < 0) or not np.all(np.isfinite(t)):
        return False
    if not math.isfinite(lam) or -lambda_max_upper(-P) <= 0.0:
        return False
    n, N, d = st.n, st.N, st.dim
    Pa = _arb_ball(P)
    # G in Arb from its parts
    Ga = arb_mat(n, d)
    Aa = _arb_ball(st.A, CONVERSION_ULPS * np.spacing(np.abs(st.A)))
    for i in range(n):
        for j in range(n):
            Ga[i, j] = Aa[i, j]
    for k, (C, W, col) in enumerate(st.couts):
        w_rad = st.cout_rad[k] if k < len(st.cout_rad) else None
        CW = _arb_ball(C, CONVERSION_ULPS * np.spacing(np.abs(C))) * _arb_ball(W, w_rad)
        for i in range(n):
            for j in range(W.shape[1]):
                Ga[i, col + j] += CW[i, j]
    Ev = arb_mat(n, d)
    for i in range(n):
        Ev[i, i] = arb(1)
    PG = Pa * Ga
    M = Ev.transpose() * PG + PG.transpose() * Ev + Ev.transpose() * (Pa * arb(lam) * 2) * Ev
    if N:
        Ea = _arb_ball(st.E, st.E_rad)
        D1 = arb_mat(N, N)
        D2 = arb_mat(N, N)
        for i in range(N):
            ti = arb(float(t[i]))
            D1[i, i] = -ti * arb(float(st.alpha[i])) * arb(float(st.beta[i]))
            D2[i, i] = ti * (arb(float(st.alpha[i])) + arb(float(st.beta[i]))) / 2
        M += Ea.transpose() * D1 * Ea
        K = Ea.transpose() * D2  # (d, N)
        for i in range(d):
            for j in range(N):
                M[i, n + j] += K[i, j]
                M[n + j, i] += K[i, j]
        for j in range(N):
            M[n + j, n + j] -= arb(float(t[j]))
    mid = np.array([[float(M[i, j].mid()) for j in range(d)] for i in range(d)])
    rad = np.array([[arb_hi(abs(M[i, j] - arb(mid[i, j]))) for j in range(d)] for i in range(d)])
    return bool(lambda_max_upper(mid, rad) < 0.0)


@dataclass(frozen=True)
class SlopeLMIResult:
    """Outcome of :func:`slope_lmi_rate`.

    ``rate`` is verified (``mu_P(J) <= -rate`` for every Jacobian of the slope set, P = ``P``),
    ``None`` when no verified answer exists; ``reason`` says why (the necessary condition's
    number when it fails). ``obstruction`` is the trace condition, always computed.
    """

    rate: float | None
    P: np.ndarray
    t: np.ndarray
    status: str
    reason: str
    obstruction: TraceObstruction
    dim: int
    time_s: float

    @property
    def euclidean(self) -> bool:
        """Whether the verified metric is the identity (a ``mu_2`` rate)."""
        return bool(np.array_equal(self.P, np.eye(self.P.shape[0])))


def _solve(st: SlopeStructure, metric: bool, kappa: float, solver: str):
    """The SDP: with ``metric=False`` maximise ``lambda`` at ``P = I``; with ``metric=True``
    bisect ``lambda`` with ``I <= P <= kappa I``. Returns ``(P, t, status)`` of the best
    ``OPTIMAL`` answer (``None`` for P and t when there is none)."""
    import cvxpy as cp  # cvxpy: keep off the API's import path

    n, N, d = st.n, st.N, st.dim
    scale = max(1.0, float(np.abs(st.G()).max()))
    t = cp.Variable(N, nonneg=True)
    E, a, b = st.E, st.alpha, st.beta
    # sum_i t_i Q_i as one linear map (dense, as in LipSDP)
    Qs = []
    for i in range(N):
        Q = -(a[i] * b[i]) * np.outer(E[i], E[i])
        ei = np.zeros(d)
        ei[n + i] = 1.0
        Q += 0.5 * (a[i] + b[i]) * (np.outer(E[i], ei) + np.outer(ei, E[i]))
        Q -= np.outer(ei, ei)
        Qs.append(Q.ravel())
    Qmap = np.array(Qs).T if N else np.zeros((d * d, 0))
    G = st.G()
    Ev = np.zeros((n, d))
    Ev[:, :n] = np.eye(n)
    neur = cp.reshape(Qmap @ t, (d, d), order="C") if N else np.zeros((d, d))
    slv = getattr(cp, solver)
    kw = {"max_iters": _SCS_MAX_ITERS} if solver == "SCS" else {}
    if not metric:
        lam = cp.Variable()
        X = Ev.T @ G + G.T @ Ev + 2 * lam * (Ev.T @ Ev) + neur
        prob = cp.Problem(cp.Maximize(lam), [0.5 * (X + X.T) << -_MARGIN * scale * np.eye(d)])
        try:
            with warnings.catch_warnings():  # an inaccurate answer is rejected below
                warnings.simplefilter("ignore", UserWarning)
                prob.solve(solver=slv, **kw)
        except (cp.error.SolverError, ValueError, ArithmeticError) as exc:
            return None, None, f"solver error: {exc}"
        if prob.status != cp.OPTIMAL or t.value is None:
            return None, None, str(prob.status)
        return np.eye(n), np.maximum(np.asarray(t.value, float), 0.0), str(prob.status)
    Pv = cp.Variable((n, n), symmetric=True)
    lamp = cp.Parameter()
    X = Ev.T @ Pv @ G + G.T @ Pv @ Ev + 2 * lamp * (Ev.T @ Pv @ Ev) + neur
    prob = cp.Problem(
        cp.Minimize(0),
        [Pv >> np.eye(n), Pv << kappa * np.eye(n), 0.5 * (X + X.T) << -_MARGIN * scale * np.eye(d)],
    )
    lo, hi = -float(np.abs(G).sum()) - 1.0, float(np.abs(G).sum()) + 1.0
    best: tuple[np.ndarray, np.ndarray] | None = None
    status = "infeasible"
    for _ in range(_METRIC_BISECTIONS):
        mid = 0.5 * (lo + hi)
        lamp.value = mid
        try:
            with warnings.catch_warnings():  # an inaccurate answer is rejected below
                warnings.simplefilter("ignore", UserWarning)
                prob.solve(solver=slv, **kw)
        except (cp.error.SolverError, ValueError, ArithmeticError):
            hi = mid
            continue
        if prob.status == cp.OPTIMAL and Pv.value is not None and t.value is not None:
            P = 0.5 * (Pv.value + Pv.value.T)
            best, lo, status = (P, np.maximum(np.asarray(t.value, float), 0.0)), mid, "optimal"
        else:
            hi = mid
    if best is None:
        return None, None, status
    return best[0], best[1], status


def slope_lmi_rate(
    st: SlopeStructure,
    *,
    metric: bool = False,
    kappa: float = 1e4,
    max_dim: int = DEFAULT_MAX_DIM,
    solver: str = "auto",
    obstruct: bool = True,
) -> SlopeLMIResult:
    """The largest verified rate of the slope-restricted LMI (11.3) (module docstring).

    ``metric=False``: ``P = I`` (a ``mu_2`` rate, what DRIP and L1-DRAC use); ``metric=True``: a
    constant metric ``I <= P <= kappa I`` found by bisection. The trace condition is checked
    first: when it already rules every LMI out, no SDP is solved and ``reason`` gives its number
    (``obstruct=False`` solves anyway: the verified, then non-positive, rate still bounds
    ``max mu`` over the slope set from above, what :func:`box_slope_bnb` needs).
    """
    t0 = time.perf_counter()
    if solver not in ("auto", "CLARABEL", "SCS"):
        raise SpecError(
            f"solver={solver!r} is not one of 'auto', 'CLARABEL', 'SCS'", field="solver"
        )
    obs = trace_obstruction(st)
    eye = np.eye(st.n)
    none = np.zeros(st.N)

    def out(rate, P, t, status, reason):
        return SlopeLMIResult(rate, P, t, status, reason, obs, st.dim, time.perf_counter() - t0)

    if obstruct and obs.blocks(0.0):
        return out(None, eye, none, "obstructed", obs.reason())
    if st.dim > max_dim:
        return out(
            None,
            eye,
            none,
            "too_large",
            f"LMI size {st.dim} exceeds max_dim = {max_dim} (no SDP solved; the trace condition "
            f"tr J(s)/n <= {obs.mean_eigenvalue:.4g} does not rule an LMI out)",
        )
    if solver == "auto":
        solver = "CLARABEL" if st.dim <= _CLARABEL_MAX_DIM else "SCS"
    P, t, status = _solve(st, metric, kappa, solver)
    if P is None or t is None:
        return out(None, eye, none, status, f"no OPTIMAL SDP answer ({solver}: {status})")
    lam = _best_rate(st, P, t)
    if lam is None:
        return out(None, P, t, status, "the multipliers leave the neuron block indefinite")
    for back in _RATE_BACKOFF:
        cand = lam - back * (1.0 + abs(lam))
        if verify_slope_lmi(st, P, t, cand):
            return out(cand, P, t, status, f"verified in Arb ({solver}, d = {st.dim})")
    return out(None, P, t, status, f"no rate near {lam:.6g} survived the Arb verification")


def sampled_slopes(st: SlopeStructure, mlps: dict[str, MLP], points: np.ndarray) -> np.ndarray:
    """The slopes ``s_i = s'(z_i(x))`` of every neuron at the ``points`` (``(M, n)``), as
    ``(M, N)``: the Jacobian's actual slopes (for tests: they lie in the ranges). ``mlps`` as
    the structure reads them: for a block with an input map ``S``, the network ``N`` itself is
    evaluated at ``S x`` only if ``mlps`` holds ``N(S .)``, e.g. ``MappedMLP(N, S).folded``
    (an estimate within rounding)."""
    X = np.atleast_2d(np.asarray(points, float))
    out = np.zeros((X.shape[0], st.N))
    for name, r0, r1, i in st.layers:
        mlp = mlps[name]
        z = X
        for k in range(i):
            z = mlp.activations[k].value_np(z @ mlp.weights[k].T + mlp.biases[k])
        pre = z @ mlp.weights[i].T + mlp.biases[i]
        out[:, r0:r1] = mlp.activations[i].prime_np(pre)
    return out


# ------------------------------------------------------------------ on a box


#: work budget of :func:`box_slope_bnb`: a count of sub-boxes (one SDP each), never wall time
DEFAULT_BOX_BUDGET = 64


@dataclass(frozen=True)
class BoxSlopeResult:
    """Outcome of :func:`box_slope_bnb`.

    ``max_mu_upper`` is a sound bound of ``max mu_2(J(x))`` over the box (``inf`` when some
    sub-box has no verified LMI), ``n_boxes`` the sub-boxes solved, ``leaves`` the final
    partition with each leaf's bound, ``stop`` ``'proved'`` (every leaf at or below
    ``target``) or ``'max_boxes'``.
    """

    max_mu_upper: float
    n_boxes: int
    leaves: tuple[tuple[tuple[tuple[float, float], ...], float], ...]
    stop: str
    time_s: float


def box_slope_bnb(
    dec: AffineBlocks,
    mlps: dict[str, MLP],
    box: np.ndarray,
    *,
    target: float = 0.0,
    max_boxes: int = DEFAULT_BOX_BUDGET,
    max_dim: int = DEFAULT_MAX_DIM,
) -> BoxSlopeResult:
    """``max mu_2(J(x))`` over ``box`` by the slope-restricted LMI per sub-box (section 11.4).

    Each sub-box gets its neurons' slope ranges from interval bounds of their pre-activations
    there (:func:`slope_structure` with the box) and the verified LMI rate ``lambda_B`` with
    ``P = I`` (:func:`slope_lmi_rate`), so ``mu_2(J(x)) <= -lambda_B`` on it. The sub-box with the
    largest bound is halved along its widest side until every bound is ``<= target`` or
    ``max_boxes`` sub-boxes are solved; the result is the largest leaf bound (sound on the box).
    """
    t0 = time.perf_counter()
    box = np.asarray(box, float)
    if box.ndim != 2 or box.shape[1] != 2 or np.any(box[:, 0] > box[:, 1]):
        raise SpecError(f"box must be (n, 2) with lo <= hi, got {box.tolist()}", field="box")

    def bound(b: np.ndarray) -> float:
        st = slope_structure(dec, mlps, b)
        res = slope_lmi_rate(st, max_dim=max_dim, obstruct=False)
        return math.inf if res.rate is None else -res.rate

    leaves = [(box, bound(box))]
    n_boxes = 1
    while n_boxes + 2 <= max_boxes:
        k = max(range(len(leaves)), key=lambda i: leaves[i][1])
        b, ub = leaves[k]
        if ub <= target:
            break
        j = int(np.argmax(b[:, 1] - b[:, 0]))
        mid = 0.5 * (b[j, 0] + b[j, 1])
        lo_b, hi_b = b.copy(), b.copy()
        lo_b[j, 1] = mid
        hi_b[j, 0] = mid
        leaves[k : k + 1] = [(lo_b, bound(lo_b)), (hi_b, bound(hi_b))]
        n_boxes += 2
    top = max(ub for _, ub in leaves)
    return BoxSlopeResult(
        top,
        n_boxes,
        tuple((tuple((float(a), float(c)) for a, c in b), float(ub)) for b, ub in leaves),
        "proved" if top <= target else "max_boxes",
        time.perf_counter() - t0,
    )
