"""Global contraction of a learned closed loop that is affine in MLP blocks (L1-DRAC Assumption 2).

L1-DRAC needs the nominal closed loop ``F(x) = f(x) + g pi_IL(x)`` to contract on all of ``R^n``
(the true SDE leaves every bounded set with positive probability), so a rate proved on a box does
not serve it. For a neural policy a box branch and bound cannot reach infinity; three routes here
do, whenever the expressions are affine in MLP blocks (docs/math/contraction.md sections 9, 11):

Route "lipschitz-affine-mlp" (the loop itself).
    If ``F(x) = A x + c + sum_k C_k h_k(x)`` with constant ``A, c, C_k`` and MLPs ``h_k``, then
    ``J(x) = A + sum_k C_k Dh_k(x)`` and, by subadditivity of the log norm and
    ``mu_2(M) <= ||M||_2``,

        mu_2(J(x)) <= mu_2(A) + sum_k ||C_k||_2 ||Dh_k(x)||_2 <= mu_2(A) + sum_k ||C_k||_2 L_k,

    with ``L_k`` a certified Lipschitz constant of ``h_k`` (``||Dh_k(x)||_2 <= L_k`` for all x).
    Every x, every t: the rate ``lambda = -(that bound)`` is global.

Route "perturbation-of-expert" (the issue's ``lambda_IL >= lambda* - ||g|| sup ||D Delta||``).
    With ``g`` constant and ``Delta = pi_IL - pi*`` affine in MLP blocks, ``Delta(x) = A_D x + c_D
    + sum_k C_k h_k(x)``, the learned Jacobian is ``J_IL = J* + g D Delta``, so

        mu_2(J_IL) <= mu_2(J*) + ||g||_2 ||D Delta(x)||_2
                   <= -lambda* + ||g||_2 (||A_D||_2 + sum_k ||C_k||_2 L_k),

    global whenever the expert's rate ``lambda*`` is (blocks shared by ``pi_IL`` and ``pi*``
    cancel in ``Delta`` before its coefficients are read).

Route "slope-lmi" (the loop itself, neuron by neuron; docs/math/contraction.md section 11).
    Every neuron of every block is slope-restricted; the S-procedure LMI of
    :mod:`drip_cert.analysis.contraction.slope_lmi` with ``P = I`` proves ``mu_2(J(x)) <= -lambda``
    for every
    x, verified in Arb. When the trace condition rules every such LMI out, its number is the
    route's reason.

Floating point: the coefficients are read from sympy with ``float()`` (within
:data:`~drip_cert.analysis.growth.closed_loop.CONVERSION_ULPS` spacings of the true ones);
``mu_2(A)``
is bounded in Arb (:func:`~drip_cert.analysis.contraction.lognorm.mu2_constant_bounds`) and widened
by the
Frobenius norm of the conversion radius (Weyl); norms are rigorous upper bounds and every sum and
product is rounded up. The Lipschitz constants come from
:func:`~drip_cert.analysis.networks.mlp.lipschitz_bound` (the smaller of the layer product and the
verified LipSDP bound), with their own provenance: the rate's ``how`` is derived from them.
"""

from __future__ import annotations

import itertools
import math
import time
from dataclasses import dataclass

import numpy as np
import sympy as sp

from drip_cert.analysis.contraction.lognorm import mu2_constant_bounds
from drip_cert.analysis.contraction.rate import ContractionResult
from drip_cert.analysis.contraction.slope_lmi import (
    TraceObstruction,
    slope_lmi_rate,
    slope_structure,
)
from drip_cert.analysis.growth.closed_loop import CONVERSION_ULPS, AffineBlocks, affine_in_blocks
from drip_cert.analysis.networks.mlp import (
    enclose_jacobian,
    enclose_jacobian_centred,
    enclose_output,
    lipschitz_bound,
)
from drip_cert.analysis.networks.policy_regularity import difference_jacobian_lipschitz
from drip_cert.model.system import System
from drip_cert.numerics.bnb import maximize
from drip_cert.numerics.rounding import (
    add_down_np,
    add_up,
    add_up_np,
    matmul_bounds,
    mul_down_np,
    mul_up,
    mul_up_np,
    norm2_up_np,
    spectral_norm_upper,
    sub_down_np,
    sum_up_np,
    up_np,
)
from drip_cert.provenance import GLOBAL, How, Quantity

