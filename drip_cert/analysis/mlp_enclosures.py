"""Fast sound enclosures of an MLP's value, Jacobian and Hessian over many boxes at once.

:func:`enclose_derivatives` propagates, for a batch of boxes ``(N, in)``, interval enclosures of

* the value ``z_k`` of every layer,
* its Jacobian ``J_k = d z_k / d x`` (``(N, n_k, in)``),
* its Hessian ``T_k = d^2 z_k / dx^2`` (``(N, n_k, in, in)``, optional),

through ``a_k = W_k z_k + b_k``, ``z_{k+1} = s_k(a_k)`` (the convention of
:mod:`drip_cert.analysis.mlp_bounds`) by the forward-mode chain rule in interval arithmetic:

``J_a = W J_z``, ``T_a = W T_z``,
``J_{k+1} = diag(s'(a)) J_a``,
``T_{k+1}[m, i, l] = s''(a_m) J_a[m, i] J_a[m, l] + s'(a_m) T_a[m, i, l]``.

Every product of a point matrix with an interval array uses the centre-radius form with the
rounding term of Higham's Thm 3.1 (``mlp_bounds._interval_matmul_point_left``), every product of
two intervals the four end products rounded outward, and the activation and its first two
derivatives are enclosed over each pre-activation interval from their monotone pieces
(:func:`enclose_activation_second` for ``s''``), with the library-function error budgets of
:mod:`drip_cert.numerics.rounding` (sound as long as numpy meets its documented accuracy, as for
the rest of :mod:`~drip_cert.analysis.mlp_bounds`).

**Centred (mean-value) pre-activations.** With ``centred=True`` the centre ``c`` of each box is
propagated with the box (the batch doubles) and every pre-activation enclosure is intersected
with its mean-value form ``a(x) in a(c) + [J_a(box)] (x - c)``; both are sound, so is their
intersection, and for small boxes the mean-value form is the tighter one (its width is first
order in the box radius with the true Jacobian as constant, where interval propagation
multiplies the radius by ``prod ||W_k||_inf``-like factors). Tighter pre-activations tighten
``s'`` and ``s''`` and hence the Jacobian and Hessian enclosures.

:func:`enclose_jacobian_centred` returns the Jacobian enclosure of the plain route intersected
with its centred form ``J(x) in J(c) + [H(box)] (x - c)``.
"""

from __future__ import annotations

import functools
from dataclasses import dataclass

import numpy as np
from flint import arb

from drip_cert.analysis.mlp_bounds import (
    _affine,
    _check_box,
    _interval_matmul_point_left,
    _mid_rad,
    _phi_bounds,
    _sech2_bounds,
    enclose_activation,
    enclose_activation_prime,
)
from drip_cert.errors import SpecError
from drip_cert.model.mlp import MLP
from drip_cert.numerics.rounding import (
    LIBM_REL,
    add_down_np,
    add_up_np,
    arb_hi,
    arb_lo,
    down_np,
    gamma,
    sub_down_np,
    sub_up_np,
    up_np,
    widen_np,
)

__all__ = [
    "DerivativeEnclosure",
    "enclose_activation_second",
    "enclose_box_and_centre",
    "enclose_derivatives",
    "enclose_jacobian_centred",
]

_TINY = 2.0**-1074


# --------------------------------------------------------------------------- interval helpers


def _imul(alo, ahi, blo, bhi):
    """Enclosure of ``a * b`` for intervals (elementwise, broadcasting): the four end products,
    each one rounding, moved outward."""
    p1, p2, p3, p4 = alo * blo, alo * bhi, ahi * blo, ahi * bhi
    lo = np.minimum(np.minimum(p1, p2), np.minimum(p3, p4))
    hi = np.maximum(np.maximum(p1, p2), np.maximum(p3, p4))
    return down_np(lo), up_np(hi)


def _iadd(alo, ahi, blo, bhi):
    """Enclosure of ``a + b`` (one rounding per end, moved outward)."""
    return add_down_np(alo, blo), add_up_np(ahi, bhi)


def _intersect(alo, ahi, blo, bhi):
    """Intersection of two enclosures of the same quantity (both sound, so is this)."""
    return np.maximum(alo, blo), np.minimum(ahi, bhi)


