"""Validation of a certificate by Monte-Carlo simulation of the true system.

:func:`validate` simulates the four processes of the DRIP paper for a system with its learned
policy (:mod:`drip_cert.validate.scenarios`) and compares every certified number with its
empirical counterpart (:mod:`drip_cert.validate.checks`, whose docstring states what is compared
with what). The result is a typed, frozen :class:`ValidationReport`.

When the certified ``T_s`` is too small to simulate (more than :data:`MAX_STEPS` steps), the run
is made at a practical ``T_s`` and every check that involves the L1-DRAC parameters is
``not_checked`` ("not at certified parameters"): such results never validate the certificate; a
short run of :data:`SHORT_STEPS` steps at the certified ``T_s`` is added when it is simulable.
"""

from __future__ import annotations

import math
from collections.abc import Mapping
from dataclasses import dataclass, field, replace
from pathlib import Path
from typing import TYPE_CHECKING, Any

from drip_cert.bounds.certificate import certify
from drip_cert.errors import SpecError
from drip_cert.model.system import System
from drip_cert.provenance import ValidationStatus, split_timings
from drip_cert.spec.load import SpecSource, as_spec
from drip_cert.spec.settings import SimSettings
from drip_cert.validate.checks import (
    HOLDS,
    NOT_CHECKED,
    NOTHING_CHECKED,
    VIOLATED,
    EmpiricalCheck,
    GapEvidence,
    checks_from_result,
    claim_arguments,
    overall_status,
    total_tail_claim,
    uncertainty_gap_name,
)
from drip_cert.validate.scenarios import (
    MAX_STEPS,
    MIN_SIMULABLE_TS,
    SHORT_PATHS,
    SHORT_STEPS,
    dtype_effect,
    has_known_diffusion,
    run_scenarios,
)

if TYPE_CHECKING:
    from drip_cert.bounds.certificate import Certificate
    from drip_cert.sim.result import SimResult

__all__ = [
    "VALIDATION_SCHEMA_VERSION",
    "ShortHorizonRun",
    "ValidationReport",
    "validate",
]

VALIDATION_SCHEMA_VERSION = 2
"""2: the embedded certificate in layout 4; wall-clock fields under ``timings``."""
"""Version of :meth:`ValidationReport.to_dict`'s layout (described by
``drip_cert/schema/validation.schema.json``; adding a key needs no bump, removing, renaming or
retyping one does)."""


@dataclass(frozen=True)
class ShortHorizonRun:
    """A short run at the certified L1-DRAC parameters (when the main run cannot be at them)."""

    horizon: float
    paths: int
    checks: tuple[EmpiricalCheck, ...]
    note: str

    @property
    def status(self) -> ValidationStatus:
        """``violated`` / ``holds`` / ``nothing_checked`` over its checks."""
        return overall_status(self.checks)

    def to_dict(self) -> dict[str, Any]:
        return {
            "horizon": self.horizon,
            "paths": self.paths,
            "checks": [c.to_dict() for c in self.checks],
            "note": self.note,
            "status": self.status,
        }


