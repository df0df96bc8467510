"""Contraction metric by convex optimisation (a quasi-convex generalized eigenvalue problem).

A constant metric ``P > 0`` makes the closed loop contract in ``||x||_P = sqrt(x^T P x)`` at rate
``lambda`` iff ``mu_{2,P}(J) <= -lambda``, i.e. ``J^T P + P J <= -2 lambda P`` for every Jacobian
``J`` in the region (Bullo, *Contraction Theory*, Thm. 3.9 with a weighted 2-norm; DRIP mentions
Riemannian metrics as an alternative route to Assumption 2). The constraint is affine in ``J`` for a
fixed ``P`` and ``lambda``, so it holds on the convex hull of any finite set of matrices on which it
holds. Polytopic over-approximation used here: the box (and time range) is cut into sub-boxes, the
Jacobian is enclosed entry-wise on each sub-box by rigorous interval arithmetic
(``lo <= J(x) <= hi`` for every ``x`` in it), and the interval matrix ``[lo, hi]`` is a box in
``R^{n x n}``, which is the convex hull of its ``2^k`` vertices (``k`` = number of entries with
``lo < hi``). Hence every Jacobian on the region lies in the convex hull of the union of vertices,
and an LMI verified at all of them holds on the whole region.

``lambda`` enters bilinearly (``lambda * P``), so it is found by bisection, each step a
feasibility SDP with the normalisation ``I <= P <= kappa I``, written once in Clarabel's conic form
(only the constraint matrix moves with ``lambda``, affinely) and solved by Clarabel directly. It is
solved on the vertices with entries that are rounding hulls (one-ulp intervals around constants)
set to their midpoints, with a margin that covers the difference. Every solver answer is re-checked:
anything but ``Solved`` counts as infeasible (``AlmostSolved`` certifies nothing), the answer is
re-checked in floats on every vertex, and the final ``P`` is verified on every vertex with rigorous
outward-rounded eigenvalue bounds (:func:`~drip_cert.analysis.contraction.lognorm.lambda_max_upper`)
on ``A_i^T P + P A_i + 2 lambda P`` computed in Arb.

The paper's bounds use the Euclidean rate; the metric rate is reported beside it with ``cond(P)``
(a metric rate turns into ``||dx(t)|| <= sqrt(cond P) e^{-lambda_P t} ||dx(0)||``, not into
Assumption 2 itself).
"""

from __future__ import annotations

import itertools
import math
import time
from collections.abc import Sequence
from dataclasses import dataclass
from typing import Any

import numpy as np
import sympy as sp
from flint import arb, arb_mat

from drip_cert.analysis.contraction.lognorm import (
    lambda_max_upper,
    mu_2,
    mu_2_weighted,
    spectral_abscissa,
)
from drip_cert.analysis.contraction.rate import (
    JacobianFn,
    SamplingOptions,
    _check_inputs,
    _grid,
    _scope,
    jacobian_function,
)
from drip_cert.errors import SolverError, SpecError
from drip_cert.numerics.interval import EncloseCallback, MatrixEnclosure, UnsupportedExpression
from drip_cert.numerics.rounding import arb_hi
from drip_cert.provenance import How, Quantity, Scope, json_float

__all__ = [
    "MetricResult",
    "interval_vertices",
    "jacobian_vertices",
    "metric_rate_lmi",
    "verify_metric",
    "contraction_metric",
    "DEFAULT_KAPPA",
    "DEFAULT_MAX_VERTICES",
]

#: default bound on cond(P) (normalisation I <= P <= kappa I)
DEFAULT_KAPPA = 1e4
#: above this many vertices the polytope is replaced by sampled Jacobians (ESTIMATE)
DEFAULT_MAX_VERTICES = 4096
#: bisection stops when the bracket on lambda is narrower than this
DEFAULT_BISECTION_TOL = 1e-4
#: sampled Jacobians of the fallback (when no polytope is available)
_METRIC_SAMPLING = SamplingOptions(n_grid=256, n_random=256)
#: strictness of the SDP constraints: A^T P + P A + 2 lambda P <= -margin I
_MARGIN = 1e-7
#: relative spread of a matrix entry over the vertices below which it is a rounding hull (a few
#: ulps of an exactly given constant), solved at its midpoint (:func:`_solve_set`)
_THIN = 1e-12


