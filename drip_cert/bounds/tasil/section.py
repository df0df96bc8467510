"""The TaSIL section of the certificate, built from a :class:`~drip_cert.model.system.System`:
sound ``h_0, h_1`` along the expert trajectories, the regularity constant ``L_Delta`` with its
provenance, the tube radius ``R``, and the certificate of docs/math/tasil.md sections 3-4 (this
project's construction, not TaSIL's own constant).
"""

from __future__ import annotations

import math
from collections.abc import Callable
from typing import Any

import numpy as np
import sympy as sp

from drip_cert._jax import jax, jnp
from drip_cert.analysis.contraction.learned_loop import difference_jacobian_bound
from drip_cert.analysis.networks.policy_regularity import (
    difference_jacobian_lipschitz,
    jacobian_lipschitz,
)
from drip_cert.bounds.tasil._common import up_closed_form
from drip_cert.bounds.tasil.certificate import TasilCertificate, tasil_certificate
from drip_cert.bounds.tasil.forms import (
    FORMS,
    TasilForm,
    form_held_out_comparison,
    form_uniform,
)
from drip_cert.bounds.tasil.trajectory import TrajectoryH, h0_lipschitz, h_continuous
from drip_cert.bounds.tasil.tube import TubeBound
from drip_cert.learn.data import Demonstrations
from drip_cert.learn.imitation import nominal_field
from drip_cert.model.system import System
from drip_cert.numerics.rounding import add_up
from drip_cert.provenance import How, Quantity
from drip_cert.spec.settings import TasilSettings

__all__ = ["l_delta_box", "tasil_section", "trajectory_h"]

#: held-out thresholds tau_j = 1.25 x the training maxima of h_j: any tau computed from the training
#: data is valid for the held-out form (docs/math/tasil.md 3.3 c); the bare maxima are exceeded by
#: about 1/n of fresh states, which alone spends the form's confidence budget
TAU_MARGIN = 1.25


def trajectory_h(
    s: System, demos: Demonstrations, L_Delta: float, speed_sound: bool
) -> tuple[list[TrajectoryH], How]:
    """Per-trajectory sound ``(h_0, h_1)`` of ``Delta = pi_IL - pi*`` along expert trajectories.

    Between grid points the speed of an autonomous contracting closed loop does not grow
    (``d/dt x_dot = J x_dot`` and ``mu_2(J) < 0``), so ``||x_dot(t)|| <= ||x_dot(t_k)||`` on
    ``[t_k, t_{k+1}]``; this makes the Lipschitz correction of docs/math/tasil.md section 4 sound
    when the expert contracts wherever its trajectories go (``speed_sound``: the rate holds for all
    ``x``, or on a box that contains a proved forward-invariant set around the support) and ``f``
    does not depend on ``t``. Otherwise the grid maximum of the speed is used and the result is
    labelled an estimate.

    Returns
    -------
    (list of TrajectoryH, How)
        One :class:`~drip_cert.bounds.tasil.trajectory.TrajectoryH` per trajectory of ``demos``
        (:func:`~drip_cert.bounds.tasil.trajectory.h_continuous`), and how they were obtained.
    """
    delta, jac, speeds, sound = _along(s, demos, speed_sound)
    hs = [
        h_continuous(demos.times, d, np.asarray(jac(jnp.asarray(traj))), v, L_Delta)
        for traj, d, v in zip(demos.states, delta, speeds)
    ]
    return hs, How.SOUND if sound else How.ESTIMATE


_FNS_KEPT = 4  #: systems whose jitted Delta, Jacobian and speed are kept (a certify has <= 4)
_FNS: dict[int, tuple[System, tuple[Any, Any, Any]]] = {}


def _difference_fns(s: System) -> tuple[Any, Any, Any]:
    """The jitted ``Delta = pi_IL - pi*``, its Jacobian and the expert's speed, each vmapped over
    states, built once per system: the training and the held-out demonstrations (same shapes)
    then share one trace and one compilation of each (the same executables, so the same
    numbers)."""
    hit = _FNS.get(id(s))
    if hit is not None and hit[0] is s:
        return hit[1]
    num = s.numeric
    # Delta = pi_IL - pi* formed symbolically first, so that terms the two policies share cancel
    # exactly (a -9.81 sin q in both) instead of in floating point
    diff = [sp.expand(a - b) for a, b in zip(s.policy("learned"), s.policy("expert"), strict=True)]
    diff_fn = s.lower(diff)

    def error(z):
        return diff_fn(0.0, z)

    delta = jax.jit(jax.vmap(error))
    jac = jax.jit(jax.vmap(jax.jacfwd(error)))
    field = nominal_field(s)
    speed_fn = jax.jit(jax.vmap(lambda z: jnp.linalg.norm(field(0.0, z, num.expert(z)))))
    while len(_FNS) >= _FNS_KEPT:
        del _FNS[next(iter(_FNS))]
    fns = (delta, jac, speed_fn)
    _FNS[id(s)] = (s, fns)
    return fns