__all__ = [
    "GlobalRate",
    "lipschitz_rate",
    "perturbation_rate",
    "best_global_rate",
    "difference_jacobian_bound",
    "slope_lmi_rate_global",
    "sup_policy_difference",
]


@dataclass(frozen=True)
class GlobalRate:
    """A contraction rate on all of ``R^n`` (and all t) with the pieces of its bound.

    Attributes
    ----------
    result
        The rate as a :class:`~drip_cert.analysis.contraction.rate.ContractionResult` (``method``
        names
        the route; ``how`` derived from the inputs).
    rate
        The rate as a :class:`~drip_cert.provenance.Quantity` ``lambda`` (its ``how`` and
        ``scope`` computed from the inputs below).
    inputs
        The quantities the bound rests on (``mu_2(A)`` or ``lambda*``, norms, Lipschitz
        constants).
    """

    result: ContractionResult
    rate: Quantity
    inputs: tuple[Quantity, ...]


def _conversion_radius(M: np.ndarray) -> float:
    """Frobenius norm (rounded up) of the radius of the float conversion of the coefficients."""
    rad = CONVERSION_ULPS * np.spacing(np.abs(np.asarray(M, dtype=float))).ravel()
    return float(norm2_up_np(rad))


def _norm_up(M: np.ndarray) -> float:
    """``||M_true||_2 <= ||M||_2 + ||E||_F`` for the converted coefficients ``M``."""
    return add_up(float(spectral_norm_upper(np.asarray(M, dtype=float))), _conversion_radius(M))


def _block_lipschitz(s: System, name: str) -> Quantity | None:
    """The certified Lipschitz constant of block ``name`` (the smaller sound one of the layer
    product and LipSDP), ``None`` when the block is not an MLP or no bound is finite."""
    mlp = s.blocks[name].mlp
    if mlp is None:
        return None
    cands = [lipschitz_bound(mlp, "product")]
    try:
        cands.append(lipschitz_bound(mlp, "lipsdp"))
    except Exception:  # noqa: BLE001 - the SDP solver may fail; the product bound stays
        pass
    sound = [q for q in cands if q.how != How.ESTIMATE and math.isfinite(q.value)]
    return min(sound, key=lambda q: q.value).renamed(f"Lip({name})") if sound else None


#: block name -> its Lipschitz quantity, shared by the routes of one call (LipSDP solved once)
LipMemo = dict[str, Quantity | None]


def _affine_and_block_sum(
    s: System, expr: sp.ImmutableMatrix, memo: LipMemo | None
) -> tuple[AffineBlocks, float, list[Quantity]] | None:
    """``expr = A x + c + sum_k C_k h_k(S_k x)`` and ``sum_k ||C_k||_2 Lip(h_k) ||S_k||_2`` (rounded
    up) with the Lipschitz constants it used, or ``None`` when ``expr`` is not affine in MLP blocks
    of ``x`` (or of a constant linear map ``S_k x`` of it, e.g. ``N(Theta^{-1} z)``) or a block has
    no finite constant (:func:`_blocks_sum`)."""
    dec = affine_in_blocks(expr, s, input_maps=True)
    if dec is None:
        return None
    parts = _blocks_sum(s, dec, memo)
    if parts is None:
        return None
    total, lips = parts
    return dec, total, lips