def _mv_form(clo, chi, dlo, dhi, r):
    """Mean-value enclosure ``[c] + [D] [-r, r]`` summed over the last axis of ``D``.

    ``c`` has shape ``(..., m)``, ``D`` ``(..., m, d)``, ``r`` ``(..., d)`` (radii, ``>= 0``).
    ``|[D] [-r, r]| <= |D|_max r``; the float dot product ``|D|_max r`` of ``d`` non-negative
    terms is within ``gamma_d`` of the exact one, so ``2 gamma_{d+1}`` times it plus an underflow
    term covers it; the centre is enclosed by ``[c]``.
    """
    mag = np.maximum(np.abs(dlo), np.abs(dhi))
    d = mag.shape[-1]
    rad = np.einsum("...md,...d->...m", mag, r)
    rad = add_up_np(up_np(rad * (1.0 + 2.0 * gamma(d + 1))), d * 8 * _TINY)
    return sub_down_np(clo, rad), add_up_np(chi, rad)


def _centred_jacobian(j, t, n: int, r):
    """Intersect the box rows (the first ``n``) of a Jacobian enclosure ``j`` (``(2n, m, d)``)
    with the mean-value form ``[J(c)] + [T(box)] [-r, r]`` (``t``: the Hessian enclosure, the
    centre rows after the box rows). Sound: the mean value theorem on each entry."""
    m, d = j[0].shape[-2:]
    mlo, mhi = _mv_form(
        j[0][n:].reshape(n, m * d),
        j[1][n:].reshape(n, m * d),
        t[0][:n].reshape(n, m * d, d),
        t[1][:n].reshape(n, m * d, d),
        r,
    )
    blo, bhi = _intersect(j[0][:n], j[1][:n], mlo.reshape(n, m, d), mhi.reshape(n, m, d))
    return np.concatenate([blo, j[0][n:]]), np.concatenate([bhi, j[1][n:]])


# --------------------------------------------------------------------------- s'' enclosures


@dataclass(frozen=True)
class _SecondConsts:
    tanh_peak: float  # upper bound of sup |tanh''| = 4 / (3 sqrt 3)
    tanh_arg: tuple[float, float]  # bracket of a* = atanh(1 / sqrt 3), where tanh'' = -peak
    gelu_peak: float  # upper bound of GELU''(0) = sqrt(2 / pi)
    gelu_trough: float  # lower bound of GELU''(+-2) = -2 phi(2)


@functools.cache
def _second_consts() -> _SecondConsts:
    """The constants of :func:`enclose_activation_second`, evaluated in Arb."""
    a_star = arb(1 / arb(3).sqrt()).atanh()
    return _SecondConsts(
        tanh_peak=arb_hi(arb(4) / (3 * arb(3).sqrt())),
        tanh_arg=(arb_lo(a_star), arb_hi(a_star)),
        gelu_peak=arb_hi((2 / arb.pi()).sqrt()),
        gelu_trough=arb_lo(-2 * (arb(-2)).exp() / (2 * arb.pi()).sqrt()),
    )


