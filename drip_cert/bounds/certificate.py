"""The certificate: every assumption with its verdict, every constant with its provenance, the
contraction rate, the delta-ISS gain, and (when the spec asks for them) the TaSIL and L1-DRAC
parts and their sum ``rho = rho_TaSIL + rho_L1`` (DRIP eq. TotalTIG).

:func:`certify` runs the pipeline of design.md on a :class:`~drip_cert.system.Spec`;
:class:`Certificate` is the frozen result, with :meth:`Certificate.to_dict` (the JSON other tools
read: ``assumptions``, ``contraction.rate``, ``contraction.metric_rate``, ``contraction.method``,
``delta_iss.gain``, ``certified``, ``l1drac``, ``tasil``, ``rho``) and
:meth:`Certificate.to_markdown`.
"""

from __future__ import annotations

import dataclasses
import math
from collections.abc import Mapping
from dataclasses import dataclass, field
from fractions import Fraction
from typing import TYPE_CHECKING, Any

import numpy as np
import sympy as sp

from drip_cert.analysis.contraction.coordinates import CoordinateChange, coordinates_from_metric
from drip_cert.analysis.contraction.invariance import (
    InvariantSet,
    best_invariant_set,
    invariant_box,
)
from drip_cert.analysis.contraction.learned_loop import best_global_rate, sup_policy_difference
from drip_cert.analysis.contraction.lmi import DEFAULT_KAPPA, contraction_metric
from drip_cert.analysis.contraction.mlp_loop import system_mlps
from drip_cert.analysis.contraction.rate import ContractionResult, contraction_rate
from drip_cert.analysis.growth.constants import (
    InputConstants,
    UncertaintyConstants,
    input_constants,
    uncertainty_constants,
)
from drip_cert.analysis.iss import delta_iss
from drip_cert.analysis.networks.block_enclosure import block_enclose_callback
from drip_cert.bounds.binding import l1drac_learned_binding, part_bindings
from drip_cert.bounds.l1drac.system import L1Inputs, L1Section, design_section, l1_inputs
from drip_cert.bounds.tasil.tube import expert_tube_bound, horizon_factor_up
from drip_cert.errors import AssumptionViolation, DripCertError
from drip_cert.model.fingerprint import Fingerprint, fingerprint_of
from drip_cert.model.system import System
from drip_cert.numerics.rounding import div_up, mul_down, mul_up, sum_down, up
from drip_cert.progress import Stages
from drip_cert.provenance import (
    Check,
    How,
    Quantity,
    Scope,
    Verdict,
    json_float,
    split_timings,
    verdict_of,
)
from drip_cert.spec.load import Spec, SpecSource, as_spec
from drip_cert.spec.settings import ContractionSettings, Settings

if TYPE_CHECKING:
    from drip_cert.analysis.contraction.lmi import MetricResult
    from drip_cert.analysis.contraction.slope_lmi import TraceObstruction
    from drip_cert.analysis.iss import DeltaISSResult
    from drip_cert.bounds.tasil.certificate import TasilCertificate
    from drip_cert.learn.imitation import DemonstrationSet
    from drip_cert.model.mlp import MLP


@dataclass(frozen=True)
class ContractionAnalysis:
    """Euclidean rate (what the paper's bounds use) and metric rate of one closed loop."""

    policy: str
    euclidean: ContractionResult
    metric: MetricResult | None
    metric_error: str = ""
    #: the trace condition ruling out every slope-restricted LMI for all x (None: not found)
    obstruction: TraceObstruction | None = None

    def to_dict(self) -> dict[str, Any]:
        out = {"policy": self.policy, **self.euclidean.to_dict()}
        out["metric_rate"] = None if self.metric is None else json_float(self.metric.metric_rate)
        out["metric"] = None if self.metric is None else self.metric.to_dict()
        if self.obstruction is not None:
            out["global_obstruction"] = self.obstruction.to_dict()
        if self.metric_error:
            out["metric_error"] = self.metric_error
        return out


def analyse_contraction(s: System, which: str, opts: ContractionSettings) -> ContractionAnalysis:
    """Contraction rate of the closed loop under the expert or the learned policy.

    Implements the check of DRIP Assumption 2 (expert) and L1-DRAC Assumption 2 (learned closed
    loop, the nominal system of the L1-DRAC layer).
    """
    J = s.closed_loop_jacobian(which)
    box = np.array(opts.region if opts.region is not None else s.support, dtype=float)
    depends_t = J.has(s.t)
    t_range = (0.0, s.horizon) if depends_t else None

    def J_num(tt, X):
        # jax and the numeric model are built at the first sample only: a rate that the
        # interval branch and bound proves alone never samples (jax: 0.3 CPU-s to import)
        from drip_cert._jax import jnp  # jax: keep off the API's import path

        try:
            jv = s.numeric.jac_batched(which)  # jitted once per model
        except ValueError as exc:
            raise DripCertError(str(exc)) from None
        X = jnp.asarray(X, dtype=jnp.float64)
        tv = jnp.broadcast_to(jnp.asarray(0.0 if tt is None else tt, jnp.float64), X.shape[:1])
        return np.asarray(jv(tv, X))

    enclose = block_enclose_callback(s.blocks) if s.blocks else None
    res = contraction_rate(
        J,
        s.states,
        box,
        s.t if depends_t else None,
        t_range,
        J_num=J_num,
        enclose=enclose,
        method=opts.method,
        tol=opts.tol,
        max_boxes=opts.max_boxes,
        max_time_s=opts.max_time,
        mlps=system_mlps(s) or None,
    )
    metric, err = None, ""
    if opts.metric:
        try:
            metric = _metric(s, which, opts, J_num=J_num, enclose=enclose)
        except DripCertError as exc:
            err = str(exc)
    return ContractionAnalysis(which, res, metric, err)


def _metric(
    s: System,
    which: str,
    opts: ContractionSettings,
    *,
    kappa: float | None = None,
    J_num: Any = None,
    enclose: Any = None,
) -> Any:
    """The LMI contraction metric of a closed loop on the contraction region (``kappa`` bounds
    ``cond P``; default that of :func:`~drip_cert.analysis.contraction.lmi.contraction_metric`)."""
    J = s.closed_loop_jacobian(which)
    box = np.array(opts.region if opts.region is not None else s.support, dtype=float)
    depends_t = J.has(s.t)
    t_range = (0.0, s.horizon) if depends_t else None
    if enclose is None and s.blocks:
        enclose = block_enclose_callback(s.blocks)
    return contraction_metric(
        J,
        s.states,
        box,
        s.t if depends_t else None,
        t_range,
        J_num=J_num,
        enclose=enclose,
        kappa=DEFAULT_KAPPA if kappa is None else kappa,
    )


#: check ids of each part of the certificate (a part's verdict is that of its checks)
PARTS: dict[str, tuple[str, ...]] = {
    "contraction": ("DRIP-A1", "DRIP-A2"),
    "tasil": ("DRIP-A1", "DRIP-A2", "TaSIL"),
    "l1drac": ("L1DRAC-A2", "L1DRAC-A7", "L1DRAC-design"),
}
_SDE_REASON = (
    "L1-DRAC Assumption 2 is needed for all x: trajectories of the true SDE leave every bounded "
    "set with positive probability, so a rate proved on {scope} does not suffice"
)


@dataclass(frozen=True)
class Claims:
    """What a certificate claims, in the user's coordinates ``x`` (frozen): the numbers that
    ``validate`` (simulated runs) and ``validate --data`` (recorded runs) check.

    A certificate computed in ``z = Theta x`` is mapped back by ``F = ||Theta^{-1}||_2``
    (docs/math/contraction.md Proposition 5.3): ``||x gap|| <= F ||z gap||``, so a radius or a
    tail threshold ``kappa`` in ``z`` is ``F`` times itself in ``x``
    (``P(||x gap|| >= F kappa) <= P(||z gap|| >= kappa)``); probabilities and the design are
    unchanged.

    Attributes
    ----------
    rho_tasil, delta_tasil
        ``P(max_t ||x'_t - x*_t|| > rho_TaSIL) <= delta_TaSIL`` (DRIP Theorem thm:TaSIL);
        ``None`` when no TaSIL part was computed.
    rho_l1, p
        ``sup_t ||X_t - x'_t||_{L_2p} <= rho_L1`` (L1-DRAC Theorem 4.1); ``p = 1`` without a
        feasible design.
    kappa, delta_l1
        The tail bound ``P(||X_t - x'_t|| >= kappa) <= delta_L1`` of the design (``kappa`` in
        ``x``); ``None`` without a feasible design or without a requested ``delta``.
    design
        The certified L1-DRAC design ``(omega, lambda_s, T_s)``; ``None`` when none is feasible.
    rho_sde
        ``sup_t ||X*_t - x'_t||_{L_2p}`` with a known diffusion, else ``None``.
    rho
        ``rho_TaSIL + rho_L1 (+ rho_sde)`` (DRIP eq. TotalTIG), ``None`` unless both parts exist.
    rho_mean
        ``max_t E||X_t - x'_t|| < rho_mean = min_{q <= p} rho(q)`` at the certified controller
        (docs/math/l1drac.md 5.6.1; ``l1drac.decomposition.rho_mean``), in ``x``
        (``E||Theta^{-1} Z|| <= F E||Z||``); ``None`` without a feasible design or a
        decomposition.
    """

    rho_tasil: float | None
    delta_tasil: float | None
    rho_l1: float | None
    p: int
    kappa: float | None
    delta_l1: float | None
    design: tuple[float, float, float] | None
    rho_sde: float | None
    rho: float | None
    rho_mean: float | None = None

    @classmethod
    def of(cls, cert: Any) -> Claims:
        """The claims of ``cert`` (a :class:`Certificate` or an object with its attributes)."""
        l1 = cert.l1
        design = l1.design if (l1 is not None and l1.feasible) else None
        coords = cert.coordinates
        kappa = design.kappa if design is not None else None
        if kappa is not None and coords is not None:
            kappa = coords.gap_in_x(kappa)  # P(||x gap|| >= F kappa) <= P(||z gap|| >= kappa)
        dec = getattr(l1, "decomposition", None) if design is not None else None
        mean = None if dec is None or dec.rho_mean is None else float(dec.rho_mean.value)
        if mean is not None and coords is not None:
            mean = float(coords.gap_in_x(mean))
        return cls(
            rho_tasil=cert.rho_tasil,
            delta_tasil=cert.tasil.delta if cert.tasil is not None else None,
            rho_l1=cert.rho_l1,
            p=design.p if design is not None else 1,
            kappa=kappa,
            delta_l1=design.delta if design is not None else None,
            design=None
            if design is None
            else (float(design.omega), float(design.lambda_s), float(design.Ts)),
            rho_sde=cert.rho_sde,
            rho=cert.rho,
            rho_mean=mean,
        )


