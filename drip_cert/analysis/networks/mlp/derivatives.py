"""Fast sound enclosures of an MLP's value, Jacobian and Hessian over many boxes at once.

:func:`enclose_derivatives` propagates, for a batch of boxes ``(N, in)``, interval enclosures of

* the value ``z_k`` of every layer,
* its Jacobian ``J_k = d z_k / d x`` (``(N, n_k, in)``),
* its Hessian ``T_k = d^2 z_k / dx^2`` (``(N, n_k, in, in)``, optional),

through ``a_k = W_k z_k + b_k``, ``z_{k+1} = s_k(a_k)`` (the convention of
:mod:`drip_cert.analysis.networks.mlp.enclosures`) by the forward-mode chain rule in interval
arithmetic:

``J_a = W J_z``, ``T_a = W T_z``,
``J_{k+1} = diag(s'(a)) J_a``,
``T_{k+1}[m, i, l] = s''(a_m) J_a[m, i] J_a[m, l] + s'(a_m) T_a[m, i, l]``.

Every product of a point matrix with an interval array uses the centre-radius form with the
rounding term of Higham's Thm 3.1
(:func:`~drip_cert.numerics.interval_np.matmul_point_left`), every product of
two intervals the four end products rounded outward, and the activation and its first two
derivatives are enclosed over each pre-activation interval from their monotone pieces
(:func:`enclose_activation_second` for ``s''``), with the library-function error budgets of
:mod:`drip_cert.numerics.rounding` (sound as long as numpy meets its documented accuracy, as for
the rest of :mod:`drip_cert.analysis.networks.mlp`).

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

from dataclasses import dataclass

import numpy as np

from drip_cert.analysis.networks.mlp.enclosures import check_box
from drip_cert.errors import SpecError
from drip_cert.model.activations import Identity, get_activation
from drip_cert.model.mlp import MLP
from drip_cert.numerics.interval_np import (
    affine_enclosure_rad,
    iadd,
    imul,
    intersect,
    matmul_point_left,
    mean_value_form,
    mid_rad,
)
from drip_cert.numerics.rounding import add_up_np, down_np, sub_down_np, up_np

__all__ = [
    "DerivativeEnclosure",
    "enclose_activation_second",
    "enclose_box_and_centre",
    "enclose_derivatives",
    "enclose_jacobian_centred",
]


# --------------------------------------------------------------------------- helpers


def _centred_jacobian(j, t, n: int, r):
    """Intersect the box rows (the first ``n``) of a Jacobian enclosure ``j`` (``(2n, m, d)``)
    with the mean-value form ``[J(c)] + [T(box)] [-r, r]`` (``t``: the Hessian enclosure, the
    centre rows after the box rows). Sound: the mean value theorem on each entry."""
    m, d = j[0].shape[-2:]
    mlo, mhi = mean_value_form(
        j[0][n:].reshape(n, m * d),
        j[1][n:].reshape(n, m * d),
        t[0][:n].reshape(n, m * d, d),
        t[1][:n].reshape(n, m * d, d),
        r,
    )
    blo, bhi = intersect(j[0][:n], j[1][:n], mlo.reshape(n, m, d), mhi.reshape(n, m, d))
    return np.concatenate([blo, j[0][n:]]), np.concatenate([bhi, j[1][n:]])


def enclose_activation_second(name, lo, hi) -> tuple[np.ndarray, np.ndarray]:
    """Sound enclosure of the second derivative ``s''`` over ``[lo, hi]`` (elementwise); the
    proofs are in the activation classes (:meth:`Activation.second_range`). A
    :class:`~drip_cert.errors.SpecError` for an activation whose slope is not Lipschitz."""
    act = get_activation(name)
    out = act.second_range(lo, hi)
    if out is None:
        raise SpecError(f"activation {act.spec!r} has no second derivative (its slope jumps)")
    return out


# --------------------------------------------------------------------------- propagation


@dataclass(frozen=True)
class DerivativeEnclosure:
    """Entrywise enclosures of an MLP's value, Jacobian and Hessian over a batch of boxes.

    For every ``x`` in box ``b``: ``value[0][b] <= mlp(x) <= value[1][b]`` (``(N, out)``),
    likewise ``jacobian`` (``(N, out, in)``) and ``hessian`` (``(N, out, in, in)``, ``None``
    when not asked for or when the network is not smooth: relu has no second derivative).
    """

    value: tuple[np.ndarray, np.ndarray]
    jacobian: tuple[np.ndarray, np.ndarray]
    hessian: tuple[np.ndarray, np.ndarray] | None


def _outer_rows(jlo, jhi):
    """Enclosure of ``P[m, i, l] = J[m, i] J[m, l]`` (the diagonal ``i = l`` as a square)."""
    plo, phi = imul(jlo[..., :, None], jhi[..., :, None], jlo[..., None, :], jhi[..., None, :])
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
    lo, hi = check_box(mlp, lo, hi)
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
    mlp: MLP,
    lo: np.ndarray,
    hi: np.ndarray,
    *,
    hessian: bool = True,
    first_rad: np.ndarray | None = None,
) -> tuple[DerivativeEnclosure, DerivativeEnclosure]:
    """Centred enclosures over the boxes ``(N, in)`` and enclosures at their centres
    (:func:`~drip_cert.numerics.interval_np.mid_rad`), from one propagation (the centres ride
    along with the boxes).

    ``first_rad``: the enclosures hold for every first-layer weight within ``first_rad`` of
    ``mlp.weights[0]`` entrywise (a network whose first layer is an interval matrix, e.g. a
    folded input map, :class:`~drip_cert.model.blocks.MappedMLP`): the first pre-activation is
    widened by ``first_rad |x|`` and its Jacobian is the interval weight itself."""
    lo, hi = check_box(mlp, lo, hi)
    box, centre = _propagate(mlp, lo, hi, hessian, True, first_rad)
    assert centre is not None
    return box, centre


def _propagate(
    mlp: MLP,
    lo: np.ndarray,
    hi: np.ndarray,
    hessian: bool,
    centred: bool,
    first_rad: np.ndarray | None = None,
) -> tuple[DerivativeEnclosure, DerivativeEnclosure | None]:
    """The propagation of :func:`enclose_derivatives` on ``(N, in)`` boxes; with ``centred`` the
    second result encloses the derivatives at the centres. ``first_rad``: the radius of an
    interval first-layer weight (:func:`enclose_box_and_centre`)."""
    d = mlp.in_dim
    n = lo.shape[0]
    hessian = hessian and mlp.smooth  # no second derivative through a kink (relu)
    if centred:
        c, r = mid_rad(lo, hi)
        zlo, zhi = np.concatenate([lo, c]), np.concatenate([hi, c])
    else:
        zlo, zhi = lo, hi
    jz: tuple[np.ndarray, np.ndarray] | None = None  # None: the identity (exact)
    tz: tuple[np.ndarray, np.ndarray] | None = None  # None: zero (exact)
    for k, (w, b, act) in enumerate(zip(mlp.weights, mlp.biases, mlp.activations)):
        wr = first_rad if k == 0 else None
        alo, ahi = affine_enclosure_rad(w, wr, b, zlo, zhi)
        if jz is None:
            if wr is None:
                pw = np.broadcast_to(w, (zlo.shape[0], *w.shape))
                ja = (pw, pw)
            else:  # d a / d x is the interval weight itself
                ja = (
                    np.broadcast_to(sub_down_np(w, wr), (zlo.shape[0], *w.shape)),
                    np.broadcast_to(add_up_np(w, wr), (zlo.shape[0], *w.shape)),
                )
        else:
            ja = matmul_point_left(w, *jz)
        ta = None
        if hessian and tz is not None:
            k = tz[0].shape[-3]
            flat = (tz[0].reshape(-1, k, d * d), tz[1].reshape(-1, k, d * d))
            tlo, thi = matmul_point_left(w, *flat)
            ta = (tlo.reshape(-1, w.shape[0], d, d), thi.reshape(-1, w.shape[0], d, d))
        if centred:
            mlo, mhi = mean_value_form(alo[n:], ahi[n:], ja[0][:n], ja[1][:n], r)
            blo, bhi = intersect(alo[:n], ahi[:n], mlo, mhi)
            alo = np.concatenate([blo, alo[n:]])
            ahi = np.concatenate([bhi, ahi[n:]])
            if ta is not None:
                ja = _centred_jacobian(ja, ta, n, r)
        if isinstance(act, Identity):
            zlo, zhi, jz, tz = alo, ahi, ja, ta
            continue
        s1lo, s1hi = act.slope_range(alo, ahi)
        jz = imul(s1lo[..., None], s1hi[..., None], *ja)
        if hessian:
            s2lo, s2hi = enclose_activation_second(act, alo, ahi)  # smooth: checked above
            plo, phi = _outer_rows(*ja)
            tz = imul(s2lo[..., None, None], s2hi[..., None, None], plo, phi)
            if ta is not None:
                tz = iadd(*tz, *imul(s1lo[..., None, None], s1hi[..., None, None], *ta))
            if centred:
                jz = _centred_jacobian(jz, tz, n, r)
        zlo, zhi = act.enclose(alo, ahi)
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
    with the mean-value form ``J(x) in [J(c)] + [H(box)] (x - c)`` (smooth networks; for a
    nonsmooth one the plain enclosure of its Clarke Jacobian alone).

    ``lo``, ``hi``: ``(..., in)``; returns ``(J_lo, J_hi)`` of shape ``(..., out, in)``. Sound by
    the mean value theorem applied to each entry ``J_ji`` on the segment from ``c`` to ``x``.
    """
    lo, hi = check_box(mlp, lo, hi)
    batch = lo.shape[:-1]
    d = mlp.in_dim
    lo = lo.reshape(-1, d)
    hi = hi.reshape(-1, d)
    c, r = mid_rad(lo, hi)
    box = enclose_derivatives(mlp, lo, hi, hessian=True)
    out = mlp.out_dim
    if box.hessian is None:
        # a nonsmooth network (relu): no second derivative, so no mean-value form; the plain
        # enclosure (of the Clarke Jacobian) is what is sound
        jlo, jhi = box.jacobian
        return jlo.reshape(*batch, out, d), jhi.reshape(*batch, out, d)
    at_c = enclose_derivatives(mlp, c, c, hessian=False, centred=False)
    hlo, hhi = box.hessian
    clo, chi = at_c.jacobian
    mlo, mhi = mean_value_form(
        clo.reshape(-1, out * d),
        chi.reshape(-1, out * d),
        hlo.reshape(-1, out * d, d),
        hhi.reshape(-1, out * d, d),
        r,
    )
    jlo, jhi = intersect(*box.jacobian, mlo.reshape(-1, out, d), mhi.reshape(-1, out, d))
    return jlo.reshape(*batch, out, d), jhi.reshape(*batch, out, d)