def _blocks_sum(
    s: System, dec: AffineBlocks, memo: LipMemo | None = None
) -> tuple[float, list[Quantity]] | None:
    """``sum_k ||C_k||_2 L_k ||S_k||_2`` rounded up (``||S_k||_2 = 1`` without an input map: the
    chain rule ``D(h o S) = Dh(S x) S``), and the Lipschitz quantities; ``None`` when a block is
    not an MLP (no certified Lipschitz constant). ``memo`` keeps each block's constant."""
    memo = {} if memo is None else memo
    total = 0.0
    lips: list[Quantity] = []
    for name, C in dec.C.items():
        if name not in memo:
            memo[name] = _block_lipschitz(s, name)
        L = memo[name]
        if L is None:
            return None
        lips.append(L)
        if np.any(C):
            term = mul_up(_norm_up(C), L.value)
            if name in dec.S:
                # S exact: float() is correctly rounded, within CONVERSION_ULPS spacings
                S = np.array([[float(e) for e in row] for row in dec.S[name].tolist()])
                term = mul_up(term, _norm_up(S))
            total = add_up(total, term)
    return total, lips


def _result(rate: Quantity, method: str, note: str, t0: float) -> ContractionResult:
    return ContractionResult(
        rate=rate.value,
        how=rate.how,
        method=method,
        scope=rate.scope,
        max_mu_upper=-rate.value,
        max_mu_sampled=math.nan,
        witness=None,
        tolerance=math.nan,
        n_boxes=0,
        time_s=time.perf_counter() - t0,
        note=note,
        stop="closed-form",
    )


def lipschitz_rate(
    s: System, which: str = "learned", memo: LipMemo | None = None
) -> GlobalRate | None:
    """Route "lipschitz-affine-mlp": ``lambda >= -(mu_2(A) + sum_k ||C_k||_2 L_k)`` on all x, t.

    ``None`` when the closed loop is not affine in MLP blocks applied to the whole state, depends
    on ``t``, or has no policy ``which``.
    """
    t0 = time.perf_counter()
    if which == "learned" and s.learned is None:
        return None
    found = _affine_and_block_sum(s, s.closed_loop(which), memo)
    if found is None:
        return None
    dec, total, lips = found
    _, mu_hi = mu2_constant_bounds(dec.A)
    mu_a = Quantity.derive(
        "mu_2(A)",
        add_up(mu_hi, _conversion_radius(dec.A)),
        method=How.SOUND,
        source="log norm of the linear part, Arb (docs/math/contraction.md section 9)",
    )
    upper = add_up(mu_a.value, total)
    rate = Quantity.derive(
        "lambda",
        -upper,
        inputs=[mu_a, *lips],
        method=How.SOUND,
        source="DRIP Assumption 2 / L1-DRAC Assumption 2, Euclidean log norm",
        note="lipschitz-affine-mlp on all x, all t: mu_2(J) <= mu_2(A) + sum ||C_k|| Lip(h_k)",
        scope=GLOBAL,
    )
    note = (
        f"mu_2(A) <= {mu_a.value:.6g}, sum_k ||C_k|| Lip(h_k) <= {total:.6g} "
        f"({', '.join(f'{q.name} <= {q.value:.4g}' for q in lips) or 'no blocks'})"
    )
    return GlobalRate(_result(rate, "lipschitz-affine-mlp", note, t0), rate, (mu_a, *lips))


