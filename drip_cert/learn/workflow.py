"""From a specification to a learned policy and its TaSIL certificate.

* the ``[tasil]`` settings are :class:`~drip_cert.system.settings.TasilSettings` (validated when
  the spec is loaded: ``spec.settings.tasil``; :func:`tasil_settings` reads a bare table);
* :func:`train_on_system` generates the expert demonstrations of DRIP Definition "Training
  Data", trains TaSIL or BC, and returns the policy as an MLP block for ``System.with_learned``;
* :func:`tasil_section` computes the per-trajectory ``h_0, h_1`` soundly, the regularity constant
  ``L_Delta`` with its provenance, and builds the certificate of docs/math/tasil.md sections 3-4
  (this project's construction, not TaSIL's own constant).
"""

from __future__ import annotations

import math
from collections.abc import Mapping
from dataclasses import dataclass
from typing import Any

import numpy as np
import sympy as sp

from drip_cert.errors import SpecError
from drip_cert.learn.data import Demonstrations, generate_demonstrations
from drip_cert.learn.mlp import MLP
from drip_cert.provenance import How, Quantity, Scope
from drip_cert.rounding import add_up, mul_up, spectral_norm_upper, sq_up, sqrt_up
from drip_cert.system.blocks import mlp_block
from drip_cert.system.settings import TasilSettings
from drip_cert.system.system import System

POLICY_BLOCK = "pi_il"  #: block name of a trained policy inside the System
TAU_MARGIN = 1.25
#: held-out thresholds tau_j = 1.25 x the training maxima of h_j: any tau computed from the training
#: data is valid for the held-out form (docs/math/tasil.md 3.3 c); the bare maxima are exceeded by
#: about 1/n of fresh states, which alone spends the form's confidence budget


def tasil_settings(table: Mapping[str, Any] | None) -> TasilSettings:
    """Validate a ``[tasil]`` table; a loaded spec already holds it as ``spec.settings.tasil``."""
    return TasilSettings.from_table(table)


def nominal_field(s: System):
    """``(t, x, u) -> f(t, x) + g(t) u``, the nominal drift of DRIP (NominalVectorFields)."""
    num = s.numeric

    def field(t, x, u):
        return num.f(t, x) + num.g(t) @ u

    return field


def demonstrations(s: System, n: int, k: int, seed: int, stream: int = 0) -> Demonstrations:
    """``n`` expert trajectories of the nominal model from ``xi_i ~ D`` (uniform on the box),
    sampled on the uniform partition of ``[0, T]`` with ``k`` intervals (DRIP Def. "Training
    Data"). ``stream`` separates training (0) from held-out (1) draws of the same seed."""
    from drip_cert._jax import jax

    key = jax.random.fold_in(jax.random.PRNGKey(seed), stream)
    return generate_demonstrations(
        nominal_field(s), s.numeric.expert, np.array(s.support), n, s.horizon, k, key
    )


def learned_system(s: System, mlp: MLP, name: str = POLICY_BLOCK, source: str = "") -> System:
    """``s`` with ``pi_IL = mlp`` as a block named ``name`` (``pi_il(x)[j]``)."""
    if mlp.in_dim != s.n or mlp.out_dim != s.m:
        raise SpecError(
            f"the policy maps R^{mlp.in_dim} -> R^{mlp.out_dim}, the system needs "
            f"R^{s.n} -> R^{s.m}"
        )
    block = mlp_block(name, mlp, source=source)
    exprs = [block.component(j)(*s.states) for j in range(s.m)]
    return s.with_learned(exprs, {name: block})


