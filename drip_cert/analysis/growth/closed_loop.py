"""Constants of the nominal closed loop that L1-DRAC needs (L1-DRAC Assumptions 1, 3 and 8).

In DRIP the L1-DRAC layer sees the nominal drift ``F(t, a) = f(t, a) + g(t) pi_IL(a)`` (the
closed loop under the mid-level policy). This module bounds

* ``Delta_f``: ``||F(t, a)||^2 <= Delta_f^2 (1 + ||a||^2)`` (Assumption 1);
* ``L_f``: the Lipschitz constant of ``F`` in ``a`` (Assumption 8, optional);
* ``Delta_star``: ``||X*_t||_{L_{2p*}} <= Delta_star`` (Assumption 3).

Sound route: when ``F(a) = A a + c + sum_k C_k h_k(a)`` with constant ``A, c, C_k`` and MLP blocks
``h_k`` applied to the state (as in the paper's example), ``||h_k(a)|| <= B_k`` (tanh/GELU hidden
layers and an affine output layer give a bounded output for tanh, see
:func:`mlp_output_bound`) and ``Lip(h_k) <= L_k``, so with ``beta = ||c|| + sum ||C_k|| B_k``:
``||F(a)|| <= ||A|| ||a|| + beta <= sqrt(||A||^2 + beta^2) sqrt(1 + ||a||^2)`` (Cauchy-Schwarz)
and ``Lip(F) <= ||A|| + sum ||C_k|| L_k``. ``Delta_star`` follows from contraction: the trajectory
from ``x_0`` stays within ``e^{-lambda t}||x_0||`` of the trajectory from ``0``, whose norm obeys
``d/dt ||y|| <= -lambda ||y|| + ||F(t, 0)||``, so ``||X*_t|| <= max_{x0 in box} ||x_0|| +
sup_t ||F(t, 0)|| / lambda`` almost surely, hence in every ``L_{2p}`` (valid when the rate holds
on all of ``R^n``; on a box it is labelled an estimate). Anything else is a sampled estimate.

With a known diffusion ``p != 0`` the nominal process (4b) is the SDE ``dX* = F dt + p dW*`` and
the deterministic bound is false; ``Delta_star`` is then the moment bound of
docs/math/contraction.md Proposition 6.5 (:func:`sde_moment_bound`): Ito on ``||X||^{2p*}``,
Jensen, and a comparison argument give ``sup_t ||X*_t||_{L_{2p*}} <= max(max_box ||x0||, u*)``
with ``u*`` the positive root of ``kappa u^2 = B u + A`` (6.5b), from the rate, ``||F(0)||`` and a
growth bound of the known diffusion ``||p||_F^2 <= a0 + a1 ||x|| + a2 ||x||^2``
(:func:`diffusion_growth`, from ``Delta_p``); ``inf`` when ``kappa <= 0``.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field

import numpy as np
import sympy as sp

from drip_cert.analysis.growth.constants import batch_fn
from drip_cert.analysis.growth.regularity import growth_bound, sup_bound
from drip_cert.analysis.networks.mlp import enclose_output, lipschitz_bound
from drip_cert.model.activations import Identity
from drip_cert.model.blocks import block_applications, linear_input_map
from drip_cert.model.mlp import MLP
from drip_cert.model.system import System
from drip_cert.numerics.rounding import (
    add_down_np,
    add_up,
    add_up_np,
    div_up,
    matmul_bounds,
    mul_up,
    norm2_up_np,
    spectral_norm_upper,
    sq_up,
    sqrt_up,
    sub_down,
    sub_down_np,
    sum_up_np,
    up_np,
)
from drip_cert.numerics.sampling import growth_ratio_estimate, holder_estimate
from drip_cert.provenance import How, Quantity

SUPERLINEAR_RADIUS = 1e5
#: a sampled growth ratio that peaks at radius >= this (the sampler goes to 1e6) is taken to grow
#: without bound (e.g. a cubic drift): Assumption 1's linear growth then fails


@dataclass(frozen=True)
class AffineBlocks:
    """``F(a) = A a + c + sum_k C_k h_k(S_k a)`` (constant ``A``, ``c``, ``C_k``; ``S_k`` the
    exact input map of block ``k`` when it is in ``S``, else the identity)."""

    A: np.ndarray
    c: np.ndarray
    C: dict[str, np.ndarray]
    S: dict[str, sp.ImmutableMatrix] = field(default_factory=dict)


def affine_in_blocks(
    exprs: sp.MatrixBase, s: System, *, input_maps: bool = False
) -> AffineBlocks | None:
    """Decompose ``exprs`` (a vector in the states) as affine in the states and in block outputs
    applied to the whole state; ``None`` when it is not of that form (or depends on ``t``).

    With ``input_maps=True`` a block may also be applied to ``S x`` for one constant matrix ``S``
    per block (:func:`~drip_cert.model.blocks.linear_input_map`; e.g. ``N(Theta^{-1} z)`` in the
    coordinates of a metric), recorded in :attr:`AffineBlocks.S`: only for callers that read
    ``S`` (a caller that ignores it would analyse ``h_k(a)`` instead of ``h_k(S_k a)``)."""
    vec = sp.Matrix(exprs)
    x = list(s.states)
    apps = set()
    for e in vec:
        apps |= block_applications(e)
    maps: dict[str, sp.ImmutableMatrix] = {}
    for a in apps:
        if a.deriv:
            return None
        if a.args == tuple(x):
            S = sp.ImmutableMatrix(sp.eye(len(x)))
        elif not input_maps:
            return None
        else:
            found = linear_input_map(a, x)
            if found is None:
                return None
            S = found
        if maps.setdefault(a.block_name, S) != S:
            return None
    syms = {a: sp.Dummy(type(a).__name__) for a in apps}
    lin = vec.xreplace(syms).applyfunc(sp.expand)  # cancellations (e.g. after a change of
    # coordinates) must show before the coefficients are read
    variables = x + list(syms.values())
    for e in lin:
        if s.t in e.free_symbols:
            return None
        if not variables:
            continue
        try:
            if not sp.Poly(e, *variables).is_linear:
                return None
        except sp.PolynomialError:
            return None
    n = len(vec)
    A = np.array([[float(sp.diff(e, xi)) for xi in x] for e in lin])
    zero = {v: 0 for v in variables}
    c = np.array([float(e.xreplace(zero)) for e in lin])
    C: dict[str, np.ndarray] = {}
    for a, z in syms.items():
        M = C.setdefault(a.block_name, np.zeros((n, s.blocks[a.block_name].out_dim)))
        for i, e in enumerate(lin):
            M[i, a.out_index] += float(sp.diff(e, z))
    eye = sp.eye(len(x))
    return AffineBlocks(A, c, C, {b: S for b, S in maps.items() if S != eye})


def mlp_output_bound(mlp: MLP) -> float:
    """``sup_x ||mlp(x)||_2`` for bounded activations, else ``inf`` (rounded up).

    When the last hidden layer's activation has a bounded range (tanh ``[-1, 1]``, sigmoid
    ``[0, 1]``: :attr:`Activation.value_range`), its outputs lie in ``[-m, m]^w`` with ``m`` the
    largest end modulus, so an affine output layer gives ``||W z + b|| <= || m |W| 1 + |b| ||``
    entrywise (row sums and the norm rounded up). A bounded output activation gives
    ``m_out sqrt(out_dim)``. (GELU, relu, ... are unbounded: ``inf``.)
    """
    out = mlp.activations[-1]
    lo, hi = out.value_range
    if math.isfinite(lo) and math.isfinite(hi):
        return mul_up(max(abs(lo), abs(hi)), sqrt_up(float(mlp.out_dim)))
    if len(mlp.weights) < 2 or not isinstance(out, Identity):
        return math.inf
    lo, hi = mlp.activations[-2].value_range
    m = max(abs(lo), abs(hi))
    if not math.isfinite(m):
        return math.inf
    W, b = mlp.weights[-1], mlp.biases[-1]
    rows = sum_up_np(np.concatenate([up_np(m * np.abs(W)), np.abs(b)[:, None]], axis=1), axis=1)
    return float(norm2_up_np(rows))


CONVERSION_ULPS = 2
"""``affine_in_blocks`` converts the sympy coefficients with ``float()``: exact for floats,
correctly rounded for rationals (``int / int``) and within an ulp for other constants
(``evalf``), so each entry is within ``CONVERSION_ULPS`` spacings of the true coefficient."""


def _norm_of_converted(M: np.ndarray, spectral: bool) -> float:
    """Upper bound of the spectral (matrix) or Euclidean (vector) norm of the true coefficients
    whose floats are ``M``: the norm of ``M`` plus the Frobenius norm of the conversion radius
    (``||X||_2 <= ||X||_F`` bounds the spectral norm of the error)."""
    M = np.asarray(M, dtype=float)
    base = float(spectral_norm_upper(M)) if spectral else float(norm2_up_np(M.ravel()))
    rad = CONVERSION_ULPS * np.spacing(np.abs(M)).ravel()  # exact: a power-of-two multiple
    return add_up(base, float(norm2_up_np(rad)))


def _box_radius_up(box: np.ndarray) -> float:
    """``max_{x in box} ||x||`` (the farthest corner), rounded up: ``sqrt(sum max(lo^2, hi^2))``."""
    return float(norm2_up_np(np.max(np.abs(box), axis=1)))


def _f_at_zero_up(dec: AffineBlocks, s: System) -> float:
    """Upper bound of ``||F(0)|| = ||c + sum_k C_k h_k(0)||``: each ``h_k(0)`` enclosed by
    interval bound propagation, the affine combination in interval arithmetic."""
    c = np.asarray(dec.c, dtype=float)
    rad_c = CONVERSION_ULPS * np.spacing(np.abs(c))  # the conversion of the true c to floats
    lo = sub_down_np(c, rad_c)
    hi = add_up_np(c, rad_c)
    for b, C in dec.C.items():
        mlp = s.blocks[b].mlp
        assert mlp is not None  # the caller checked that every block of dec.C has an MLP
        zero = np.zeros(mlp.in_dim)
        hlo, hhi = enclose_output(mlp, zero, zero)
        # C h for h in [hlo, hhi]: centre-radius with the product rounding (matmul_bounds), plus
        # the conversion radius of C times |h|
        m = 0.5 * hlo + 0.5 * hhi
        r = up_np(np.maximum(hhi - m, m - hlo))
        clo, chi = matmul_bounds(C, m[:, None])
        rad = matmul_bounds(np.abs(C), r[:, None])[1][:, 0]
        habs = np.maximum(np.abs(hlo), np.abs(hhi))
        conv = matmul_bounds(CONVERSION_ULPS * np.spacing(np.abs(C)), habs[:, None])[1][:, 0]
        rad = add_up_np(rad, conv)
        lo = sub_down_np(add_down_np(lo, clo[:, 0]), rad)
        hi = add_up_np(add_up_np(hi, chi[:, 0]), rad)
    return float(norm2_up_np(np.maximum(np.abs(lo), np.abs(hi))))


@dataclass(frozen=True)
class DiffusionGrowth:
    """A growth bound of the known diffusion on ``[0, T] x R^n`` (docs/math/contraction.md (6.5a)):

    ``||p(t, x)||_F^2 <= a0 + a1 ||x|| + a2 ||x||^2``, every coefficient ``>= 0``.

    ``quantity`` is the bound it rests on (``Delta_p``), for the provenance of what uses it.
    """

    a0: float
    a1: float
    a2: float
    quantity: Quantity
    note: str


def diffusion_growth(s: System, Delta_p: Quantity | None = None) -> tuple[DiffusionGrowth, ...]:
    """Growth bounds (6.5a) of ``s.diffusion``; empty when the known diffusion is zero.

    Parameters
    ----------
    s
        The system.
    Delta_p
        ``Delta_p`` with ``||p(t, x)||_F^2 <= Delta_p^2 (1 + ||x||^2)^{1/2}`` (L1-DRAC Assumption 1
        as :func:`~drip_cert.analysis.growth.constants.uncertainty_constants` computes it, or the
        user's ``[constants]`` value); computed here by
        :func:`~drip_cert.analysis.growth.regularity.growth_bound` when ``None``.

    Returns
    -------
    tuple of DiffusionGrowth
        Every bound proved (each is valid; the caller keeps the one giving the smallest result):
        ``(1 + r^2)^{1/2} <= 1 + r`` gives ``a0 = a1 = Delta_p^2``, ``a2 = 0``; when ``p`` does not
        depend on the state, ``Delta_p`` bounds ``sup_t ||p(t)||_F`` itself (the supremum of
        the ratio is attained at ``x = 0``), so ``a0 = Delta_p^2``, ``a1 = a2 = 0`` (exact for a
        constant ``p``); when the entries of ``p`` have finite whole-space enclosures
        (:func:`~drip_cert.analysis.growth.regularity.sup_bound`), ``a0 = sup ||p||_F^2``, ``a1 = a2
        = 0``.
        Squares are rounded up.
    """
    p = s.diffusion
    if p is None or all(e == 0 for e in p):
        return ()
    depends_t = any(s.t in e.free_symbols for e in p)
    t_sym = s.t if depends_t else None
    t_rng = (0.0, float(s.horizon)) if depends_t else (0.0, 0.0)
    if Delta_p is None:
        Delta_p = growth_bound(
            sp.Matrix(p),
            s.states,
            t_sym,
            t_rng,
            sp.Rational(1, 2),
            "Delta_p",
            source="L1-DRAC Assumption 1",
            evaluate=batch_fn(s, sp.Matrix(p)) if s.blocks else None,
        )
    D2 = sq_up(Delta_p.value) if math.isfinite(Delta_p.value) else math.inf
    apps = set()
    for e in p:
        apps |= block_applications(e)
    if not apps and not any(x in e.free_symbols for e in p for x in s.states):
        note = f"p independent of x: ||p||_F^2 <= Delta_p^2 = {D2:.6g}"
        return (DiffusionGrowth(D2, 0.0, 0.0, Delta_p, note),)
    out = [
        DiffusionGrowth(
            D2,
            D2,
            0.0,
            Delta_p,
            "||p||_F^2 <= Delta_p^2 (1 + ||x||^2)^(1/2) <= Delta_p^2 (1 + ||x||), "
            f"Delta_p^2 = {D2:.6g}",
        )
    ]
    if not apps:
        sup = sup_bound(sp.Matrix(p), s.states, t_sym, t_rng, "sup ||p||_F", source="")
        if math.isfinite(sup.value):
            S2 = sq_up(sup.value)
            note = f"||p||_F^2 <= sup ||p||_F^2 = {S2:.6g} (whole-space enclosures)"
            out.append(DiffusionGrowth(S2, 0.0, 0.0, sup, note))
    return tuple(out)


def sde_moment_bound(
    r0: float, b: float, lam: float, q: int, a0: float, a1: float = 0.0, a2: float = 0.0
) -> float:
    """``sup_t ||X_t||_{L_{2q}}`` for ``dX = F(t, X) dt + p(t, X) dW`` (docs/math/contraction.md
    Proposition 6.5), rounded up; ``inf`` when (6.5c) ``kappa > 0`` fails.

    Hypotheses: ``(x - y)^T (F(t, x) - F(t, y)) <= -lam ||x - y||^2`` for all ``x, y`` (a global
    log-norm rate), ``||F(t, 0)|| <= b``, ``||p(t, x)||_F^2 <= a0 + a1 ||x|| + a2 ||x||^2`` and
    ``||X_0|| <= r0`` almost surely. With ``k = (2q - 1) / 2``,

    ``kappa = lam - k a2``, ``B = b + k a1``, ``A = k a0`` and
    ``u* = B / (2 kappa) + sqrt((B / (2 kappa))^2 + A / kappa)`` (the positive root of
    ``kappa u^2 = B u + A``), the bound is ``max(r0, u*)`` (6.5b). ``u*`` grows with ``A, B`` and
    falls with ``kappa``: ``kappa`` is rounded down, everything else up.

    Parameters
    ----------
    r0
        ``||X_0|| <= r0`` (the farthest corner of the initial support).
    b
        ``sup_t ||F(t, 0)||``.
    lam
        The rate (``> 0``).
    q
        The moment order (``p*`` of L1-DRAC Assumption 3: the ``L_{2q}`` norm), an integer ``>= 1``.
    a0, a1, a2
        The growth bound of the diffusion (:class:`DiffusionGrowth`).
    """
    if q < 1 or int(q) != q:
        raise ValueError(f"the moment order q must be an integer >= 1, got {q!r}")
    if min(r0, b, a0, a1, a2) < 0 or not lam > 0:
        raise ValueError("r0, b, a0, a1, a2 must be >= 0 and lam > 0")
    k = (2 * int(q) - 1) / 2  # exact: a half-integer below 2^52
    kappa = sub_down(lam, mul_up(k, a2)) if a2 > 0 else lam
    if not kappa > 0 or not math.isfinite(kappa):
        return math.inf
    A = mul_up(k, a0)
    B = add_up(b, mul_up(k, a1))
    h = div_up(B, 2.0 * kappa)  # 2 kappa is exact
    u = add_up(h, sqrt_up(add_up(sq_up(h), div_up(A, kappa))))
    return max(r0, u)


@dataclass(frozen=True)
class ClosedLoopConstants:
    """``Delta_f``, ``L_f`` (and whether Assumption 8 is used) and ``Delta_star``."""

    Delta_f: Quantity
    L_f: Quantity
    Delta_star: Quantity
    #: ``sup_t ||X*_t - x'_t||_{L_2p}``: the nominal SDE (known diffusion) against the ODE ``x'``
    #: that TaSIL is about (:func:`nominal_sde_gap`); ``None`` without a known diffusion
    rho_sde: Quantity | None = None

    def quantities(self) -> tuple[Quantity, ...]:
        """The constants of L1-DRAC's assumptions (``rho_sde`` is not one: it adds to ``rho``)."""
        return (self.Delta_f, self.L_f, self.Delta_star)


def nominal_sde_gap(
    r0: float,
    F0: float,
    lam: Quantity,
    p: int,
    growths: tuple[DiffusionGrowth, ...],
    method: How,
    suffix: str = "",
) -> Quantity:
    """``sup_t ||X*_t - x'_t||_{L_2p}`` for the nominal SDE ``dX* = F dt + p(t, X*) dW`` and the
    ODE ``dx' = F dt`` from the same initial state (docs/math/contraction.md Proposition 6.6).

    DRIP's decomposition ``||X - x*|| <= ||X - X*|| + ||X* - x'|| + ||x' - x*||`` needs this middle
    term when the known diffusion is not zero (L1-DRAC bounds the first, TaSIL the last). The error
    ``e = X* - x'`` has the drift ``F(x' + e) - F(x')``, which is ``0`` at ``e = 0`` and contracts
    at ``lam``, and the diffusion ``p(t, x' + e)``; with ``||x'_t|| <= R = r0 + ||F(0)|| / lam``
    (the ODE, surely) a growth bound ``a0 + a1 ||x|| + a2 ||x||^2`` of ``||p||_F^2`` becomes
    ``(a0 + a1 R + a2 R^2) + (a1 + 2 a2 R) ||e|| + a2 ||e||^2``, and Proposition 6.5 with
    ``r0 = 0`` (same start) and ``b = 0`` gives the bound (:func:`sde_moment_bound`). For a bounded
    diffusion it is ``sqrt((2p - 1) sup||p||_F^2 / (2 lam))``. The smallest over ``growths``.
    """
    R = add_up(r0, div_up(F0, lam.value))
    vals = []
    for g in growths:
        a0 = add_up(g.a0, add_up(mul_up(g.a1, R), mul_up(g.a2, sq_up(R))))
        a1 = add_up(g.a1, mul_up(2.0, mul_up(g.a2, R)))
        vals.append(sde_moment_bound(0.0, 0.0, lam.value, p, a0, a1, g.a2))
    i = int(np.argmin(vals))
    value, growth = vals[i], growths[i]
    note = (
        f"sup_t ||X*_t - x'_t||_L{2 * p} (nominal SDE against the ODE, contraction.md Prop. 6.6: "
        f"lambda = {lam.value:.6g}, sup_t ||x'_t|| <= {R:.6g}; {growth.note})"
        if math.isfinite(value)
        else "no finite bound of ||X* - x'|| (contraction.md Prop. 6.6: the known diffusion "
        f"grows too fast for lambda = {lam.value:.6g}; {growth.note})"
    )
    return Quantity.derive(
        "rho_sde",
        value,
        inputs=[lam, growth.quantity],
        method=method,
        source="DRIP decomposition with a known diffusion (this project: the nominal SDE of "
        "L1-DRAC (4b) against the nominal ODE of TaSIL)",
        note=note + suffix,
    )


def _sde_delta_star(
    r0: float,
    F0: float,
    lam: Quantity,
    p_star: int,
    growths: tuple[DiffusionGrowth, ...],
    method: How,
    source: str,
    what_f0: str,
    suffix: str = "",
) -> Quantity:
    """``Delta_star`` of Proposition 6.5 for a nominal process with a known diffusion: the
    smallest bound over the diffusion's growth bounds ``growths`` (each one valid)."""
    k = (2 * p_star - 1) / 2
    vals = [sde_moment_bound(r0, F0, lam.value, p_star, g.a0, g.a1, g.a2) for g in growths]
    i = int(np.argmin(vals))
    value, growth = vals[i], growths[i]
    if math.isfinite(value):
        why = (
            f"sup_t ||X*_t||_L{2 * p_star} <= max(max_box ||x0||, u*) = max({r0:.6g}, u*) "
            f"(contraction.md Prop. 6.5: nominal SDE with the known diffusion, {what_f0} "
            f"= {F0:.6g}, lambda = {lam.value:.6g}, p* = {p_star}; {growth.note})"
        )
    elif not math.isfinite(growth.a0) or not math.isfinite(growth.a1):
        why = (
            "no finite growth bound of the known diffusion (Delta_p = "
            f"{growth.quantity.value:.6g}): contraction.md Prop. 6.5 gives nothing; give "
            "Delta_star in [constants] if you know one"
        )
    else:
        why = (
            f"contraction.md (6.5c) fails: kappa = lambda - {k:g} a2 = {lam.value:.6g} - "
            f"{k:g} * {growth.a2:.6g} <= 0 (the diffusion grows too fast for the "
            f"{2 * p_star}-th moment to stay bounded by this argument)"
        )
    return Quantity.derive(
        "Delta_star",
        value,
        inputs=[lam, growth.quantity],
        method=method,
        source=source,
        note=why + suffix,
    )


def closed_loop_constants(
    s: System,
    which: str,
    lam: Quantity,
    global_rate: bool,
    *,
    p_star: int = 1,
    p: int = 1,
    Delta_p: Quantity | None = None,
) -> ClosedLoopConstants:
    """Bound ``Delta_f``, ``L_f``, ``Delta_star`` of the closed loop under ``which`` policy.

    Parameters
    ----------
    s
        The system.
    which
        ``'learned'`` (DRIP's L1-DRAC nominal system) or ``'expert'``.
    lam
        The contraction rate of that closed loop (``> 0``).
    global_rate
        Whether ``lam`` holds on all of ``R^n`` (needed for a sound ``Delta_star``).
    p_star
        The moment order of L1-DRAC Assumption 3 (``Delta_star`` bounds the ``L_{2 p_star}``
        norm); matters only with a known diffusion.
    p
        The moment order of ``rho_L1`` (``rho_sde`` bounds the same ``L_{2p}`` norm).
    Delta_p
        The growth constant of the known diffusion (:func:`diffusion_growth`); computed when
        ``None`` and the diffusion is not zero.
    """
    F = s.closed_loop(which)
    box = np.array(s.support, dtype=float)
    r0 = _box_radius_up(box)
    # a block read through an input map, h(S a) (e.g. N(Theta^{-1} z)): sup||h(S a)|| <= sup||h||,
    # h(S 0) = h(0), Lip(h o S) <= Lip(h) ||S||_2
    dec = affine_in_blocks(F, s, input_maps=True)
    src_f = "L1-DRAC Assumption 1 (nominal drift = closed loop under the policy)"
    src_l = "L1-DRAC Assumption 8"
    src_s = "L1-DRAC Assumption 3"
    growths = diffusion_growth(s, Delta_p)
    if dec is not None and all(s.blocks[b].mlp is not None for b in dec.C):
        # every norm is a rigorous upper bound and every operation is rounded up (all terms >= 0)
        nA = _norm_of_converted(dec.A, spectral=True)
        beta = _norm_of_converted(dec.c, spectral=False)
        lip = nA
        lips = []
        for b, C in dec.C.items():
            mlp = s.blocks[b].mlp
            assert mlp is not None  # checked above: every block of dec.C has an MLP
            nC = _norm_of_converted(C, spectral=True)
            Lh = lipschitz_bound(mlp)
            lips.append(Lh)
            beta = add_up(beta, mul_up(nC, mlp_output_bound(mlp)))
            term = mul_up(nC, Lh.value)
            if b in dec.S:  # S exact: float() correctly rounded, within CONVERSION_ULPS spacings
                S = np.array([[float(e) for e in row] for row in dec.S[b].tolist()])
                term = mul_up(term, _norm_of_converted(S, spectral=True))
            lip = add_up(lip, term)
        dF = Quantity.derive(
            "Delta_f",
            sqrt_up(add_up(sq_up(nA), sq_up(beta))),
            method=How.SOUND,
            source=src_f,
            note=f"F = A a + c + sum C h(a): sqrt(||A||^2 + beta^2), ||A|| = {nA:.6g}, "
            f"beta = ||c|| + sum ||C|| sup||h|| = {beta:.6g} (norms and sums rounded up)",
        )
        lF = Quantity.derive(
            "L_f",
            lip,
            inputs=lips,
            method=How.SOUND,
            source=src_l,
            note="||A|| + sum ||C|| Lip(h) (spectral-norm product bound of each MLP; times "
            "||S|| for a block applied to S a)",
        )
        F0 = _f_at_zero_up(dec, s)
        global_ok = global_rate and lam.how.proved
        method = How.SOUND if global_ok else How.ESTIMATE
        if growths:
            dS = _sde_delta_star(
                r0,
                F0,
                lam,
                p_star,
                growths,
                method,
                src_s,
                "||F(0)||",
                "" if global_ok else " (rate not global: estimate)",
            )
            gap = nominal_sde_gap(
                r0, F0, lam, p, growths, method, "" if global_ok else " (rate not global)"
            )
            return ClosedLoopConstants(dF, lF, dS, gap)
        bound = add_up(r0, div_up(F0, lam.value))
        dS = Quantity.derive(
            "Delta_star",
            bound,
            inputs=[lam],
            method=method,
            source=src_s,
            note=f"max_box ||x0|| + ||F(0)||/lambda = {r0:.6g} + {F0:.6g}/{lam.value:.6g}"
            + ("" if global_ok else " (rate not global: estimate)"),
        )
        return ClosedLoopConstants(dF, lF, dS)
    # sampled estimates
    fn = batch_fn(s, sp.Matrix(F))
    times = np.linspace(0.0, s.horizon, 5)
    growth = growth_ratio_estimate(fn, s.n, 1.0, times)
    holder = holder_estimate(fn, s.n, 1.0, times)
    D, L = growth.value, holder.value
    est = "sampled (spheres of radii up to 1e6): an estimate, not a bound"
    est_D, est_L = est + growth.diagnostics(), est + holder.diagnostics()
    if float(np.linalg.norm(growth.argmax)) >= SUPERLINEAR_RADIUS:
        # the ratio is largest at the outermost sampled radius: it grows without bound
        D, L = math.inf, math.inf
        est_D = est_L = (
            "the sampled ratio ||F(a)|| / sqrt(1 + ||a||^2) still grows at ||a|| = 1e6: "
            "super-linear growth, L1-DRAC Assumption 1 fails"
        )
    F0 = max(float(np.linalg.norm(fn(float(t), np.zeros((1, s.n)))[0])) for t in times)
    if growths:
        return ClosedLoopConstants(
            Quantity("Delta_f", D, How.ESTIMATE, src_f, est_D),
            Quantity("L_f", L, How.ESTIMATE, src_l, est_L),
            _sde_delta_star(
                r0,
                F0,
                lam,
                p_star,
                growths,
                How.ESTIMATE,
                src_s,
                "||F(t,0)|| sampled at 5 times",
                " (F(t,0) sampled: estimate)",
            ),
            nominal_sde_gap(r0, F0, lam, p, growths, How.ESTIMATE, " (F(t,0) sampled: estimate)"),
        )
    return ClosedLoopConstants(
        Quantity("Delta_f", D, How.ESTIMATE, src_f, est_D),
        Quantity("L_f", L, How.ESTIMATE, src_l, est_L),
        Quantity(
            "Delta_star",
            r0 + F0 / lam.value,
            How.ESTIMATE,
            src_s,
            "max_box ||x0|| + ||F(t,0)||/lambda with F(t,0) sampled at 5 times",
        ),
    )
