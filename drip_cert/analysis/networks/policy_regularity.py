"""Regularity of a policy's Jacobian: a bound on ``L_dpi`` (DRIP Assumption "PolicyRegularity" (b)).

Routes, strongest first: an affine policy (exact 0); a policy affine in MLP blocks applied to the
state (the layerwise bound of :mod:`drip_cert.analysis.networks.mlp.lipschitz`, global); a policy
without
blocks on a box (interval enclosures of its second derivatives, valid on that box only); otherwise
a sampled estimate. A kink of the Jacobian (``Abs``, ``Max``, ``Min``) anywhere the policy is used
makes the constant infinite: the assumption fails there.
"""

from __future__ import annotations

import math

import numpy as np
import sympy as sp

from drip_cert.analysis.growth.closed_loop import CONVERSION_ULPS, affine_in_blocks
from drip_cert.analysis.networks.mlp import jacobian_lipschitz_bound
from drip_cert.analysis.networks.mlp.derivatives import enclose_derivatives
from drip_cert.model.blocks import block_applications
from drip_cert.model.system import System
from drip_cert.numerics.interval import UnsupportedExpression, compile_enclosure, enclose_expr
from drip_cert.numerics.interval_np import affine_enclosure, iadd, imul
from drip_cert.numerics.rounding import (
    add_up,
    add_up_np,
    mul_up,
    norm2_up_np,
    spectral_norm_upper,
    sq_up,
    sqrt_up,
    sub_down_np,
    up_np,
)
from drip_cert.provenance import How, Quantity, Scope

__all__ = [
    "LOCAL_GRID",
    "LOCAL_MAX_BOXES",
    "LOCAL_SPLIT",
    "difference_jacobian_lipschitz",
    "jacobian_lipschitz",
    "local_jacobian_lipschitz",
]

#: The local route's work (:func:`local_jacobian_lipschitz`), counts, the same on every machine:
#: a first grid of ``k^n <= LOCAL_GRID`` equal sub-boxes (16 x 16 in 2-D, 4^4 in 4-D), then
#: rounds that bisect the ``LOCAL_SPLIT`` sub-boxes of largest bound, ``LOCAL_MAX_BOXES`` bounded
#: sub-boxes in all (the bound is first order in the sub-box width: refining where it is largest
#: is what lowers the maximum).
LOCAL_GRID = 256
LOCAL_SPLIT = 256
LOCAL_MAX_BOXES = 8192


def jacobian_lipschitz(s: System, which: str, box: np.ndarray | None = None) -> Quantity:
    """A bound on the Lipschitz constant of the Jacobian of ``pi*`` or ``pi_IL`` (operator norm;
    DRIP Assumption "PolicyRegularity" (b)).

    Routes: zero Hessian (affine policy, exact 0); a policy ``A x + b + C h(x)`` linear in MLP
    blocks applied to the state gives ``sum ||C_h||_2 L_dh`` with the sound layerwise bound of
    :func:`drip_cert.analysis.networks.mlp.jacobian_lipschitz_bound` (global); a policy without
    blocks
    gets a sound bound on ``box`` from interval enclosures of its second derivatives
    (``||d^2 pi|| <= ||d^2 pi||_F``), valid on that box only; anything else is a sampled
    estimate of ``sup ||d^2 pi||_F`` (labelled so).
    """
    q = _jacobian_lipschitz_of(sp.Matrix(s.policy(which)), s, f"L_dpi_{which}", box)
    assert q is not None  # the sampled estimate is the last route
    return q


