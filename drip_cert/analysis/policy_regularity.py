"""Regularity of a policy's Jacobian: a bound on ``L_dpi`` (DRIP Assumption "PolicyRegularity" (b)).

Routes, strongest first: an affine policy (exact 0); a policy affine in MLP blocks applied to the
state (the layerwise bound of :mod:`drip_cert.analysis.mlp.lipschitz`, global); a policy without
blocks on a box (interval enclosures of its second derivatives, valid on that box only); otherwise
a sampled estimate. A kink of the Jacobian (``Abs``, ``Max``, ``Min``) anywhere the policy is used
makes the constant infinite: the assumption fails there.
"""

from __future__ import annotations

import math

import numpy as np
import sympy as sp

from drip_cert.analysis.closed_loop import affine_in_blocks
from drip_cert.analysis.mlp import jacobian_lipschitz_bound
from drip_cert.model.blocks import block_applications
from drip_cert.model.system import System
from drip_cert.numerics.interval import UnsupportedExpression, enclose_expr
from drip_cert.numerics.rounding import add_up, mul_up, spectral_norm_upper, sq_up, sqrt_up
from drip_cert.provenance import How, Quantity, Scope

__all__ = ["difference_jacobian_lipschitz", "jacobian_lipschitz"]


def jacobian_lipschitz(s: System, which: str, box: np.ndarray | None = None) -> Quantity:
    """A bound on the Lipschitz constant of the Jacobian of ``pi*`` or ``pi_IL`` (operator norm;
    DRIP Assumption "PolicyRegularity" (b)).

    Routes: zero Hessian (affine policy, exact 0); a policy ``A x + b + C h(x)`` linear in MLP
    blocks applied to the state gives ``sum ||C_h||_2 L_dh`` with the sound layerwise bound of
    :func:`drip_cert.analysis.mlp.jacobian_lipschitz_bound` (global); a policy without blocks
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
    if dec is not None and all(s.blocks[b].mlp is not None for b in dec.C):
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