def _along(s: System, demos: Demonstrations, speed_sound: bool):
    """``Delta`` at the grid points of every trajectory, the (jitted) Jacobian of ``Delta``, the
    per-interval speed bounds (sound when ``speed_sound`` and the system is autonomous, see
    :func:`trajectory_h`) and whether they are sound."""
    delta, jac, speed_fn = _difference_fns(s)
    # the expert's speed decays along a contracting AUTONOMOUS closed loop: no t in f nor in g
    autonomous = not any(s.t in e.free_symbols for e in (*s.f, *s.g))
    sound = speed_sound and autonomous
    ds, speeds = [], []
    for traj in demos.states:
        X = jnp.asarray(traj)
        ds.append(np.asarray(delta(X)))
        sp_ = np.asarray(speed_fn(X))
        speeds.append(sp_[:-1] if sound else np.maximum(sp_[:-1], sp_[1:]))
    return ds, jac, speeds, sound


def h0_by_lipschitz(
    s: System, demos: Demonstrations, lip: float, speed_sound: bool
) -> tuple[list[float], How]:
    """Per-trajectory continuous-time ``h_0`` from a Lipschitz constant ``lip`` of ``Delta``
    (:func:`~drip_cert.bounds.tasil.trajectory.h0_lipschitz`): sound under the conditions of
    :func:`trajectory_h`, an estimate otherwise. No Jacobian-Lipschitz constant is needed."""
    delta, _, speeds, sound = _along(s, demos, speed_sound)
    h0 = [h0_lipschitz(demos.times, d, v, lip) for d, v in zip(delta, speeds)]
    return h0, How.SOUND if sound else How.ESTIMATE


def l_delta_box(points: np.ndarray, S: np.ndarray | None, margin: float) -> np.ndarray:
    """The box on which a box-scoped ``L_Delta`` is computed (docs/math/tasil.md 3.12, "Which
    box"): the hull of the box around ``points`` (every training and held-out expert state) and
    of ``S`` (a box proved to hold every expert trajectory from the support; ``None``: not
    known), enlarged by the tube radius ``margin`` on every side, rounded outward (the box must
    contain the tube; the one-ulp widening moves the sub-box grid of the local bounds, which
    changed the paper plain MLP's local ``L_Delta`` by 1 %: 35.21 -> 35.56).

    Only with ``S`` does the box contain the tube of radius ``margin`` around the expert
    trajectory of a *new* initial state, which is where the lemma uses ``L_Delta``.
    """
    pts = np.asarray(points, dtype=float).reshape(-1, np.shape(points)[-1])
    lo, hi = pts.min(axis=0), pts.max(axis=0)
    if S is not None:
        S = np.asarray(S, dtype=float)
        lo, hi = np.minimum(lo, S[:, 0]), np.maximum(hi, S[:, 1])
    return np.stack([np.nextafter(lo - margin, -np.inf), np.nextafter(hi + margin, np.inf)], axis=1)


