"""Directed (outward) rounding: the one module of drip-cert that owns it.

Every number that drip-cert labels ``exact`` or ``sound`` and computes in floating point goes
through the functions here, or through Arb (python-flint) with :func:`arb_lo` / :func:`arb_hi`.

Guarantee
---------
1. **Correctly rounded operations.** IEEE-754 binary64 ``+ - * /`` and ``sqrt`` are correctly
   rounded: with the default rounding mode (round to nearest, which neither Python nor numpy ever
   changes) the computed result ``r`` is the exact result ``x`` of the operation *on the same
   float operands* rounded to the nearest float, so ``|x - r| <= ulp/2`` and
   ``nextafter(r, -inf) <= x <= nextafter(r, +inf)``. This also holds on gradual underflow
   (the error is then at most half of ``2**-1074``) and on overflow (``r = +-inf`` only when
   ``|x|`` exceeds the largest float, and ``nextafter(inf, -inf)`` is that largest float).
   :func:`up`, :func:`down` and the ``*_up`` / ``*_down`` helpers move one ulp outward; chain
   them, each on already-rounded operands, to bound a formula in one direction (interval
   arithmetic). ``math.fsum`` is correctly rounded as well (Shewchuk); :func:`sum_up` moves it
   two ulps to cover the documented double rounding of x87 builds.
2. **Sums and products of arrays.** numpy's ``sum`` and ``@`` (BLAS, classical algorithm, any
   summation order, with or without FMA) satisfy the standard bound (Higham, *Accuracy and
   Stability of Numerical Algorithms*, 2nd ed., eq. (3.5) and Thm 3.1):
   ``|fl(sum x_i) - sum x_i| <= gamma_{n-1} sum |x_i|`` and
   ``|fl(A B) - A B| <= gamma_k |A| |B|`` entrywise (``k`` the inner dimension),
   ``gamma_k = k u / (1 - k u)``, ``u = 2**-53``; underflow adds at most ``k 2**-1075`` per dot
   product. :func:`sum_up_np`, :func:`matmul_bounds` add ``2 gamma`` times the computed magnitude
   (the factor 2 covers the rounding of the magnitude itself) plus an underflow term.
3. **Library functions are not correctly rounded.** ``exp``, ``log``, ``tanh``, ``erf``... of libm
   and numpy carry a few ulps of error, and ``scipy.special.ndtr`` more in its tails. Where speed
   forces float evaluation (vectorised enclosures of MLPs) the result is widened by a documented
   error budget (:data:`LIBM_REL`, :func:`ndtr_rel_budget`) that is several times the accuracy
   the libraries document and that ``tests/test_rounding.py`` measures against mpmath; this rests
   on the libraries meeting their documented accuracy and is said so wherever it is used.
   Everywhere else elementary functions are evaluated in Arb (rigorous ball arithmetic).
4. **Arb.** An ``arb`` ball ``[m +- r]`` contains the exact value; :func:`arb_lo` /
   :func:`arb_hi` convert its ends to floats and move one ulp outward (``float()`` of an arb is
   within one ulp whatever its rounding direction).

NaN propagates through the scalar and array helpers (a NaN bound means "unknown", see
:mod:`drip_cert.provenance`); :func:`enclose_down` / :func:`enclose_up` instead return
``-inf`` / ``+inf`` (no information) for the ends of an interval.

Rigorous linear algebra built only on the rules above: :func:`sym_lambda_max_upper` (largest
eigenvalue of symmetric matrices, batched), :func:`spectral_norm_upper` and, in Arb,
:func:`nonneg_spectral_norm_upper` (nonnegative matrices, Collatz-Wielandt).
"""

from __future__ import annotations

import math
from collections.abc import Iterable

import numpy as np
from flint import arb

