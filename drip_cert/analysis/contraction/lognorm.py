"""Matrix measures (logarithmic norms) and rigorous bounds on the largest symmetric eigenvalue.

The log norm induced by a vector norm is ``mu(A) = lim_{h->0+} (||I + hA|| - 1) / h`` (DRIP, the
definition before Assumption 2; Bullo, *Contraction Theory for Dynamical Systems*, Sec. 2.3).
Its closed forms are (Desoer & Vidyasagar 1975; Bullo Table 2.1)

* ``mu_1(A)   = max_j ( a_jj + sum_{i != j} |a_ij| )``  (column sums),
* ``mu_inf(A) = max_i ( a_ii + sum_{j != i} |a_ij| )``  (row sums),
* ``mu_2(A)   = lambda_max((A + A^T) / 2)``,
* ``mu_{2,P}(A) = lambda_max(P^{1/2} A P^{-1/2} + (P^{1/2} A P^{-1/2})^T) / 2``, the largest
  generalized eigenvalue of ``((A^T P + P A) / 2, P)``, for the norm ``||x||_P = sqrt(x^T P x)``.

All of them are vectorised over leading batch axes ``(..., n, n)``.

:func:`lambda_max_upper` and :func:`mu2_interval_upper` are *rigorous* (outward-rounded with Arb)
and are what the sound contraction certificates use. :func:`mu2_constant_bounds` encloses
``mu_2`` of one constant matrix to about one ulp *relative* (exact rational characteristic
polynomial, roots isolated in Arb), so that a value within rounding of 0 (``+8.4e-27``) keeps
its sign; the float :func:`mu_2` (``eigvalsh``) is an estimate with an absolute error of order
``eps ||A||``.
"""

from __future__ import annotations

import math

import numpy as np
import sympy as sp
from flint import acb, arb, arb_mat, fmpq, fmpq_mat

from drip_cert.errors import SpecError
from drip_cert.numerics.interval import UnsupportedExpression, enclose_expr
from drip_cert.numerics.rounding import arb_hi, arb_lo, sym_lambda_max_upper

__all__ = [
    "mu_1",
    "mu_inf",
    "mu_2",
    "mu_2_weighted",
    "spectral_abscissa",
    "lambda_max_upper",
    "mu2_interval_upper",
    "mu2_constant_bounds",
    "perron_upper",
]


def _square(A: np.ndarray, name: str = "A") -> np.ndarray:
    A = np.asarray(A, dtype=float)
    if A.ndim < 2 or A.shape[-1] != A.shape[-2]:
        raise SpecError(
            f"expected a square matrix or a batch of them, shape (..., n, n); got {A.shape}",
            field=name,
        )
    return A


def _offdiag_abs(A: np.ndarray, axis: int) -> np.ndarray:
    absA = np.abs(A)
    diag_abs = np.abs(np.diagonal(A, axis1=-2, axis2=-1))
    return absA.sum(axis=axis) - diag_abs


def mu_1(A: np.ndarray) -> np.ndarray:
    """Log norm induced by the 1-norm: ``max_j (a_jj + sum_{i!=j} |a_ij|)`` (column sums)."""
    A = _square(A)
    d = np.diagonal(A, axis1=-2, axis2=-1)
    return np.max(d + _offdiag_abs(A, axis=-2), axis=-1)


def mu_inf(A: np.ndarray) -> np.ndarray:
    """Log norm induced by the inf-norm: ``max_i (a_ii + sum_{j!=i} |a_ij|)``."""
    A = _square(A)
    d = np.diagonal(A, axis1=-2, axis2=-1)
    return np.max(d + _offdiag_abs(A, axis=-1), axis=-1)


def mu_2(A: np.ndarray) -> np.ndarray:
    """Log norm induced by the Euclidean norm: ``lambda_max((A + A^T)/2)`` (DRIP Assumption 2)."""
    A = _square(A)
    S = 0.5 * (A + np.swapaxes(A, -1, -2))
    return np.linalg.eigvalsh(S)[..., -1]