def perturbation_rate(
    s: System, expert_rate: Quantity, memo: LipMemo | None = None
) -> GlobalRate | None:
    """Route "perturbation-of-expert": ``lambda_IL >= lambda* - ||g||_2 sup_x ||D(pi_IL - pi*)||``.

    Needs a constant ``g``, a global (exact or sound) ``expert_rate`` and ``pi_IL - pi*`` affine in
    MLP blocks; ``None`` otherwise.
    """
    t0 = time.perf_counter()
    if s.learned is None or s.g.free_symbols:
        return None
    if expert_rate.how == How.ESTIMATE or not expert_rate.scope.all_x:
        return None
    if not expert_rate.scope.all_t or not math.isfinite(expert_rate.value):
        return None
    d_norm = difference_jacobian_bound(s, memo)
    if d_norm is None:
        return None
    g = np.array(s.g.tolist(), dtype=float)
    g_norm = Quantity.derive(
        "||g||_2", _norm_up(g), method=How.SOUND, source="spectral norm of the constant g"
    )
    value = expert_rate.value - mul_up(g_norm.value, d_norm.value)
    # lambda* - (rounded-up product) can round up in the subtraction: step one ulp down
    value = float(np.nextafter(value, -np.inf))
    rate = Quantity.derive(
        "lambda",
        value,
        inputs=[expert_rate, g_norm, d_norm],
        method=How.SOUND,
        source="DRIP Assumption 2 / L1-DRAC Assumption 2, Euclidean log norm",
        note="perturbation-of-expert on all x, all t: lambda_IL >= lambda* - ||g|| sup||D Delta||",
        scope=GLOBAL,
    )
    note = (
        f"lambda* = {expert_rate.value:.6g}, ||g||_2 <= {g_norm.value:.6g}, "
        f"sup||D(pi_IL - pi*)|| <= {d_norm.value:.6g}"
    )
    return GlobalRate(
        _result(rate, "perturbation-of-expert", note, t0), rate, (expert_rate, g_norm, d_norm)
    )


def difference_jacobian_bound(s: System, memo: LipMemo | None = None) -> Quantity | None:
    """``sup_x ||D(pi_IL - pi*)(x)||_2`` on all of ``R^n`` (sound) when ``pi_IL - pi* = A_D x +
    c_D + sum_k C_k h_k(x)`` is affine in MLP blocks: ``||A_D||_2 + sum_k ||C_k||_2 Lip(h_k)``,
    rounded up (for a piecewise-linear ``h_k`` a bound on every Clarke Jacobian, so a Lipschitz
    constant of the difference, docs/math/nonsmooth.md); ``None`` otherwise."""
    if s.learned is None:
        return None
    found = _affine_and_block_sum(s, sp.ImmutableMatrix(s.learned - s.expert), memo)
    if found is None:
        return None
    dec, total, lips = found
    return Quantity.derive(
        "sup||D(pi_IL - pi*)||",
        add_up(_norm_up(dec.A), total),
        inputs=lips,
        method=How.SOUND,
        source="||A_Delta|| + sum_k ||C_k|| Lip(h_k), all x",
    )


def slope_lmi_rate_global(
    s: System,
    which: str = "learned",
    reasons: list[str] | None = None,
    obstructions: list[TraceObstruction] | None = None,
) -> GlobalRate | None:
    """Route "slope-lmi": ``mu_2(J(x)) <= -lambda`` for all x from the slope-restricted LMI
    (:func:`~drip_cert.analysis.contraction.slope_lmi.slope_lmi_rate` with ``P = I``), verified in
    Arb.

    ``None`` when the loop is not affine in MLP blocks applied to the state or no verified rate
    exists; then the reason (the trace condition's number, the solver status, the LMI size) is
    appended to ``reasons`` and, when the trace condition rules every LMI out, the condition
    (:class:`~drip_cert.analysis.contraction.slope_lmi.TraceObstruction`, its numbers) to
    ``obstructions``.
    """
    t0 = time.perf_counter()
    if which == "learned" and s.learned is None:
        return None
    # a block read through a constant input map (N(Theta^{-1} z) in a metric's coordinates) is
    # folded into its first layer by slope_structure
    dec = affine_in_blocks(s.closed_loop(which), s, input_maps=True)
    if dec is None or not dec.C or any(s.blocks[b].mlp is None for b in dec.C):
        return None
    mlps = {b: s.blocks[b].mlp for b in dec.C}
    st = slope_structure(dec, mlps)  # type: ignore[arg-type]
    res = slope_lmi_rate(st)
    if res.rate is None:
        if reasons is not None:
            reasons.append(f"slope-lmi route: {res.reason}")
        if obstructions is not None and res.obstruction.blocks():
            obstructions.append(res.obstruction)
        return None
    rate = Quantity.derive(
        "lambda",
        res.rate,
        method=How.SOUND,
        source="DRIP Assumption 2 / L1-DRAC Assumption 2, Euclidean log norm",
        note="slope-lmi on all x, all t: S-procedure LMI over every neuron's slope range, P = I, "
        "verified in Arb (docs/math/contraction.md section 11)",
        scope=GLOBAL,
    )
    folded = f" (input maps folded into the first layer: {', '.join(sorted(dec.S))})"
    note = (
        f"{st.N} neurons, LMI size {st.dim}, {res.reason}"
        + (folded if dec.S else "")
        + "; trace condition tr J(s)/n <= "
        f"{res.obstruction.mean_eigenvalue:.4g} at the worst slope vertex found"
    )
    return GlobalRate(_result(rate, "slope-lmi", note, t0), rate, ())