def difference_jacobian_lipschitz(s: System, box: np.ndarray | None = None) -> Quantity | None:
    """A bound on the Lipschitz constant of ``d Delta`` with ``Delta = pi_IL - pi*`` itself
    (DRIP Assumption "PolicyRegularity" (b) applied to the difference).

    The same routes as :func:`jacobian_lipschitz`, on the symbolic difference: terms that the
    two policies share (a gravity compensation ``9.81 sin q`` in both) cancel before any bound
    is taken, so the result can be far below the triangle bound ``L_dpi(pi_IL) + L_dpi(pi*)``
    (0 when the policies differ by an affine map). The caller takes the smaller of the two.
    ``None`` when no sound route applies (no sampled estimate is made for the difference).
    """
    diff = sp.Matrix(s.policy("learned")) - sp.Matrix(s.policy("expert"))
    diff = diff.applyfunc(sp.expand)
    return _jacobian_lipschitz_of(diff, s, "L_dDelta", box, estimate=False)


def _jacobian_lipschitz_of(
    pol: sp.Matrix, s: System, name: str, box: np.ndarray | None, estimate: bool = True
) -> Quantity | None:
    """The routes of :func:`jacobian_lipschitz` for the policy expressions ``pol`` (``None``
    instead of the sampled estimate when ``estimate`` is False)."""
    rough = sorted(
        f"{b} ({', '.join(a.spec for a in mlp.activations if not a.smooth)})"
        for b, mlp in ((b, s.blocks[b].mlp) for e in pol for b in _block_names(e))
        if mlp is not None and not mlp.smooth
    )
    if rough:
        return Quantity(
            name,
            math.inf,
            How.SOUND,
            "DRIP Assumption PolicyRegularity (b)",
            f"not Lipschitz: the policy's Jacobian jumps across the kinks of the network "
            f"{rough[0]} (piecewise linear), so no Lipschitz constant exists "
            "(docs/math/nonsmooth.md)",
        )
    jump, branch = _kink_branches(pol, s, box)
    if jump is not None:
        return Quantity(
            name,
            math.inf,
            How.SOUND,
            "DRIP Assumption PolicyRegularity (b)",
            f"the Jacobian of pi is discontinuous where {jump} = 0"
            + ("" if box is None else " (which the box may contain)")
            + ": pi is not C^1 there, its Jacobian has no Lipschitz constant and the "
            "assumption fails (smooth the policy, e.g. sqrt(x^2 + eps^2) for Abs(x))",
        )
    # a kink kept off the box by its enclosure is still a kink elsewhere: no global route then
    dec = affine_in_blocks(pol, s) if branch is None else None
    local = (
        local_jacobian_lipschitz(pol, s, box, name)
        if box is not None and branch is None and s.blocks and (dec is None or dec.C)
        else None
    )
    if dec is not None and all(s.blocks[b].mlp is not None for b in dec.C):
        glob = _affine_in_blocks_route(dec, s, name)
        # the global bound holds for all x; the local one, on the box only, wins when smaller
        return local if local is not None and local.value < glob.value else glob
    if local is not None:
        return local
    if box is not None and not s.blocks:
        # on the box each Abs(a) is its smooth branch +-a (no DiracDelta in d^2 pi)
        pol_box = pol if branch is None else pol.replace(sp.Abs, branch)
        try:
            acc = 0.0
            for e in pol_box:
                for xi in s.states:
                    for xj in s.states:
                        lo, hi = enclose_expr(
                            sp.diff(e, xi, xj),
                            list(s.states),
                            [tuple(b) for b in np.asarray(box, dtype=float)],
                        )
                        acc = add_up(acc, sq_up(max(abs(lo), abs(hi))))
            region = [[round(float(v), 4) for v in row] for row in np.asarray(box)]
            return Quantity.derive(
                name,
                sqrt_up(acc),
                method=How.SOUND,
                source="DRIP Assumption PolicyRegularity (b)",
                note=f"interval enclosure of d^2 pi (Frobenius) on the box {region}: "
                "valid on that box only",
                scope=Scope(tuple(map(tuple, np.asarray(box, dtype=float)))),
            )
        except UnsupportedExpression:
            pass
    if not estimate:
        return None
    # sampled estimate of sup ||Hessian||_F on the support box enlarged by 1
    from drip_cert._jax import jax, jnp  # jax: keep off the API's import path

    fn = s.lower(list(pol))
    hess = jax.jit(jax.vmap(jax.hessian(lambda z: fn(0.0, z))))
    rng = np.random.default_rng(0)
    box = np.array(s.support)
    X = rng.uniform(box[:, 0] - 1.0, box[:, 1] + 1.0, size=(4096, s.n))
    H = np.asarray(hess(jnp.asarray(X)))
    val = float(np.max(np.sqrt(np.sum(H**2, axis=(1, 2, 3)))))
    return Quantity(
        name,
        val,
        How.ESTIMATE,
        "DRIP Assumption PolicyRegularity (b)",
        "sampled sup ||d^2 pi||_F on the support box enlarged by 1 (4096 points, "
        "seed 0): an estimate, not a bound",
    )