__all__ = [
    "EPS",
    "LIBM_ABS",
    "LIBM_REL",
    "LIBM_ULPS",
    "UNIT_ROUNDOFF",
    "add_down",
    "add_down_np",
    "add_up",
    "add_up_np",
    "arb_bounds",
    "arb_hi",
    "arb_lo",
    "arb_norm2_up",
    "arb_sqrt_up",
    "div_down",
    "div_up",
    "down",
    "down_np",
    "enclose_down",
    "enclose_up",
    "gamma",
    "matmul_bounds",
    "mul_down",
    "mul_down_np",
    "mul_up",
    "mul_up_np",
    "ndtr_rel_budget",
    "nonneg_spectral_norm_upper",
    "norm2_up",
    "norm2_up_np",
    "spectral_norm_upper",
    "sq_up",
    "sqrt_down",
    "sqrt_up",
    "sqrt_up_np",
    "sub_down",
    "sub_down_np",
    "sub_up",
    "sub_up_np",
    "sum_down",
    "sum_sq_up",
    "sum_up",
    "sum_up_np",
    "sym_lambda_max_upper",
    "up",
    "up_np",
    "widen_np",
]

_INF = math.inf

EPS = 2.0**-52
"""Machine epsilon of binary64: the spacing of floats in ``[1, 2)``; ``ulp(x) <= EPS |x|``."""

UNIT_ROUNDOFF = 2.0**-53
"""``u``: the relative error bound of one correctly rounded operation (normal range)."""

_TINY = 2.0**-1074
"""The smallest positive (subnormal) float: the absolute error unit below the normal range."""

LIBM_ULPS = 8
"""Error budget, in units of :data:`EPS` relative, of numpy's / libm's ``exp``, ``expm1``,
``log``, ``log1p`` and ``tanh`` in binary64. numpy validates its own float64 implementations to
<= 1 ulp (exp, log, expm1) and <= 2 ulps (tanh) (``numpy/_core/tests/data/umath-validation-set-*``),
glibc documents <= 2 ulps for these on x86-64; 8 is four times the worst of them."""

LIBM_REL = LIBM_ULPS * EPS
"""Relative error budget of the library functions of :data:`LIBM_ULPS`."""

LIBM_ABS = 2.0**-1022
"""Absolute floor added to every library-function budget: results near or below the normal
range (gradual underflow, or flushed to 0) carry an absolute, not relative, error of a few
``2**-1074``; the smallest normal float ``2**-1022`` is ``2**52`` times that."""

_NDTR_BASE_ULPS = 64
"""Constant part of :func:`ndtr_rel_budget` (the rational approximations of cephes' ``erf`` /
``erfc`` and the few roundings around them)."""

_NDTR_Z2_ULPS = 4
"""Factor of ``z^2`` in :func:`ndtr_rel_budget` (the amplification of argument roundings by
``exp(-z^2/2)``: about ``0.75`` by analysis, ``1.0`` measured)."""


# ----------------------------------------------------------------------------------- scalars
def up(x: float, ulps: int = 1) -> float:
    """``x`` moved ``ulps`` floats towards ``+inf``: an upper bound of the exact result of one
    correctly rounded operation whose computed value is ``x`` (NaN stays NaN)."""
    x = float(x)
    for _ in range(ulps):
        x = math.nextafter(x, _INF)
    return x


def down(x: float, ulps: int = 1) -> float:
    """``x`` moved ``ulps`` floats towards ``-inf`` (see :func:`up`)."""
    x = float(x)
    for _ in range(ulps):
        x = math.nextafter(x, -_INF)
    return x


def enclose_down(x: float) -> float:
    """Lower end of an enclosure from a computed value: one ulp down, NaN (no information) to
    ``-inf``."""
    x = float(x)
    return -_INF if x != x else math.nextafter(x, -_INF)


def enclose_up(x: float) -> float:
    """Upper end of an enclosure from a computed value: one ulp up, NaN to ``+inf``."""
    x = float(x)
    return _INF if x != x else math.nextafter(x, _INF)