@dataclass(frozen=True)
class Certificate:
    """The certificate of one system (frozen). See the module docstring for the JSON keys.

    The verdict is computed from the checks (:func:`~drip_cert.provenance.verdict_of`):
    ``certified`` when every check holds, is proved (exact, sound or given) and is used only where
    its scope is justified; ``conditional`` when every check holds but some rest on estimates or
    on an unproved region; ``not_certified`` when a check fails or could not be evaluated.
    """

    system: System
    assumptions: tuple[Check, ...]
    inputs: InputConstants
    uncertainty: UncertaintyConstants
    contraction_expert: ContractionAnalysis
    contraction_learned: ContractionAnalysis | None
    delta_iss: DeltaISSResult | None
    l1: L1Section | None = None
    tasil: TasilCertificate | None = None
    tasil_provenance: Mapping[str, Any] = field(default_factory=dict)
    notes: tuple[str, ...] = ()
    invariance: InvariantSet | None = None
    extra_quantities: tuple[Quantity, ...] = ()  #: other inputs of the checks (h0, h1, gamma0)
    coordinates: CoordinateChange | None = None  #: None: computed in the user's x
    alternatives: tuple[Mapping[str, Any], ...] = ()  #: the other coordinates tried, in summary
    #: the parts not computed: ``(part, "not_requested" | "not_applicable", reason)``
    skipped: tuple[tuple[str, str, str], ...] = ()
    fingerprint: Fingerprint | None = None  #: of the policy and design, in x (recorded data)

    @property
    def verdict(self) -> Verdict:
        """``certified`` / ``conditional`` / ``not_certified`` (see the class docstring)."""
        return verdict_of(self.assumptions)[0]

    @property
    def verdict_reasons(self) -> tuple[str, ...]:
        """What the verdict rests on when it is not ``certified``."""
        return verdict_of(self.assumptions)[1]

    @property
    def certified(self) -> bool:
        """``verdict == certified``: every link proved, every scope justified."""
        return self.verdict == Verdict.CERTIFIED

    def part_verdicts(self) -> dict[str, dict[str, Any]]:
        """The verdict of every part (``contraction``, ``tasil``, ``l1drac``), named up front: a
        part that was not computed is ``not_requested`` (the spec did not ask for it) or
        ``not_applicable`` (the system has nothing it could be about), with the reason."""
        out: dict[str, dict[str, Any]] = {}
        skipped = dict((part, (status, why)) for part, status, why in self.skipped)
        for part, ids in PARTS.items():
            if part in skipped:
                status, why = skipped[part]
                out[part] = {"verdict": status, "reasons": [why]}
                continue
            v, why_v = verdict_of([c for c in self.assumptions if c.id in ids])
            out[part] = {"verdict": v.value, "reasons": list(why_v)}
        checks = {p: [c for c in self.assumptions if c.id in ids] for p, ids in PARTS.items()}
        for part, b in part_bindings(out, checks, self._l1_learned_binding()).items():
            out[part]["binding"] = b
        return out

    def _l1_learned_binding(self) -> dict[str, Any] | None:
        """The L1-DRAC part's chain when its nominal loop is the learned one, not proved for all
        x (:func:`~drip_cert.bounds.binding.l1drac_learned_binding`)."""
        if self.contraction_learned is None or self.l1 is None:
            return None
        design = self.l1.design if self.l1.feasible else None
        return l1drac_learned_binding(
            self.contraction_learned,
            self.system.support,
            self.rho_l1_native,
            design.p if design is not None else 1,
            in_z=self.coordinates is not None,
        )

    @property
    def rho_certified(self) -> bool:
        """Whether ``rho = rho_TaSIL + rho_L1`` is certified: both parts computed and certified
        (a radius with one part missing is no bound on the total gap)."""
        parts = self.part_verdicts()
        both = all(parts[p]["verdict"] == Verdict.CERTIFIED.value for p in ("tasil", "l1drac"))
        q = self.rho_sde_quantity
        sde_ok = q is None or (q.how.proved and math.isfinite(q.value))
        return both and sde_ok

    @property
    def machine_dependent(self) -> tuple[str, ...]:
        """The searches that stopped on a wall-time guard (their bounds depend on the machine's
        speed); empty when the certificate is a function of its inputs alone."""
        out = []
        for name, a in (("expert", self.contraction_expert), ("learned", self.contraction_learned)):
            if a is not None and a.euclidean.machine_dependent:
                out.append(f"contraction of the {name} closed loop ({a.euclidean.n_boxes} boxes)")
        return tuple(out)

    @property
    def estimated(self) -> tuple[str, ...]:
        """Names of the estimates (not bounds) among the quantities the checks rest on."""
        names = [q.name for q in self.all_quantities() if q.how == How.ESTIMATE]
        for c in self.assumptions:
            names.extend(
                r for r in c.rests_on if r not in names and self._how_of(r) == How.ESTIMATE
            )
        return tuple(dict.fromkeys(names))

    def _how_of(self, name: str) -> How | None:
        for q in self.all_quantities():
            if q.name == name:
                return q.how
        return None

    def all_quantities(self) -> list[Quantity]:
        qs = list(self.inputs.quantities()) + list(self.uncertainty.values.values())
        qs.append(self.contraction_expert.euclidean.to_quantity())
        if self.contraction_learned is not None:
            q = self.contraction_learned.euclidean.to_quantity()
            qs.append(q.renamed("lambda_learned", source="L1-DRAC Assumption 2"))
        qs.extend(self.extra_quantities)
        if self.l1 is not None:
            have = {q.name for q in qs}
            qs.extend(q for q in self.l1.constants.values() if q.name not in have)
            if self.l1.rho_sde is not None:
                qs.append(self.l1.rho_sde)
        return qs

    @property
    def rho_l1_native(self) -> float | None:
        """``rho_L1`` in the coordinates the certificate was computed in (``system.states``)."""
        design = None if self.l1 is None else self.l1.design
        if design is None or not design.feasible or design.rho is None:
            return None
        return float(design.rho)

    @property
    def rho_tasil_native(self) -> float | None:
        """``rho_TaSIL`` in the coordinates the certificate was computed in."""
        if self.tasil is None or self.tasil.rho is None:
            return None
        return float(self.tasil.rho)

    def _in_x(self, v: float | None) -> float | None:
        if v is None or self.coordinates is None:
            return v
        return self.coordinates.gap_in_x(v)

    @property
    def rho_l1(self) -> float | None:
        """``rho_L1`` in the user's coordinates ``x`` (mapped back by ``||Theta^{-1}||_2``)."""
        return self._in_x(self.rho_l1_native)

    @property
    def rho_tasil(self) -> float | None:
        """``rho_TaSIL`` in the user's coordinates ``x``."""
        return self._in_x(self.rho_tasil_native)

    @property
    def rho_sde_quantity(self) -> Quantity | None:
        """``sup_t ||X*_t - x'_t||_{L_2p}`` (the nominal SDE against the nominal ODE), present
        when the system has a known diffusion and the L1-DRAC part was computed."""
        return None if self.l1 is None else self.l1.rho_sde

    @property
    def rho_sde(self) -> float | None:
        """:attr:`rho_sde_quantity` in the user's coordinates ``x``."""
        q = self.rho_sde_quantity
        return None if q is None else self._in_x(float(q.value))

    @property
    def rho(self) -> float | None:
        """``rho = rho_TaSIL + rho_L1`` (DRIP eq. TotalTIG) when both parts exist (rounded up);
        with a known diffusion also ``+ rho_sde``: L1-DRAC's nominal process is then an SDE, and
        its distance to TaSIL's nominal ODE is the third term of the decomposition
        (docs/math/contraction.md Proposition 6.6)."""
        if self.rho_l1 is None or self.rho_tasil is None:
            return None
        total = up(self.rho_tasil + self.rho_l1)
        return total if self.rho_sde is None else up(total + self.rho_sde)

    def claims(self) -> Claims:
        """What this certificate claims, in the user's ``x`` (:class:`Claims`): the one reading
        of the bounds that ``validate`` and ``validate --data`` check."""
        return Claims.of(self)

    def to_dict(self) -> dict[str, Any]:
        ce = self.contraction_expert
        contraction = {
            "rate": json_float(ce.euclidean.rate),
            "metric_rate": None if ce.metric is None else json_float(ce.metric.metric_rate),
            "method": ce.euclidean.method,
            "how": ce.euclidean.how.value,
            "region": ce.euclidean.region,
            "scope": ce.euclidean.scope.to_dict(),
            "invariant_set": None if self.invariance is None else self.invariance.to_dict(),
            "expert": ce.to_dict(),
            "learned": None
            if self.contraction_learned is None
            else self.contraction_learned.to_dict(),
        }
        diss = None
        if self.delta_iss is not None:
            d = self.delta_iss
            g = next((q for q in self.extra_quantities if q.name == "gamma0"), None)
            diss = {
                "gain": json_float(d.tight_gain_asymptotic if g is None else g.value),
                "gain_paper": json_float(d.paper_gain_asymptotic),
                "theta_star": json_float(d.theta_star),
                "used": d.used,
                "how": (g.how if g is not None else How(d.how)).value,
                "scope": ce.euclidean.scope.describe(),
                "source": "tighter comparison-lemma bound (this project's derivation, valid under "
                "DRIP Assumption 2); the paper's Proposition 1 gain is gain_paper",
                "detail": d.to_dict(),
            }
        rho = {
            "rho_tasil": json_float(self.rho_tasil) if self.rho_tasil is not None else None,
            "rho_l1": json_float(self.rho_l1) if self.rho_l1 is not None else None,
            "rho_total": json_float(self.rho) if self.rho is not None else None,
            "rho_sde": json_float(self.rho_sde) if self.rho_sde is not None else None,
            "certified": self.rho_certified,
            "coordinates": "x (the spec's states)",
            "source": "DRIP eq. (TotalTIG): rho = rho_TaSIL + rho_L1"
            + (
                " + rho_sde (a known diffusion: the nominal SDE of L1-DRAC against the nominal "
                "ODE of TaSIL, docs/math/contraction.md Prop. 6.6)"
                if self.rho_sde is not None
                else ""
            ),
            "note": "rho_TaSIL is a (1 - delta) radius of max_t ||x'_t - x*_t||, rho_L1 an L_2p "
            "moment bound of ||X_t - x'_t||: their sum is reported as the paper states it, and "
            "validate checks each part with the statistic it bounds",
        }
        verdict, reasons = verdict_of(self.assumptions)
        machine = self.machine_dependent
        out = {
            "schema_version": SCHEMA_VERSION,
            "system": self.system.to_dict(),
            "verdict": verdict.value,
            "verdict_reasons": list(reasons),
            "certified": verdict == Verdict.CERTIFIED,
            "parts": self.part_verdicts(),
            "sound": not self.estimated,
            "estimated_constants": list(self.estimated),
            "given_constants": sorted(
                {q.name for q in self.all_quantities() if q.how == How.GIVEN}
            ),
            "assumptions": [c.to_dict() for c in self.assumptions],
            "constants": {q.name: q.to_dict() for q in self.all_quantities()},
            "input_operator": self.inputs.to_dict(),
            "contraction": contraction,
            "delta_iss": diss,
            "l1drac": None if self.l1 is None else self.l1.to_dict(),
            "tasil": None
            if self.tasil is None
            else {**self.tasil.to_dict(), "provenance": dict(self.tasil_provenance)},
            "rho": rho,
            "coordinates": self._coordinates_dict(),
            "notes": list(self.notes),
            "reproducible": {
                "machine_independent": not machine,
                "stopped_on_time": list(machine),
                "note": "every search stops on a count of work (boxes, evaluations, steps): the "
                "same inputs give the same certificate on any machine, apart from the wall-clock "
                "measurements under 'timings'"
                if not machine
                else "a wall-time guard fired: the searches listed stopped on time, so their "
                "bounds (and what rests on them) depend on this machine's speed and load; "
                "remove [contraction] max_time for a reproducible certificate",
            },
            "fingerprint": None if self.fingerprint is None else self.fingerprint.to_dict(),
        }
        out["timings"] = split_timings(out)
        return out

    def _coordinates_dict(self) -> dict[str, Any]:
        """Which coordinates the numbers live in, and the conversion (schema 3)."""
        if self.coordinates is None:
            out: dict[str, Any] = {
                "system": "x",
                "note": "every number is in the spec's coordinates x",
            }
        else:
            out = {
                "system": "z = Theta x",
                **self.coordinates.to_dict(),
                "rho_tasil_z": json_float(self.rho_tasil_native)
                if self.rho_tasil_native is not None
                else None,
                "rho_l1_z": json_float(self.rho_l1_native)
                if self.rho_l1_native is not None
                else None,
                "note": "the certificate is computed for the equivalent system in z = Theta x "
                "(docs/math/contraction.md section 5): rates, gains, constants, the TaSIL and "
                "L1-DRAC sections and the system shown are in z; rho.* are mapped back to x by "
                "factor_to_x >= ||Theta^{-1}||_2 (Proposition 5.3); input-space quantities "
                "(h0, policy errors, the L1-DRAC input) are the same in both; "
                "contraction.metric_rate and contraction.expert.metric are the best "
                "constant-metric rate found and its P in x; the metric used here was chosen "
                "among the candidates (alternatives) by the final radius in x",
            }
        out["alternatives"] = [dict(a) for a in self.alternatives]
        return out