@dataclass(frozen=True)
class MetricResult:
    """A verified constant contraction metric.

    Attributes
    ----------
    metric_rate
        ``lambda_P`` with ``mu_{2,P}(A_i) <= -lambda_P`` at every vertex, verified rigorously.
    euclidean_rate
        ``-max_i mu_2(A_i)`` over the same vertices (the ``P = I`` rate, what the paper's bounds
        use), rigorously rounded.
    P
        The metric (read-only array), ``I <= P <= kappa I``.
    cond_P
        Condition number of ``P``.
    how
        ``SOUND`` when the vertices come from the interval enclosure, ``ESTIMATE`` when they are
        sampled Jacobians.
    region, n_vertices, kappa, bisection_tol, time_s, note
        Scope and bookkeeping.
    """

    metric_rate: float
    euclidean_rate: float
    P: np.ndarray
    cond_P: float
    how: How
    scope: Scope
    n_vertices: int
    kappa: float
    bisection_tol: float
    time_s: float
    note: str = ""
    method: str = "lmi-metric"

    def __post_init__(self) -> None:
        P = np.array(self.P, dtype=float)
        P.setflags(write=False)
        object.__setattr__(self, "P", P)

    @property
    def region(self) -> str:
        """Where the metric rate holds, as text."""
        return self.scope.describe()

    @property
    def transient_gain(self) -> float:
        """``sqrt(cond P)``: overshoot factor of the Euclidean distance under the metric rate."""
        return math.sqrt(self.cond_P)

    def to_quantity(self) -> Quantity:
        """The metric rate as a :class:`Quantity` named ``lambda_P``."""
        return Quantity(
            "lambda_P",
            self.metric_rate,
            self.how,
            "contraction metric (Bullo, Contraction Theory, Thm 3.9, weighted 2-norm)",
            f"LMI on {self.n_vertices} vertices, {self.region}, cond(P) = {self.cond_P:.4g}; "
            f"Euclidean rate on the same vertices {self.euclidean_rate:.6g}",
            self.scope,
        )

    def to_dict(self) -> dict[str, Any]:
        """JSON-ready dictionary."""
        return {
            "metric_rate": json_float(self.metric_rate),
            "euclidean_rate": json_float(self.euclidean_rate),
            "P": self.P.tolist(),
            "cond_P": json_float(self.cond_P),
            "how": How(self.how).value,
            "method": self.method,
            "region": self.region,
            "n_vertices": int(self.n_vertices),
            "kappa": json_float(self.kappa),
            "bisection_tol": json_float(self.bisection_tol),
            "time_s": float(self.time_s),
            "note": self.note,
        }


# --------------------------------------------------------------------------------------------
# vertices
# --------------------------------------------------------------------------------------------


def interval_vertices(lo: np.ndarray, hi: np.ndarray) -> np.ndarray:
    """All ``2^k`` vertices of the interval matrix ``[lo, hi]`` (``k`` uncertain entries).

    Returns an array of shape ``(2^k, n, n)``.
    """
    lo = np.asarray(lo, dtype=float)
    hi = np.asarray(hi, dtype=float)
    idx = np.flatnonzero(hi.ravel() > lo.ravel())
    base = lo.ravel().copy()
    out = np.repeat(base[None, :], 2 ** len(idx), axis=0)
    for v, choice in enumerate(itertools.product((0, 1), repeat=len(idx))):
        for j, c in zip(idx, choice):
            if c:
                out[v, j] = hi.ravel()[j]
    return out.reshape(-1, *lo.shape)