def add_up(a: float, b: float) -> float:
    """Upper bound of ``a + b`` (exact, not moved, when an operand is 0)."""
    r = float(a) + float(b)
    return r if (a == 0.0 or b == 0.0) else up(r)


def add_down(a: float, b: float) -> float:
    """Lower bound of ``a + b``."""
    return down(float(a) + float(b))


def sub_up(a: float, b: float) -> float:
    """Upper bound of ``a - b``."""
    return up(float(a) - float(b))


def sub_down(a: float, b: float) -> float:
    """Lower bound of ``a - b``."""
    return down(float(a) - float(b))


def mul_up(a: float, b: float) -> float:
    """Upper bound of ``a * b`` (``0 * inf`` is NaN, as in IEEE; exact when an operand is 0)."""
    r = float(a) * float(b)
    return r if (r == 0.0 and (a == 0.0 or b == 0.0)) else up(r)


def mul_down(a: float, b: float) -> float:
    """Lower bound of ``a * b``."""
    return down(float(a) * float(b))


def div_up(a: float, b: float) -> float:
    """Upper bound of ``a / b`` (``b != 0``)."""
    return up(float(a) / float(b))


def div_down(a: float, b: float) -> float:
    """Lower bound of ``a / b`` (``b != 0``)."""
    return down(float(a) / float(b))


def sq_up(a: float) -> float:
    """Upper bound of ``a**2`` (exact for 0)."""
    return mul_up(a, a)


def sqrt_up(a: float) -> float:
    """Upper bound of ``sqrt(a)`` (``a >= 0``; ``inf`` stays ``inf``; exact for 0)."""
    return 0.0 if a == 0.0 else up(math.sqrt(a))


def sqrt_down(a: float) -> float:
    """Lower bound of ``sqrt(a)`` (``a >= 0``), never below 0."""
    return max(0.0, down(math.sqrt(a)))


def sum_up(values: Iterable[float]) -> float:
    """Upper bound of ``sum(values)``: ``math.fsum`` (correctly rounded) moved two ulps up."""
    return up(math.fsum(float(v) for v in values), 2)


def sum_down(values: Iterable[float]) -> float:
    """Lower bound of ``sum(values)`` (see :func:`sum_up`)."""
    return down(math.fsum(float(v) for v in values), 2)


def sum_sq_up(values: Iterable[float]) -> float:
    """Upper bound of ``sum v**2`` (every square and partial sum rounded up)."""
    acc = 0.0
    for v in values:
        acc = add_up(acc, sq_up(float(v)))
    return acc


def norm2_up(values: Iterable[float]) -> float:
    """Upper bound of the Euclidean norm ``sqrt(sum v**2)`` (scaled as in :func:`norm2_up_np`)."""
    return float(norm2_up_np(np.fromiter((float(v) for v in values), dtype=np.float64)))


def gamma(n: int) -> float:
    """Upper bound of ``gamma_n = n u / (1 - n u)`` (Higham's constant), for ``n u < 1/2``."""
    nu = float(n) * UNIT_ROUNDOFF  # exact: a power-of-two scaling of an integer < 2**53
    if not nu < 0.5:
        raise ValueError(f"gamma_n needs n u < 1/2, got n = {n}")
    return div_up(nu, sub_down(1.0, nu))


# ----------------------------------------------------------------------------------- arrays
#: Arrays with at least this many entries take the integer form of :func:`up_np` (about 7x
#: faster than ``np.nextafter`` at 64k entries on the reference machine); below it the fixed
#: cost of the integer form's few passes exceeds ``np.nextafter``'s (crossover ~400 entries).
NEXTAFTER_INT_MIN = 512