def _affine_in_blocks_route(dec, s: System, name: str) -> Quantity:
    """The global route for ``pi = A x + b + sum_h C_h h(x)``: exact 0 without blocks, else
    ``sum ||C_h||_2 L_dh`` (layerwise product-rule bound of each MLP, valid for all x)."""
    if not dec.C:
        return Quantity(
            name,
            0.0,
            How.EXACT,
            "DRIP Assumption PolicyRegularity (b)",
            "affine policy: zero Hessian",
        )
    total, notes, parts = 0.0, [], []
    for bname, C in sorted(dec.C.items()):
        c2 = float(spectral_norm_upper(np.atleast_2d(C)))
        mlp = s.blocks[bname].mlp
        assert mlp is not None  # checked above: every block of dec.C has an MLP
        Lq = jacobian_lipschitz_bound(mlp)
        parts.append(Lq)
        total = add_up(total, mul_up(c2, Lq.value))
        notes.append(f"||C_{bname}||_2 <= {c2:.4g} times L_d{bname} = {Lq.value:.4g}")
    return Quantity.derive(
        name,
        total,
        inputs=parts,
        method=How.SOUND,
        source="DRIP Assumption PolicyRegularity (b)",
        note="policy affine in MLP blocks; "
        + "; ".join(notes)
        + " (layerwise product-rule bound, global)",
    )


