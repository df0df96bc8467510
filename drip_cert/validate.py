"""Validation: every certified number against Monte-Carlo simulation of the true system.

:func:`validate` simulates the four processes of the DRIP paper with
:func:`drip_cert.sim.engine.simulate` and compares

* the policy gap ``max_t E||x'_t - x*_t||`` with ``rho_TaSIL``,
* the uncertainty gap ``max_t E||X_t - x'_t||`` and its ``L_{2p}`` norm with ``rho_L1(p)``
  (L1-DRAC Theorem 4.1: ``||X_t - x'_t||_{L_2p} < rho_L1(p)``, and ``E|.| <= L_2p``),
* the tail frequency ``P(||X_t - x'_t|| >= kappa)`` with ``delta`` (L1-DRAC (130a)),
* the total gap ``max_t E||X_t - x*_t||`` with ``rho = rho_TaSIL + rho_L1`` (DRIP (TotalTIG)).

A violation is declared only when the one-sided lower confidence bound of the empirical quantity
(t interval for means, Clopper-Pearson for frequencies, at the engine's level) exceeds the bound;
the ratio ``bound / empirical`` is reported for every check, because a bound that holds but is
a thousand times too loose is a finding too. When the certified ``T_s`` is too small to simulate
(more than :data:`MAX_STEPS` steps), the run is made at a practical ``T_s`` and every result is
labelled "not at certified parameters": such results never validate the certificate.
"""

from __future__ import annotations

import math
from collections.abc import Mapping
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np

from drip_cert.errors import SpecError
from drip_cert.system.system import System

MAX_STEPS = 200_000  #: largest number of Euler steps per path accepted for a certified-T_s run
SHORT_STEPS = 2_000  #: steps of the short-horizon run at the certified T_s (dt = T_s)
SHORT_PATHS = 200  #: paths of the short-horizon run
MIN_SIMULABLE_TS = 1e-9
#: below this T_s an Euler step changes an O(1) state by less than ~1e-9 relative: with float64
#: (eps 2.2e-16) the drift of one step keeps fewer than 7 digits, and below ~1e-15 it is lost
#: entirely, so a run at such T_s says nothing about the certificate
PRACTICAL = {"omega": 50.0, "lambda_s": 10.0, "Ts": 0.01, "dt": 1e-3}
#: default practical L1-DRAC parameters (those of the authors' Julia examples, T_s = 10 dt)
SIM_KEYS = {"dt", "paths", "chunk_size", "omega", "lambda_s", "Ts", "record_every"}


@dataclass(frozen=True)
class SimSettings:
    """Validated ``[simulation]`` table: practical parameters for runs that cannot use the
    certified ones."""

    dt: float = PRACTICAL["dt"]
    paths: int = 1000
    chunk_size: int = 2048
    omega: float = PRACTICAL["omega"]
    lambda_s: float = PRACTICAL["lambda_s"]
    Ts: float = PRACTICAL["Ts"]
    record_every: int = 10

    @staticmethod
    def from_table(table: Mapping[str, Any]) -> SimSettings:
        extra = set(table) - SIM_KEYS
        if extra:
            raise SpecError(
                f"unknown key(s) {sorted(extra)}; allowed {sorted(SIM_KEYS)}", field="simulation"
            )
        kw: dict[str, Any] = {}
        for key in ("dt", "omega", "lambda_s", "Ts"):
            if key in table:
                v = table[key]
                if (
                    isinstance(v, bool)
                    or not isinstance(v, int | float)
                    or not v > 0
                    or not math.isfinite(v)
                ):
                    raise SpecError(
                        f"must be a finite number > 0, got {v!r}", field=f"simulation.{key}"
                    )
                kw[key] = float(v)
        for key in ("paths", "chunk_size", "record_every"):
            if key in table:
                v = table[key]
                if isinstance(v, bool) or not isinstance(v, int) or v < 1:
                    raise SpecError(
                        f"must be a positive integer, got {v!r}", field=f"simulation.{key}"
                    )
                kw[key] = int(v)
        return SimSettings(**kw)


def x0_sampler(box) -> Any:
    """Uniform initial law on the box ``D`` (jax key -> state)."""
    from drip_cert._jax import jax, jnp

    b = np.array(box, dtype=float)
    lo, hi = jnp.asarray(b[:, 0]), jnp.asarray(b[:, 1])

    def sample(key):
        return jax.random.uniform(key, (b.shape[0],), minval=lo, maxval=hi, dtype=jnp.float64)

    return sample


def _check(
    name: str,
    bound: float | None,
    stat_value: float,
    ci_low: float,
    ci_high: float,
    what: str,
    note: str = "",
) -> dict[str, Any]:
    if bound is None or not math.isfinite(bound):
        holds = True
        ratio = math.inf if bound is not None else None
        note = (note + "; " if note else "") + (
            "bound is vacuous (infinite)" if bound is not None else "no bound certified"
        )
    else:
        holds = not (ci_low > bound)
        ratio = bound / stat_value if stat_value > 0 else math.inf
    return {
        "name": name,
        "what": what,
        "bound": bound,
        "empirical": stat_value,
        "ci_low": ci_low,
        "ci_high": ci_high,
        "ratio": ratio,
        "holds": bool(holds),
        "note": note,
    }