def best_global_rate(
    s: System,
    expert_rate: Quantity | None,
    reasons: list[str] | None = None,
    obstructions: list[TraceObstruction] | None = None,
) -> GlobalRate | None:
    """The largest proved rate of the three routes (``None`` when none applies); ``reasons``
    collects why the slope-lmi route proved nothing, when it did not, and ``obstructions`` the
    trace condition when it rules out every slope-restricted LMI."""
    memo: LipMemo = {}
    cands = [lipschitz_rate(s, "learned", memo)]
    if expert_rate is not None:
        cands.append(perturbation_rate(s, expert_rate, memo))
    if not any(c is not None and c.result.holds for c in cands):
        cands.append(slope_lmi_rate_global(s, "learned", reasons, obstructions))
    ok = [c for c in cands if c is not None and math.isfinite(c.rate.value)]
    return max(ok, key=lambda c: c.rate.value) if ok else None


#: relative tolerance of the branch and bound on sup ||pi_IL - pi*|| (a 10 % looser h0 is a 10 %
#: looser rho_TaSIL; tighter costs boxes exponentially in n)
SUP_DIFF_RTOL = 0.1
#: work budget of that branch and bound: a count of sub-boxes, never wall time, so the bound (and
#: rho_TaSIL) is the same on every machine. 8000 boxes: ~3 ms each for the paper example's two
#: 64-64 / 4-16 networks on one quiet core (~25 s), about what the former 10 s budget reached
SUP_DIFF_MAX_BOXES = 8000
#: sub-boxes split per round of that branch and bound (the networks enclose the round's boxes in
#: one propagation; the round size doubles from 1 up to this, numerics/bnb.py). 16: on a 300-box
#: budget as tight as one box at a time (1.10x the sampled sup in tests/test_learned_loop.py;
#: 32 gives 1.27x, 64 1.39x: wide rounds spend the budget on boxes that did not need a split)
SUP_DIFF_BATCH = 16


def _affine_enclosure(s: System, dec: AffineBlocks, lo: np.ndarray, hi: np.ndarray):
    """Rigorous ``(lo, hi)`` of ``A x + c + sum_k C_k h_k(x)`` over the box ``[lo, hi]``
    (centre-radius products rounded outward, the coefficient conversion radius included).
    ``lo``, ``hi``: ``(..., n)``, a batch of boxes enclosed at once."""

    def lin(M: np.ndarray, vlo: np.ndarray, vhi: np.ndarray):
        # x -> M x on the last axis: (..., d) @ M^T, each product enclosed by matmul_bounds
        m = 0.5 * vlo + 0.5 * vhi
        r = up_np(np.maximum(vhi - m, m - vlo))
        clo, chi = matmul_bounds(m, M.T)
        rad = matmul_bounds(r, np.abs(M).T)[1]
        vabs = np.maximum(np.abs(vlo), np.abs(vhi))
        conv = matmul_bounds(vabs, (CONVERSION_ULPS * np.spacing(np.abs(M))).T)[1]
        rad = add_up_np(rad, conv)
        return sub_down_np(clo, rad), add_up_np(chi, rad)

    c = np.asarray(dec.c, dtype=float)
    rc = CONVERSION_ULPS * np.spacing(np.abs(c))
    olo, ohi = lin(dec.A, lo, hi)
    olo, ohi = sub_down_np(add_down_np(olo, c), rc), add_up_np(add_up_np(ohi, c), rc)
    for name, C in dec.C.items():
        mlp = s.blocks[name].mlp
        assert mlp is not None  # checked by the caller
        hlo, hhi = enclose_output(mlp, lo, hi)
        a, b = lin(C, hlo, hhi)
        olo, ohi = add_down_np(olo, a), add_up_np(ohi, b)
    return olo, ohi