@dataclass(frozen=True)
class ValidationReport:
    """The validation of one certificate: checks, empirical gaps, notes and the simulation.

    ``status`` is ``violated`` when a check (of the main or the short run) is violated, else
    ``holds`` when at least one holds, else ``nothing_checked``; ``holds`` is
    ``status == "holds"``. ``result`` is the :class:`~drip_cert.sim.result.SimResult` (not part
    of :meth:`to_dict`; save it with ``result.save``), or the
    :class:`~drip_cert.validate.data.DataResult` of recorded data.
    """

    checks: tuple[EmpiricalCheck, ...]
    short_horizon: ShortHorizonRun | None
    certificate: Certificate
    empirical: Mapping[str, Any]
    at_certified_parameters: bool
    horizon: float
    certified_horizon: float
    l1_parameters: Mapping[str, float]
    diverged_fraction: Mapping[str, float]
    notes: tuple[str, ...]
    result: GapEvidence = field(repr=False, compare=False)

    @property
    def all_checks(self) -> tuple[EmpiricalCheck, ...]:
        """The main run's checks, then the short run's."""
        return self.checks + (self.short_horizon.checks if self.short_horizon else ())

    @property
    def status(self) -> ValidationStatus:
        return overall_status(self.all_checks)

    @property
    def holds(self) -> bool:
        return self.status == HOLDS

    @property
    def simulation(self) -> SimResult:
        """``result`` of a simulated validation (a :class:`SpecError` for recorded data, which
        have no simulation to save or plot)."""
        from drip_cert.sim.result import SimResult  # jax: keep off the API's import path

        if not isinstance(self.result, SimResult):
            raise SpecError("this validation checked recorded data: it has no simulation")
        return self.result

    @property
    def unfingerprinted_data(self) -> bool:
        """Whether this validates recorded data that carry no fingerprint (accepted unverified
        by ``accept_unfingerprinted``; a simulation is never unfingerprinted)."""
        data = getattr(self.result, "data", None)  # DataResult.data: the recorded data
        return data is not None and data.fingerprint is None

    @property
    def counts(self) -> dict[str, int]:
        """Number of checks per status (main and short run)."""
        every = self.all_checks
        return {st: sum(c.status == st for c in every) for st in (HOLDS, VIOLATED, NOT_CHECKED)}

    def with_notes_before(self, notes: tuple[str, ...] | list[str]) -> ValidationReport:
        """The same report with ``notes`` put before its own."""
        return replace(self, notes=tuple(notes) + self.notes)

    def to_dict(self) -> dict[str, Any]:
        """JSON-ready report (the keys of the ``validation.json`` file)."""
        out = {
            "schema_version": VALIDATION_SCHEMA_VERSION,
            "status": self.status,
            "holds": self.holds,
            "counts": self.counts,
            "certificate": self.certificate.to_dict(),
            "empirical": dict(self.empirical),
            "checks": [c.to_dict() for c in self.checks],
            "at_certified_parameters": self.at_certified_parameters,
            "horizon": self.horizon,
            "certified_horizon": self.certified_horizon,
            "short_horizon_at_certified_parameters": (
                None if self.short_horizon is None else self.short_horizon.to_dict()
            ),
            "l1_parameters": dict(self.l1_parameters),
            "diverged_fraction": dict(self.diverged_fraction),
            "simulation": self.result.to_dict(),
            "notes": list(self.notes),
        }
        out["timings"] = split_timings(out)  # the certificate keeps its own under its key
        return out