def mu_2_weighted(A: np.ndarray, P: np.ndarray) -> np.ndarray:
    """Log norm induced by ``||x||_P = sqrt(x^T P x)``, ``P`` symmetric positive definite.

    Computed as ``lambda_max(L^{-1} ((A^T P + P A)/2) L^{-T})`` with ``P = L L^T`` (Cholesky), which
    has the same eigenvalues as the symmetric part of ``P^{1/2} A P^{-1/2}``.

    Parameters
    ----------
    A
        ``(..., n, n)``.
    P
        ``(n, n)`` or broadcastable to ``A``; must be symmetric positive definite.
    """
    A = _square(A)
    P = _square(P, "P")
    if not np.allclose(P, np.swapaxes(P, -1, -2), rtol=1e-12, atol=0.0):
        raise SpecError("P must be symmetric; symmetrise it as (P + P.T) / 2", field="P")
    try:
        L = np.linalg.cholesky(P)
    except np.linalg.LinAlgError as exc:
        raise SpecError("P must be positive definite (Cholesky failed)", field="P") from exc
    S = 0.5 * (np.swapaxes(A, -1, -2) @ P + P @ A)
    Y = np.linalg.solve(L, S)  # L^{-1} S
    M = np.linalg.solve(L, np.swapaxes(Y, -1, -2))  # L^{-1} S^T L^{-T} = L^{-1} S L^{-T}
    M = 0.5 * (M + np.swapaxes(M, -1, -2))
    return np.linalg.eigvalsh(M)[..., -1]


def spectral_abscissa(A: np.ndarray) -> np.ndarray:
    """``max Re lambda_i(A)``: a lower bound on every log norm of ``A``."""
    A = _square(A)
    return np.max(np.linalg.eigvals(A).real, axis=-1)


# --------------------------------------------------------------------------------------------
# rigorous bounds
# --------------------------------------------------------------------------------------------


# _hi / _lo: float ends of an Arb ball, one ulp outward (drip_cert.numerics.rounding owns rounding)
_hi = arb_hi
_lo = arb_lo


def _arb_matrix(M: np.ndarray, R: np.ndarray | None = None) -> arb_mat:
    n = M.shape[0]
    if R is None:
        return arb_mat([[arb(float(M[i, j])) for j in range(n)] for i in range(n)])
    return arb_mat([[arb(float(M[i, j]), float(R[i, j])) for j in range(n)] for i in range(n)])


def perron_upper(N: np.ndarray) -> float:
    """Rigorous upper bound on the spectral radius of a non-negative matrix ``N``.

    Collatz-Wielandt: for any vector ``v > 0``, ``rho(N) <= max_i (N v)_i / v_i``. ``v`` is the
    numerically computed Perron vector (floored to stay positive); the quotient is evaluated in
    Arb and rounded up, so the bound is rigorous whatever the quality of ``v``.
    """
    N = np.asarray(N, dtype=float)
    if np.any(N < 0):
        raise SpecError("perron_upper needs an entry-wise non-negative matrix", field="N")
    if not np.all(np.isfinite(N)):
        return math.inf
    if not np.any(N):
        return 0.0
    n = N.shape[0]
    S = 0.5 * (N + N.T)
    w, V = np.linalg.eigh(S)
    v = np.abs(V[:, -1])
    v = np.maximum(v, 1e-8 * v.max())
    best = math.inf
    for cand in (v, np.ones(n)):
        A = _arb_matrix(N)
        vv = arb_mat([[arb(float(c))] for c in cand])
        Nv = A * vv
        q = max(_hi(Nv[i, 0] / vv[i, 0]) for i in range(n))
        best = min(best, q)
    return best