def _difference_jacobian_at(
    s: System, dec: AffineBlocks, c: np.ndarray, hi: np.ndarray | None = None
):
    """Rigorous ``(lo, hi)`` of ``D Delta(x) = A + sum_k C_k Dh_k(x)`` at the point ``c`` or, with
    ``hi``, for every ``x`` in the box ``[c, hi]`` (each network's Jacobian enclosed by
    :func:`~drip_cert.analysis.networks.mlp.enclose_jacobian_centred` there). ``c``, ``hi``:
    ``(..., n)``, a batch of points or boxes; the result has shape ``(..., n_out, n)``."""
    A = np.asarray(dec.A, dtype=float)
    ra = CONVERSION_ULPS * np.spacing(np.abs(A))
    jlo, jhi = sub_down_np(A, ra), add_up_np(A, ra)
    for name, C in dec.C.items():
        mlp = s.blocks[name].mlp
        assert mlp is not None
        if hi is None:
            hlo, hhi = enclose_jacobian(mlp, c, c)
        else:
            hlo, hhi = enclose_jacobian_centred(mlp, c, hi)
        m = 0.5 * hlo + 0.5 * hhi
        rr = up_np(np.maximum(hhi - m, m - hlo))
        plo, phi = matmul_bounds(C, m)  # (out, k) @ (..., k, n): batched like @
        rad = matmul_bounds(np.abs(C), rr)[1]
        conv = matmul_bounds(
            CONVERSION_ULPS * np.spacing(np.abs(C)), np.maximum(abs(hlo), abs(hhi))
        )
        rad = add_up_np(rad, conv[1])
        jlo = sub_down_np(add_down_np(jlo, plo), rad)
        jhi = add_up_np(add_up_np(jhi, phi), rad)
    return jlo, jhi