EST_RATE_FLOOR = 2.0**-52  #: smallest sampled rate a conditional L1-DRAC design is built on

SCHEMA_VERSION = 4
"""Version of :meth:`Certificate.to_dict`'s layout (2: ``verdict``, ``parts``, scopes; 3:
``coordinates``: the certificate may be computed in metric coordinates z, ``rho`` is in x; 4:
every part named in ``parts`` (``not_requested`` / ``not_applicable`` with the reason),
``rho.certified``, wall-clock fields moved under ``timings``, ``reproducible``)."""


def _rate_check(cid: str, r: Any, what: str, source: str) -> Check:
    """``mu_2 <= -lambda < 0`` for one closed loop, labelled from the rate's provenance."""
    lam = r.to_quantity()
    return Check.compare(
        cid,
        Quantity.derive("max_mu2", -lam.value, inputs=[lam]),
        0.0,
        f"{what}: mu_2(J) <= -lambda with lambda = {r.rate:.6g} ({r.how.value}, {r.method}) on "
        f"{r.region}" + ("" if r.holds else "; contraction is not established"),
        strict=True,
        source=source,
        witness=None if r.holds else r.witness,
    )


def _invariance(s: System, r: Any, g_box: np.ndarray | None = None) -> InvariantSet | None:
    """A forward-invariant ball inside the box where the expert's rate is proved (None when the
    rate is global or not positive). For a state-dependent g (``g_box``: the box its sups are
    taken over) a global rate still needs one inside that box."""
    if not r.holds or not r.how.proved or (r.scope.all_x and g_box is None):
        return None
    scope = r.scope
    if scope.all_x:
        assert g_box is not None
        scope = Scope(tuple((float(a), float(b)) for a, b in g_box), scope.t_range)
    from drip_cert._jax import jnp  # jax: keep off the API's import path

    num = s.numeric

    def F_num(z):
        z = jnp.asarray(z, dtype=jnp.float64)
        return np.asarray(num.f(0.0, z) + num.g(0.0, z) @ num.expert(z))

    return best_invariant_set(
        s.closed_loop("expert"),
        s.states,
        s.t,
        r.rate,
        scope,
        np.asarray(s.support, dtype=float),
        s.horizon,
        F_num,
        block_enclose_callback(s.blocks) if s.blocks else None,
    )