def _next_up_int(y: np.ndarray) -> np.ndarray:
    """``np.nextafter(y, inf)`` bit for bit, through the integer representation.

    Proof. For a binary64 ``v`` that is not NaN, read its 64 bits as a signed integer ``b``.
    Non-negative floats (sign bit clear) are ordered as their integers, ``+0`` is ``b = 0`` and
    the next float up is ``b + 1`` (``+inf`` after the largest float); negative floats (sign bit
    set, ``b < 0``) are ordered *reversed*, so the next float up, toward zero, is ``b - 1``
    (``-0.0`` after ``-2**-1074``; ``-max`` after ``-inf``). ``b + ((b >> 63) | 1)`` is ``b + 1``
    for ``b >= 0`` and ``b - 1`` for ``b < 0`` (``>>`` on int64 is arithmetic). Three inputs
    are handled apart: ``-0.0`` (``b = -2**63``, whose ``b - 1`` would wrap) is first turned into
    ``+0.0`` by ``y + 0.0`` (exact, round to nearest), whose successor ``2**-1074`` is
    ``nextafter(-0.0, inf)`` as well; ``+inf`` and NaN are returned unchanged, as
    ``np.nextafter`` returns them. ``tests/test_rounding.py`` checks bit identity with
    ``np.nextafter`` on every special value and a million random bit patterns.
    """
    z = np.add(y, 0.0, dtype=np.float64)  # a fresh array; -0.0 -> +0.0
    b = z.view(np.int64)
    step = b >> 63
    step |= 1
    step += b
    out = step.view(np.float64)
    if not np.isfinite(z).all():
        keep = np.isnan(z) | (z == np.inf)
        out[keep] = z[keep]
    return out


def up_np(x, ulps: int = 1) -> np.ndarray:
    """Elementwise :func:`up` (``np.nextafter(x, inf)``, bit for bit); NaN stays NaN.

    Arrays of :data:`NEXTAFTER_INT_MIN` entries or more are moved through their integer
    representation (:func:`_next_up_int`, the same floats, several times faster).
    """
    y = np.asarray(x, dtype=np.float64)
    if y.ndim and y.size >= NEXTAFTER_INT_MIN:
        for _ in range(ulps):
            y = _next_up_int(y)
        return y
    for _ in range(ulps):
        y = np.nextafter(y, np.inf)
    return y


def down_np(x, ulps: int = 1) -> np.ndarray:
    """Elementwise :func:`down` (``np.nextafter(x, -inf)``, bit for bit: ``-up(-x)``, negation
    being exact)."""
    y = np.asarray(x, dtype=np.float64)
    if y.ndim and y.size >= NEXTAFTER_INT_MIN:
        y = np.negative(y)
        for _ in range(ulps):
            y = _next_up_int(y)
        np.negative(y, out=y)
        return y
    for _ in range(ulps):
        y = np.nextafter(y, -np.inf)
    return y


def add_up_np(a, b) -> np.ndarray:
    """Elementwise upper bound of ``a + b``."""
    return up_np(np.add(a, b, dtype=np.float64))


def add_down_np(a, b) -> np.ndarray:
    """Elementwise lower bound of ``a + b``."""
    return down_np(np.add(a, b, dtype=np.float64))


def sub_up_np(a, b) -> np.ndarray:
    """Elementwise upper bound of ``a - b``."""
    return up_np(np.subtract(a, b, dtype=np.float64))


def sub_down_np(a, b) -> np.ndarray:
    """Elementwise lower bound of ``a - b``."""
    return down_np(np.subtract(a, b, dtype=np.float64))


def mul_up_np(a, b) -> np.ndarray:
    """Elementwise upper bound of ``a * b``."""
    return up_np(np.multiply(a, b, dtype=np.float64))


def mul_down_np(a, b) -> np.ndarray:
    """Elementwise lower bound of ``a * b``."""
    return down_np(np.multiply(a, b, dtype=np.float64))


def sqrt_up_np(a) -> np.ndarray:
    """Elementwise upper bound of ``sqrt(a)`` (``a >= 0``)."""
    return up_np(np.sqrt(np.asarray(a, dtype=np.float64)))