def sup_policy_difference(
    s: System, box: np.ndarray, ball: tuple[np.ndarray, float] | None = None
) -> Quantity | None:
    """Sound upper bound of ``sup_{x in box} ||pi_IL(x) - pi*(x)||_2`` by branch and bound.

    With ``ball = (c, r)`` the sup is over ``box cap {||x - c||_2 <= r}`` (docs/math/tasil.md
    section 3.10): the search starts on ``box`` clipped to the ball's bounding box, and a sub-box
    whose rounded-down distance to ``c`` exceeds ``r`` holds no point of the set (bound 0, as the
    norm is >= 0).

    ``pi_IL - pi*`` must be affine in MLP blocks (shared blocks cancel first); each sub-box is
    enclosed by interval bound propagation through the networks and centre-radius products, the
    norm of the enclosure rounded up; the smallest of that, the first- and second-order forms
    around the box centre and the centred form with the box's interval Jacobian (docs/math/tasil.md
    section 3.9) bounds the sub-box. ``None`` when the difference has another form.
    """
    if s.learned is None:
        return None
    dec = affine_in_blocks(sp.ImmutableMatrix(s.learned - s.expert), s)
    if dec is None or any(s.blocks[b].mlp is None for b in dec.C):
        return None
    box = np.asarray(box, dtype=float)
    parts = _blocks_sum(s, dec)
    # global Lipschitz constant of the difference: ||A|| + sum ||C_k|| Lip(h_k) (mean-value form)
    lip = math.inf if parts is None else add_up(_norm_up(dec.A), parts[0])
    lips = [] if parts is None else parts[1]
    l2q = difference_jacobian_lipschitz(s)  # Lipschitz constant of D Delta (global), or None
    l2 = math.inf if l2q is None or l2q.how == How.ESTIMATE else l2q.value
    if l2q is not None and math.isfinite(l2):
        lips = [*lips, l2q]

    if ball is not None:
        bc, br = np.asarray(ball[0], dtype=float), float(ball[1])
        rad = np.full(bc.shape, br)
        box = np.stack(
            [
                np.maximum(box[:, 0], sub_down_np(bc, rad)),
                np.minimum(box[:, 1], add_up_np(bc, rad)),
            ],
            axis=1,
        )
        if np.any(box[:, 0] > box[:, 1]):
            return _empty_sup(lips, box)
    if not dec.C and box.shape[0] <= AFFINE_VERTEX_MAX_DIM:
        return _affine_sup(s, dec, box, ball)

    def upper_many(bs: np.ndarray) -> np.ndarray:
        """Per sub-box ``B`` of the batch ``bs`` (``(K, n, 2)``), an upper bound of the sup."""
        blo, bhi = bs[:, :, 0], bs[:, :, 1]
        lo, hi = _affine_enclosure(s, dec, blo, bhi)
        ub = norm2_up_np(np.maximum(np.abs(lo), np.abs(hi)))
        c = 0.5 * blo + 0.5 * bhi
        r = up_np(np.maximum(bhi - c, c - blo))
        clo, chi = _affine_enclosure(s, dec, c, c)
        cmag = np.maximum(np.abs(clo), np.abs(chi))
        # centred (interval mean-value) form, docs/math/tasil.md section 3.9: per component,
        # Delta_i(x) = Delta_i(c) + D Delta_i(z_i)(x - c) with z_i in the box, so
        # |Delta_i(x)| <= |Delta_i(c)| + sum_j max|[D Delta](box)_ij| r_j
        jlo, jhi = _difference_jacobian_at(s, dec, blo, bhi)
        spread = matmul_bounds(np.maximum(np.abs(jlo), np.abs(jhi)), r[:, :, None])[1][..., 0]
        ub = np.minimum(ub, norm2_up_np(add_up_np(cmag, spread)))
        if math.isfinite(lip):
            # first order: ||D(x)|| <= ||D(c)|| + Lip ||x - c||, D(c) enclosed at the point c
            ub = np.minimum(ub, add_up_np(norm2_up_np(cmag), mul_up_np(lip, norm2_up_np(r))))
        if math.isfinite(l2):
            # second order: D(x) = D(c) + DD(c)(x - c) + E, ||E|| <= L2/2 ||x - c||^2; the linear
            # part's range over the box is exact per component: D(c)_i +- sum_j |DD(c)_ij| r_j
            plo, phi = _difference_jacobian_at(s, dec, c)
            spread = matmul_bounds(np.maximum(np.abs(plo), np.abs(phi)), r[:, :, None])[1][..., 0]
            lin = np.maximum(np.abs(sub_down_np(clo, spread)), np.abs(add_up_np(chi, spread)))
            r2 = norm2_up_np(r) ** 2 * (1.0 + 4.0 * 2.0**-52)
            ub = np.minimum(ub, add_up_np(norm2_up_np(lin), mul_up_np(0.5 * l2, r2)))
        if ball is not None:
            # a sub-box whose distance to the ball's centre (rounded down) exceeds the radius
            # holds no point of the set: bound 0 (the norm is >= 0)
            gap = np.maximum(np.maximum(sub_down_np(blo, bc), sub_down_np(bc, bhi)), 0.0)
            far = -sum_up_np(-mul_down_np(gap, gap)) > mul_up(br, br)  # a lower bound of the sum
            ub = np.where(far, 0.0, ub)
        return ub

    def value_many(xs: np.ndarray) -> np.ndarray:
        d = xs @ dec.A.T + dec.c
        for name, C in dec.C.items():
            mlp = s.blocks[name].mlp
            assert mlp is not None
            d = d + mlp.apply_np(xs) @ C.T
        v = np.linalg.norm(d, axis=-1)
        if ball is not None:  # a sample outside the set says nothing of its sup
            v = np.where(np.linalg.norm(xs - bc, axis=-1) > br, 0.0, v)
        return v

    res = maximize(
        box,
        None,
        rtol=SUP_DIFF_RTOL,
        max_boxes=SUP_DIFF_MAX_BOXES,
        corners=True,
        upper_many=upper_many,
        value_many=value_many,
        batch=SUP_DIFF_BATCH,
    )
    where = box.tolist() if ball is None else f"{box.tolist()} cap B({bc.tolist()}, {br:.6g})"
    return Quantity.derive(
        "sup||pi_IL - pi*||",
        res.upper,
        inputs=lips,
        method=How.SOUND,
        source="interval branch and bound over the box (analysis/contraction/learned_loop.py)",
        note=f"over {where}: <= {res.upper:.6g} (sampled {res.lower:.6g}, "
        f"{res.n_boxes} boxes, stop {res.stop})",
    )