def jacobian_vertices(
    J: sp.Matrix,
    states: Sequence[sp.Symbol],
    box: np.ndarray | None = None,
    t: sp.Symbol | None = None,
    t_range: tuple[float, float] | None = None,
    *,
    enclose: EncloseCallback | None = None,
    splits: int = 4,
    max_vertices: int = DEFAULT_MAX_VERTICES,
) -> np.ndarray:
    """Vertices of a polytope that contains ``{J(t, x)}`` over the region (see module docstring).

    Each variable ``J`` depends on is cut into ``splits`` equal parts. Raises
    :class:`UnsupportedExpression` when an entry has no enclosure, and :class:`SpecError` when the
    count would exceed ``max_vertices`` (lower ``splits`` or sample instead).
    """
    n, states, box, t_range = _check_inputs(J, states, box, t, t_range)
    depends_t = t is not None and J.has(t)
    if depends_t and t_range is None:
        raise SpecError("J depends on t; give t_range", field="t_range")
    if J.free_symbols & set(states) and box is None:
        raise SpecError("J depends on the states; give a box of shape (n, 2)", field="box")
    sbox = box if box is not None else np.zeros((n, 2))
    full = np.vstack([sbox, [t_range]]) if depends_t else sbox
    variables = [*states, t] if depends_t else list(states)
    menc = MatrixEnclosure(J, variables, enclose)
    cuts = []
    for i, v in enumerate(variables):
        k = splits if (J.has(v) and full[i, 1] > full[i, 0]) else 1
        e = np.linspace(full[i, 0], full[i, 1], k + 1)
        cuts.append(list(zip(e[:-1], e[1:])))
    verts: list[np.ndarray] = []
    count = 0
    for cell in itertools.product(*cuts):
        lo, hi = menc(np.array(cell, dtype=float))
        k = int(np.count_nonzero(hi > lo))
        count += 2**k
        if count > max_vertices:
            raise SpecError(
                f"more than max_vertices = {max_vertices} vertices (an entry-wise hull with {k} "
                f"uncertain entries per sub-box); lower splits or raise max_vertices",
                field="max_vertices",
            )
        verts.append(interval_vertices(lo, hi))
    V = np.concatenate(verts)
    return np.unique(V.reshape(len(V), -1), axis=0).reshape(-1, n, n)


# --------------------------------------------------------------------------------------------
# verification and the SDP
# --------------------------------------------------------------------------------------------


def _arb_mat(M: np.ndarray) -> arb_mat:
    n = M.shape[0]
    return arb_mat([[arb(float(M[i, j])) for j in range(n)] for i in range(n)])


def verify_metric(As: np.ndarray, P: np.ndarray, lam: float) -> bool:
    """Rigorously check ``P > 0`` and ``A_i^T P + P A_i + 2 lam P <= 0`` for every ``A_i``.

    The products are formed in Arb (balls); the largest eigenvalue of each ball matrix is bounded
    by :func:`~drip_cert.analysis.contraction.lognorm.lambda_max_upper` (midpoint + radius).
    """
    P = np.asarray(P, dtype=float)
    if not np.array_equal(P, P.T):
        return False
    if -lambda_max_upper(-P) <= 0.0:  # lambda_min(P) > 0, rigorously
        return False
    Pa = _arb_mat(P)
    two_lam = arb(2) * arb(float(lam))
    n = P.shape[0]
    for A in np.asarray(As, dtype=float):
        Aa = _arb_mat(A)
        M = Aa.transpose() * Pa + Pa * Aa + Pa * two_lam
        mid = np.array([[float(M[i, j].mid()) for j in range(n)] for i in range(n)])
        # radius around the *float* midpoint, so that [mid - rad, mid + rad] contains the ball
        rad = np.array(
            [[arb_hi(abs(M[i, j] - arb(mid[i, j]))) for j in range(n)] for i in range(n)]
        )
        if lambda_max_upper(mid, rad) > 0.0:
            return False
    return True