def certify(
    spec: SpecSource,
    *,
    demonstrations: DemonstrationSet | None = None,
    policy: MLP | None = None,
    progress: bool = False,
) -> Certificate:
    """The DRIP certificate of a system: assembles the constants, rates, gains and bounds.

    Parameters
    ----------
    spec
        A spec file's path (``str`` or :class:`~pathlib.Path`, loaded here), a loaded
        :class:`~drip_cert.spec.load.Spec`, or a bare :class:`~drip_cert.model.system.System`
        (default settings; no ``[l1drac]`` part, and a TaSIL part only when ``demonstrations``
        are given): :func:`~drip_cert.spec.load.as_spec`. Another type raises
        :class:`~drip_cert.errors.InputTypeError`.
    demonstrations
        The expert demonstrations the learned policy was trained on
        (:func:`~drip_cert.learn.imitation.demonstration_set`); the TaSIL bound is computed on
        them. ``None``: they are drawn from the spec's ``[tasil]`` settings (seed, trajectories,
        samples), the same draw ``drip-cert train`` makes with those settings.
    policy
        An MLP to use as the learned policy ``pi_IL`` (replaces the spec's).
    progress
        Report each stage and its duration on stderr.

    Notes
    -----
    Coordinates (``[contraction] metric``, docs/math/contraction.md section 5): with ``"auto"``
    (the default) the certificate is computed in the spec's coordinates ``x`` and, when an LMI
    contraction metric ``P`` of the expert closed loop is found and the Euclidean rate fails or
    is slower than the metric rate, also for the equivalent system in ``z = Theta x``
    (``P = Theta^T Theta``); the better one is returned (verdict first, then fewer failing
    checks, then the smaller finite radii in ``x``; a tie keeps ``x``), the other summarised
    under ``coordinates.alternatives``. The metric candidates are finished best-first, and a
    candidate whose L1-DRAC design could not make it the choice (a lower bound on its order
    computed before the design, :func:`_finish_candidates`) is not designed: it is listed with
    verdict ``"skipped"`` and the bound that ruled it out. When the expert's rate fails in
    ``x`` (DRIP-A2 fails there, so ``x``'s verdict is ``not_certified`` whatever its other
    parts give), ``x`` is finished only if no candidate in ``z`` is better than that; otherwise
    its summary says it was not finished (its constants, TaSIL and L1-DRAC parts are not
    computed, ``failing`` counts DRIP-A2 alone).
    ``"lmi"`` always uses the metric when one is found, a given matrix ``P`` uses that metric,
    ``"euclidean"`` never changes coordinates.
    """
    spec = as_spec(spec)
    if policy is not None:
        from drip_cert.learn.imitation import learned_system  # jax: keep off the API's import path

        spec = spec.with_system(learned_system(spec.system, policy))
    stage = Stages("certify", enabled=progress)
    opts = spec.settings.contraction
    if opts.coordinates == "given":
        assert opts.P is not None  # set with "given" by ContractionSettings.from_table
        change = coordinates_from_metric(np.array(opts.P), "given in [contraction] metric")
        cert = _certify_in_metric(spec, change, demonstrations, stage)
        stage.done()
        return cert
    stage("contraction rate of the expert closed loop")
    ce_x = analyse_contraction(spec.system, "expert", opts)
    metric, eu = ce_x.metric, ce_x.euclidean
    if (
        opts.coordinates == "euclidean"
        or metric is None
        or (opts.coordinates == "auto" and eu.holds and eu.rate >= metric.metric_rate)
    ):
        cert = _certify_in(spec, demonstrations, stage, expert=ce_x)
        stage.done()
        return cert
    # the metric that maximises the rate may have a large cond P, which inflates the radii mapped
    # back to x: also try metrics with cond P capped lower, and choose by the final result
    metrics = [metric]
    for kappa in METRIC_KAPPAS:
        if kappa < metric.cond_P:
            try:
                m = _metric(spec.system, "expert", opts, kappa=kappa)
            except DripCertError:
                continue
            if m.metric_rate > 0 and (not eu.holds or m.metric_rate > eu.rate):
                metrics.append(m)
    if demonstrations is None and spec.system.learned is not None:
        # drawn once for every candidate coordinate system (each maps the same draw to z)
        from drip_cert.learn.imitation import demonstration_set  # jax: keep off the API's path

        demonstrations = demonstration_set(spec.system, spec.settings.tasil)
    prepared: list[_Unfinished] = []
    for m in metrics:
        change = coordinates_from_metric(
            m.P,
            f"the LMI contraction metric of the expert closed loop (rate {m.metric_rate:.6g}, "
            f"cond P <= {m.kappa:g})",
        )
        stage(f"the certificate in z = Theta x (rate {m.metric_rate:.6g}, cond P {m.cond_P:.3g})")
        prepared.append(_prepare_in_metric(spec, change, demonstrations, stage))
    # x, lazily: when the expert's rate fails in x, x's verdict is not_certified whatever else
    # it holds, and once a candidate in z is better than that, x's other parts are not computed
    a2_x = _expert_rate_check(spec.system, opts, ce_x)
    x_low = (_VERDICT_ORDER[Verdict.NOT_CERTIFIED], 1, 0.0)  # x's key is >= this when a2_x fails
    cert_x: Certificate | dict[str, Any]
    head: list[Certificate]
    if a2_x.holds:
        cert_x = _certify_in(spec, demonstrations, stage, expert=ce_x)
        head = [] if opts.coordinates == "lmi" else [cert_x]
        in_z = _finish_candidates(head, prepared, stage)
    else:
        in_z = _finish_candidates([], prepared, stage)
        keys = [_preference(c) for c in in_z if isinstance(c, Certificate)]
        if opts.coordinates == "auto" and not any(k < x_low for k in keys):
            cert_x = _certify_in(spec, demonstrations, stage, expert=ce_x)  # x may be chosen
            head = [cert_x]
        else:
            cert_x = _unfinished_x_summary(ce_x, a2_x, min(keys) if keys else None)
            head = []
    stage.done()
    # z only when strictly better: a tie keeps the user's own coordinates (listed first)
    pool = [*head, *(c for c in in_z if isinstance(c, Certificate))]
    chosen = min(pool, key=_preference)
    others = [c for c in [cert_x, *in_z] if c is not chosen]
    chosen = dataclasses.replace(
        chosen,
        alternatives=tuple(c if isinstance(c, dict) else _summary(c) for c in others),
    )
    if chosen.coordinates is not None:
        # the best constant-metric rate found (in x: the rate-maximising LMI metric) is reported
        # as contraction.metric_rate; the checks above use the metric chosen by the final radius
        ce = dataclasses.replace(chosen.contraction_expert, metric=metric)
        chosen = dataclasses.replace(chosen, contraction_expert=ce)
    return chosen


METRIC_KAPPAS = (10.0, 100.0)
"""Caps of ``cond P`` tried besides the rate-maximising metric (when that one's ``cond P`` is
larger): the candidates of the rate / condition-number trade-off of the coordinate choice."""


_VERDICT_ORDER = {Verdict.CERTIFIED: 0, Verdict.CONDITIONAL: 1, Verdict.NOT_CERTIFIED: 2}


def _finish_candidates(
    head: list[Certificate], cands: list[_Unfinished], stage: Stages
) -> list[Certificate | dict[str, Any]]:
    """The metric candidates, finished best-first; a candidate that cannot beat the best found
    is not designed (its summary, with the bound that ruled it out, takes its place).

    The candidates are finished in the order of :meth:`_Unfinished.key_lower_bound` (ties: the
    order given). With ``(K, i)`` the key and pool position (``head`` first) of the one
    :func:`_preference` chooses among those finished so far, candidate ``j`` with bound ``L``
    is skipped when ``L > K``, or ``L == K`` and ``j > i``: its key is ``>= L``, and ``min``
    keeps the first of equal keys, so it could not be chosen, and the choice among the rest is
    the choice among all (the chosen certificate is the one finishing every candidate gives).
    Deterministic: the bounds are functions of the inputs.
    """
    n0 = len(head)
    lows = [u.key_lower_bound() for u in cands]
    out: list[Certificate | dict[str, Any] | None] = [None] * len(cands)
    best: tuple[tuple[int, int, float], int] | None = None
    for i, c in enumerate(head):
        if best is None or _preference(c) < best[0]:
            best = (_preference(c), i)
    for j in sorted(range(len(cands)), key=lambda j: (lows[j], j)):
        u, low = cands[j], lows[j]
        designs = u.l1 is not None and u.l1.designs
        if designs and best is not None and (low, n0 + j) > (best[0], best[1]):
            out[j] = _skipped_summary(u, low, best[0])
            continue
        if u.change is not None:
            stage(f"finishing the candidate in z = Theta x (cond Theta {u.change.cond:.3g})")
        cert = _finish(u)
        out[j] = cert
        key = _preference(cert)
        if best is None or (key, n0 + j) < (best[0], best[1]):
            best = (key, n0 + j)
    return [c for c in out if c is not None]


def _skipped_summary(
    u: _Unfinished, low: tuple[int, int, float], best: tuple[int, int, float]
) -> dict[str, Any]:
    """The summary of a candidate not designed: what it has, and the bound that ruled it out."""
    assert u.change is not None and u.l1 is not None
    rt = u.rho_tasil_x()
    lo_l1 = 0.0 if isinstance(u.l1.inputs, L1Section) else u.l1.inputs.rho_lower_bound()
    return {
        "coordinates": "z = Theta x",
        "verdict": "skipped",
        "expert_rate": json_float(u.c.expert.euclidean.rate),
        "cond_theta": json_float(u.change.cond),
        "rho_tasil_x": json_float(rt) if rt is not None else None,
        "rho_l1_x": None,
        "rho_l1_x_at_least": json_float(mul_down(u.change.to_x, lo_l1)),
        "factor_to_x": u.change.to_x,
        "failing": low[1],
        "verdict_reasons": [
            "not designed: its L1-DRAC design could not make it the choice. Before the design "
            f"its verdict is at best {_VERDICT_NAMES[low[0]]} with {low[1]} failing checks, "
            f"and rho_TaSIL + rho_L1 >= {low[2]:.6g} in x (rho_L1 >= {lo_l1:.6g} in z for any "
            "design: L1-DRAC (16a), (16b), (21a) at any omega, bounds/l1drac/lower.py); a "
            f"certificate finished before it has verdict {_VERDICT_NAMES[best[0]]}, {best[1]} "
            f"failing checks, rho {best[2]:.6g} in x"
        ],
    }


_VERDICT_NAMES = {v: k.value for k, v in _VERDICT_ORDER.items()}


def _preference(c: Certificate) -> tuple[int, int, float]:
    """Better verdict first, then fewer checks that fail (or could not be evaluated), then the
    smaller radius in x: the sum of the finite radii that exist (``rho_TaSIL``, ``rho_L1``), inf
    when none is finite."""
    failing = sum(1 for a in c.assumptions if not a.holds)
    parts = [v for v in (c.rho_tasil, c.rho_l1) if v is not None and math.isfinite(v)]
    rho = up(sum(parts)) if parts else math.inf
    return _VERDICT_ORDER[c.verdict], failing, rho


