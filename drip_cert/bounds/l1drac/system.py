"""L1-DRAC for a :class:`~drip_cert.model.system.System`: the constants a system determines plus
the user's design inputs (spec table ``[l1drac]``), then the designer of
:mod:`drip_cert.bounds.l1drac.designer`.

System-determined constants (with provenance): ``lambda`` (contraction rate of the closed loop
under the learned policy, the nominal system of DRIP's L1-DRAC layer; the expert's when no learned
policy is given), ``Delta_g``, ``Delta_g_dot``, ``Delta_g_perp``, ``Delta_Theta``, ``m``, the
uncertainty and known-diffusion constants and their matched/unmatched parts, ``Delta_f``, ``L_f``
and ``Delta_star``. Time-Lipschitz constants (the hats) are 0 for time-invariant terms; for
time-varying ones they are sampled estimates. User inputs: ``p`` (default 1), ``lambda_s``,
``omega``, ``Ts``, ``rho_r``, ``rho_a``, ``delta``, ``alpha`` (default 0: the identity coupling
``D = D_bar``; otherwise the largest distance between the two support boxes, a sound bound on any
coupling's ``W_{2p}``), ``eps_r``, ``eps_a`` (default 1e-3, the slacks of (16)), ``p_star``
(default ``p``), the objective (``objective``, ``rho_budget``; default: the smallest rho at
``Ts`` = 1e-3 s, see :func:`~drip_cert.bounds.l1drac.designer.design`), ``front`` (the
(Ts, rho) Pareto front, on ``design.front``), and any constant override in ``[constants]``.
"""

from __future__ import annotations

import math
from collections.abc import Mapping
from dataclasses import dataclass, field
from typing import Any

import numpy as np

from drip_cert.analysis.growth.closed_loop import closed_loop_constants
from drip_cert.bounds.l1drac.constants import L1Constants
from drip_cert.bounds.l1drac.decomposition import L1Decomposition, decompose
from drip_cert.bounds.l1drac.designer import TradeoffRow, design, tradeoff_table
from drip_cert.bounds.l1drac.lower import rho_lower_bound
from drip_cert.bounds.l1drac.request import DesignRequest
from drip_cert.bounds.l1drac.result import L1Design
from drip_cert.errors import AssumptionViolation
from drip_cert.model.system import System
from drip_cert.numerics.rounding import norm2_up, up_np
from drip_cert.provenance import How, Quantity
from drip_cert.spec.settings import ConstantsTable, L1Settings

DEFAULT_EPS = L1Settings().eps_r  #: default slacks eps_r, eps_a of (16a), (16b)


@dataclass(frozen=True)
class L1Section:
    """The L1-DRAC part of a certificate: constants used, the design, or why there is none."""

    constants: Mapping[str, Quantity]
    design: L1Design | None
    error: str = ""
    tradeoff: tuple[TradeoffRow, ...] = ()  #: rows at the design's omega and lambda_s
    #: ``sup_t ||X*_t - x'_t||_{L_2p}`` with a known diffusion (``None`` without one): the third
    #: term of ``rho`` (docs/math/contraction.md Proposition 6.6)
    rho_sde: Quantity | None = None
    decomposition: L1Decomposition | None = None  #: rho_L1 term by term (decomposition.py)
    #: the integer and boolean constants of :class:`L1Constants` (``p_star``, ``m``, ``lip_f``):
    #: in ``constants_used`` too, so that it is a complete ``design-l1`` [constants] table
    discrete: Mapping[str, int | bool] = field(default_factory=dict)

    @property
    def feasible(self) -> bool:
        return self.design is not None and bool(self.design.feasible)

    def to_dict(self) -> dict[str, Any]:
        out: dict[str, Any] = {} if self.design is None else dict(self.design.to_dict())
        if self.design is None:
            out.update(feasible=False, reason=self.error)
        out["constants_used"] = {k: q.to_dict() for k, q in self.constants.items()}
        out["constants_used"].update(self.discrete)
        out["rho_sde"] = None if self.rho_sde is None else self.rho_sde.to_dict()
        out["tradeoff"] = [
            {"rho_a": r.rho_a, "Ts_max": r.Ts_max, "rho": r.rho} for r in self.tradeoff
        ]
        out["decomposition"] = None if self.decomposition is None else self.decomposition.to_dict()
        return out