def checks_from_result(
    res: Any,
    rho_tasil: float | None,
    rho_l1: float | None,
    rho_total: float | None,
    p: int,
    kappa: float | None,
    delta: float | None,
    with_l1: bool,
) -> list[dict[str, Any]]:
    """The validation checks of one simulation result against the certified numbers."""
    out = []
    pol = res.gap("policy")
    out.append(
        _check(
            "policy_gap",
            rho_tasil,
            pol.max_mean,
            pol.max_ci_low,
            pol.max_ci_high,
            "max_t E||x'_t - x*_t|| vs rho_TaSIL",
        )
    )
    unc = res.gap("uncertainty_l1" if with_l1 else "uncertainty_true")
    tot = res.gap("total_l1" if with_l1 else "total_true")
    out.append(
        _check(
            "uncertainty_gap",
            rho_l1,
            unc.max_mean,
            unc.max_ci_low,
            unc.max_ci_high,
            "max_t E||X_t - x'_t|| vs rho_L1(p)",
        )
    )
    if p <= unc.lp_norms.shape[0]:
        lp = unc.lp_norms[p - 1]
        i = int(np.nanargmax(lp))
        out.append(
            _check(
                f"uncertainty_L{2 * p}_norm",
                rho_l1,
                float(lp[i]),
                float(lp[i]),
                float(lp[i]),
                f"max_t (E||X_t - x'_t||^{2 * p})^(1/{2 * p}) vs rho_L1(p)",
                "point estimate (no confidence interval for moments)",
            )
        )
    if kappa is not None and delta is not None and unc.kappas:
        j = int(np.argmin(np.abs(np.array(unc.kappas) - kappa)))
        freq = unc.tail_freq[j]
        i = int(np.nanargmax(freq))
        n = max(unc.n, 1)
        # one-sided lower Clopper-Pearson bound for the violation test
        from scipy.stats import beta as _beta

        k = int(round(freq[i] * n))
        lower = float(_beta.ppf(1 - unc.level, k, n - k + 1)) if k > 0 else 0.0
        out.append(
            _check(
                "tail_frequency",
                delta,
                float(freq[i]),
                lower,
                float(unc.tail_upper[j][i]),
                f"max_t P(||X_t - x'_t|| >= kappa = {kappa:.4g}) vs delta",
            )
        )
    out.append(
        _check(
            "total_gap",
            rho_total,
            tot.max_mean,
            tot.max_ci_low,
            tot.max_ci_high,
            "max_t E||X_t - x*_t|| vs rho = rho_TaSIL + rho_L1",
        )
    )
    return out