def lambda_max_upper(S: np.ndarray, R: np.ndarray | None = None) -> float:
    """Rigorous upper bound on ``lambda_max(sym A)`` for every ``A`` in ``[S - R, S + R]``.

    Method (this project's): let ``Q`` be the numerically computed eigenvector matrix of the
    symmetric ``S`` (numpy ``eigh``). In Arb compute ``M = Q^T S Q`` and ``E = Q^T Q - I``. For
    ``x = Q y``: ``x^T S x = y^T M y <= lambda_max(M) ||y||^2`` and
    ``(1 - ||E||_F) ||y||^2 <= ||x||^2 <= (1 + ||E||_F) ||y||^2``, so ``lambda_max(S)`` is at
    most ``g / (1 - ||E||_F)`` when ``g >= 0`` and ``g / (1 + ||E||_F)`` when ``g < 0``, where ``g``
    is the Gershgorin bound ``max_i (M_ii + sum_{j!=i} |M_ij|)`` of the nearly diagonal ``M``. The
    perturbation ``R >= 0`` adds ``rho(R)`` (Weyl; ``|Delta| <= R`` entry-wise implies
    ``||Delta||_2 <= rho(R)``), bounded by :func:`perron_upper`. Every step is outward-rounded,
    so the result is rigorous; its excess over the true value is of order ``n eps ||S||``.
    """
    S = np.asarray(S, dtype=float)
    n = S.shape[0]
    if not np.all(np.isfinite(S)):
        return math.inf
    Ssym = 0.5 * (S + S.T)
    if not np.array_equal(S, S.T):  # widen R by the rounding of the symmetric part
        extra = np.nextafter(2.0 * np.spacing(np.abs(Ssym)), np.inf)
        R = extra if R is None else np.nextafter(np.asarray(R, dtype=float) + extra, np.inf)
    S = Ssym
    _, Q = np.linalg.eigh(S)
    Qa = _arb_matrix(Q)
    M = Qa.transpose() * _arb_matrix(S) * Qa
    E = Qa.transpose() * Qa - arb_mat(
        n, n, [1 if i == j else 0 for i in range(n) for j in range(n)]
    )
    e2 = arb(0)
    for i in range(n):
        for j in range(n):
            a = E[i, j].abs_upper()  # exact upper end of |E_ij| (a ball's square may dip below 0)
            e2 += a * a
    eF = _hi(e2.sqrt())
    if eF >= 0.5:
        raise ArithmeticError("eigenvector matrix far from orthogonal; cannot bound lambda_max")
    g = -math.inf
    for i in range(n):
        row = M[i, i]
        for j in range(n):
            if j != i:
                row += abs(M[i, j])
        g = max(g, _hi(row))
    den = arb(1) - arb(eF) if g >= 0 else arb(1) + arb(eF)
    bound = _hi(arb(g) / den)
    if R is not None:
        R = np.asarray(R, dtype=float)
        if np.any(R < 0):
            raise SpecError("radius matrix R must be non-negative", field="R")
        Rs = np.maximum(R, R.T)  # |sym(Delta)| <= (R + R^T)/2 <= max(R, R^T)
        bound = _hi(arb(bound) + arb(perron_upper(Rs)))
    return bound


def mu2_interval_upper(lo: np.ndarray, hi: np.ndarray) -> float:
    """Rigorous upper bound on ``mu_2(A)`` over the interval matrix ``lo <= A <= hi``.

    Rohn-type bound, sharpened on the diagonal: write ``A = C + D + Delta`` where ``C`` has the
    off-diagonal centres and the diagonal *upper* ends ``hi_ii``, ``D = diag(a_ii - hi_ii) <= 0``
    and ``Delta`` is off-diagonal with ``|Delta| <= R`` (the off-diagonal radii). Then
    ``mu_2(A) = lambda_max(sym C + D + sym Delta) <= lambda_max(sym C) + rho(sym R)``, because
    adding a negative semidefinite ``D`` never raises ``lambda_max`` (Weyl) and
    ``|sym Delta| <= sym R`` entry-wise gives ``||sym Delta||_2 <= rho(sym R)``. It is often
    tighter than the plain Rohn bound ``lambda_max(sym centre) + rho(sym radius)`` (a wide negative
    diagonal costs nothing), but not always: with ``a_11 in [-1, 1]``, ``a_12 = a_21 in
    [-0.1, 0.1]``, ``a_22 = 0`` it gives 1.1 where Rohn gives 1.0099 (both valid). ``C`` is
    rounded to floats and ``R`` rounded up so that the decomposition holds; both terms are
    bounded rigorously by :func:`lambda_max_upper`.
    """
    lo = np.asarray(lo, dtype=float)
    hi = np.asarray(hi, dtype=float)
    if not (np.all(np.isfinite(lo)) and np.all(np.isfinite(hi))):
        return math.inf
    C = 0.5 * lo + 0.5 * hi
    R = np.maximum(np.nextafter(hi - C, np.inf), np.nextafter(C - lo, np.inf))
    R = np.maximum(np.nextafter(R, np.inf), 0.0)
    diag = np.diag_indices_from(C)
    C[diag] = hi[diag]
    R[diag] = 0.0
    # lambda_max_upper takes the symmetric part of C (widening R by its rounding) and bounds the
    # symmetric part of the perturbation by max(R, R^T) >= |sym(Delta)|
    return lambda_max_upper(C, R)