# ------------------------------------------------------------------ regularity (L_Delta)
def jacobian_lipschitz(s: System, which: str, box: np.ndarray | None = None) -> Quantity:
    """A bound on the Lipschitz constant of the Jacobian of ``pi*`` or ``pi_IL`` (operator norm;
    DRIP Assumption "PolicyRegularity" (b)).

    Routes: zero Hessian (affine policy, exact 0); a policy ``A x + b + C h(x)`` linear in MLP
    blocks applied to the state gives ``sum ||C_h||_2 L_dh`` with the sound layerwise bound of
    :func:`drip_cert.learn.mlp_bounds.jacobian_lipschitz_bound` (global); a policy without blocks
    gets a sound bound on ``box`` from interval enclosures of its second derivatives
    (``||d^2 pi|| <= ||d^2 pi||_F``), valid on that box only; anything else is a sampled
    estimate of ``sup ||d^2 pi||_F`` (labelled so).
    """
    from drip_cert.analysis.closed_loop import affine_in_blocks
    from drip_cert.learn.mlp_bounds import jacobian_lipschitz_bound

    pol = sp.Matrix(s.policy(which))
    jump, branch = _kink_branches(pol, s, box)
    if jump is not None:
        return Quantity(
            f"L_dpi_{which}",
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
                f"L_dpi_{which}",
                0.0,
                How.EXACT,
                "DRIP Assumption PolicyRegularity (b)",
                "affine policy: zero Hessian",
            )
        total, notes, parts = 0.0, [], []
        for bname, C in sorted(dec.C.items()):
            c2 = float(spectral_norm_upper(np.atleast_2d(C)))
            Lq = jacobian_lipschitz_bound(s.blocks[bname].mlp)
            parts.append(Lq)
            total = add_up(total, mul_up(c2, Lq.value))
            notes.append(f"||C_{bname}||_2 <= {c2:.4g} times L_d{bname} = {Lq.value:.4g}")
        return Quantity.derive(
            f"L_dpi_{which}",
            total,
            inputs=parts,
            method=How.SOUND,
            source="DRIP Assumption PolicyRegularity (b)",
            note="policy affine in MLP blocks; "
            + "; ".join(notes)
            + " (layerwise product-rule bound, global)",
        )
    if box is not None and not s.blocks:
        from drip_cert.analysis.interval import UnsupportedExpression, enclose_expr

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
                f"L_dpi_{which}",
                sqrt_up(acc),
                method=How.SOUND,
                source="DRIP Assumption PolicyRegularity (b)",
                note=f"interval enclosure of d^2 pi (Frobenius) on the box {region}: "
                "valid on that box only",
                scope=Scope(tuple(map(tuple, np.asarray(box, dtype=float)))),
            )
        except UnsupportedExpression:
            pass
    # sampled estimate of sup ||Hessian||_F on the support box enlarged by 1
    from drip_cert._jax import jax, jnp

    fn = s.lower(list(pol))
    hess = jax.jit(jax.vmap(jax.hessian(lambda z: fn(0.0, z))))
    rng = np.random.default_rng(0)
    box = np.array(s.support)
    X = rng.uniform(box[:, 0] - 1.0, box[:, 1] + 1.0, size=(4096, s.n))
    H = np.asarray(hess(jnp.asarray(X)))
    val = float(np.max(np.sqrt(np.sum(H**2, axis=(1, 2, 3)))))
    return Quantity(
        f"L_dpi_{which}",
        val,
        How.ESTIMATE,
        "DRIP Assumption PolicyRegularity (b)",
        "sampled sup ||d^2 pi||_F on the support box enlarged by 1 (4096 points, "
        "seed 0): an estimate, not a bound",
    )


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
    from drip_cert.analysis.interval import UnsupportedExpression, enclose_expr

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


# ------------------------------------------------------------------ h_0, h_1 along trajectories
def trajectory_h(s: System, demos: Demonstrations, L_Delta: float, speed_sound: bool):
    """Per-trajectory sound ``(h_0, h_1)`` of ``Delta = pi_IL - pi*`` along expert trajectories.

    Between grid points the speed of an autonomous contracting closed loop does not grow
    (``d/dt x_dot = J x_dot`` and ``mu_2(J) < 0``), so ``||x_dot(t)|| <= ||x_dot(t_k)||`` on
    ``[t_k, t_{k+1}]``; this makes the Lipschitz correction of docs/math/tasil.md section 4 sound
    when the expert contracts wherever its trajectories go (``speed_sound``: the rate holds for all
    ``x``, or on a box that contains a proved forward-invariant set around the support) and ``f``
    does not depend on ``t``. Otherwise the grid maximum of the speed is used and the result is
    labelled an estimate.
    """
    from drip_cert._jax import jax, jnp
    from drip_cert.bounds.tasil import h_continuous

    num = s.numeric
    delta = jax.jit(jax.vmap(lambda z: num.learned(z) - num.expert(z)))
    jac = jax.jit(jax.vmap(jax.jacfwd(lambda z: num.learned(z) - num.expert(z))))
    field = nominal_field(s)
    speed_fn = jax.jit(jax.vmap(lambda z: jnp.linalg.norm(field(0.0, z, num.expert(z)))))
    autonomous = not any(s.t in e.free_symbols for e in s.f) and s.g_is_constant
    sound = speed_sound and autonomous
    hs = []
    for traj in demos.states:
        X = jnp.asarray(traj)
        d = np.asarray(delta(X))
        j = np.asarray(jac(X))
        sp_ = np.asarray(speed_fn(X))
        speed = sp_[:-1] if sound else np.maximum(sp_[:-1], sp_[1:])
        hs.append(h_continuous(demos.times, d, j, speed, L_Delta))
    how = How.SOUND if sound else How.ESTIMATE
    return hs, how