def _tanh_second_point(z: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Enclosure of ``tanh''(z) = -2 tanh(z) sech^2(z)`` at float points: ``tanh`` widened by
    its error budget, ``sech^2`` by the cancellation-free form (``mlp_bounds._sech2_bounds``),
    the product of the two enclosures rounded outward (the factor ``-2`` is exact)."""
    t_lo, t_hi = widen_np(np.tanh(z), LIBM_REL)
    q_lo, q_hi = _sech2_bounds(np.abs(z))
    p_lo, p_hi = _imul(np.clip(t_lo, -1.0, 1.0), np.clip(t_hi, -1.0, 1.0), q_lo, q_hi)
    return -2.0 * p_hi, -2.0 * p_lo


def _gelu_second_point(z: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Enclosure of ``GELU''(z) = phi(z) (2 - z^2)`` at float points (``phi`` from
    ``mlp_bounds._phi_bounds``, ``2 - z^2`` rounded both ways)."""
    zz_lo, zz_hi = down_np(z * z), up_np(z * z)
    w_lo, w_hi = sub_down_np(2.0, zz_hi), sub_up_np(2.0, zz_lo)
    return _imul(*_phi_bounds(z), w_lo, w_hi)


def enclose_activation_second(name: str | None, lo, hi) -> tuple[np.ndarray, np.ndarray]:
    """Sound enclosure of the second derivative ``s''`` over ``[lo, hi]`` (elementwise).

    * tanh: ``tanh'' = -2 tanh sech^2`` is odd with ``tanh''' = -2 sech^2 (1 - 3 tanh^2)``: it
      increases on ``(-inf, -a*]``, decreases on ``[-a*, a*]`` and increases on ``[a*, inf)``,
      ``a* = atanh(1/sqrt 3)``, ``tanh''(+-a*) = -+4/(3 sqrt 3)``. Over an interval its minimum
      is at an end unless the interval contains ``a*`` (then ``-4/(3 sqrt 3)``) and its maximum
      at an end unless it contains ``-a*`` (then ``+4/(3 sqrt 3)``).
    * GELU: ``GELU'' = phi (2 - z^2)``, ``GELU''' = phi z (z^2 - 4)``: local maximum
      ``sqrt(2/pi)`` at 0, local minima ``-2 phi(2)`` at ``+-2``, monotone in between.
    * identity: 0.

    The extreme values and ``a*`` are bracketed in Arb; a bracket that may meet the interval
    counts as contained (the global extreme is always a valid bound).
    """
    lo = np.asarray(lo, dtype=np.float64)
    hi = np.asarray(hi, dtype=np.float64)
    if name is None or name == "identity":
        return np.zeros_like(lo), np.zeros_like(hi)
    c = _second_consts()
    if name == "tanh":
        l_lo, l_hi = _tanh_second_point(lo)
        h_lo, h_hi = _tanh_second_point(hi)
        a_lo, a_hi = c.tanh_arg
        has_min = (lo <= a_hi) & (hi >= a_lo)
        has_max = (lo <= -a_lo) & (hi >= -a_hi)
        dlo = np.where(has_min, -c.tanh_peak, np.minimum(l_lo, h_lo))
        dhi = np.where(has_max, c.tanh_peak, np.maximum(l_hi, h_hi))
        return np.maximum(dlo, -c.tanh_peak), np.minimum(dhi, c.tanh_peak)
    if name == "gelu":
        l_lo, l_hi = _gelu_second_point(lo)
        h_lo, h_hi = _gelu_second_point(hi)
        has_max = (lo <= 0.0) & (hi >= 0.0)
        has_min = ((lo <= 2.0) & (hi >= 2.0)) | ((lo <= -2.0) & (hi >= -2.0))
        dlo = np.where(has_min, c.gelu_trough, np.minimum(l_lo, h_lo))
        dhi = np.where(has_max, c.gelu_peak, np.maximum(l_hi, h_hi))
        return dlo, dhi
    raise SpecError(f"activation {name!r} is not supported", field="activation")


# --------------------------------------------------------------------------- propagation


@dataclass(frozen=True)
class DerivativeEnclosure:
    """Entrywise enclosures of an MLP's value, Jacobian and Hessian over a batch of boxes.

    For every ``x`` in box ``b``: ``value[0][b] <= mlp(x) <= value[1][b]`` (``(N, out)``),
    likewise ``jacobian`` (``(N, out, in)``) and ``hessian`` (``(N, out, in, in)``, ``None``
    when not asked for).
    """

    value: tuple[np.ndarray, np.ndarray]
    jacobian: tuple[np.ndarray, np.ndarray]
    hessian: tuple[np.ndarray, np.ndarray] | None


def _layer_acts(mlp: MLP) -> list[str | None]:
    return [mlp.activation] * (len(mlp.weights) - 1) + [mlp.output_activation]


def _outer_rows(jlo, jhi):
    """Enclosure of ``P[m, i, l] = J[m, i] J[m, l]`` (the diagonal ``i = l`` as a square)."""
    plo, phi = _imul(jlo[..., :, None], jhi[..., :, None], jlo[..., None, :], jhi[..., None, :])
    # J_i^2 >= 0 and <= max(lo^2, hi^2): tighter than the four products when 0 is inside
    sq_hi = up_np(np.maximum(jlo * jlo, jhi * jhi))
    sq_lo = np.where((jlo <= 0.0) & (jhi >= 0.0), 0.0, down_np(np.minimum(jlo * jlo, jhi * jhi)))
    d = np.arange(jlo.shape[-1])
    plo[..., d, d] = sq_lo
    phi[..., d, d] = sq_hi
    return plo, phi


def enclose_derivatives(
    mlp: MLP, lo, hi, *, hessian: bool = True, centred: bool = True
) -> DerivativeEnclosure:
    """Sound enclosures of ``mlp``, its Jacobian and (optionally) its Hessian over boxes.

    Parameters
    ----------
    mlp
        The network.
    lo, hi
        ``(..., in)``: a batch of boxes (any leading shape).
    hessian
        Whether to propagate the Hessian (about four times the work of the Jacobian).
    centred
        Intersect every pre-activation enclosure with its mean-value form about the box centre
        (see the module docstring); doubles the batch, tighter for small boxes.

    Returns
    -------
    DerivativeEnclosure

    Notes
    -----
    Proof sketch. Each step encloses, for every ``x`` in the box, the exact value of the
    quantity it computes, given enclosures of its inputs: the affine maps by the centre-radius
    product with Higham's error bound, the diagonal scalings and products by the four end
    products rounded outward, sums one rounding outward, and ``s, s', s''`` over the enclosure
    of the pre-activation by their monotone pieces. By induction over layers every enclosure
    holds; the mean-value form holds by the mean value theorem applied to each pre-activation
    ``a_m`` on the segment from ``c`` to ``x`` (inside the box, where ``J_a`` is enclosed).
    """
    lo, hi = _check_box(mlp, lo, hi)
    batch = lo.shape[:-1]
    d = mlp.in_dim
    box, _ = _propagate(mlp, lo.reshape(-1, d), hi.reshape(-1, d), hessian, centred)
    return _reshape(box, batch)


def _reshape(e: DerivativeEnclosure, batch: tuple[int, ...]) -> DerivativeEnclosure:
    out, d = e.jacobian[0].shape[-2:]

    def rs(pair, *tail):
        return (pair[0].reshape(*batch, *tail), pair[1].reshape(*batch, *tail))

    return DerivativeEnclosure(
        rs(e.value, out),
        rs(e.jacobian, out, d),
        None if e.hessian is None else rs(e.hessian, out, d, d),
    )


def enclose_box_and_centre(
    mlp: MLP, lo: np.ndarray, hi: np.ndarray, *, hessian: bool = True
) -> tuple[DerivativeEnclosure, DerivativeEnclosure]:
    """Centred enclosures over the boxes ``(N, in)`` and enclosures at their centres
    (``mlp_bounds._mid_rad``), from one propagation (the centres ride along with the boxes)."""
    lo, hi = _check_box(mlp, lo, hi)
    box, centre = _propagate(mlp, lo, hi, hessian, True)
    assert centre is not None
    return box, centre


def _propagate(
    mlp: MLP, lo: np.ndarray, hi: np.ndarray, hessian: bool, centred: bool
) -> tuple[DerivativeEnclosure, DerivativeEnclosure | None]:
    """The propagation of :func:`enclose_derivatives` on ``(N, in)`` boxes; with ``centred`` the
    second result encloses the derivatives at the centres."""
    d = mlp.in_dim
    n = lo.shape[0]
    if centred:
        c, r = _mid_rad(lo, hi)
        zlo, zhi = np.concatenate([lo, c]), np.concatenate([hi, c])
    else:
        zlo, zhi = lo, hi
    jz: tuple[np.ndarray, np.ndarray] | None = None  # None: the identity (exact)
    tz: tuple[np.ndarray, np.ndarray] | None = None  # None: zero (exact)
    for w, b, act in zip(mlp.weights, mlp.biases, _layer_acts(mlp)):
        alo, ahi = _affine(w, b, zlo, zhi)
        if jz is None:
            pw = np.broadcast_to(w, (zlo.shape[0], *w.shape))
            ja = (pw, pw)
        else:
            ja = _interval_matmul_point_left(w, *jz)
        ta = None
        if hessian and tz is not None:
            k = tz[0].shape[-3]
            flat = (tz[0].reshape(-1, k, d * d), tz[1].reshape(-1, k, d * d))
            tlo, thi = _interval_matmul_point_left(w, *flat)
            ta = (tlo.reshape(-1, w.shape[0], d, d), thi.reshape(-1, w.shape[0], d, d))
        if centred:
            mlo, mhi = _mv_form(alo[n:], ahi[n:], ja[0][:n], ja[1][:n], r)
            blo, bhi = _intersect(alo[:n], ahi[:n], mlo, mhi)
            alo = np.concatenate([blo, alo[n:]])
            ahi = np.concatenate([bhi, ahi[n:]])
            if ta is not None:
                ja = _centred_jacobian(ja, ta, n, r)
        if act is None or act == "identity":
            zlo, zhi, jz, tz = alo, ahi, ja, ta
            continue
        s1lo, s1hi = enclose_activation_prime(act, alo, ahi)
        jz = _imul(s1lo[..., None], s1hi[..., None], *ja)
        if hessian:
            s2lo, s2hi = enclose_activation_second(act, alo, ahi)
            plo, phi = _outer_rows(*ja)
            tz = _imul(s2lo[..., None, None], s2hi[..., None, None], plo, phi)
            if ta is not None:
                tz = _iadd(*tz, *_imul(s1lo[..., None, None], s1hi[..., None, None], *ta))
            if centred:
                jz = _centred_jacobian(jz, tz, n, r)
        zlo, zhi = enclose_activation(act, alo, ahi)
    if jz is None:  # pragma: no cover - an MLP has at least one layer
        raise SpecError("an MLP needs at least one layer")
    if tz is None and hessian:  # one affine layer: zero Hessian
        zero = np.zeros((zlo.shape[0], mlp.out_dim, d, d))
        tz = (zero, zero)
    jz = (np.broadcast_to(jz[0], jz[0].shape), np.broadcast_to(jz[1], jz[1].shape))

    def part(sl: slice) -> DerivativeEnclosure:
        return DerivativeEnclosure(
            (zlo[sl], zhi[sl]),
            (np.array(jz[0][sl]), np.array(jz[1][sl])),
            None if tz is None or not hessian else (tz[0][sl], tz[1][sl]),
        )

    return part(slice(0, n)), (part(slice(n, None)) if centred else None)


def enclose_jacobian_centred(mlp: MLP, lo, hi) -> tuple[np.ndarray, np.ndarray]:
    """Jacobian enclosure over boxes, the plain (centred pre-activation) enclosure intersected
    with the mean-value form ``J(x) in [J(c)] + [H(box)] (x - c)``.

    ``lo``, ``hi``: ``(..., in)``; returns ``(J_lo, J_hi)`` of shape ``(..., out, in)``. Sound by
    the mean value theorem applied to each entry ``J_ji`` on the segment from ``c`` to ``x``.
    """
    lo, hi = _check_box(mlp, lo, hi)
    batch = lo.shape[:-1]
    d = mlp.in_dim
    lo = lo.reshape(-1, d)
    hi = hi.reshape(-1, d)
    c, r = _mid_rad(lo, hi)
    box = enclose_derivatives(mlp, lo, hi, hessian=True)
    at_c = enclose_derivatives(mlp, c, c, hessian=False, centred=False)
    assert box.hessian is not None
    out = mlp.out_dim
    hlo, hhi = box.hessian
    clo, chi = at_c.jacobian
    mlo, mhi = _mv_form(
        clo.reshape(-1, out * d),
        chi.reshape(-1, out * d),
        hlo.reshape(-1, out * d, d),
        hhi.reshape(-1, out * d, d),
        r,
    )
    jlo, jhi = _intersect(*box.jacobian, mlo.reshape(-1, out, d), mhi.reshape(-1, out, d))
    return jlo.reshape(*batch, out, d), jhi.reshape(*batch, out, d)