def _summary(c: Certificate) -> dict[str, Any]:
    return {
        "coordinates": "x" if c.coordinates is None else "z = Theta x",
        "verdict": c.verdict.value,
        "expert_rate": json_float(c.contraction_expert.euclidean.rate),
        "cond_theta": None if c.coordinates is None else json_float(c.coordinates.cond),
        "rho_tasil_x": json_float(c.rho_tasil) if c.rho_tasil is not None else None,
        "rho_l1_x": json_float(c.rho_l1) if c.rho_l1 is not None else None,
        "factor_to_x": None if c.coordinates is None else c.coordinates.to_x,
        "failing": sum(1 for a in c.assumptions if not a.holds),
        "verdict_reasons": list(c.verdict_reasons),
    }


def _certify_in_metric(
    spec: Spec, change: CoordinateChange, demonstrations: DemonstrationSet | None, stage: Stages
) -> Certificate:
    """The certificate of the equivalent system in ``z = Theta x``, labelled with ``change``."""
    return _finish(_prepare_in_metric(spec, change, demonstrations, stage))


def _prepare_in_metric(
    spec: Spec, change: CoordinateChange, demonstrations: DemonstrationSet | None, stage: Stages
) -> _Unfinished:
    """:func:`_prepare_in` for the equivalent system in ``z = Theta x``."""
    zspec = spec.in_coordinates(change.theta)
    demos = demonstrations
    if demos is None and spec.system.learned is not None:
        from drip_cert.learn.imitation import demonstration_set  # jax: keep off the API's path

        demos = demonstration_set(spec.system, spec.settings.tasil)
    zdemos = None if demos is None else _demonstrations_in_z(demos, change)
    u = _prepare_in(zspec, zdemos, stage)
    return dataclasses.replace(u, change=change, x_system=spec.system)


def _demonstrations_in_z(demos: DemonstrationSet, change: CoordinateChange) -> DemonstrationSet:
    """The demonstrations as states of the z-system (inputs unchanged)."""
    from drip_cert.learn.data import Demonstrations  # jax: keep off the API's import path

    def one(d: Demonstrations | None) -> Demonstrations | None:
        if d is None:
            return None
        states = d.states @ change.theta.T
        return Demonstrations(
            times=d.times,
            states=states,
            actions=d.actions,
            x0=states[:, 0].copy(),
            source=f"{d.source} (mapped to z = Theta x)",
            integration_error=mul_up(change.to_z, d.integration_error),
        )

    train = one(demos.train)
    assert train is not None
    return dataclasses.replace(demos, train=train, heldout=one(demos.heldout))


def _certify_in(
    spec: Spec,
    demonstrations: DemonstrationSet | None,
    stage: Stages,
    expert: ContractionAnalysis | None = None,
) -> Certificate:
    """The certificate of ``spec`` in its own coordinates (see :func:`certify`): one call per
    part, in the order their checks, notes and skipped parts appear in the certificate
    (``expert``: the expert's contraction analysis when already computed)."""
    return _finish(_prepare_in(spec, demonstrations, stage, expert))


@dataclass(frozen=True)
class _Unfinished:
    """A certificate computed up to its L1-DRAC design (the costly part of a candidate)."""

    spec: Spec
    k: _Constants
    c: _ContractionPart
    a: _L1Assumptions
    d: _DeltaISSPart
    t: _TasilPart
    l1: _L1Prepared | None  #: None: no L1-DRAC part
    change: CoordinateChange | None = None  #: None: in the spec's own coordinates
    x_system: System | None = None  #: with ``change``: the system in x (of the fingerprint)

    def key_lower_bound(self) -> tuple[int, int, float]:
        """A lower bound, in the order of :func:`_preference`, on the finished certificate's
        key: adding the L1-DRAC check can only worsen the verdict and add failing checks; a
        failing design adds one (a larger key whatever the radius); a feasible one has
        ``rho_L1 >= `` :meth:`~drip_cert.bounds.l1drac.system.L1Inputs.rho_lower_bound`,
        mapped to x rounded down (``rho_L1`` in x is ``factor_to_x rho_L1(z)`` rounded up)."""
        checks = (*self.c.checks, *self.a.checks, *self.t.checks)
        v = _VERDICT_ORDER[verdict_of(checks)[0]]
        failing = sum(1 for ch in checks if not ch.holds)
        lo = 0.0
        if self.l1 is not None and not isinstance(self.l1.inputs, L1Section):
            lo = self.l1.inputs.rho_lower_bound()
            if self.change is not None:
                lo = mul_down(self.change.to_x, lo)
        rt = self.rho_tasil_x()
        parts = [v_ for v_ in (rt, lo) if v_ is not None and math.isfinite(v_)]
        return v, failing, sum_down(parts) if parts else 0.0

    def rho_tasil_x(self) -> float | None:
        """``rho_TaSIL`` in x (as :attr:`Certificate.rho_tasil` reports it)."""
        tasil = self.t.section
        if tasil is None or tasil.rho is None:
            return None
        v = float(tasil.rho)
        return v if self.change is None else self.change.gap_in_x(v)


def _prepare_in(
    spec: Spec,
    demonstrations: DemonstrationSet | None,
    stage: Stages,
    expert: ContractionAnalysis | None = None,
) -> _Unfinished:
    """Every part of the certificate of ``spec`` but the L1-DRAC design (:func:`_finish`)."""
    s, settings = spec.system, spec.settings
    k = _constants_part(s, settings, stage)
    c = _contraction_part(s, settings.contraction, k, stage, expert)
    a = _l1drac_assumptions(s, settings, k, c)
    d = _delta_iss_part(c, k)
    t = _tasil_part(s, settings, demonstrations, k, c, d, stage)
    l1 = _l1drac_prepare(s, settings, k, a, stage) if a.wanted else None
    return _Unfinished(spec, k, c, a, d, t, l1)


def _finish(u: _Unfinished) -> Certificate:
    """The certificate of a prepared candidate: its L1-DRAC design, then the assembly."""
    spec, k, c, a, d, t = u.spec, u.k, u.c, u.a, u.d, u.t
    s = spec.system
    l1 = _L1Part(None, (), ()) if u.l1 is None else _l1drac_finish(s, u.l1)
    cert = Certificate(
        system=s,
        assumptions=(*c.checks, *a.checks, *t.checks, *l1.checks),
        inputs=k.ic,
        uncertainty=k.uc,
        contraction_expert=c.expert,
        contraction_learned=c.learned,
        delta_iss=d.result,
        l1=l1.section,
        tasil=t.section,
        tasil_provenance=t.provenance,
        notes=(*spec.notes, *c.notes, *d.notes, *t.notes, *l1.notes),
        invariance=c.invariance,
        extra_quantities=(*([] if d.gamma0 is None else [d.gamma0]), *t.quantities),
        skipped=(*a.skipped, *t.skipped),
        fingerprint=fingerprint_of(s, _deployed_design(l1.section)),
    )
    if u.change is None:
        return cert
    assert u.x_system is not None
    fp = fingerprint_of(u.x_system, _deployed_design(cert.l1), u.change.theta)  # of x, not z
    return dataclasses.replace(cert, coordinates=u.change, fingerprint=fp)


@dataclass(frozen=True)
class _Constants:
    """The input and uncertainty constants and DRIP Assumption 1 (its scope not yet set)."""

    g_box: np.ndarray | None  #: the box of every sup ||g||, for a state-dependent g
    ic: InputConstants
    uc: UncertaintyConstants
    a1: Check


def _constants_part(s: System, settings: Settings, stage: Stages) -> _Constants:
    """The growth, Lipschitz and Hoelder bounds, and DRIP Assumption 1 on them."""
    stage("input and uncertainty constants (growth, Lipschitz, Hoelder bounds)")
    # a state-dependent g: every sup ||g|| over the box where the expert's rate is computed, the
    # set the trajectories must be proved to stay in (docs/math/contraction.md section 6)
    g_box = _g_box(s, settings.contraction)  # region validated at load (contains the support)
    ic = input_constants(s, g_box)
    uc = uncertainty_constants(s, settings.constants)
    a1_inputs = [ic.Delta_g, uc["Delta_mu"], uc["Delta_sigma"]]
    a1_finite = all(math.isfinite(q.value) for q in a1_inputs)
    a1 = Check.derive(
        "DRIP-A1",
        ic.rank.value == s.m and a1_finite,
        (
            f"g has full column rank m = {s.m} (smallest singular value >= "
            f"{ic.min_singular_value.value:.4g}, {ic.rank.how.value}); Delta_g = "
            f"{ic.Delta_g.value:.6g} (Frobenius), {ic.Delta_g_spectral.value:.6g} (spectral); "
            f"Delta_mu = {uc['Delta_mu'].value:.6g} ({uc['Delta_mu'].how.value}), "
            f"Delta_sigma = {uc['Delta_sigma'].value:.6g} ({uc['Delta_sigma'].how.value})"
            + ("" if a1_finite else "; a growth bound is not finite")
        ),
        inputs=[ic.rank, ic.min_singular_value, *a1_inputs],
        lhs=float(ic.rank.value),
        rhs=float(s.m),
        margin=ic.min_singular_value.value,
        source="DRIP Assumption 1",
    )
    return _Constants(g_box, ic, uc, a1)


@dataclass(frozen=True)
class _ContractionPart:
    """The contraction rates, the invariant set and DRIP Assumptions 1 (scoped) and 2."""

    expert: ContractionAnalysis
    learned: ContractionAnalysis | None  #: None without a learned policy
    invariance: InvariantSet | None
    lam_ex: Quantity  #: the expert's rate
    checks: tuple[Check, ...]  #: DRIP-A1, DRIP-A2
    notes: tuple[str, ...]