# ------------------------------------------------------------------ training and certificate
@dataclass(frozen=True)
class TrainedPolicy:
    """A trained policy with its data, for the certificate and the reports."""

    system: System  #: the system with pi_IL set to the trained policy
    mlp: MLP
    result: Any  #: drip_cert.learn.tasil.TrainResult
    train: Demonstrations
    heldout: Demonstrations | None
    settings: TasilSettings


def train_on_system(
    s: System, settings: TasilSettings, method: str | None = None, progress: bool = False
) -> TrainedPolicy:
    """Generate demonstrations, train TaSIL (or BC) and attach the policy to ``s``.

    Training and held-out demonstrations use independent streams of ``settings.seed``.
    """
    from drip_cert.learn.tasil import train_policy

    method = method or settings.method
    train = demonstrations(s, settings.trajectories, settings.samples, settings.seed, 0)
    heldout = (
        demonstrations(s, settings.heldout, settings.samples, settings.seed, 1)
        if settings.heldout > 0
        else None
    )
    res = train_policy(
        train,
        s.numeric.expert,
        method=method,
        order=settings.order,
        hidden=settings.hidden,
        activation=settings.activation,
        seed=settings.seed,
        steps=settings.steps,
        lr=settings.lr,
        batch=settings.batch,
        progress=progress,
    )
    return TrainedPolicy(learned_system(s, res.mlp), res.mlp, res, train, heldout, settings)