def _svec_index(n: int) -> list[tuple[int, int]]:
    """Entries ``(i, j)``, ``i <= j``, of the upper triangle in column-major order (Clarabel's
    ``PSDTriangleConeT`` layout)."""
    return [(i, j) for j in range(n) for i in range(j + 1)]


def _svec(M: np.ndarray, index: list[tuple[int, int]]) -> np.ndarray:
    """``svec(M)``: the upper triangle of a symmetric ``M``, off-diagonal entries times ``sqrt 2``
    (so that ``<svec X, svec Y> = tr(X Y)``, the scaling of Clarabel's PSD triangle cone)."""
    return np.array([M[i, j] * (1.0 if i == j else math.sqrt(2.0)) for i, j in index])


@dataclass(frozen=True)
class _MetricSDP:
    """The feasibility SDP of :func:`metric_rate_lmi` in Clarabel's conic form, built once.

    The decision vector ``p`` holds the upper triangle of ``P`` (``P = sum_k p_k E_k`` with
    ``E_k = e_i e_j^T + e_j e_i^T``, ``i < j``, or ``e_i e_i^T``). With ``S`` the matrix whose
    column ``k`` is ``svec(E_k)`` and ``L_A`` that of ``svec(A^T E_k + E_k A)``, the constraints
    ``P - I >= 0``, ``kappa I - P >= 0`` and ``-(A^T P + P A + 2 lam P) - margin I >= 0`` read
    ``G(lam) p + s = h``, ``s`` in a product of PSD triangle cones, with
    ``G(lam) = G_0 + lam G_1`` (rows ``-S``; ``S``; ``L_A + 2 lam S`` per matrix). Only ``G``
    depends on ``lam``, affinely, so each bisection step is one sparse sum and one solve.
    """

    G0: Any  # scipy.sparse.csc_matrix
    G1: Any
    h: np.ndarray
    E: np.ndarray  # (m, n, n) basis of the symmetric matrices
    n_blocks: int

    @classmethod
    def build(cls, As: np.ndarray, kappa: float, margin: float) -> _MetricSDP:
        import scipy.sparse as sps  # scipy: only a metric search needs it (not every certify)

        n = As.shape[1]
        index = _svec_index(n)
        E = np.zeros((len(index), n, n))
        for k, (i, j) in enumerate(index):
            E[k, i, j] = E[k, j, i] = 1.0
        S = np.stack([_svec(Ek, index) for Ek in E], axis=1)
        eye = _svec(np.eye(n), index)
        zero = np.zeros_like(S)
        g0, g1, h = [-S, S], [zero, zero], [-eye, kappa * eye]
        for A in As:
            g0.append(np.stack([_svec(A.T @ Ek + Ek @ A, index) for Ek in E], axis=1))
            g1.append(2.0 * S)
            h.append(-margin * eye)
        return cls(
            sps.csc_matrix(np.vstack(g0)),
            sps.csc_matrix(np.vstack(g1)),
            np.concatenate(h),
            E,
            len(As) + 2,
        )

    def solve(self, lam: float) -> np.ndarray | None:
        """``P`` from one Clarabel solve at rate ``lam``; ``None`` unless the status is
        ``Solved`` (``AlmostSolved``, infeasible, or a solver error certify nothing)."""
        import clarabel  # clarabel: only a metric search solves an SDP (not every certify)
        import scipy.sparse as sps  # scipy: as clarabel

        m, n = self.E.shape[0], self.E.shape[1]
        settings = clarabel.DefaultSettings()
        settings.verbose = False
        cones = [clarabel.PSDTriangleConeT(n)] * self.n_blocks
        try:
            solver = clarabel.DefaultSolver(
                sps.csc_matrix((m, m)),
                np.zeros(m),
                (self.G0 + lam * self.G1).tocsc(),
                self.h,
                cones,
                settings,
            )
            sol = solver.solve()
        except Exception:  # a solver failure is an infeasible step, never a certificate
            return None
        if sol.status != clarabel.SolverStatus.Solved:
            return None
        return np.einsum("k,kij->ij", np.asarray(sol.x, dtype=float), self.E)