def sum_up_np(x, axis: int = -1) -> np.ndarray:
    """Upper bound of the exact sum of the float entries of ``x`` along ``axis``.

    ``|fl(sum) - sum| <= gamma_{n-1} sum|x_i|`` (any order); the computed ``sum |x_i|`` is at
    least ``(1 - gamma_{n-1})`` times the exact one, so adding ``2 gamma_n`` times it (rounded up)
    covers the error. Additions never underflow (a subnormal sum is exact).
    """
    x = np.asarray(x, dtype=np.float64)
    n = x.shape[axis]
    if n == 0:
        return np.zeros(np.delete(x.shape, axis % x.ndim))
    s = x.sum(axis=axis)
    if n == 1:
        return s
    err = up_np(2.0 * gamma(n) * np.abs(x).sum(axis=axis))
    return add_up_np(s, err)


def norm2_up_np(x, axis: int = -1) -> np.ndarray:
    """Upper bound of the Euclidean norm of ``x`` along ``axis`` (vectorised :func:`norm2_up`).

    The entries are first scaled by a power of two ``s >= max |x_i|`` (exact, except for entries
    that become subnormal, which are rounded up), so that tiny entries do not underflow to a
    rounded-up ``2**-1074`` whose square root would be ``1e-162``; the result is
    ``s * sqrt(sum (x_i / s)^2)`` with every step rounded up.
    """
    x = np.abs(np.asarray(x, dtype=np.float64))
    if x.size == 0:
        return sum_up_np(x, axis=axis)
    big = np.max(x, axis=axis, keepdims=True)
    _, ex = np.frexp(np.where(np.isfinite(big) & (big > 0), big, 1.0))
    scale = np.ldexp(1.0, ex)  # a power of two >= max |x_i|
    y = up_np(x / scale)
    out = up_np(np.squeeze(scale, axis=axis) * sqrt_up_np(sum_up_np(up_np(y * y), axis=axis)))
    out = np.where(np.squeeze(big, axis=axis) == 0, 0.0, out)
    return np.where(np.isfinite(np.squeeze(big, axis=axis)), out, np.squeeze(big, axis=axis))


def widen_np(y, rel, abs_: float = LIBM_ABS) -> tuple[np.ndarray, np.ndarray]:
    """``[y - rel |y| - abs_, y + rel |y| + abs_]``, rounded outward: the enclosure of a value
    known to within a relative error ``rel`` (array or scalar) and an absolute error ``abs_``."""
    y = np.asarray(y, dtype=np.float64)
    pad = add_up_np(up_np(np.abs(y) * rel), abs_)
    return sub_down_np(y, pad), add_up_np(y, pad)


def ndtr_rel_budget(z) -> np.ndarray:
    """Relative error budget of ``scipy.special.ndtr(z)`` (the normal CDF), ``(4 z^2 + 64) EPS``,
    for results in the normal range (below it :data:`LIBM_ABS` covers the absolute error).

    scipy evaluates ``ndtr(z)`` as ``erfc(-z / sqrt 2) / 2`` (cephes). The rounding of ``-z/sqrt
    2`` (relative ``u``) and of ``x * x`` inside ``erfc`` (``x = |z| / sqrt 2``) enter through
    ``exp(-x^2)``, whose relative error is the absolute error of its argument:
    ``2 x^2 u + x^2 u = (3/4) z^2 EPS``; the rational approximations and remaining roundings are
    within a few ulps (cephes documents a peak relative error of ``5.7e-14`` for ``erfc`` on
    ``[0, 26.6]``). Measured against mpmath (``tests/test_rounding.py``) the error reaches
    ``1.0 z^2 EPS``; the budget is four times that.
    """
    z = np.asarray(z, dtype=np.float64)
    return (_NDTR_Z2_ULPS * z * z + _NDTR_BASE_ULPS) * EPS