def _contraction_part(
    s: System,
    opts: ContractionSettings,
    k: _Constants,
    stage: Stages,
    expert: ContractionAnalysis | None = None,
) -> _ContractionPart:
    """The expert's rate, a forward-invariant set where it is used, the learned loop's rate
    (``expert``: the expert's analysis when already computed, else computed here)."""
    if expert is None:
        stage("contraction rate of the expert closed loop")
    ce = expert if expert is not None else analyse_contraction(s, "expert", opts)
    r = ce.euclidean
    stage("forward-invariant set (where the expert's rate is used)")
    inv = _invariance(s, r, k.g_box)
    a1 = k.a1 if k.g_box is None else k.a1.with_scope(*_g_scope(k.g_box, inv))
    a2 = _expert_a2(s, r, inv)
    lam_ex = r.to_quantity()
    notes: list[str] = []
    cl = None
    if s.learned is not None:
        stage("contraction rate of the learned closed loop")
        cl = _learned_contraction(s, opts, lam_ex, notes)
    return _ContractionPart(ce, cl, inv, lam_ex, (a1, a2), tuple(notes))


def _expert_a2(s: System, r: Any, inv: InvariantSet | None) -> Check:
    """DRIP Assumption 2 (the expert's rate), scoped to the trajectories it is used for."""
    a2 = _rate_check("DRIP-A2", r, "expert closed loop", "DRIP Assumption 2")
    return a2.with_scope(*_expert_scope(r, inv, s.horizon))


def _expert_rate_check(s: System, opts: ContractionSettings, ce: ContractionAnalysis) -> Check:
    """The certificate's DRIP-A2 check in the spec's own coordinates, from the expert's analysis
    alone (the same check :func:`_contraction_part` makes: its invariant set needs a rate that
    holds, so a failing check is computed without the constants)."""
    r = ce.euclidean
    inv = _invariance(s, r, _g_box(s, opts)) if r.holds else None
    return _expert_a2(s, r, inv)


def _unfinished_x_summary(
    ce: ContractionAnalysis, a2: Check, best: tuple[int, int, float] | None
) -> dict[str, Any]:
    """The summary of the spec's own coordinates when they were not finished: the expert's rate
    fails there (``a2``), so their verdict is ``not_certified`` whatever the other parts give, and
    a certificate in z (key ``best``) is better; ``failing`` counts the checks computed."""
    reason = verdict_of((a2,))[1]
    best_text = (
        ""
        if best is None
        else f"; the certificate chosen has verdict {_VERDICT_NAMES[best[0]]}, {best[1]} failing "
        f"checks, rho {best[2]:.6g} in x"
    )
    return {
        "coordinates": "x",
        "verdict": Verdict.NOT_CERTIFIED.value,
        "expert_rate": json_float(ce.euclidean.rate),
        "cond_theta": None,
        "rho_tasil_x": None,
        "rho_l1_x": None,
        "factor_to_x": None,
        "failing": 1,
        "verdict_reasons": [
            *reason,
            "not finished: with the expert's rate failing in x the verdict in x is not_certified "
            "whatever its other parts give, so its constants, TaSIL and L1-DRAC parts were not "
            "computed" + best_text,
        ],
    }


@dataclass(frozen=True)
class _L1Assumptions:
    """L1-DRAC Assumptions 2 (learned loop) and 7, or why the L1-DRAC part is skipped."""

    wanted: bool  #: an [l1drac] table and a g free of x
    source: ContractionAnalysis  #: L1-DRAC's nominal loop: the learned one, else the expert's
    checks: tuple[Check, ...]
    skipped: tuple[tuple[str, str, str], ...]


def _l1drac_assumptions(
    s: System, settings: Settings, k: _Constants, c: _ContractionPart
) -> _L1Assumptions:
    """The assumptions of the L1-DRAC layer on the contraction part (part of the verdict only
    when the L1-DRAC part is requested)."""
    wanted = "l1drac" in settings.present and k.g_box is None
    src = c.learned if c.learned is not None else c.expert
    checks: list[Check] = []
    skipped: list[tuple[str, str, str]] = []
    if c.learned is not None and wanted:
        rl = c.learned.euclidean
        a2l = _rate_check(
            "L1DRAC-A2",
            rl,
            "learned closed loop (the nominal system of the L1-DRAC layer)",
            "L1-DRAC Assumption 2",
        )
        checks.append(a2l.with_scope(*_sde_scope(rl.scope, s.horizon)))
    if wanted:
        a7 = _unmatched_check(src.euclidean.to_quantity(), k.ic, k.uc)
        checks.append(a7.with_scope(*_sde_scope(a7.scope, s.horizon)))
    elif k.g_box is not None:
        skipped.append(("l1drac", "not_applicable", G_X_L1_REASON))
    else:
        skipped.append(
            (
                "l1drac",
                "not_requested",
                "no [l1drac] table: the L1-DRAC part (rho_L1) was not computed; its assumptions "
                "(2 for the learned loop, 7) are reported under contraction and constants but "
                "are not part of the verdict; add an [l1drac] table to certify it",
            )
        )
    return _L1Assumptions(wanted, src, tuple(checks), tuple(skipped))


@dataclass(frozen=True)
class _DeltaISSPart:
    """The delta-ISS gain of the expert closed loop and ``gamma0`` (comparison lemma)."""

    result: DeltaISSResult | None
    gamma0: Quantity | None  #: None when the expert loop is not shown to contract
    notes: tuple[str, ...]


def _delta_iss_part(c: _ContractionPart, k: _Constants) -> _DeltaISSPart:
    """delta-ISS of the expert loop from its rate and ``Delta_g``."""
    if not c.expert.euclidean.holds:
        return _DeltaISSPart(
            None, None, ("no delta-ISS gain: the expert closed loop is not shown to contract",)
        )
    try:
        diss = delta_iss(c.lam_ex, k.ic.Delta_g, k.ic.Delta_g_spectral)
    except AssumptionViolation as exc:  # pragma: no cover - guarded by r.holds
        return _DeltaISSPart(None, None, (str(exc),))
    gamma0 = _input_gain(
        "gamma0", k.ic.Delta_g_spectral, c.lam_ex, "delta-ISS gain (comparison lemma)"
    )
    return _DeltaISSPart(diss, gamma0, ())


@dataclass(frozen=True)
class _TasilPart:
    """The TaSIL section, its check, and the quantities it rests on (``gamma0`` apart)."""

    section: TasilCertificate | None
    provenance: Mapping[str, Any]
    quantities: tuple[Quantity, ...]
    checks: tuple[Check, ...]
    skipped: tuple[tuple[str, str, str], ...]
    notes: tuple[str, ...]


def _tasil_part(
    s: System,
    settings: Settings,
    demonstrations: DemonstrationSet | None,
    k: _Constants,
    c: _ContractionPart,
    d: _DeltaISSPart,
    stage: Stages,
) -> _TasilPart:
    """``rho_TaSIL`` (always computed when a learned policy exists; docs/math/tasil.md 3-4)."""
    notes: list[str] = []
    lam_ex = c.lam_ex
    if s.learned is None:
        why = (
            "no learned policy ([policy] learned or [tasil] policy): there is no imitation "
            "gap to bound"
        )
        return _TasilPart(None, {}, (), (), (("tasil", "not_applicable", why),), ())
    if "tasil" not in settings.present:
        notes.append(
            "no [tasil] table: the TaSIL part is computed with the default settings "
            f"({_tasil_defaults_text(settings.tasil)})"
        )
    gamma0 = d.gamma0
    if gamma0 is None:
        # no bound on the imitation gap without the expert's contraction: the part fails
        fail = Check.derive(
            "TaSIL",
            False,
            "rho_TaSIL not computed: the expert closed loop is not shown to contract (DRIP "
            "Assumption 2), so there is no delta-ISS gain to carry the policy error",
            inputs=[lam_ex],
            source="DRIP Theorem thm:TaSIL",
        )
        return _TasilPart(None, {}, (), (fail,), (), tuple(notes))
    from drip_cert.bounds.tasil.section import (  # jax: keep off the API's import path
        tasil_section,
    )
    from drip_cert.learn.imitation import (  # jax: keep off the API's import path
        demonstration_set,
    )

    r, inv, cl, ic = c.expert.euclidean, c.invariance, c.learned, k.ic
    st = settings.tasil
    stage("TaSIL section (demonstrations, h0 and h1 along them, the bound)")
    demos = demonstration_set(s, st) if demonstrations is None else demonstrations
    train, held = demos.train, demos.heldout
    room = math.inf if inv is None else (inv.room if inv.proved else math.inf)
    # the comparison bound needs the learned loop to contract on all of R^n, proved
    cmp_gain = None
    if cl is not None and cl.euclidean.holds and cl.euclidean.scope.all_x:
        lam_il = cl.euclidean.to_quantity()
        if lam_il.how != How.ESTIMATE and lam_il.value > 0:
            cmp_gain = _input_gain(
                "gamma_IL",
                ic.Delta_g_spectral,
                lam_il.renamed("lambda_learned"),
                "comparison bound of the learned loop on [0, T] (docs/math/tasil.md 3.7)",
                horizon=s.horizon,
            )
    uniform_h0 = tube = None
    if cmp_gain is not None:
        stage("sup of ||pi_IL - pi*|| over a set holding every expert trajectory")
        uniform_h0, S_inv = _uniform_h0(s, r, inv, notes)
        if cl is not None:
            stage("the same sup along the expert's contraction tube (TaSIL section 3.10)")
            tube = expert_tube_bound(s, S_inv, r, cl.euclidean, ic.Delta_g_spectral, uniform_h0)
    tasil, tasil_prov, tq = tasil_section(
        s,
        train,
        held,
        gamma0,
        st,
        room=room,
        speed_sound=r.scope.all_x or (inv is not None and inv.proved),
        method=f"{st.method}-{st.order}",
        comparison_gain=cmp_gain,
        uniform_h0=uniform_h0,
        tube=tube,
        expert_set=lambda: _expert_set(s, r, inv),
    )
    quantities = tuple(q for q in tq if q.name != "gamma0")
    ok = tasil.rho is not None and math.isfinite(tasil.rho)
    # why rho is infinite: the lemma's failure, else the failing form's own reason
    why = tasil.gap_reason or next(
        (f"{f.name}: {f.note}" for f in tasil.forms if f.name == tasil.rho_form), ""
    )
    tcheck = Check.derive(
        "TaSIL",
        ok,
        "rho_TaSIL = "
        + (f"{tasil.rho:.6g}" if ok else "inf")
        + f" ({tasil.rho_form}); deterministic gap bound over the given initial "
        f"states {tasil.gap_bound:.6g}" + ("" if ok or not why else f"; {why}"),
        inputs=[gamma0, *quantities, lam_ex],
        method=How.SOUND,
        lhs=float(tasil.rho) if ok else math.inf,
        rhs=math.inf,
        source="docs/math/tasil.md sections 3-4 (this project's construction)",
    )
    scope_ok, scope_why = _tasil_scope(r, inv, tasil, s.horizon, k.g_box)
    if scope_ok and not tasil_prov.get("L_Delta_covers_support", True):
        scope_ok, scope_why = False, str(tasil_prov["L_Delta_cover"])
    checks = (tcheck.with_scope(scope_ok, scope_why),)
    return _TasilPart(tasil, tasil_prov, quantities, checks, (), tuple(notes))