def local_jacobian_lipschitz(
    pol: sp.MatrixBase, s: System, box: np.ndarray, name: str = "L_dpi"
) -> Quantity | None:
    """A sound bound on the Lipschitz constant of ``D pol`` on ``box`` from per-sub-box Hessian
    enclosures, the whole expression's Hessian enclosed at once (so terms that cancel in ``pol``,
    e.g. a network trained to reproduce ``-9.81 sin q`` in ``pi_IL - pi*``, cancel per sub-box).

    ``pol = r(x) + sum_h C_h h(x)`` with ``r`` free of blocks and each ``h`` a smooth MLP block
    applied to the state. The box is cut into ``k^n <= LOCAL_SUBBOXES`` equal sub-boxes; on each,
    ``[D^2 pol] = [D^2 r] + sum_h [C_h] [D^2 h]``: ``D^2 r`` by the rigorous interval extension of
    :mod:`drip_cert.numerics.interval`, ``D^2 h`` by the batched enclosures of
    :func:`~drip_cert.analysis.networks.mlp.derivatives.enclose_derivatives` (each neuron's slope
    and
    curvature ranges restricted to the sub-box: local, not the global layer product), ``C_h``
    widened by :data:`~drip_cert.analysis.growth.closed_loop.CONVERSION_ULPS` spacings. For ``x, y``
    in
    the (convex) box, ``D pol(x) - D pol(y) = int_0^1 D^2 pol(y + t (x - y)) [x - y] dt`` and
    ``||D^2 pol [v]||_2 <= ||D^2 pol||_F ||v||``, so the largest Frobenius norm of the enclosures
    (rounded up) is the constant, valid on the box (DRIP Assumption PolicyRegularity (b) there).
    ``None`` when ``pol`` has another form or a term has no interval extension.
    """
    split = _split_blocks(pol, s)
    if split is None:
        return None
    rest, terms = split
    box = np.asarray(box, dtype=float)
    n, m = s.n, len(rest)
    x = list(s.states)
    try:
        second = [
            [
                [
                    compile_enclosure(d2, x) if (d2 := sp.diff(r, x[a], x[b])) != 0 else None
                    for b in range(n)
                ]
                for a in range(n)
            ]
            for r in rest
        ]
    except UnsupportedExpression:
        return None

    def bound(LO: np.ndarray, HI: np.ndarray) -> np.ndarray:
        """Per box, an upper bound of ``sup ||D^2 pol||_F`` over it."""
        N = LO.shape[0]
        Hlo, Hhi = np.zeros((N, m, n, n)), np.zeros((N, m, n, n))
        for j in range(m):
            for a in range(n):
                for b in range(a, n):
                    F = second[j][a][b]
                    if F is None:
                        continue
                    for i in range(N):
                        lo, hi = F(list(zip(LO[i], HI[i])))
                        Hlo[i, j, a, b] = Hlo[i, j, b, a] = lo
                        Hhi[i, j, a, b] = Hhi[i, j, b, a] = hi
        for Cm, bname, M, c in terms:
            mlp = s.blocks[bname].mlp
            assert mlp is not None  # _split_blocks keeps MLP blocks only
            tlo, thi = _block_hessian_in_x(mlp, M, c, LO, HI)
            clo, chi = _converted(Cm)
            for j in range(m):
                for o in range(Cm.shape[1]):
                    if Cm[j, o] == 0.0:
                        continue
                    plo, phi = imul(clo[j, o], chi[j, o], tlo[:, o], thi[:, o])
                    Hlo[:, j], Hhi[:, j] = iadd(Hlo[:, j], Hhi[:, j], plo, phi)
        mag = np.maximum(np.abs(Hlo), np.abs(Hhi)).reshape(N, -1)
        return norm2_up_np(mag, axis=-1)

    # a grid of LOCAL_GRID sub-boxes, then rounds that bisect the LOCAL_SPLIT boxes of largest
    # bound along their widest side (relative to the box), LOCAL_MAX_BOXES bounded boxes in all
    k = 1
    while (k + 1) ** n <= LOCAL_GRID:
        k += 1
    edges = [np.linspace(lo, hi, k + 1) for lo, hi in box]  # ends exactly lo and hi
    idx = np.stack(np.meshgrid(*[np.arange(k)] * n, indexing="ij"), axis=-1).reshape(-1, n)
    LO = np.stack([edges[d][idx[:, d]] for d in range(n)], axis=1)
    HI = np.stack([edges[d][idx[:, d] + 1] for d in range(n)], axis=1)
    ub = bound(LO, HI)
    work = LO.shape[0]
    width = np.maximum(box[:, 1] - box[:, 0], np.finfo(float).tiny)
    while work + 2 * LOCAL_SPLIT <= LOCAL_MAX_BOXES and np.isfinite(ub).all():
        top = np.argsort(-ub, kind="stable")[:LOCAL_SPLIT]
        keep = np.ones(ub.size, dtype=bool)
        keep[top] = False
        lo, hi = LO[top], HI[top]
        d = np.argmax((hi - lo) / width, axis=1)
        mid = lo[np.arange(d.size), d] + 0.5 * (hi - lo)[np.arange(d.size), d]
        hi1, lo2 = hi.copy(), lo.copy()
        hi1[np.arange(d.size), d] = mid  # the halves share the float mid: they cover the box
        lo2[np.arange(d.size), d] = mid
        cl, ch = np.concatenate([lo, lo2]), np.concatenate([hi1, hi])
        LO, HI = np.concatenate([LO[keep], cl]), np.concatenate([HI[keep], ch])
        ub = np.concatenate([ub[keep], bound(cl, ch)])
        work += cl.shape[0]
    N = work
    names = ", ".join(sorted({t[1] for t in terms})) or "none"
    val = float(np.max(ub))
    region = [[round(float(v), 4) for v in row] for row in box]
    return Quantity.derive(
        name,
        val,
        method=How.SOUND,
        source="DRIP Assumption PolicyRegularity (b)",
        note=f"local route: Hessian of the whole expression enclosed on {N} sub-boxes "
        "(bisected where largest) of the box "
        f"{region} (blocks {names} with slope ranges local to each "
        "sub-box, shared terms cancelling per sub-box), largest Frobenius norm: valid on that "
        "box only",
        scope=Scope(tuple(map(tuple, box))),
    )