def validate(
    s: SpecSource,
    cert: Any = None,
    sim: SimSettings | None = None,
    *,
    paths: int,
    seed: int,
    practical_ts: float | None = None,
    horizon: float | None = None,
    progress: bool = False,
    run_dir: Path | None = None,
    backend: Any = None,
    policy_dtype: str = "float64",
    dtype: str = "float64",
) -> ValidationReport:
    """Validate certificate ``cert`` of ``s`` (which must have a learned policy) by simulation.

    ``s`` is a :class:`~drip_cert.model.system.System`, a :class:`~drip_cert.spec.load.Spec` or
    a spec file's path (:func:`~drip_cert.spec.load.as_spec`); ``cert`` defaults to its
    certificate (computed here) and ``sim`` to its ``[simulation]`` settings. ``practical_ts``
    and ``horizon``, when given, must be finite and positive.
    ``backend`` (:class:`~drip_cert.sim.backend.Backend`, default local) runs the main
    simulation and changes no number. ``policy_dtype="float32"`` evaluates the learned policy
    of the main run in float32 (opt-in, faster); its effect on the gaps, measured on the first
    paths against float64, is then a note and ``empirical["policy_dtype_effect"]``;
    ``dtype="float32"`` runs the whole simulation in float32 (states, noise, vector fields,
    policy, L1-DRAC) and reports its effect as ``empirical["dtype_effect"]``.

    Returns
    -------
    ValidationReport
        The checks of the main run and of the short-horizon run at the certified parameters
        (when the main run is not at them), the empirical gaps, the notes and the simulation.
    """
    from drip_cert.control.l1drac import L1Params  # jax: keep off the API's import path

    spec = as_spec(s, argument="s")
    s = spec.system
    sim = spec.settings.simulation if sim is None else sim
    for name, value in (("practical_ts", practical_ts), ("horizon", horizon)):
        if value is not None and not (math.isfinite(value) and value > 0):
            raise SpecError(f"must be a finite number > 0 (seconds), got {value!r}", field=name)
    if s.learned is None:
        raise SpecError(
            "validation needs a learned policy (policy.learned, or train one with "
            "`drip-cert train`)",
            field="policy.learned",
        )
    if cert is None:
        cert = certify(spec, progress=progress)
    T = float(horizon or s.horizon)
    notes: list[str] = []
    coords = getattr(cert, "coordinates", None)
    x0_box, theta = None, None
    if coords is not None:
        # like with like: the certificate's bounds are about the system in z = Theta x; simulate
        # that system from the push-forward of the initial law (docs/math/contraction.md 5.3)
        x0_box, theta = s.support, coords.theta
        in_z: System = cert.system
        s = in_z
        notes.append(
            "simulated in the certificate's coordinates z = Theta x (the same law: the initial "
            "law pushed forward by Theta) and validated in the user's x: every gap is of "
            "x = Theta^{-1} z, compared with the bounds mapped back to x (factor_to_x = "
            f"{coords.to_x:.6g}, Proposition 5.3 of docs/math/contraction.md; tail thresholds "
            "kappa scaled by the same factor)"
        )
    design = cert.l1.design if (cert.l1 is not None and cert.l1.feasible) else None
    at_cert = False
    if design is not None:
        k = max(1, math.ceil(design.Ts / sim.dt))
        n_steps = math.floor(T / design.Ts) * k
        if 1 <= n_steps <= MAX_STEPS:
            at_cert = True
            dt = design.Ts / k
            # the grid must hit the horizon: simulate a whole number of periods T_s within T
            periods = recorded_periods(math.floor(T / design.Ts), k)
            if periods < math.floor(T / design.Ts):
                notes.append(
                    f"simulated {periods} periods T_s of {math.floor(T / design.Ts)} within T "
                    f"(the last {math.floor(T / design.Ts) - periods}: a step count with a "
                    "recording grid of at least "
                    f"{RECORDS_LEAST} times ending at the simulated horizon)"
                )
            T = periods * design.Ts
            params = L1Params(design.omega, design.lambda_s, design.Ts, dt)
        else:
            notes.append(
                f"the certified T_s = {design.Ts:.3g} s needs {n_steps:.3g} Euler steps per path "
                f"over T = {T:g} s (limit {MAX_STEPS}): simulated at a practical T_s instead; "
                "these results are NOT a validation of the certificate"
            )
    if not at_cert:
        ts = practical_ts or sim.Ts
        dt = min(sim.dt, ts)
        dt = ts / max(1, round(ts / dt))
        params = L1Params(sim.omega, sim.lambda_s, ts, dt)
        if design is None and not s.g_depends_on_x:
            notes.append(
                "no feasible L1-DRAC design is certified: the L1 run uses practical "
                "parameters and no uncertainty bound is checked"
            )
    # the bounds in the user's x (mapped back when the certificate is in z): the gaps are too
    c = cert.claims()
    why = "no feasible L1-DRAC design" if design is None else "practical T_s, see the notes"
    with_l1 = not s.g_depends_on_x
    if not with_l1:
        why = (
            "L1-DRAC is not applicable: g depends on the state (L1-DRAC needs g(t)); the true "
            "process is simulated without it"
        )
        notes.append(
            "g depends on the state: no L1-DRAC process is simulated; the L1-DRAC checks are "
            "not_checked and the uncertainty gaps shown are those of the true process without "
            "L1-DRAC (for information)"
        )
    kappas = _thresholds(c)
    record_every = record_stride(int(round(T / dt)))
    res = run_scenarios(
        s,
        paths=paths,
        seed=seed,
        dt=dt,
        T=T,
        l1_params=params,
        chunk_size=sim.chunk_size,
        record_every=record_every,
        kappas=kappas,
        p_max=max(4, 2 * c.p),  # E r^{4p} gives the variance of r^{2p} for the L_2p check
        w2_times=(T,),
        run_dir=run_dir,
        progress=progress,
        x0_box=x0_box,
        theta=theta,
        backend=backend,
        policy_dtype=policy_dtype,
        dtype=dtype,
    )
    if has_known_diffusion(s):
        notes.append(
            "known diffusion p != 0: the uncertainty gaps are measured against L1-DRAC's "
            "nominal process (4b), the learned closed loop with the known diffusion "
            "(scenario nominal_sde, driven by the true processes' Brownian path), not the ODE x'"
        )
    effect = None
    if policy_dtype != "float64" or dtype != "float64":
        # on this machine: ~2 x 1000 paths, less than a cluster's start-up and compile
        effect = dtype_effect(s, res, x0_box=x0_box, theta=theta)
        notes.append(effect.note())
    checks = checks_from_result(
        res,
        **claim_arguments(c),
        at_certified_l1=at_cert and with_l1,
        not_certified_why=why,
        with_l1=with_l1,
    )
    if T < s.horizon:
        cause = (
            "horizon shortened"
            if horizon is not None and horizon < s.horizon
            else "the largest multiple of the certified T_s"
        )
        notes.append(
            f"simulated horizon [0, {T:.6g}] s ends {s.horizon - T:.3g} s before the certified "
            f"T = {s.horizon:g} s ({cause}): the checks cover these times only (a violation "
            "found is still one)"
        )
    short = None
    if design is not None and not at_cert:
        if design.Ts >= MIN_SIMULABLE_TS:
            t_short = SHORT_STEPS * design.Ts
            sres = run_scenarios(
                s,
                paths=SHORT_PATHS,
                seed=seed,
                dt=design.Ts,
                T=t_short,
                l1_params=L1Params(design.omega, design.lambda_s, design.Ts, design.Ts),
                chunk_size=SHORT_PATHS,
                record_every=SHORT_STEPS // 100,
                kappas=kappas,
                p_max=max(4, 2 * c.p),
                x0_box=x0_box,
                theta=theta,
            )
            short_checks = checks_from_result(
                sres,
                **claim_arguments(c),
                policy=False,
            )
            short = ShortHorizonRun(
                horizon=t_short,
                paths=SHORT_PATHS,
                checks=tuple(short_checks),
                note=f"short horizon [0, {t_short:.3g}] s at the certified parameters",
            )
        else:
            notes.append(
                f"no short-horizon run at the certified T_s = {design.Ts:.3g} s either: "
                f"below {MIN_SIMULABLE_TS:g} s an Euler step is lost in float64 rounding"
            )
    emp: dict[str, Any] = {}
    for key, gap in (
        ("tig_max", "total_l1"),
        ("policy_ig_max", "policy"),
        ("uncertainty_ig_max", uncertainty_gap_name(res, with_l1)),
        ("tig_max_without_l1", "total_true"),
    ):
        if not with_l1 and gap == "total_l1":
            continue  # no L1-DRAC process for g(t, x): absent, the notes say why
        g = res.gap(gap)
        emp[key] = {
            "value": g.max_mean,
            "ci_low": g.max_ci_low,
            "ci_high": g.max_ci_high,
            "argmax_time": g.argmax_time,
        }
    emp["w2"] = [w.to_dict() for w in res.w2]
    if effect is not None:
        emp["dtype_effect" if effect.end_to_end else "policy_dtype_effect"] = effect.to_dict()
    notes.append(
        "W2 estimates from samples are biased upward (see the same-law baselines "
        "beside each); they are reported, not checked against a bound"
    )
    every = checks + (list(short.checks) if short is not None else [])
    if overall_status(every) == NOTHING_CHECKED:
        notes.insert(
            0,
            "nothing was checked: no finite certified bound could be compared at certified "
            "parameters (see each check's reason)",
        )
    return ValidationReport(
        checks=tuple(checks),
        short_horizon=short,
        certificate=cert,
        empirical=emp,
        at_certified_parameters=at_cert,
        horizon=T,
        certified_horizon=float(s.horizon),
        l1_parameters={
            "omega": params.omega,
            "lambda_s": params.lambda_s,
            "Ts": params.Ts,
            "dt": params.dt,
        },
        diverged_fraction={st.name: st.diverged_fraction for st in res.status},
        notes=tuple(notes),
        result=res,
    )