def _l_delta(
    s: System, box: np.ndarray
) -> tuple[Quantity, Quantity, Quantity, Quantity | None, bool, Quantity]:
    """``L_dpi(pi_IL)``, ``L_dpi(pi*)``, their triangle bound, the bound on the difference
    itself (``None`` when it has none), whether the difference is used, and the ``L_Delta``
    used, on ``box`` (docs/math/tasil.md 3.12)."""
    L_il = jacobian_lipschitz(s, "learned", box)
    L_ex = jacobian_lipschitz(s, "expert", box)
    L_tri = Quantity.derive(
        "L_Delta",
        add_up(L_il.value, L_ex.value),
        inputs=[L_il, L_ex],
        source="DRIP Assumption PolicyRegularity (b)",
        note="L_dpi(pi_IL) + L_dpi(pi*) (triangle inequality)",
    )
    # the difference itself: terms both policies share cancel; a sound bound on it is preferred
    # to any triangle bound that rests on an estimate, and to a larger sound one
    L_dir = difference_jacobian_lipschitz(s, box)
    direct = L_dir is not None and (L_tri.how == How.ESTIMATE or L_dir.value < L_tri.value)
    L_Delta = (
        Quantity.derive(
            "L_Delta",
            L_dir.value,
            inputs=[L_dir],
            source="DRIP Assumption PolicyRegularity (b)",
            note="Lipschitz constant of d(pi_IL - pi*) bounded on the difference itself ("
            + L_dir.note
            + f"); the triangle bound L_dpi(pi_IL) + L_dpi(pi*) is {L_tri.value:.6g}",
        )
        if L_dir is not None and direct
        else L_tri
    )
    return L_il, L_ex, L_tri, L_dir, direct, L_Delta


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
    comparison_gain: Quantity | None = None,
    uniform_h0: Quantity | None = None,
    tube: TubeBound | None = None,
    expert_set: Callable[[], tuple[np.ndarray | None, str]] | None = None,
) -> tuple[TasilCertificate, dict[str, Any], tuple[Quantity, ...]]:
    """The TaSIL certificate of ``s.learned`` (docs/math/tasil.md sections 3-4).

    Parameters
    ----------
    s
        The system, with its learned policy.
    train, heldout
        Training demonstrations, and fresh expert trajectories unused in training (or ``None``).
    gamma0
        The linear delta-ISS gain of the expert closed loop (tighter comparison bound).
    room
        How far the learned trajectory may stray from the expert's before leaving the region
        where the expert's rate is proved (``inf`` for a global rate; the room of a proved
        forward-invariant ball otherwise, :mod:`drip_cert.analysis.contraction.invariance`). The
        lemma's tube
        radius ``R`` is capped below it, so that the gap bound keeps the learned trajectory there.
    speed_sound
        Whether the expert's speed is proved non-increasing along its trajectories (the rate holds
        wherever they go), which makes the continuous-time sups of ``h_0, h_1`` sound.
    settings, method
        The ``[tasil]`` settings (``delta``, ``eta``, ``tube_radius``) and the recorded method.
    comparison_gain
        ``sup||g||_2 / lambda_IL`` when the learned closed loop is proved to contract on all of
        ``R^n`` (never an estimate): the comparison bound of docs/math/tasil.md section 3.7.
    uniform_h0
        With ``comparison_gain``: a sound bound of ``sup ||pi_IL - pi*||`` over a set proved to
        contain every expert trajectory from the support; gives the sure form ``"uniform"``.
    tube
        With ``comparison_gain``: the time-resolved sure bound along the expert's tube
        (docs/math/tasil.md section 3.10); the form ``"uniform"`` takes the smaller.
    expert_set
        Called only when the ``L_Delta`` used holds on a box only: a box proved to hold every
        expert trajectory from the support on ``[0, T]`` (with the reason), or ``(None, why)``.
        The box of ``L_Delta`` is then enlarged to hold it plus the tube, so that the lemma's
        tube around the expert trajectory of a *new* initial state stays where ``L_Delta``
        holds; without such a set the provenance says ``L_Delta_covers_support = False`` and
        the certificate marks the TaSIL scope unjustified (a box around the demonstrations says
        nothing about new trajectories).

    Returns
    -------
    (TasilCertificate, provenance dict, quantities)
        ``quantities`` are the inputs the TaSIL check rests on (``L_dpi_*``, ``h0``, ``h1``), each
        with its computed label. ``L_Delta`` is the smaller of the triangle bound
        ``L_dpi(pi_IL) + L_dpi(pi*)`` and a bound on the difference ``pi_IL - pi*`` itself
        (:func:`~drip_cert.analysis.networks.policy_regularity.difference_jacobian_lipschitz`; used
        only
        when it is not an estimate).
    """
    # the tube of assumption A2: the box around all expert states, enlarged by the tube radius
    # (1 when no finite radius is set); region-limited bounds then cap R at that radius
    margin = settings.tube_radius if math.isfinite(settings.tube_radius) else 1.0
    # (the held-out states too: their h0, h1 use L_Delta as well)
    pts = np.concatenate(
        [d.states.reshape(-1, s.n) for d in (train, heldout) if d is not None], axis=0
    )
    box = l_delta_box(pts, None, margin)
    L_il, L_ex, L_tri, L_dir, direct, L_Delta = _l_delta(s, box)
    covers, cover_why = True, "L_Delta holds for all x"
    if not L_Delta.scope.all_x:
        S, why = expert_set() if expert_set is not None else (None, "no set was searched for")
        if S is None:
            covers = False
            cover_why = (
                "L_Delta is proved on the box around the demonstrations only, and no set "
                f"holding every expert trajectory from the support is proved ({why}): the "
                "bound says nothing about the trajectory of a new initial state"
            )
        else:
            wide = l_delta_box(pts, np.asarray(S, dtype=float), margin)
            if not np.array_equal(wide, box):
                box = wide
                L_il, L_ex, L_tri, L_dir, direct, L_Delta = _l_delta(s, box)
            cover_why = (
                f"L_Delta is proved on a box holding {why}, enlarged by the tube radius "
                f"{margin:.6g}: every expert trajectory from the support and its tube"
            )
    R = settings.tube_radius
    if not L_Delta.scope.all_x:
        R = min(R, margin)
    if math.isfinite(room) and room > 0.0:
        # strictly below the room (the first-exit argument needs gap < room); with no room at
        # all (the invariant set fills the region) R is left as it is and the certificate marks
        # the TaSIL scope unjustified (bounds/certificate.py, _tasil_scope)
        R = min(R, math.nextafter(room, 0.0))
    provenance: dict[str, Any] = {
        "L_dpi_learned": L_il.to_dict(),
        "L_dpi_expert": L_ex.to_dict(),
        "L_dDelta": None if L_dir is None else L_dir.to_dict(),
        "L_Delta_route": "difference" if direct else "triangle",
        "gamma0": gamma0.to_dict(),
        "tube_radius_R": R,
        "room": room,
        "L_Delta_box": box.tolist(),
        "L_Delta_covers_support": covers,
        "L_Delta_cover": cover_why,
    }
    # the TaSIL check rests on the route used: the difference alone, or both policies' constants
    qs: list[Quantity] = [gamma0] + ([L_dir] if L_dir is not None and direct else [L_il, L_ex])
    if not math.isfinite(L_Delta.value):
        # the comparison form from data (docs/math/tasil.md 3.7): sound h0 along the expert
        # trajectories from a global Lipschitz constant of Delta (no Jacobian-Lipschitz one)
        by_data = None
        if comparison_gain is not None and heldout is not None:
            lip = difference_jacobian_bound(s)
            if lip is not None and math.isfinite(lip.value):
                h0t, how_h = h0_by_lipschitz(s, train, lip.value, speed_sound)
                h0v, _ = h0_by_lipschitz(s, heldout, lip.value, speed_sound)
                h0q = Quantity.derive(
                    "h0",
                    max(h0t),
                    inputs=[lip],
                    method=how_h,
                    source="docs/math/tasil.md (A3)",
                    note="continuous-time sup along the expert trajectories from a Lipschitz "
                    "constant of pi_IL - pi* (docs/math/tasil.md section 4)",
                )
                by_data = (h0t, h0v, lip, h0q)
        cert = _not_lipschitz(
            L_Delta if direct else (L_il if not math.isfinite(L_il.value) else L_ex),
            train,
            heldout,
            gamma0,
            R,
            settings,
            method,
            comparison_gain,
            uniform_h0,
            None if by_data is None else (by_data[0], by_data[1]),
        )
        extra: list[Quantity] = [q for q in (comparison_gain, uniform_h0) if q is not None]
        if by_data is not None and cert.rho_form == "held_out":
            provenance["comparison_gain"] = comparison_gain.to_dict()  # type: ignore[union-attr]
            provenance["sup_D_Delta"] = by_data[2].to_dict()
            extra = [q for q in (comparison_gain, by_data[2], by_data[3]) if q is not None]
        return cert, provenance, tuple(qs) + tuple(extra)
    h_train, how_t = trajectory_h(s, train, L_Delta.value, speed_sound)
    train_h0, train_h1 = [h.h0 for h in h_train], [h.h1 for h in h_train]
    heldout_h0 = heldout_h1 = None
    if heldout is not None:
        h_val, _ = trajectory_h(s, heldout, L_Delta.value, speed_sound)
        heldout_h0, heldout_h1 = [h.h0 for h in h_val], [h.h1 for h in h_val]
    # thresholds computed from the training data only (valid for the held-out form): the
    # training maxima with a 25 % margin, so that fresh states rarely exceed them
    tau = (TAU_MARGIN * max(train_h0), TAU_MARGIN * max(train_h1))
    cert = tasil_certificate(
        train_h0,
        train_h1,
        gamma0=gamma0.value,
        tau=tau,
        L_Delta=L_Delta.value,
        delta=settings.delta,
        eta=settings.eta,
        R=R,
        heldout_h0=heldout_h0,
        heldout_h1=heldout_h1,
        method=method,
        continuous=True,
        comparison_gain=None if comparison_gain is None else comparison_gain.value,
        uniform_h0=None if uniform_h0 is None else uniform_h0.value,
        tube=tube,
    )
    if comparison_gain is not None:
        provenance["comparison_gain"] = comparison_gain.to_dict()
        used = cert.gap_route == "comparison" or any(
            c.id == "tasil.comparison" for f in cert.forms for c in f.checks
        )
        if used:  # the TaSIL check then rests on it (and on the learned loop's rate)
            qs.append(comparison_gain)
        if uniform_h0 is not None and cert.rho_form == "uniform":
            provenance["uniform_h0"] = uniform_h0.to_dict()
            qs.append(uniform_h0)
        if tube is not None and cert.rho_form == "uniform":
            qs.extend(tube.inputs)
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
    L: Quantity,
    train: Demonstrations,
    heldout: Demonstrations | None,
    gamma0: Quantity,
    R: float,
    settings: TasilSettings,
    method: str,
    comparison_gain: Quantity | None = None,
    uniform_h0: Quantity | None = None,
    h0_data: tuple[list[float], list[float]] | None = None,
) -> TasilCertificate:
    """The TaSIL certificate when a policy's Jacobian has no Lipschitz constant (DRIP Assumption
    PolicyRegularity (b) fails: a relu network, an ``Abs`` kink).

    The lemma and every statistical form built on it need ``L_Delta``: they are reported as
    ``not applicable``, not as failed checks. The uniform form of docs/math/tasil.md 3.8 needs
    no ``L_Delta`` (only the learned loop's contraction on all of ``R^n`` and a sound
    ``sup_S ||pi_IL - pi*||``): when both are given it proceeds and gives ``rho``, with
    probability 1. With ``h0_data`` (training and held-out ``h_0``, sound from a Lipschitz
    constant of ``Delta``; ``h_1`` is not needed) the held-out form is computed through the
    comparison bound alone (:func:`~drip_cert.bounds.tasil.forms.form_held_out_comparison`),
    and ``rho`` is the smaller of the two forms that hold.
    """
    why = (
        "not applicable: the policy's Jacobian is not Lipschitz (the lemma route needs it): "
        f"DRIP Assumption PolicyRegularity (b) fails for {L.name}: {L.note}"
    )
    forms = [TasilForm(name, math.inf, False, True, why) for name in FORMS if name != "uniform"]
    rho, rho_form, gap, route = (
        math.inf,
        "held_out" if heldout is not None else "drip_shaped",
        math.inf,
        why,
    )
    h0 = tau0 = math.nan
    if comparison_gain is not None and h0_data is not None:
        h0t, h0v = h0_data
        h0, tau0 = max(h0t), TAU_MARGIN * max(h0t)
        held = form_held_out_comparison(h0v, tau0, comparison_gain.value, settings.delta)
        forms[0] = held
        # every given state's gap <= gamma_IL h0_i (section 3.7): the deterministic bound
        gap, route = up_closed_form(comparison_gain.value * max(max(h0t), max(h0v))), ""
        if held.holds and not held.vacuous:
            rho, rho_form = held.value, "held_out"
    if comparison_gain is not None and uniform_h0 is not None:
        cg, u = comparison_gain.value, uniform_h0.value
        uni = up_closed_form(cg * u)
        if math.isfinite(uni):
            forms.append(
                form_uniform(
                    uni,
                    f"sup||g||_2/lambda_IL * sup_S ||pi_IL - pi*|| = {cg:.6g} * {u:.6g}",
                    "; needs no Lipschitz Jacobian",
                )
            )
            if uni < rho:
                rho, rho_form = uni, "uniform"
            gap, route = min(gap, uni), ""
    return TasilCertificate(
        method=method,
        h0=h0,
        h1=math.nan,
        gamma0=gamma0.value,
        L_Delta=math.inf,
        eta=settings.eta,
        R=R,
        gap_bound=gap,
        gap_reason=route,
        rho=rho,
        rho_form=rho_form,
        delta=settings.delta,
        n=int(train.states.shape[0]),
        n_val=0 if heldout is None else int(heldout.states.shape[0]),
        tau0=tau0,
        tau1=math.nan,
        forms=tuple(forms),
        vacuous_forms=tuple(f.name for f in forms if f.vacuous or not f.holds),
        continuous=True,
    )