def _split_blocks(pol: sp.MatrixBase, s: System):
    """``(r, terms)`` with ``pol = r(x) + sum_k C_k h_k(M_k x + c_k)``: ``r`` a list of block-free
    expressions in the states; each term ``(C, block, M, c)`` with ``C`` a ``(m, out)`` float
    matrix and the block's argument affine in the states (``M`` ``(in, n)``, ``c``; the identity
    for a block applied to the state, as after a change of coordinates ``x = Theta^-1 z`` it is
    not). ``None`` when ``pol`` depends on ``t``, is not linear with constant coefficients in the
    block outputs, differentiates a block, or applies one that is not a smooth MLP."""
    x = list(s.states)
    apps = set()
    for e in pol:
        apps |= block_applications(e)
    maps: dict[tuple, tuple[np.ndarray, np.ndarray]] = {}
    for a in apps:
        mlp = s.blocks[a.block_name].mlp
        if a.deriv or mlp is None or not mlp.smooth or len(a.args) != mlp.in_dim:
            return None
        key = (a.block_name, tuple(a.args))
        if key in maps:
            continue
        M = np.zeros((len(a.args), len(x)))
        c = np.zeros(len(a.args))
        for i, arg in enumerate(a.args):
            arg = sp.expand(sp.sympify(arg))
            try:
                P = sp.Poly(arg, *x)
            except sp.PolynomialError:
                return None
            if P.total_degree() > 1 or any(v.free_symbols for v in P.coeffs()):
                return None
            M[i] = [float(P.coeff_monomial(xi)) for xi in x]
            c[i] = float(P.coeff_monomial(1))
        maps[key] = (M, c)
    syms = {a: sp.Dummy(f"z_{a.block_name}_{a.out_index}") for a in apps}
    zs = list(syms.values())
    rest: list[sp.Expr] = []
    C: dict[tuple, np.ndarray] = {}
    for j, e in enumerate(pol):
        ez = sp.expand(sp.sympify(e).xreplace(syms))
        if s.t in ez.free_symbols:
            return None
        if not zs:
            rest.append(ez)
            continue
        try:
            P = sp.Poly(ez, *zs)
        except sp.PolynomialError:
            return None
        if P.total_degree() > 1:
            return None
        for a, z in syms.items():
            coef = P.coeff_monomial(z)
            if coef.free_symbols:
                return None
            key = (a.block_name, tuple(a.args))
            out = s.blocks[a.block_name].out_dim
            Cm = C.setdefault(key, np.zeros((len(pol), out)))
            Cm[j, a.out_index] += float(coef)
        rest.append(P.coeff_monomial(1))
    terms = [(Cm, key[0], *maps[key]) for key, Cm in sorted(C.items(), key=lambda kv: str(kv[0]))]
    return rest, terms