#: an affine difference's sup over a box is read at its 2^n vertices up to this dimension
AFFINE_VERTEX_MAX_DIM = 12


def _affine_sup(
    s: System, dec: AffineBlocks, box: np.ndarray, ball: tuple[np.ndarray, float] | None
) -> Quantity:
    """``sup ||A x + c||_2`` over ``box`` (and the ball) for an affine difference, no search.

    ``x -> ||A x + c||`` is convex, so its maximum over a box is attained at a vertex: each of the
    ``2^n`` vertices is enclosed rigorously (:func:`_affine_enclosure` at the point, the
    coefficient conversion included) and the largest norm rounded up is the bound, exact up to
    rounding. Over ``box cap B(c_b, r)`` the smaller of that and ``||A c_b + c|| + ||A||_2 r`` (the
    triangle inequality on the ball) holds.
    """
    vals = []
    for v in itertools.product(*box):
        pt = np.asarray(v, dtype=float)
        lo, hi = _affine_enclosure(s, dec, pt, pt)
        vals.append(float(norm2_up_np(np.maximum(np.abs(lo), np.abs(hi)))))
    value = max(vals)
    how = f"affine difference: the largest of its {len(vals)} vertex values (convex norm)"
    if ball is not None:
        bc, br = np.asarray(ball[0], dtype=float), float(ball[1])
        lo, hi = _affine_enclosure(s, dec, bc, bc)
        at_c = float(norm2_up_np(np.maximum(np.abs(lo), np.abs(hi))))
        via_ball = add_up(at_c, mul_up(_norm_up(dec.A), br))
        if via_ball < value:
            value, how = via_ball, "affine difference: ||A c + c0|| + ||A||_2 r on the ball"
    return Quantity.derive(
        "sup||pi_IL - pi*||",
        value,
        method=How.SOUND,
        source="vertex enumeration of an affine difference (analysis/contraction/learned_loop.py)",
        note=f"over {box.tolist()}: <= {value:.6g} ({how}, rounded up)",
    )


def _empty_sup(lips: list[Quantity], box: np.ndarray) -> Quantity:
    """The sup over an empty set, bounded by 0 (the norm is >= 0)."""
    return Quantity.derive(
        "sup||pi_IL - pi*||",
        0.0,
        inputs=lips,
        method=How.SOUND,
        source="interval branch and bound over the box (analysis/contraction/learned_loop.py)",
        note=f"over {box.tolist()} cap the ball: empty, 0 boxes",
    )