@dataclass(frozen=True)
class L1Inputs:
    """The L1-DRAC constants of a system and the design request, before the design (the costly
    part: :func:`design_section`)."""

    constants: Mapping[str, Quantity]  #: every constant, with its provenance
    consts: L1Constants  #: the same numbers, as the designer takes them
    request: DesignRequest
    rho_sde: Quantity | None
    discrete: Mapping[str, int | bool]

    def rho_lower_bound(self) -> float:
        """A lower bound on the ``rho`` of any feasible design (:func:`rho_lower_bound`)."""
        return rho_lower_bound(self.consts, self.request.p)


def design_section(inputs: L1Inputs) -> L1Section:
    """Run the designer on prepared inputs: the section :func:`l1_section` returns."""
    consts = inputs.consts
    d = design(consts, inputs.request)
    rows: tuple[TradeoffRow, ...] = ()
    # a feasible design has omega and lambda_s (condition (24) was verified)
    if d.feasible and d.omega is not None and d.lambda_s is not None:
        rows = tradeoff_table(consts, d.p, d.omega, d.lambda_s)
    return L1Section(
        inputs.constants,
        d,
        tradeoff=rows,
        rho_sde=inputs.rho_sde,
        decomposition=decompose(consts, d),
        discrete=inputs.discrete,
    )


def l1_section(
    s: System,
    settings: L1Settings,
    given: ConstantsTable,
    lam: Quantity,
    global_rate: bool,
    which: str,
    input_q: Mapping[str, Quantity],
    unc_q: Mapping[str, Quantity],
) -> L1Section:
    """Assemble the L1-DRAC constants of ``s`` and run the designer (:func:`l1_inputs`, then
    :func:`design_section`)."""
    inputs = l1_inputs(s, settings, given, lam, global_rate, which, input_q, unc_q)
    return inputs if isinstance(inputs, L1Section) else design_section(inputs)