def _matmul_err(A: np.ndarray, B: np.ndarray) -> np.ndarray:
    """Entrywise bound of ``|fl(A @ B) - A @ B|`` (see :func:`matmul_bounds`)."""
    k = A.shape[-1]
    return add_up_np(up_np(2.0 * gamma(k + 1) * (np.abs(A) @ np.abs(B))), k * 8 * _TINY)


def matmul_bounds(A, B) -> tuple[np.ndarray, np.ndarray]:
    """``(lo, hi)`` with ``lo <= A @ B <= hi`` entrywise for float arrays (batched like ``@``).

    ``|fl(A B) - A B| <= gamma_k |A| |B| + k 2**-1075`` (inner dimension ``k``); the magnitude
    ``|A| |B|`` is itself computed in floating point (at least ``1 - gamma_k`` times the exact one),
    so ``2 gamma_k`` times it plus ``k 2**-1072`` (rounded up) covers the error.
    """
    A = np.asarray(A, dtype=np.float64)
    B = np.asarray(B, dtype=np.float64)
    C = A @ B
    err = _matmul_err(A, B)
    return sub_down_np(C, err), add_up_np(C, err)


# ------------------------------------------------------------------------------------- Arb
def arb_lo(v: arb) -> float:
    """A float ``<=`` every point of the ball ``v`` (``-inf`` for a non-finite ball)."""
    if not v.is_finite():
        return -_INF
    return math.nextafter(float(v.lower()), -_INF)


def arb_hi(v: arb) -> float:
    """A float ``>=`` every point of the ball ``v`` (``+inf`` for a non-finite ball)."""
    if not v.is_finite():
        return _INF
    return math.nextafter(float(v.upper()), _INF)


def arb_bounds(v: arb) -> tuple[float, float]:
    """``(arb_lo(v), arb_hi(v))``."""
    return arb_lo(v), arb_hi(v)


def arb_sqrt_up(x: float) -> float:
    """Upper bound of ``sqrt(q)`` for every ``q`` in ``[0, x]``, the root taken in Arb.

    ``x < 0`` is read as 0 (an upper bound of a nonnegative quantity); ``inf``, ``-inf`` and NaN
    give ``inf`` (no finite bound). The Arb twin of :func:`sqrt_up`, at most an ulp above it.
    """
    x = float(x)
    if not math.isfinite(x):
        return _INF
    return arb_hi(arb(max(x, 0.0)).sqrt())


def arb_norm2_up(values: Iterable[float]) -> float:
    """Upper bound of the Euclidean norm ``sqrt(sum v**2)``, the squares, sum and root in Arb
    (an infinite or NaN entry gives ``inf``). The Arb twin of :func:`norm2_up`."""
    acc = arb(0)
    for v in values:
        acc += arb(float(v)) ** 2
    return arb_hi(acc.sqrt())


# ------------------------------------------------------------------- rigorous linear algebra
def _sym_abs(R: np.ndarray) -> np.ndarray:
    return np.maximum(R, np.swapaxes(R, -1, -2))


def _perron_upper_np(N: np.ndarray) -> np.ndarray:
    """Upper bound of the spectral radius of entrywise non-negative ``N`` (batched).

    Collatz-Wielandt: ``rho(N) <= max_i (N v)_i / v_i`` for any ``v > 0``; tried with the
    (floored) Perron vector of the symmetric part and with ``v = 1`` (the largest row sum).
    """
    n = N.shape[-1]
    best: np.ndarray | None = None
    _, V = np.linalg.eigh(0.5 * (N + np.swapaxes(N, -1, -2)))
    v1 = np.abs(V[..., :, -1])
    v1 = np.maximum(v1, 1e-8 * v1.max(axis=-1, keepdims=True))
    v1 = np.where(np.isfinite(v1) & (v1 > 0), v1, 1.0)
    for v in (v1, np.ones(N.shape[:-1])):
        _, hi = matmul_bounds(N, v[..., :, None])
        q = up_np(hi[..., 0] / v).max(axis=-1)
        best = q if best is None else np.minimum(best, q)
    assert best is not None  # the loop over the two test vectors always runs
    return best if n else np.zeros(N.shape[:-2])