def tasil_section(
    s: System,
    train: Demonstrations,
    heldout: Demonstrations | None,
    gamma0: Quantity,
    settings: TasilSettings,
    *,
    room: float = math.inf,
    speed_sound: bool = False,
    method: str = "tasil-1",
):
    """The TaSIL certificate of ``s.learned`` (docs/math/tasil.md sections 3-4).

    Parameters
    ----------
    gamma0
        The linear delta-ISS gain of the expert closed loop (tighter comparison bound).
    room
        How far the learned trajectory may stray from the expert's before leaving the region
        where the expert's rate is proved (``inf`` for a global rate; the room of a proved
        forward-invariant ball otherwise, :mod:`drip_cert.analysis.invariance`). The lemma's tube
        radius ``R`` is capped below it, so that the gap bound keeps the learned trajectory there.
    speed_sound
        Whether the expert's speed is proved non-increasing along its trajectories (the rate holds
        wherever they go), which makes the continuous-time sups of ``h_0, h_1`` sound.

    Returns
    -------
    (TasilCertificate, provenance dict, quantities)
        ``quantities`` are the inputs the TaSIL check rests on (``L_dpi_*``, ``h0``, ``h1``), each
        with its computed label. ``L_Delta = L_dpi(pi_IL) + L_dpi(pi*)`` (triangle inequality).
    """
    from drip_cert.bounds.tasil import tasil_certificate

    # the tube of assumption A2: the box around all expert states, enlarged by the tube radius
    # (1 when no finite radius is set); region-limited bounds then cap R at that radius
    margin = settings.tube_radius if math.isfinite(settings.tube_radius) else 1.0
    pts = train.states.reshape(-1, s.n)
    box = np.stack([pts.min(axis=0) - margin, pts.max(axis=0) + margin], axis=1)
    L_il = jacobian_lipschitz(s, "learned", box)
    L_ex = jacobian_lipschitz(s, "expert", box)
    R = settings.tube_radius
    if not (L_il.scope.all_x and L_ex.scope.all_x):
        R = min(R, margin)
    if math.isfinite(room):
        # strictly below the room (the first-exit argument needs gap < room)
        R = min(R, math.nextafter(room, 0.0))
    L_Delta = Quantity.derive(
        "L_Delta",
        add_up(L_il.value, L_ex.value),
        inputs=[L_il, L_ex],
        source="DRIP Assumption PolicyRegularity (b)",
        note="L_dpi(pi_IL) + L_dpi(pi*)",
    )
    provenance = {
        "L_dpi_learned": L_il.to_dict(),
        "L_dpi_expert": L_ex.to_dict(),
        "gamma0": gamma0.to_dict(),
        "tube_radius_R": R,
        "room": room,
    }
    qs: list[Quantity] = [gamma0, L_il, L_ex]
    if not math.isfinite(L_Delta.value):
        return (
            _not_lipschitz(
                L_il if not math.isfinite(L_il.value) else L_ex,
                train,
                heldout,
                gamma0,
                R,
                settings,
                method,
            ),
            provenance,
            tuple(qs),
        )
    h_train, how_t = trajectory_h(s, train, L_Delta.value, speed_sound)
    h_val, _ = (
        trajectory_h(s, heldout, L_Delta.value, speed_sound)
        if heldout is not None
        else (None, how_t)
    )
    # thresholds computed from the training data only (valid for the held-out form): the
    # training maxima with a 25 % margin, so that fresh states rarely exceed them
    tau = (TAU_MARGIN * max(h.h0 for h in h_train), TAU_MARGIN * max(h.h1 for h in h_train))
    cert = tasil_certificate(
        [h.h0 for h in h_train],
        [h.h1 for h in h_train],
        gamma0=gamma0.value,
        tau=tau,
        L_Delta=L_Delta.value,
        delta=settings.delta,
        eta=settings.eta,
        R=R,
        heldout_h0=None if h_val is None else [h.h0 for h in h_val],
        heldout_h1=None if h_val is None else [h.h1 for h in h_val],
        method=method,
        continuous=True,
    )
    provenance["h_how"] = how_t.value
    h_note = (
        "continuous-time sup along the expert trajectories (docs/math/tasil.md section 4)"
        if how_t == How.SOUND
        else "grid values with an unproved speed bound between grid points: an estimate"
    )
    for name, val in (("h0", cert.h0), ("h1", cert.h1)):
        qs.append(
            Quantity.derive(
                name,
                val,
                inputs=[L_Delta],
                method=how_t,
                source="docs/math/tasil.md (A3)",
                note=h_note,
            )
        )
    return cert, provenance, tuple(qs)


def _not_lipschitz(
    L: Quantity, train, heldout, gamma0: Quantity, R: float, settings: TasilSettings, method: str
):
    """The TaSIL certificate when a policy's Jacobian has no Lipschitz constant: every form
    fails (DRIP Assumption PolicyRegularity (b)); ``h_0``, ``h_1`` are not computed (their sound
    continuous-time sups need ``L_Delta``)."""
    from drip_cert.bounds.tasil import FORMS, TasilCertificate, TasilForm

    why = f"DRIP Assumption PolicyRegularity (b) fails for {L.name}: {L.note}"
    forms = tuple(TasilForm(name, math.inf, False, True, "not computed: " + why) for name in FORMS)
    return TasilCertificate(
        method=method,
        h0=math.nan,
        h1=math.nan,
        gamma0=gamma0.value,
        L_Delta=math.inf,
        eta=settings.eta,
        R=R,
        gap_bound=math.inf,
        gap_reason=why,
        rho=math.inf,
        rho_form="held_out" if heldout is not None else "drip_shaped",
        delta=settings.delta,
        n=int(train.states.shape[0]),
        n_val=0 if heldout is None else int(heldout.states.shape[0]),
        tau0=math.nan,
        tau1=math.nan,
        forms=forms,
        vacuous_forms=FORMS,
        continuous=True,
    )