@dataclass(frozen=True)
class _L1Part:
    """The L1-DRAC section (constants, design verified in Arb, ``rho_L1``, ``rho_sde``)."""

    section: L1Section | None
    checks: tuple[Check, ...]  #: L1DRAC-design
    notes: tuple[str, ...]


@dataclass(frozen=True)
class _L1Prepared:
    """The L1-DRAC part up to its design: the rate it rests on, the constants and request (or
    a section without a design when there can be none), the notes."""

    lam: Quantity
    inputs: L1Inputs | L1Section
    notes: tuple[str, ...]

    @property
    def designs(self) -> bool:
        """Whether finishing runs the designer (the costly part)."""
        return not isinstance(self.inputs, L1Section)


def _l1drac_part(
    s: System, settings: Settings, k: _Constants, a: _L1Assumptions, stage: Stages
) -> _L1Part:
    """The L1-DRAC design on the rate of its nominal loop (L1-DRAC (16), (21), (24))."""
    return _l1drac_finish(s, _l1drac_prepare(s, settings, k, a, stage))


def _l1drac_prepare(
    s: System, settings: Settings, k: _Constants, a: _L1Assumptions, stage: Stages
) -> _L1Prepared:
    """The L1-DRAC constants on the rate of its nominal loop, and the design request."""
    stage("L1-DRAC constants, design and its verification in Arb")
    src = a.source
    notes: list[str] = []
    lam_q = src.euclidean.to_quantity()
    est = -src.euclidean.max_mu_sampled
    # a sampled rate below float resolution (e.g. 5e-324 for a loop with mu_2 = 0 exactly) is
    # no evidence of contraction: no design on it (it also underflows the designer's logs)
    if lam_q.value <= 0 and est > EST_RATE_FLOOR:
        # the rigorous route did not establish contraction but sampling suggests it: design
        # with the estimate, labelled so; the L1DRAC-A2 check above stays failed
        lam_q = Quantity.derive(
            "lambda",
            est,
            inputs=[lam_q],
            method=How.ESTIMATE,
            source=lam_q.source,
            note="sampled estimate of the rate (the sound bound did not establish "
            "contraction): the L1-DRAC design below is conditional on it",
        )
        notes.append(
            "the L1-DRAC design uses a sampled estimate of the contraction rate of "
            f"the {src.policy} closed loop ({est:.6g}); it is not certified"
        )
    inputs = l1_inputs(
        s,
        settings.l1drac,
        settings.constants,
        lam_q,
        lam_q.scope.all_x,
        src.policy,
        {q.name: q for q in k.ic.quantities()},
        k.uc.values,
    )
    return _L1Prepared(lam_q, inputs, tuple(notes))


def _l1drac_finish(s: System, prep: _L1Prepared) -> _L1Part:
    """The L1-DRAC design of prepared inputs (verified in Arb) and its check."""
    lam_q, notes = prep.lam, prep.notes
    l1 = prep.inputs if isinstance(prep.inputs, L1Section) else design_section(prep.inputs)
    design_inputs = list(l1.constants.values())
    design_values = l1.design.to_dict() if l1.design is not None else {}
    dcheck = Check.derive(
        "L1DRAC-design",
        l1.feasible,
        (
            (
                "conditional on the ESTIMATED rate lambda = " + f"{lam_q.value:.6g}: "
                if lam_q.how == How.ESTIMATE
                else ""
            )
            + (
                "feasible design: "
                + ", ".join(
                    f"{key} = {design_values[key]:.6g}"
                    for key in ("omega", "lambda_s", "Ts", "rho_r", "rho_a", "rho")
                )
                if l1.feasible
                else "no feasible design: "
                + (l1.design.reason if l1.design is not None else l1.error)
            )
        ),
        inputs=design_inputs,
        source="L1-DRAC (16), (21), (24)",
    )
    return _L1Part(l1, (dcheck.with_scope(*_sde_scope(dcheck.scope, s.horizon)),), notes)


def _unmatched_check(lam_l1: Quantity, ic: InputConstants, uc: UncertaintyConstants) -> Check:
    """L1-DRAC Assumption 7: ``lambda > Delta_g_perp * max(Delta_mu_perp, L_mu_perp)``."""
    dgp = ic.Delta_g_perp
    mu_perp, l_perp = uc["Delta_mu_perp"], uc["L_mu_perp"]
    mperp = Quantity.derive(
        "max(Delta_mu_perp, L_mu_perp)",
        _nan_max(mu_perp.value, l_perp.value),
        inputs=[mu_perp, l_perp],
    )
    rhs7 = Quantity.derive(
        "Delta_g_perp * max(Delta_mu_perp, L_mu_perp)",
        mul_up(dgp.value, mperp.value),
        inputs=[dgp, mperp],
    )
    return Check.compare(
        "L1DRAC-A7",
        rhs7,
        lam_l1,
        f"unmatched small gain: lambda = {lam_l1.value:.6g} > Delta_g_perp * max(Delta_mu_perp, "
        f"L_mu_perp) = {dgp.value:.6g} * {mperp.value:.6g} = {rhs7.value:.6g}",
        strict=True,
        source="L1-DRAC Assumption 7",
    )


def _tasil_defaults_text(st: Any) -> str:
    """The TaSIL settings a certificate without a ``[tasil]`` table uses, as text."""
    return (
        f"n = {st.trajectories} demonstrations, heldout = {st.heldout}, k = {st.samples} samples, "
        f"delta = {st.delta:g}, seed = {st.seed}; add a [tasil] table to change them"
    )


def _deployed_design(l1: Any) -> tuple[float, float, float] | None:
    """``(omega, lambda_s, T_s)`` the deployed controller runs (``None``: no feasible design)."""
    if l1 is None or not l1.feasible:
        return None
    d = l1.design
    return (float(d.omega), float(d.lambda_s), float(d.Ts))


def _learned_contraction(
    s: System, opts: ContractionSettings, lam_ex: Quantity, notes: list[str]
) -> ContractionAnalysis:
    """The learned loop's rate: first the global routes for loops affine in MLP blocks
    (:mod:`drip_cert.analysis.contraction.learned_loop`; L1-DRAC needs all of R^n), then, when they
    prove
    nothing, the configured route on the contraction region (a box result)."""
    reasons: list[str] = []
    obstructions: list[TraceObstruction] = []
    g = best_global_rate(s, lam_ex, reasons, obstructions)
    notes.extend(f"learned closed loop: {r}" for r in reasons)
    if g is not None and g.result.holds and g.result.how != How.ESTIMATE:
        notes.append(
            f"learned closed loop: rate {g.result.rate:.6g} proved on all x by the "
            f"{g.result.method} route ({g.result.note})"
        )
        return ContractionAnalysis("learned", g.result, None)
    if g is not None:
        notes.append(
            f"learned closed loop: the global {g.result.method} route gives {g.result.rate:.6g} "
            f"(not a contraction: {g.result.note}); the box route follows"
        )
    box = analyse_contraction(s, "learned", opts)
    return dataclasses.replace(box, obstruction=obstructions[0]) if obstructions else box