def sym_lambda_max_upper(S, R=None) -> np.ndarray | float:
    """Rigorous upper bound of ``lambda_max(sym A)`` for every ``A`` with ``|A - S| <= R``.

    Batched over leading axes (``S`` of shape ``(..., n, n)``); a float result per matrix, ``inf``
    where the bound fails (non-finite input, or an eigenvector matrix far from orthogonal).

    Method (the floating-point twin of
    :func:`drip_cert.analysis.contraction.lognorm.lambda_max_upper`): ``H``
    the float symmetric part (its rounding is added to ``R``), ``Q`` the float eigenvectors of
    ``H``; ``M = Q^T H Q`` and ``E = Q^T Q - I`` are computed with entrywise error bounds
    (:func:`matmul_bounds`). For ``x = Q y``: ``x^T H x = y^T (Q^T H Q) y <= g ||y||^2`` with
    ``g`` the Gershgorin bound of ``Q^T H Q`` (every entry widened by its error), and
    ``(1 - ||E||_F) ||y||^2 <= ||x||^2 <= (1 + ||E||_F) ||y||^2``, so ``lambda_max(H)`` is at most
    ``g / (1 - ||E||_F)`` (``g >= 0``) or ``g / (1 + ||E||_F)`` (``g < 0``). A perturbation with
    ``|sym Delta| <= max(R, R^T)`` adds at most its spectral radius (Weyl), bounded by
    Collatz-Wielandt. Every operation is rounded in the safe direction.
    """
    S = np.asarray(S, dtype=np.float64)
    if S.ndim < 2 or S.shape[-1] != S.shape[-2]:
        raise ValueError(f"expected square matrices (..., n, n), got shape {S.shape}")
    batch = S.shape[:-2]
    n = S.shape[-1]
    if n == 0:
        empty = np.full(batch, -_INF)
        return empty if batch else float(empty)
    finite = np.all(np.isfinite(S), axis=(-1, -2))
    Rr = np.zeros_like(S) if R is None else np.broadcast_to(np.asarray(R, np.float64), S.shape)
    finite &= np.all(np.isfinite(Rr), axis=(-1, -2))
    if np.any(Rr < 0):
        raise ValueError("the radius matrix R must be non-negative")
    S = np.where(finite[..., None, None], S, 0.0)
    Rr = np.where(finite[..., None, None], Rr, 0.0)
    St = np.swapaxes(S, -1, -2)
    H = 0.5 * (S + St)  # symmetric (+ commutes); one rounding: |H - sym S| <= u |H| + 2**-1075
    Rs = _sym_abs(Rr)
    if not np.array_equal(S, St):
        Rs = add_up_np(Rs, add_up_np(up_np(np.abs(H) * UNIT_ROUNDOFF), _TINY))
    _, Q = np.linalg.eigh(H)
    P = H @ Q
    errP = _matmul_err(H, Q)
    M = np.swapaxes(Q, -1, -2) @ P
    Qa = np.abs(np.swapaxes(Q, -1, -2))
    # |M - Q^T H Q| <= err(Q^T P) + |Q|^T err(H Q)
    errM = add_up_np(_matmul_err(np.swapaxes(Q, -1, -2), P), matmul_bounds(Qa, errP)[1])
    G = np.swapaxes(Q, -1, -2) @ Q
    eye = np.eye(n)
    E = G - eye
    # |E - (Q^T Q - I)| <= err(Q^T Q) + the rounding of the subtraction (<= u |E|)
    errE = add_up_np(_matmul_err(np.swapaxes(Q, -1, -2), Q), up_np(np.abs(E) * UNIT_ROUNDOFF))
    Eabs = add_up_np(np.abs(E), errE)
    eF = sqrt_up_np(sum_up_np(up_np(Eabs * Eabs).reshape(*batch, n * n), axis=-1))
    off = add_up_np(np.abs(M), errM)
    off = np.where(eye.astype(bool), 0.0, off)
    diag = add_up_np(np.diagonal(M, axis1=-2, axis2=-1), np.diagonal(errM, axis1=-2, axis2=-1))
    g = add_up_np(diag, sum_up_np(off, axis=-1)).max(axis=-1)
    with np.errstate(divide="ignore", invalid="ignore"):
        den = np.where(g >= 0, down_np(1.0 - eF), up_np(1.0 + eF))
        bound = up_np(g / den)
    bound = np.where((eF < 0.5) & ~np.isnan(bound), bound, _INF)
    if np.any(Rs > 0):
        bound = add_up_np(bound, _perron_upper_np(Rs))
    bound = np.where(finite, bound, _INF)
    return bound if batch else float(bound)