def _solve_set(As: np.ndarray, kappa: float) -> tuple[np.ndarray, float]:
    """The matrices the SDP is solved on, and the margin that covers the ones left out.

    An entry whose spread over all ``As`` is at most :data:`_THIN` (relative) is a rounding
    hull, not a variation (a constant Jacobian entry like ``45149/1000`` encloses to a one-ulp
    interval, and ``k`` such entries give ``2^k`` vertices): it is set to its midpoint and the
    duplicates dropped. Each matrix then differs from one kept by ``D`` with ``|D_ij| <= r_ij``
    (half the spread), so ``||D^T P + P D||_2 <= 2 ||P||_2 ||r||_F <= 2 kappa ||r||_F``: the SDP's
    margin grows by that much and its answer holds on every matrix. The final verification is
    on all of them anyway.
    """
    lo, hi = As.min(axis=0), As.max(axis=0)
    thin = (hi - lo) <= _THIN * (1.0 + np.abs(lo) + np.abs(hi))
    if not np.any(thin & (hi > lo)):
        return As, _MARGIN
    mid = 0.5 * (lo + hi)
    red = np.where(thin[None], mid[None], As)
    red = np.unique(red.reshape(len(red), -1), axis=0).reshape(-1, *As.shape[1:])
    r = np.where(thin, 0.5 * (hi - lo), 0.0)
    return red, _MARGIN + 2.0 * kappa * float(np.linalg.norm(r))


def metric_rate_lmi(
    As: np.ndarray,
    kappa: float = DEFAULT_KAPPA,
    tol: float = DEFAULT_BISECTION_TOL,
) -> tuple[float, np.ndarray, str]:
    """Best rate of a common metric ``I <= P <= kappa I`` for the matrices ``As`` by bisection.

    Returns ``(lambda_P, P, log)`` where ``lambda_P`` is verified by :func:`verify_metric`
    (``mu_{2,P}(A_i) <= -lambda_P`` for all ``i``), and ``log`` summarises the solves.
    Raises :class:`SolverError` when not even the Euclidean start point verifies.

    Each step solves the SDP of :class:`_MetricSDP` (built once, at the first step) on
    :func:`_solve_set` of ``As`` with Clarabel, re-checks the answer in floats on every matrix,
    and the final ``P`` is verified in Arb on every matrix. The number of solves is fixed by the
    bracket and ``tol`` (none when the Euclidean rate already meets the spectral abscissa).
    """
    As = np.asarray(As, dtype=float)
    if As.ndim != 3 or As.shape[1] != As.shape[2] or len(As) == 0:
        raise SpecError(f"As must have shape (V, n, n) with V >= 1, got {As.shape}", field="As")
    if not kappa >= 1.0:
        raise SpecError(f"kappa must be >= 1, got {kappa}", field="kappa")
    n = As.shape[1]
    eye = np.eye(n)
    red, margin = _solve_set(As, kappa)
    sdp: list[_MetricSDP] = []  # built at the first solve (none when the bracket is closed)

    def feasible(value: float) -> np.ndarray | None:
        if not sdp:
            sdp.append(_MetricSDP.build(red, kappa, margin))
        Pv = sdp[0].solve(value)
        if Pv is None:
            return None
        Pv = 0.5 * (Pv + Pv.T)
        # numpy re-check of the solver's answer (the rigorous check comes at the end)
        if np.linalg.eigvalsh(Pv)[0] <= 0:
            return None
        M = np.swapaxes(As, 1, 2) @ Pv + Pv @ As + 2 * value * Pv
        if np.max(np.linalg.eigvalsh(0.5 * (M + np.swapaxes(M, 1, 2)))[:, -1]) >= 0:
            return None
        return Pv

    euclid = -float(np.max(mu_2(As)))
    lo = euclid - 1e-6 * (1 + abs(euclid))
    P_best = eye.copy()
    hi = -float(np.max(spectral_abscissa(As)))  # no metric beats the spectral abscissa
    n_solves = 0
    while hi - lo > tol:
        mid = 0.5 * (lo + hi)
        Pv = feasible(mid)
        n_solves += 1
        if Pv is None:
            hi = mid
        else:
            lo, P_best = mid, Pv
    # the rate this P actually achieves, then verified rigorously (a little below, for rounding)
    achieved = -float(np.max(mu_2_weighted(As, P_best)))
    log = f"{n_solves} SDP solves on {len(red)} of {len(As)} vertices, bracket [{lo:.6g}, {hi:.6g}]"
    for cand in (achieved - 1e-9 * (1 + abs(achieved)), lo):
        if verify_metric(As, P_best, cand):
            return cand, P_best, log
    if verify_metric(As, eye, euclid - 1e-9 * (1 + abs(euclid))):
        return euclid - 1e-9 * (1 + abs(euclid)), eye, "no SDP answer survived verification"
    raise SolverError("no metric (not even P = I) survived rigorous verification")