def _converted(v: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """An interval around float coefficients read from sympy constants: ``CONVERSION_ULPS``
    spacings each way (:data:`~drip_cert.analysis.growth.closed_loop.CONVERSION_ULPS`)."""
    rad = up_np(CONVERSION_ULPS * np.spacing(np.abs(v)))
    return sub_down_np(v, rad), add_up_np(v, rad)


def _block_hessian_in_x(mlp, M: np.ndarray, c: np.ndarray, LO: np.ndarray, HI: np.ndarray):
    """Enclosure of the Hessian of ``x -> h(M x + c)``, ``M^T D^2 h(M x + c) M``, over the boxes
    ``[LO, HI]`` (``(N, n)``): ``D^2 h`` enclosed over the interval hull of ``M [LO, HI] + c``
    (outward rounded, widened by the coefficients' conversion error), then the two products with
    the interval ``M`` entry by entry. Returns ``(lo, hi)`` of shape ``(N, out, n, n)``."""
    N, n = LO.shape
    if M.shape == (n, n) and np.array_equal(M, np.eye(n)) and not np.any(c):
        ident = enclose_derivatives(mlp, LO, HI, hessian=True).hessian
        assert ident is not None  # a smooth network (checked by _split_blocks)
        return ident
    Mlo, Mhi = _converted(M)
    clo, chi = _converted(c)
    ylo, yhi = affine_enclosure(M, c, LO, HI)
    big = np.maximum(np.abs(LO), np.abs(HI))
    slack = add_up_np(up_np(big @ (Mhi - Mlo).T), up_np(chi - clo))
    ylo, yhi = sub_down_np(ylo, slack), add_up_np(yhi, slack)
    hess = enclose_derivatives(mlp, ylo, yhi, hessian=True).hessian
    assert hess is not None  # a smooth network (checked by _split_blocks)
    hlo, hhi = hess  # (N, out, k, k)
    k = M.shape[0]
    out = hlo.shape[1]
    tlo, thi = np.zeros((N, out, n, n)), np.zeros((N, out, n, n))
    for i in range(n):
        for l in range(n):  # noqa: E741
            for a in range(k):
                for b in range(k):
                    plo, phi = imul(Mlo[a, i], Mhi[a, i], hlo[:, :, a, b], hhi[:, :, a, b])
                    plo, phi = imul(plo, phi, Mlo[b, l], Mhi[b, l])
                    tlo[:, :, i, l], thi[:, :, i, l] = iadd(
                        tlo[:, :, i, l], thi[:, :, i, l], plo, phi
                    )
    return tlo, thi


def _block_names(e: sp.Expr) -> set[str]:
    return {a.block_name for a in block_applications(e)}


def _kinks(pol: sp.Matrix, s: System) -> list[sp.Expr]:
    """Arguments ``a`` where the Jacobian of ``pol`` may jump: ``sign(a)``, ``Heaviside(a)``."""
    jac = pol.jacobian(list(s.states))
    args: list[sp.Expr] = []
    for e in jac:
        for atom in e.atoms(sp.sign, sp.Heaviside):
            if atom.args[0] not in args:
                args.append(atom.args[0])
    return args


def _kink_branches(pol: sp.Matrix, s: System, box: np.ndarray | None):
    """``(jump, branch)`` for the kinks of ``pol``'s Jacobian on ``box``.

    ``Abs``, ``Max``, ``Min`` (the only non-smooth functions a spec can write) differentiate to
    ``sign``/``Heaviside`` of an argument; the Jacobian jumps where that argument changes sign.
    On a box each argument is enclosed rigorously. ``jump`` is the text of the first argument
    whose enclosure contains 0 (possibly pessimistically; any argument when ``box`` is None),
    else None. ``branch`` is None without kinks; when every kink is proved off the box it maps
    an ``Abs`` argument ``a`` to its branch there (``a`` or ``-a``), for ``pol.replace``.
    """
    signs: dict[sp.Expr, int] = {}
    for a in _kinks(pol, s):
        if box is None:
            return str(a), None
        try:
            lo, hi = enclose_expr(
                a, list(s.states), [tuple(b) for b in np.asarray(box, dtype=float)]
            )
        except UnsupportedExpression:
            return str(a), None
        if lo <= 0.0 <= hi:
            return str(a), None
        signs[a] = 1 if lo > 0.0 else -1
    if not signs:
        return None, None
    return None, lambda a: signs[a] * a if a in signs else sp.Abs(a)