# --------------------------------------------------------------------------------------------
# mu_2 of one constant matrix, to relative accuracy
# --------------------------------------------------------------------------------------------

EXACT_MAX_DIM = 48
"""Largest ``n`` for which :func:`mu2_constant_bounds` takes the exact rational route (the
characteristic polynomial of a ``48 x 48`` dyadic matrix and its roots take well under a second);
above it the bounds come from
:func:`~drip_cert.numerics.rounding.sym_lambda_max_upper` and a Rayleigh
quotient in Arb (absolute accuracy ``~ n eps ||A||``)."""


def _fmpq(x: float) -> fmpq:
    """The exact rational value of a finite float."""
    return fmpq(*float(x).as_integer_ratio())


def _exact_entries(
    A: np.ndarray | sp.MatrixBase,
) -> tuple[np.ndarray, list, np.ndarray, np.ndarray]:
    """Split ``A`` into exactly known parts.

    Returns ``(C, Q, R, Rf)``: ``Q`` the exact rational centre (a list of rows of ``fmpq``),
    ``R`` the radius of ``A`` around ``Q`` (non-zero only for entries that are not rational,
    enclosed in Arb), ``C`` a float matrix and ``Rf >= R`` the radius of ``A`` around ``C`` (adds
    the rounding of rationals that are not floats, such as ``1/3``).
    """
    if not isinstance(A, sp.MatrixBase):
        C = np.asarray(A, dtype=float)
        if C.ndim != 2:
            raise SpecError(f"expected a square matrix, got shape {C.shape}", field="A")
        Q = [[_fmpq(v) if math.isfinite(v) else fmpq(0) for v in row] for row in C]
        return C, Q, np.zeros_like(C), np.zeros_like(C)
    n, m = A.shape
    C, R, Rf = np.zeros((n, m)), np.zeros((n, m)), np.zeros((n, m))
    Q = []
    for i in range(n):
        row = []
        for j in range(m):
            e = sp.sympify(A[i, j])
            if e.free_symbols:
                raise SpecError(f"entry ({i}, {j}) = {e} is not constant", field="A")
            if e.is_Rational or e.is_Float:
                q = sp.Rational(e)
                row.append(fmpq(int(q.p), int(q.q)))
                C[i, j] = float(q)
                if sp.Rational(C[i, j]) != q:  # round to nearest: within one spacing
                    Rf[i, j] = float(np.nextafter(np.spacing(abs(C[i, j])), np.inf))
                continue
            try:
                lo, hi = enclose_expr(e, [], np.zeros((0, 2)))
            except UnsupportedExpression as exc:
                raise SpecError(
                    f"entry ({i}, {j}) = {e} is not a real constant", field="A"
                ) from exc
            c = 0.5 * lo + 0.5 * hi
            C[i, j] = c
            R[i, j] = Rf[i, j] = max(
                math.nextafter(hi - c, math.inf), math.nextafter(c - lo, math.inf)
            )
            row.append(_fmpq(c))
        Q.append(row)
    return C, Q, R, Rf


