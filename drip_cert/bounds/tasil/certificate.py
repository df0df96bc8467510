"""The TaSIL certificate: a bound on the policy-induced imitation gap (rho_TaSIL).

Implements docs/math/tasil.md sections 3 and 4, **a construction of this project, not TaSIL's own
constant** (the body of Pfrommer et al. 2022, whose Thm 4.3 the DRIP paper's Theorem "TaSIL"
cites, is not available). Every report carries :data:`LABEL`. :func:`tasil_certificate` applies
the lemma (:mod:`~drip_cert.bounds.tasil.lemma`) to every given initial state and computes every
statistical form (:mod:`~drip_cert.bounds.tasil.forms`); the h's come from
:mod:`~drip_cert.bounds.tasil.trajectory`.

Assumptions (checked where data allow, otherwise stated in :data:`ASSUMPTIONS`): (A1) the expert
closed loop is (eta, gamma_0 s)-locally delta-ISS (DRIP Proposition ``prop:deltaISS`` and its
corollary give ``gamma_0 = sup_t (theta lambda_theta)^{-1/2} (1 - e^{-lambda_theta t})^{1/2}``);
(A2) ``d Delta`` is ``L_Delta``-Lipschitz on the tube of radius ``R`` around expert trajectories
(``L_Delta <= L_dpi(pi_hat) + L_dpi(pi_star)``, DRIP Assumption ``PolicyRegularity`` b); (A3) the
h's are measured on the expert trajectories.

Probability semantics of ``rho``: every gap-radius form is stated at the *joint* level ``1 - delta``
over the data and a fresh initial state ``xi ~ D``: ``P[max_t ||x_hat_t - x*_t|| > rho] <= delta``
(the DRIP-shaped form of section 3.4 splits delta in three; the held-out and threshold forms give
``delta/2`` to the data and require the exceedance probability ``<= delta/2``). This is a
high-probability radius, not a bound on the expectation ``E_xi`` in DRIP's policy-IG
(``eqn:Decomposition:IG:Policy``).
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from dataclasses import dataclass, field
from typing import Any

import numpy as np

from drip_cert.bounds.tasil._common import positive, probability, up_closed_form
from drip_cert.bounds.tasil.forms import (
    ClassConstants,
    TasilForm,
    form_drip,
    form_expectation,
    form_held_out,
    form_threshold,
    form_uniform,
)
from drip_cert.bounds.tasil.lemma import eps_star, imitation_gap_lemma
from drip_cert.bounds.tasil.tube import TubeBound
from drip_cert.errors import SpecError
from drip_cert.provenance import Check, json_float

__all__ = ["ASSUMPTIONS", "LABEL", "TasilCertificate", "tasil_certificate"]

LABEL = "construction of this project (docs/math/tasil.md section 3), not TaSIL's own constant"
ASSUMPTIONS = (
    "A1: expert closed loop locally delta-ISS with linear gain gamma0 on perturbations <= eta",
    "A2: d(pi_hat - pi_star) is L_Delta-Lipschitz (operator norm) on the radius-R tube",
    "A3: h0, h1 are sups along expert trajectories (sound sups in continuous time)",
    "statistical forms: training / held-out initial states i.i.d. from D, independent of each "
    "other; held-out states unused in training; tau and class constants fixed before the data",
)


@dataclass(frozen=True)
class TasilCertificate:
    """The TaSIL certificate (docs/math/tasil.md sections 3-4), labelled :data:`LABEL`.

    Attributes
    ----------
    method
        Training method of the policy (free text, e.g. ``"tasil-1"``, ``"bc"``).
    h0, h1
        Maxima over all given (training and held-out) trajectories.
    gamma0, L_Delta, eta, R
        The constants of A1-A2.
    gap_bound, gap_reason
        Deterministic bound over the given initial states: the max over them of the per-state
        sharp lemma bound; ``inf`` with the reason when the lemma fails for some state.
    rho, rho_form
        The statistical gap radius used in ``rho_total`` (joint level ``1 - delta``), and the name
        of its form (chosen before looking at the values: ``use`` argument, or ``held_out`` when
        held-out data are given, else ``drip_shaped``). ``inf`` when that form fails.
    delta, n, n_val
        Confidence parameter and data sizes.
    tau0, tau1
        The thresholds of the held-out and threshold forms.
    forms
        Every statistical form, computed or with the reason it is not.
    vacuous_forms
        Names of the forms that are vacuous or whose conditions fail.
    continuous
        Whether h's are continuous-time sups (section 4).
    gap_checks
        The lemma's conditions at the worst given initial state.
    comparison_gain, gap_route
        ``sup||g||_2 / lambda_IL`` when the learned closed loop is proved to contract on all of
        ``R^n`` (the comparison bound ``gap <= comparison_gain * h_0``, docs/math/tasil.md
        section 3.7), else ``None``; ``gap_route`` says which bound gave ``gap_bound``
        (``"lemma"``, ``"comparison"`` or ``"uniform"``).
    tube
        The time-resolved sure bound along the expert's tube (docs/math/tasil.md section 3.10),
        ``rho_TaSIL(t)`` on its grid, or ``None`` when not computed.
    label, assumptions
        :data:`LABEL` and :data:`ASSUMPTIONS`.
    """

    method: str
    h0: float
    h1: float
    gamma0: float
    L_Delta: float
    eta: float
    R: float
    gap_bound: float
    gap_reason: str
    rho: float
    rho_form: str
    delta: float
    n: int
    n_val: int
    tau0: float
    tau1: float
    forms: tuple[TasilForm, ...]
    vacuous_forms: tuple[str, ...]
    continuous: bool = False
    gap_checks: tuple[Check, ...] = ()
    comparison_gain: float | None = None
    gap_route: str = "lemma"
    tube: TubeBound | None = None
    label: str = LABEL
    assumptions: tuple[str, ...] = field(default=ASSUMPTIONS)

    @property
    def certified(self) -> bool:
        """``rho`` is finite (its form holds and is not vacuous)."""
        return math.isfinite(self.rho)

    def form(self, name: str) -> TasilForm:
        """The form called ``name``."""
        for f in self.forms:
            if f.name == name:
                return f
        raise KeyError(name)

    def to_dict(self) -> dict[str, Any]:
        """JSON-ready dictionary; ``vacuous`` is true when ``rho`` is not certified."""
        return {
            "method": self.method,
            "label": self.label,
            "h0": json_float(self.h0),
            "h1": json_float(self.h1),
            "gamma0": json_float(self.gamma0),
            "L_Delta": json_float(self.L_Delta),
            "eta": json_float(self.eta),
            "R": json_float(self.R),
            "gap_bound": json_float(self.gap_bound),
            "gap_reason": self.gap_reason,
            "rho": json_float(self.rho),
            "rho_form": self.rho_form,
            "delta": self.delta,
            "n": self.n,
            "n_val": self.n_val,
            "tau0": json_float(self.tau0),
            "tau1": json_float(self.tau1),
            "vacuous": not self.certified,
            "vacuous_forms": list(self.vacuous_forms),
            "continuous": self.continuous,
            "forms": [f.to_dict() for f in self.forms],
            "gap_checks": [c.to_dict() for c in self.gap_checks],
            "comparison_gain": None
            if self.comparison_gain is None
            else json_float(self.comparison_gain),
            "gap_route": self.gap_route,
            "tube": None if self.tube is None else self.tube.to_dict(),
            "assumptions": list(self.assumptions),
        }


def _h_pair(which: str, h0, h1) -> tuple[np.ndarray, np.ndarray]:
    """The per-trajectory ``h_0``, ``h_1`` of the ``which`` (``train`` or ``heldout``) data as flat
    arrays, checked finite, ``>= 0``, non-empty and of equal length."""
    arrays = []
    for name, values in ((f"{which}_h0", h0), (f"{which}_h1", h1)):
        a = np.asarray(values, dtype=np.float64).reshape(-1)
        if not np.all(np.isfinite(a)) or np.any(a < 0):
            raise SpecError(f"{name} must be finite and >= 0", field=name)
        arrays.append(a)
    a0, a1 = arrays
    if a0.size != a1.size or a0.size == 0:
        raise SpecError(
            f"{which}_h0 and {which}_h1 need the same number (>= 1) of trajectories, got "
            f"{a0.size} and {a1.size}",
            field=f"{which}_h0",
        )
    return a0, a1


def tasil_certificate(
    train_h0: Sequence[float],
    train_h1: Sequence[float],
    *,
    gamma0: float,
    L_Delta: float,
    delta: float,
    eta: float = math.inf,
    R: float = math.inf,
    heldout_h0: Sequence[float] | None = None,
    heldout_h1: Sequence[float] | None = None,
    tau: tuple[float, float] | None = None,
    constants: ClassConstants | None = None,
    use: str | None = None,
    method: str = "tasil-1",
    continuous: bool = False,
    comparison_gain: float | None = None,
    uniform_h0: float | None = None,
    tube: TubeBound | None = None,
) -> TasilCertificate:
    """Build the TaSIL certificate (docs/math/tasil.md sections 3-4; DRIP Theorem ``thm:TaSIL``
    shape).

    Parameters
    ----------
    train_h0, train_h1
        Per-trajectory ``h_0``, ``h_1`` of the ``n`` training trajectories
        (:class:`~drip_cert.bounds.tasil.trajectory.TrajectoryH`).
    gamma0, L_Delta, eta, R
        The constants of A1-A2 (``gamma0`` from the delta-ISS analysis).
    delta
        Joint failure probability of ``rho``.
    heldout_h0, heldout_h1
        Per-trajectory h's of ``n_val`` fresh expert trajectories not used in training (form 3.3 c).
    tau
        ``(tau0, tau1)`` fixed before seeing any data. When ``None``: the held-out form uses the
        training maxima (independent of the held-out data); the parametric forms round the
        training maxima up to a geometric grid of ``K = 64`` values and pay ``log K``.
    constants
        :class:`ClassConstants` for the parametric forms (3.3 a, b and 3.4); omitted forms are
        reported as not computed.
    use
        The form whose radius becomes ``rho``: ``"held_out"``, ``"threshold"`` or
        ``"drip_shaped"``. Default: ``"held_out"`` when held-out data are given, else
        ``"drip_shaped"``. It is fixed by the inputs, never by comparing values (taking the
        minimum over forms would need a union bound over them).
    method
        Name of the training method, recorded.
    continuous
        The h's are continuous-time sups (section 4).
    comparison_gain
        An upper bound on ``sup||g||_2 / lambda_IL``, given only when the learned closed loop is
        proved to contract at ``lambda_IL`` on all of ``R^n``: then every gap also obeys the
        comparison bound ``gap <= comparison_gain * h_0`` (docs/math/tasil.md section 3.7), with
        no condition on ``h_1``, ``L_Delta`` or the tube; the smaller bound is used.
    uniform_h0
        With ``comparison_gain``: a sound upper bound of ``sup_{x in S} ||pi_IL(x) - pi*(x)||``
        over a set ``S`` proved to contain every expert trajectory from the support on ``[0, T]``.
        Then ``gap(xi) <= comparison_gain * uniform_h0`` for EVERY initial state of the support
        (docs/math/tasil.md section 3.8): the form ``"uniform"``, holding with probability 1. A
        sure bound needs no union bound: ``rho`` is the smaller of it and the chosen form's
        radius (when that holds), and the deterministic ``gap_bound`` takes it too.
    tube
        With ``comparison_gain``: the time-resolved sure bound along the expert's tube
        (:func:`~drip_cert.bounds.tasil.tube.tube_bound`, docs/math/tasil.md section 3.10), for
        every initial state of the support; the form ``"uniform"`` takes the smaller of it and
        ``comparison_gain * uniform_h0`` (both hold with probability 1, the same event).

    Returns
    -------
    TasilCertificate
    """
    h0t, h1t = _h_pair("train", train_h0, train_h1)
    have_val = heldout_h0 is not None or heldout_h1 is not None
    if have_val:
        if heldout_h0 is None or heldout_h1 is None:
            raise SpecError("give both heldout_h0 and heldout_h1", field="heldout_h0")
        h0v, h1v = _h_pair("heldout", heldout_h0, heldout_h1)
    else:
        h0v = h1v = np.zeros(0)
    delta = probability(delta)
    gamma0 = positive("gamma0", gamma0)
    L = positive("L_Delta", L_Delta, allow_zero=True)
    eta = positive("eta", eta, allow_inf=True)
    R = positive("R", R, allow_inf=True)
    if tau is not None:
        if len(tau) != 2:
            raise SpecError(f"tau must be (tau0, tau1), got {tau!r}", field="tau")
        tau = (
            positive("tau[0]", tau[0], allow_zero=True),
            positive("tau[1]", tau[1], allow_zero=True),
        )
    if use is None:
        use = "held_out" if have_val else "drip_shaped"
    if use not in ("held_out", "threshold", "drip_shaped"):
        raise SpecError(
            f"use={use!r}: rho must come from 'held_out', 'threshold' or 'drip_shaped'", field="use"
        )
    if use == "held_out" and not have_val:
        raise SpecError(
            "use='held_out' needs heldout_h0/heldout_h1 from fresh expert trajectories; give them "
            "or choose use='drip_shaped' with class constants",
            field="heldout_h0",
        )
    if use in ("threshold", "drip_shaped") and constants is None:
        raise SpecError(
            f"use={use!r} needs class constants (ClassConstants q, B_theta, L_theta, b); give them "
            "or held-out trajectories and use='held_out'",
            field="constants",
        )
    n, n_val = int(h0t.size), int(h0v.size)
    cg = None if comparison_gain is None else positive("comparison_gain", comparison_gain)

    # deterministic lemma per given initial state
    all0, all1 = np.concatenate([h0t, h0v]), np.concatenate([h1t, h1v])
    bounds = eps_star(all0, all1, gamma0, L) * gamma0
    worst = int(np.argmax(bounds))
    lem = imitation_gap_lemma(all0[worst], all1[worst], gamma0, L, eta, R, continuous=continuous)
    n_fail = 0
    if not lem.holds:
        n_fail = sum(
            not imitation_gap_lemma(a, b, gamma0, L, eta, R).holds for a, b in zip(all0, all1)
        )
    gap_bound, route = lem.bound, "lemma"
    uni = math.inf
    uni_how = ""
    if cg is not None and uniform_h0 is not None:
        uni = up_closed_form(cg * positive("uniform_h0", uniform_h0, allow_zero=True))
        uni_how = (
            f"sup||g||_2 (1 - e^(-lambda_IL T))/lambda_IL * sup_S ||pi_IL - pi*|| = {cg:.6g} * "
            f"{uniform_h0:.6g}"
        )
    if cg is not None and tube is not None and tube.rho < uni:
        uni = tube.rho
        uni_how = (
            f"max over t <= T of the time-resolved bound along the expert's tube "
            f"(docs/math/tasil.md 3.10, {len(tube.H)} intervals) = {tube.rho:.6g}"
        )
    if cg is not None:
        # every state's gap <= cg h0_i <= cg max h0 (section 3.7): valid whatever the lemma says
        gap_cmp = up_closed_form(cg * float(all0.max()))
        if gap_cmp < gap_bound:
            gap_bound, route = gap_cmp, "comparison"
        if uni < gap_bound:
            gap_bound, route = uni, "uniform"
    where = "training" if worst < n else "held-out"
    idx = worst if worst < n else worst - n
    gap_reason = (
        ""
        if math.isfinite(gap_bound)
        else f"lemma fails on {n_fail} of {all0.size} states; worst: {where} #{idx}: {lem.reason}"
    )

    obs = (float(h0t.max()), float(h1t.max()))
    # the held-out form's thresholds: fixed in advance, or the training maxima (independent of
    # the held-out data); without held-out data only a given tau is reported
    if tau is not None:
        tau0, tau1 = tau
    else:
        tau0, tau1 = obs if have_val else (math.nan, math.nan)
    forms: list[TasilForm] = []
    if have_val:
        forms.append(form_held_out(h0v, h1v, tau0, tau1, gamma0, L, eta, R, delta, continuous, cg))
    else:
        forms.append(TasilForm("held_out", math.inf, False, True, "not computed: no held-out data"))
    if constants is not None:
        forms.append(form_threshold(obs, tau, constants, n, gamma0, L, eta, R, delta, continuous))
        forms.append(form_expectation(obs, tau, constants, n, delta))
        forms.append(form_drip(obs, tau, constants, n, gamma0, L, eta, R, delta))
    else:
        for name in ("threshold", "expectation", "drip_shaped"):
            forms.append(TasilForm(name, math.inf, False, True, "not computed: no class constants"))
    if math.isfinite(uni):
        forms.append(form_uniform(uni, uni_how))
    chosen = next(f for f in forms if f.name == use)
    ok = chosen.holds and not chosen.vacuous and math.isfinite(chosen.value)
    rho = chosen.value if ok else math.inf
    if uni < rho:  # a sure bound: min with it needs no union bound
        rho, use = uni, "uniform"
    vac = tuple(f.name for f in forms if f.vacuous or not f.holds)
    return TasilCertificate(
        method=method,
        h0=float(all0.max()),
        h1=float(all1.max()),
        gamma0=gamma0,
        L_Delta=L,
        eta=eta,
        R=R,
        gap_bound=gap_bound,
        gap_reason=gap_reason,
        rho=rho,
        rho_form=use,
        delta=delta,
        n=n,
        n_val=n_val,
        tau0=float(tau0),
        tau1=float(tau1),
        forms=tuple(forms),
        vacuous_forms=vac,
        continuous=continuous,
        gap_checks=lem.checks,
        comparison_gain=cg,
        gap_route=route,
        tube=tube if cg is not None else None,
    )