def l1_inputs(
    s: System,
    settings: L1Settings,
    given: ConstantsTable,
    lam: Quantity,
    global_rate: bool,
    which: str,
    input_q: Mapping[str, Quantity],
    unc_q: Mapping[str, Quantity],
) -> L1Inputs | L1Section:
    """Assemble the L1-DRAC constants of ``s`` and the design request; a section without a
    design when there can be none (no contraction, a constant without a finite value).

    Parameters
    ----------
    settings
        The spec's ``[l1drac]`` settings (validated at load).
    given
        The spec's ``[constants]`` (overrides, labelled ``given``; validated at load).
    lam
        Contraction rate of the closed loop under ``which`` policy.
    global_rate
        Whether ``lam`` holds on all of ``R^n``.
    input_q, unc_q
        Input-operator and uncertainty quantities by name.
    """
    st = settings
    q: dict[str, Quantity] = {}
    if lam.value <= 0:
        return L1Section(
            {"lambda": lam},
            None,
            f"the {which} closed loop is not shown to contract (lambda = "
            f"{lam.value:.6g}): L1-DRAC Assumption 2 fails, no design",
        )
    q["lambda"] = lam.renamed("lambda", source="L1-DRAC Assumption 2 (" + which + " closed loop)")
    cl = closed_loop_constants(
        s,
        which,
        lam,
        global_rate,
        p_star=st.p_star or st.p,
        p=st.p,
        Delta_p=unc_q.get("Delta_p"),
    )
    for qq in cl.quantities():
        q[qq.name] = qq
    for name in ("Delta_g", "Delta_g_dot", "Delta_g_perp", "Delta_Theta"):
        q[name] = input_q[name]
    for name, qq in unc_q.items():
        q[name] = qq
    # time-Lipschitz constants (hats): computed with the uncertainty constants (sup over t and a
    # of the time derivative, through g(t) too); a name they lack is unknown
    for name in (
        "L_p_hat",
        "L_p_par_hat",
        "L_p_perp_hat",
        "L_mu_hat",
        "L_mu_par_hat",
        "L_mu_perp_hat",
        "L_sigma_hat",
        "L_sigma_par_hat",
        "L_sigma_perp_hat",
    ):
        if name not in q:
            q[name] = Quantity(
                name,
                math.nan,
                How.ESTIMATE,
                "L1-DRAC Assumptions 1, 5, 6",
                "not computed: give this constant in [constants]",
            )
    alpha_default = 0.0
    alpha_note = "identity coupling D = D_bar (same initial state): W_2p = 0"
    if s.true_support is not None:
        a = np.array(s.support)
        b = np.array(s.true_support)
        far = up_np(np.maximum(np.abs(a[:, 1] - b[:, 0]), np.abs(b[:, 1] - a[:, 0])))
        alpha_default = norm2_up(far)
        alpha_note = "largest distance between the supports of D and D_bar (any coupling)"
    # the supports' distance is a proved bound on any coupling's W_2p (outward rounded); a value
    # in [l1drac] is the user's claim about D and D_bar
    q["alpha"] = Quantity.derive(
        "alpha",
        alpha_default if st.alpha is None else st.alpha,
        method=How.SOUND if st.alpha is None else How.GIVEN,
        source="L1-DRAC (18a)",
        note=alpha_note if st.alpha is None else "given in [l1drac]",
    )
    for key in ("eps_r", "eps_a"):
        # a slack of (16) is a design choice, not a claim about the system: the number the
        # design uses is exactly this one (nothing to be true or false about it)
        q[key] = Quantity.derive(
            key,
            getattr(st, key),
            source="L1-DRAC (16)",
            note="design slack" + ("" if key in st.given else f" (default {DEFAULT_EPS})"),
        )
    for name, v in given.values.items():
        if name in q:
            q[name] = Quantity(name, v, How.GIVEN, q[name].source, "given in [constants]")
    lip_f = st.lip_f if st.lip_f is not None else math.isfinite(q["L_f"].value)
    discrete = {"p_star": st.p_star or st.p, "m": s.m, "lip_f": bool(lip_f)}
    bad = [k for k, v in q.items() if not math.isfinite(v.value) and not (k == "L_f" and not lip_f)]
    if bad:
        return L1Section(
            q,
            None,
            "constants without a finite value: "
            + ", ".join(f"{k} ({q[k].note})" for k in bad)
            + "; give them in [constants]",
            rho_sde=cl.rho_sde,
            discrete=discrete,
        )
    # the [constants] mapping of L1Constants.from_mapping: reals, the ints p_star, m, the bool lip_f
    values: dict[str, Any] = {k: v.value for k, v in q.items()}
    values.update(p_star=st.p_star, m=s.m, lip_f=bool(lip_f))
    if not lip_f:
        values["L_f"] = 0.0
    try:
        consts = L1Constants.from_mapping(values)
    except AssumptionViolation as exc:
        return L1Section(q, None, str(exc), rho_sde=cl.rho_sde, discrete=discrete)
    req = DesignRequest(
        p=st.p,
        lambda_s=st.lambda_s,
        omega=st.omega,
        Ts=st.Ts,
        rho_r=st.rho_r,
        rho_a=st.rho_a,
        delta=st.delta,
        objective=st.objective,
        rho_budget=st.rho_budget,
        front=st.front,
    )
    return L1Inputs(q, consts, req, cl.rho_sde, discrete)