def _sym_lambda_max_exact(Q: list, n: int) -> tuple[float, float]:
    """Enclosure of ``lambda_max((A + A^T) / 2)`` for the exact rational matrix ``Q``: the
    characteristic polynomial has exact rational coefficients, its roots (all real, the matrix
    is symmetric) are isolated by Arb (``fmpq_poly.complex_roots``: certified balls at the working
    precision), and ``lambda_max`` lies between the largest lower end and the largest upper
    end of their real parts."""
    half = fmpq(1, 2)
    S = fmpq_mat(n, n, [(Q[i][j] + Q[j][i]) * half for i in range(n) for j in range(n)])
    # python-flint 0.9's stub says list[acb]; the runtime returns (root, multiplicity) pairs
    roots: list[tuple[acb, int]] = S.charpoly().complex_roots()  # type: ignore[assignment]
    lo = max(arb_lo(c.real) for c, _ in roots)
    hi = max(arb_hi(c.real) for c, _ in roots)
    return lo, hi


def _sym_lambda_max_float(C: np.ndarray) -> tuple[float, float]:
    """Enclosure of ``lambda_max((C + C^T) / 2)`` for a float ``C`` of any size: ``hi`` from
    :func:`~drip_cert.numerics.rounding.sym_lambda_max_upper`, ``lo`` the Rayleigh quotient
    ``v^T S v / v^T v`` in Arb at the float top eigenvector ``v`` (any ``v`` gives a lower
    bound)."""
    hi = float(sym_lambda_max_upper(C))
    Ca = _arb_matrix(C)
    Sa = (Ca + Ca.transpose()) * arb(0.5)
    v = np.linalg.eigh(0.5 * (C + C.T))[1][:, -1]
    va = arb_mat([[arb(float(x))] for x in v])
    lo = arb_lo((va.transpose() * Sa * va)[0, 0] / (va.transpose() * va)[0, 0])
    return lo, hi


def mu2_constant_bounds(A: np.ndarray | sp.MatrixBase) -> tuple[float, float]:
    """Rigorous ``(lo, hi)`` with ``lo <= mu_2(A) = lambda_max((A + A^T)/2) <= hi`` for one constant
    matrix (DRIP Assumption 2 for a linear or affine closed loop).

    Exact route (``n <= EXACT_MAX_DIM``): every float (and every sympy ``Integer``, ``Rational`` or
    ``Float``) is an exact rational, so the symmetric part and its characteristic polynomial are
    computed exactly (FLINT ``fmpq_mat.charpoly``) and its roots isolated in Arb; ``lo`` and ``hi``
    are within a few ulps of ``mu_2`` *relative to* ``mu_2`` itself, so a tiny ``mu_2`` keeps its
    sign (a matrix with ``mu_2 = +6.5e-27`` and unit entries gives ``lo > 0``, where ``eigvalsh``
    returns ``0`` or ``-1e-16``). Entries of a sympy matrix that are not rational (``sqrt(2)``,
    ``pi``) are enclosed in Arb (:func:`~drip_cert.numerics.interval.enclose_expr`); the
    enclosure's float centre goes through the exact route and its radius ``R`` widens the result by
    ``rho(max(R, R^T))`` (Weyl; bounded by :func:`perron_upper`).

    Above ``EXACT_MAX_DIM``: ``hi`` from
    :func:`~drip_cert.numerics.rounding.sym_lambda_max_upper` and
    ``lo`` from a Rayleigh quotient in Arb (absolute accuracy ``~ n eps ||A||``).

    Parameters
    ----------
    A
        ``(n, n)`` float array or a constant ``sympy.Matrix``.

    Returns
    -------
    tuple of float
        ``(lo, hi)``; ``(-inf, inf)`` when an entry is not finite.
    """
    C, Q, R, Rf = _exact_entries(A)
    if C.shape[0] != C.shape[1]:
        raise SpecError(f"expected a square matrix, got shape {C.shape}", field="A")
    n = C.shape[0]
    if n == 0:
        raise SpecError("mu_2 of an empty matrix is undefined", field="A")
    if not (np.all(np.isfinite(C)) and np.all(np.isfinite(Rf))):
        return -math.inf, math.inf
    if n <= EXACT_MAX_DIM:
        lo, hi = _sym_lambda_max_exact(Q, n)
    else:
        lo, hi = _sym_lambda_max_float(C)
        R = Rf
    if np.any(R > 0):
        w = arb(perron_upper(np.maximum(R, R.T)))
        lo = arb_lo(arb(lo) - w)
        hi = arb_hi(arb(hi) + w)
    return lo, hi