RECORDS_TARGET = 200
"""About this many recorded times per validation run: enough to locate ``max_t`` of a gap."""
RECORDS_MOST = 1000
"""At most this many: the recorded states of a chunk stay a few hundred MiB at 2000 paths."""
RECORDS_LEAST = 50
"""A grid with fewer records gives way to a slightly shorter horizon (:func:`recorded_periods`)."""
PERIODS_DROP_MOST = 0.01
"""At most this fraction of the periods ``T_s`` is dropped to reach :data:`RECORDS_LEAST`."""


def recorded_periods(periods: int, k: int) -> int:
    """The number of whole periods ``T_s`` to simulate (``k`` Euler steps each): ``periods``
    when its step count has a recording grid (:func:`record_stride`) of at least
    :data:`RECORDS_LEAST` times, else the largest count within :data:`PERIODS_DROP_MOST` of it
    that has one. A prime number of periods above :data:`RECORDS_MOST` with ``k = 1`` recorded
    only ``t = T``; the certificate holds on all of ``[0, T]``, so checking it on a horizon
    shorter by under 1 % with 50-1000 recorded times is a validation of the same claim on
    more times."""

    def n_records(m: int) -> int:
        return (m * k) // record_stride(m * k)

    if n_records(periods) >= min(RECORDS_LEAST, periods * k):
        return periods
    lowest = max(1, math.ceil(periods * (1.0 - PERIODS_DROP_MOST)))
    for m in range(periods - 1, lowest - 1, -1):
        if n_records(m) >= RECORDS_LEAST:
            return m
    return periods