def contraction_metric(
    J: sp.Matrix,
    states: Sequence[sp.Symbol],
    box: np.ndarray | None = None,
    t: sp.Symbol | None = None,
    t_range: tuple[float, float] | None = None,
    *,
    J_num: JacobianFn | None = None,
    enclose: EncloseCallback | None = None,
    splits: int = 4,
    max_vertices: int = DEFAULT_MAX_VERTICES,
    kappa: float = DEFAULT_KAPPA,
    tol: float = DEFAULT_BISECTION_TOL,
    sampling: SamplingOptions = _METRIC_SAMPLING,
) -> MetricResult:
    """Contraction metric ``P`` and rate for the closed loop with Jacobian ``J`` on a region.

    Vertices come from :func:`jacobian_vertices` (SOUND); when the expression has no rigorous
    enclosure or the vertex count exceeds ``max_vertices``, sampled Jacobians are used instead
    and the result is an ESTIMATE. Inputs as in
    :func:`~drip_cert.analysis.contraction.rate.contraction_rate`.
    """
    t0 = time.perf_counter()
    n, states, box, t_range = _check_inputs(J, states, box, t, t_range)
    depends_t = t is not None and J.has(t)
    depends_x = bool(J.free_symbols & set(states))
    note = ""
    try:
        As = jacobian_vertices(
            J,
            states,
            box,
            t,
            t_range,
            enclose=enclose,
            splits=splits,
            max_vertices=max_vertices,
        )
        how = How.SOUND
    except (UnsupportedExpression, SpecError) as exc:
        if isinstance(exc, SpecError) and exc.field != "max_vertices":
            raise
        if J_num is None:
            J_num = jacobian_function(J, states, t)
        sbox = box if box is not None else np.zeros((n, 2))
        full = np.vstack([sbox, [t_range]]) if depends_t else sbox
        rng = np.random.default_rng(sampling.seed)
        pts = np.concatenate(
            [
                _grid(full, sampling.n_grid),
                full[:, 0] + rng.random((sampling.n_random, full.shape[0])) * np.ptp(full, axis=1),
            ]
        )
        tv = pts[:, n] if depends_t else np.zeros(len(pts))
        As = J_num(tv, pts[:, :n])
        how = How.ESTIMATE
        note = f"sampled Jacobians ({len(As)}), NOT a polytope: {exc}"
    rate, P, log = metric_rate_lmi(As, kappa=kappa, tol=tol)
    euclid = -max(lambda_max_upper(A) for A in As)
    w = np.linalg.eigvalsh(P)
    return MetricResult(
        metric_rate=rate,
        euclidean_rate=euclid,
        P=P,
        cond_P=float(w[-1] / w[0]),
        how=how,
        scope=_scope(box if depends_x else None, t_range, depends_t),
        n_vertices=len(As),
        kappa=kappa,
        bisection_tol=tol,
        time_s=time.perf_counter() - t0,
        note=(note + "; " if note else "") + log,
    )