def _expert_set(
    s: System, r: Any, inv: InvariantSet | None, equilibrium_ball: bool = True
) -> tuple[np.ndarray | None, str]:
    """A box ``S`` proved to hold every expert trajectory from the support on ``[0, T]``: the
    support itself when it is forward invariant (Nagumo, docs/math/contraction.md 7.2), else the
    box around a proved invariant ball, else (``equilibrium_ball``) the box around the ball
    ``||x|| <= max_support ||x||`` when the rate holds for all x and ``x = 0`` is an equilibrium
    of the expert loop; ``(None, why)`` when none is proved.

    Nagumo's condition gives one solution that stays in the support; *every* solution does when
    solutions are unique, which the expert's proved rate gives on the set where it holds: for all
    x, or on a box ``B`` holding the support in its interior (a second solution from the same
    state coincides with the first while both are in the convex ``B``, by the one-sided Lipschitz
    bound; it would have to reach the boundary of ``B`` at a point of the support, which lies in
    the interior: it never leaves). A rate on a box that the support touches does not suffice."""
    support = np.asarray(s.support, dtype=float)
    enclose = block_enclose_callback(s.blocks) if s.blocks else None
    if (
        r.holds
        and r.how.proved
        and r.scope.covers_time(s.horizon)
        and (r.scope.all_x or _in_interior(support, r.scope.box))
    ):
        try:
            if invariant_box(s.closed_loop("expert"), s.states, s.t, support, s.horizon, enclose):
                return support, "the support (forward invariant for the expert, Nagumo)"
        except DripCertError:
            pass
    if inv is not None and inv.proved and inv.centre:
        c = np.asarray(inv.centre, dtype=float)
        box = np.stack([c - inv.radius, c + inv.radius], axis=1)
        return box, f"the box around the expert's invariant ball (radius {inv.radius:.4g})"
    global_rate = r.holds and r.how.proved and r.scope.all_x and r.scope.covers_time(s.horizon)
    if equilibrium_ball and global_rate:
        F = s.closed_loop("expert")
        at_zero = F.subs({x: 0 for x in s.states})
        if all(sp.simplify(e) == 0 for e in at_zero):
            # x = 0 is a trajectory of the expert loop and the Euclidean rate holds for all x and
            # t: ||x(t)|| <= e^{-lambda t} ||x(0)|| <= the largest corner norm of the support
            rho = _corner_norm_up(support)
            box = np.array([[-rho, rho]] * s.n)
            return box, (
                f"the ball ||x|| <= {rho:.4g} around the expert's equilibrium x = 0 (the "
                "largest norm on the support; the rate holds for all x)"
            )
    return None, (
        "the support is not proved forward invariant and no invariant ball is proved"
        + ("" if inv is None else f": {inv.reason}")
    )


def _in_interior(inner: np.ndarray, outer: Any) -> bool:
    """Whether the box ``inner`` lies in the interior of the box ``outer`` (strictly inside on
    every side)."""
    o = np.asarray(outer, dtype=float)
    return bool(np.all(o[:, 0] < inner[:, 0]) and np.all(inner[:, 1] < o[:, 1]))


def _corner_norm_up(box: np.ndarray) -> float:
    """An upper bound of ``max_{x in box} ||x||_2`` (the largest corner norm), checked exactly:
    the float returned squared is at least the exact rational sum of squares."""
    exact = sum(
        max(Fraction(float(lo)) ** 2, Fraction(float(hi)) ** 2) for lo, hi in np.asarray(box)
    )
    rho = math.sqrt(float(exact))
    while Fraction(rho) ** 2 < exact:
        rho = math.nextafter(rho, math.inf)
    return rho


def _uniform_h0(
    s: System, r: Any, inv: InvariantSet | None, notes: list[str]
) -> tuple[Quantity | None, np.ndarray | None]:
    """``sup_{x in S} ||pi_IL(x) - pi*(x)||`` (sound) over the box ``S`` of :func:`_expert_set`;
    ``None`` when no such set is proved or the difference is not affine in MLP blocks. Also
    returns ``S``."""
    # the sure forms keep the sets of the previous stop (the equilibrium ball is used only to
    # place L_Delta, where it costs nothing)
    S, why = _expert_set(s, r, inv, equilibrium_ball=False)
    if S is None:
        return None, None
    q = sup_policy_difference(s, S)
    if q is not None:
        notes.append(f"sup ||pi_IL - pi*|| over {why}: {q.note}")
    return q, S


def _nan_max(a: float, b: float) -> float:
    """``max(a, b)`` that propagates NaN (Python's ``max`` silently drops it)."""
    if math.isnan(a) or math.isnan(b):
        return math.nan
    return max(a, b)


def _time_ok(scope: Scope, horizon: float) -> tuple[bool, str]:
    if scope.covers_time(horizon):
        return True, ""
    return False, f"proved only for {scope.describe()}, not for t in [0, {horizon:g}]"


def _expert_scope(r: Any, inv: InvariantSet | None, horizon: float) -> tuple[bool, str]:
    """Is the expert's rate usable for the trajectories the certificate is about?"""
    ok, why = _time_ok(r.scope, horizon)
    if not ok:
        return ok, why
    if r.scope.all_x:
        return True, "the rate holds for all x"
    if inv is not None and inv.proved:
        return True, inv.reason
    return False, (
        f"the expert rate is proved only on {r.region}"
        + (f"; {inv.reason}" if inv is not None else "")
    )


def _input_gain(
    name: str, g_norm: Quantity, lam: Quantity, source: str, horizon: float | None = None
) -> Quantity:
    """``sup||g||_2 / lambda`` rounded up: the gain from an input-space disturbance to the state
    gap of a loop contracting at ``lambda`` (the comparison lemma); labelled from its inputs.
    With ``horizon`` T: ``sup||g||_2 (1 - e^{-lambda T}) / lambda``, the gain on ``[0, T]``
    (docs/math/tasil.md section 3.7)."""
    if horizon is None:
        value, how = div_up(g_norm.value, lam.value), f"sup||g||_2 / {lam.name}"
    else:
        value = mul_up(g_norm.value, horizon_factor_up(lam.value, horizon))
        how = f"sup||g||_2 (1 - e^(-{lam.name} T)) / {lam.name}, T = {horizon:g}"
    return Quantity.derive(
        name, value, inputs=[g_norm, lam], source=source, note=f"{how}, rounded up"
    )


def _tasil_scope(
    r: Any, inv: InvariantSet | None, tasil: Any, horizon: float, g_box: np.ndarray | None = None
) -> tuple[bool, str]:
    """The TaSIL bound uses the rate along the learned trajectory: it must stay where the rate
    (and L_Delta) hold. With a proved invariant ball the lemma's tube condition (gap <= R, R
    below the ball's room) keeps it there. A state-dependent g (``g_box``) asks the same of a
    global rate: the gains use ``sup ||g||`` over ``g_box`` only."""
    ok, why = _expert_scope(r, inv, horizon)
    if not ok:
        return ok, why + "; the learned trajectories are not shown to stay in the box"
    if r.scope.all_x and g_box is None:
        return True, "the expert rate holds for all x; L_Delta on the tube of radius R"
    if inv is None or not inv.proved:
        return False, (
            "g depends on the state and sup ||g|| is taken over the box "
            f"{[[float(a), float(b)] for a, b in np.asarray(g_box)]}, but no forward-invariant "
            "set of the expert inside it is proved"
            + ("" if inv is None else f" ({inv.reason})")
            + ": the trajectories are not shown to stay where the gains hold; enlarge "
            "[contraction] region"
        )
    if not tasil.R < inv.room:
        return False, (
            f"{inv.reason}; it leaves no room inside the region where the rate is proved "
            f"(room {inv.room:.6g}), so the lemma's tube of radius R = {tasil.R:.6g} does not keep "
            "the learned trajectories there: enlarge [contraction] region, or prove the rate for "
            "all x"
        )
    return True, (
        f"{inv.reason}; the lemma's tube radius R = {tasil.R:.6g} is below that room, so the "
        "learned trajectories stay in the box (first-exit argument)"
    )


G_X_L1_REASON = (
    "the input operator g depends on the state; L1-DRAC's theory (its adaptation law, filter and "
    "Theorem 4.1) needs g(t), so rho_L1 is not computed and the certificate covers the "
    "contraction and TaSIL parts only; docs/recipes.md shows input transformations that make g "
    "depend on t only"
)
"""Why the L1-DRAC part is ``not_applicable`` for a state-dependent g."""


def _g_box(s: System, opts: ContractionSettings) -> np.ndarray | None:
    """The box every ``sup ||g||`` of a state-dependent g is taken over: the box where the
    expert's rate is computed (``[contraction] region``, else the support); ``None`` for g(t)."""
    if not s.g_depends_on_x:
        return None
    return np.array(opts.region if opts.region is not None else s.support, dtype=float)


def _g_scope(g_box: np.ndarray, inv: InvariantSet | None) -> tuple[bool, str]:
    """Is ``sup ||g||`` (and the rank of g) over ``g_box`` usable for the trajectories?"""
    box = [[float(a), float(b)] for a, b in g_box]
    if inv is not None and inv.proved:
        return True, f"g depends on the state: its bounds hold on {box}; {inv.reason}"
    return False, (
        f"g depends on the state: its bounds hold on {box} only, and no forward-invariant set "
        "of the expert inside it is proved" + ("" if inv is None else f" ({inv.reason})")
    )


def _sde_scope(scope: Scope, horizon: float) -> tuple[bool, str]:
    ok, why = _time_ok(scope, horizon)
    if not ok:
        return ok, why
    if scope.all_x:
        return True, "holds for all x"
    return False, _SDE_REASON.format(scope=scope.describe())