def record_stride(n_steps: int) -> int:
    """Steps between recorded times: a divisor ``d`` of ``n_steps`` (the grid must end at ``T``)
    whose number of records ``n_steps / d`` is closest in ratio to :data:`RECORDS_TARGET` among
    those at most :data:`RECORDS_MOST`. A plain
    "largest divisor below the target" falls to tiny strides when ``n_steps`` has a large prime
    factor (285720 = 2^3 3 5 2381 gave 28572 records, 3.5 GiB of states at 2000 paths)."""
    divisors: set[int] = set()
    k = 1
    while k * k <= n_steps:
        if n_steps % k == 0:
            divisors.update((k, n_steps // k))
        k += 1
    fits = [d for d in divisors if n_steps // d <= RECORDS_MOST]
    # closest in ratio: 997 steps (a prime) keep all 997 records rather than one
    return min(fits, key=lambda d: (abs(math.log(n_steps / d / RECORDS_TARGET)), d))


def _thresholds(claims: Any) -> tuple[float, ...]:
    """Tail thresholds to simulate: ``kappa`` and the total tail's threshold
    (:func:`~drip_cert.validate.checks.total_tail_claim`) where finite."""
    out: list[float] = []
    kappa = claims.kappa
    if kappa is not None and math.isfinite(kappa) and kappa > 0:
        out.append(float(kappa))
        thr, _, _ = total_tail_claim(
            claims.rho_tasil,
            kappa,
            claims.delta_tasil,
            claims.delta_l1,
            claims.rho_sde,
            claims.p,
        )
        if thr is not None and math.isfinite(thr):
            out.append(thr)
    return tuple(dict.fromkeys(out))