def run_scenarios(
    s: System,
    *,
    paths: int,
    seed: int,
    dt: float,
    T: float,
    l1_params: Any,
    chunk_size: int,
    record_every: int,
    kappas: tuple[float, ...] = (),
    p_max: int = 4,
    w2_times: tuple[float, ...] = (),
    run_dir: Path | None = None,
    progress: bool = False,
):
    """Simulate the four scenarios of the DRIP paper for ``s`` (with its learned policy)."""
    from drip_cert.sim.engine import SimConfig, simulate

    cfg = SimConfig(
        T=T,
        dt=dt,
        n_paths=paths,
        seed=seed,
        chunk_size=min(chunk_size, paths),
        l1=l1_params,
        record_every=record_every,
        kappas=kappas,
        p_max=p_max,
        w2_times=w2_times,
        w2_points=min(2000, max(2, paths // 2)),
    )
    return simulate(s.sim_model(), cfg, x0_sampler(s.support), run_dir=run_dir, progress=progress)


def validate(
    s: System,
    cert: Any,
    sim: SimSettings,
    *,
    paths: int,
    seed: int,
    practical_ts: float | None = None,
    horizon: float | None = None,
    progress: bool = False,
    run_dir: Path | None = None,
) -> dict[str, Any]:
    """Validate certificate ``cert`` of ``s`` (which must have a learned policy) by simulation.

    Returns the JSON-ready report with the keys ``certificate``, ``empirical``, ``checks``,
    ``at_certified_parameters``, ``diverged_fraction`` and ``holds``.
    """
    from drip_cert.control.l1drac import L1Params

    if s.learned is None:
        raise SpecError(
            "validation needs a learned policy (policy.learned, or train one with "
            "`drip-cert train`)",
            field="policy.learned",
        )
    T = float(horizon or s.horizon)
    notes: list[str] = []
    design = cert.l1.design if (cert.l1 is not None and cert.l1.feasible) else None
    at_cert = False
    if design is not None:
        k = max(1, math.ceil(design.Ts / sim.dt))
        n_steps = math.floor(T / design.Ts) * k
        if 1 <= n_steps <= MAX_STEPS:
            at_cert = True
            dt = design.Ts / k
            # the grid must hit the horizon: simulate the largest multiple of T_s within T
            T = math.floor(T / design.Ts) * design.Ts
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
        if design is None:
            notes.append(
                "no feasible L1-DRAC design is certified: the L1 run uses practical "
                "parameters and no uncertainty bound is checked"
            )
    rho_l1 = cert.rho_l1 if at_cert else None
    rho_tasil = cert.rho_tasil
    rho_total = cert.rho if at_cert else None
    p = design.p if design is not None else 1
    kappa = design.kappa if (design is not None and at_cert) else None
    delta = design.delta if design is not None else None
    record_every = max(1, int(round(T / dt)) // 200)
    while int(round(T / dt)) % record_every:
        record_every -= 1
    res = run_scenarios(
        s,
        paths=paths,
        seed=seed,
        dt=dt,
        T=T,
        l1_params=params,
        chunk_size=sim.chunk_size,
        record_every=record_every,
        kappas=(kappa,) if kappa else (),
        p_max=max(4, p),
        w2_times=(T,),
        run_dir=run_dir,
        progress=progress,
    )
    checks = checks_from_result(res, rho_tasil, rho_l1, rho_total, p, kappa, delta, True)
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
                kappas=(design.kappa,) if design.kappa else (),
                p_max=max(4, p),
            )
            short = {
                "horizon": t_short,
                "paths": SHORT_PATHS,
                "checks": checks_from_result(
                    sres, None, cert.rho_l1, None, p, design.kappa, design.delta, True
                ),
                "note": f"short horizon [0, {t_short:.3g}] s at the certified parameters",
            }
        else:
            notes.append(
                f"no short-horizon run at the certified T_s = {design.Ts:.3g} s either: "
                f"below {MIN_SIMULABLE_TS:g} s an Euler step is lost in float64 rounding"
            )
    if not at_cert:
        for c in checks:
            c["note"] = (c["note"] + "; " if c["note"] else "") + "not at certified parameters"
    emp = {}
    for key, gap in (
        ("tig_max", "total_l1"),
        ("policy_ig_max", "policy"),
        ("uncertainty_ig_max", "uncertainty_l1"),
        ("tig_max_without_l1", "total_true"),
    ):
        g = res.gap(gap)
        emp[key] = {
            "value": g.max_mean,
            "ci_low": g.max_ci_low,
            "ci_high": g.max_ci_high,
            "argmax_time": g.argmax_time,
        }
    emp["w2"] = [w.to_dict() for w in res.w2]
    notes.append(
        "W2 estimates from samples are biased upward (see the same-law baselines "
        "beside each); they are reported, not checked against a bound"
    )
    return {
        "certificate": cert.to_dict(),
        "empirical": emp,
        "checks": checks,
        "at_certified_parameters": at_cert,
        "short_horizon_at_certified_parameters": short,
        "l1_parameters": {
            "omega": params.omega,
            "lambda_s": params.lambda_s,
            "Ts": params.Ts,
            "dt": params.dt,
        },
        "diverged_fraction": {st.name: st.diverged_fraction for st in res.status},
        "simulation": res.to_dict(),
        "holds": all(c["holds"] for c in checks)
        and (short is None or all(c["holds"] for c in short["checks"])),
        "notes": notes,
        "_result": res,
    }


def validate_spec(
    spec_path: str | Path,
    *,
    trajectories: int = 1000,
    seed: int = 0,
    out: str | Path | None = None,
    practical_ts: float | None = None,
    quick: bool = False,
    progress: bool = False,
) -> dict[str, Any]:
    """``drip-cert validate``: certify the spec's system and validate it by simulation.

    A spec without a learned policy gets one trained by TaSIL with its ``[tasil]`` settings.
    """
    from drip_cert.bounds.certificate import certify
    from drip_cert.learn.workflow import tasil_settings, train_on_system
    from drip_cert.system import load_spec
    from drip_cert.system.spec import Spec

    spec = load_spec(spec_path)
    s = spec.system
    notes = []
    if s.learned is None:
        st = tasil_settings(spec.table("tasil"))
        if quick:
            st = type(st)(**{**st.__dict__, "steps": min(st.steps, 300)})
        tp = train_on_system(s, st, progress=progress)
        s = tp.system
        notes.append(
            f"no learned policy in the spec: trained {st.method} ({st.steps} steps, "
            f"{st.trajectories} trajectories, seed {st.seed})"
        )
        spec = Spec(spec.path, s, spec.tables)
    cert = certify(spec)
    sim = SimSettings.from_table(spec.table("simulation"))
    paths = min(trajectories, 200) if quick else trajectories
    horizon = min(s.horizon, 2.0) if quick else None
    rep = validate(
        s,
        cert,
        sim,
        paths=paths,
        seed=seed,
        practical_ts=practical_ts,
        horizon=horizon,
        progress=progress,
    )
    rep["notes"] = notes + rep["notes"]
    res = rep.pop("_result")
    if out is not None:
        out = Path(out)
        res.save(out / "simulation")
        from drip_cert.report import atomic_write_json

        atomic_write_json(out / "validation.json", rep)
    return rep