def spectral_norm_upper(W) -> np.ndarray | float:
    """Rigorous upper bound of the spectral norm ``||W||_2`` (batched over leading axes).

    ``||W||_2^2 = lambda_max(G)`` with ``G = W W^T`` or ``W^T W`` (the smaller); ``G`` is computed
    in floating point with its entrywise error (:func:`matmul_bounds`) and its largest eigenvalue
    bounded by :func:`sym_lambda_max_upper`; the square root is rounded up. The excess over the
    true norm is of order ``n EPS ||W||_2``.
    """
    W = np.asarray(W, dtype=np.float64)
    if W.ndim < 2:
        raise ValueError(f"expected a matrix (..., m, n), got shape {W.shape}")
    m, n = W.shape[-2:]
    if m == 0 or n == 0:
        out = np.zeros(W.shape[:-2])
        return out if out.ndim else 0.0
    Wt = np.swapaxes(W, -1, -2)
    A, B = (W, Wt) if m <= n else (Wt, W)
    G = A @ B
    lam = sym_lambda_max_upper(G, _matmul_err(A, B))
    out = sqrt_up_np(np.maximum(lam, 0.0))
    out = np.where(np.all(W == 0, axis=(-1, -2)), 0.0, out)
    return out if out.ndim else float(out)


def nonneg_spectral_norm_upper(M) -> float:
    """Rigorous upper bound of ``||M||_2`` for an entrywise nonnegative float matrix, in Arb.

    ``||M||_2^2 = rho(M^T M)`` and, for a nonnegative matrix ``B`` and any positive vector ``v``,
    ``rho(B) <= max_i (B v)_i / v_i`` (Collatz-Wielandt: ``diag(v)^{-1} B diag(v)`` has these row
    sums). ``v`` is the numerical top right singular vector of ``M`` (made positive); the products
    are in ball arithmetic. The Frobenius norm (:func:`arb_norm2_up`) is a second bound; the
    smaller one is returned. Tighter than :func:`spectral_norm_upper` for the small nonnegative
    matrices of entrywise Jacobian bounds (docs/math/l1drac.md section 2, the bounded route).
    """
    M = np.asarray(M, dtype=float)
    if not np.any(M):
        return 0.0
    fro = arb_norm2_up(M.ravel().tolist())
    _, _, vt = np.linalg.svd(M)
    v = np.abs(vt[0])
    v = np.maximum(v, 1e-8 * float(v.max()))
    rows, cols = M.shape
    Ma = [[arb(float(M[i, j])) for j in range(cols)] for i in range(rows)]
    va = [arb(float(x)) for x in v]
    Mv = [sum((Ma[i][j] * va[j] for j in range(cols)), arb(0)) for i in range(rows)]
    ratios = []
    for j in range(cols):
        btv = sum((Ma[i][j] * Mv[i] for i in range(rows)), arb(0))
        ratios.append(arb_hi(btv / va[j]))
    cw = arb_hi(arb(max(ratios)).sqrt())
    return min(fro, cw)
