"""Validation: every certified number against Monte-Carlo simulation of the true system.

:func:`validate` simulates the four processes of the DRIP paper with
:func:`drip_cert.sim.engine.simulate` and compares like with like:

* ``rho_TaSIL`` is a ``(1 - delta_TaSIL)`` radius of ``max_t ||x'_t - x*_t||``
  (docs/math/tasil.md 3.4):
  the fraction of paths whose maximum exceeds it, with its one-sided Clopper-Pearson lower
  bound, against ``delta_TaSIL``, and the empirical ``(1 - delta)``-quantile of the per-path
  maxima beside ``rho`` (``policy_radius``);
* ``rho_L1(p)`` bounds ``||X_t - x'_t||_{L_2p}`` at every ``t`` (L1-DRAC Theorem 4.1): the
  one-sided lower t bound of ``E||X_t - x'_t||^{2p}``, raised to ``1/(2p)``
  (``uncertainty_L{2p}_norm``), and of the mean, since ``E|.| <= L_2p`` (``uncertainty_gap``);
* ``P(||X_t - x'_t|| >= kappa) <= delta_L1`` at every ``t`` (L1-DRAC (130a)), with the
  Clopper-Pearson lower bound (``tail_frequency``);
* the total: ``rho = rho_TaSIL + rho_L1`` adds a radius to a moment bound, so
  ``max_t E||X_t - x*_t|| <= rho`` is NOT implied (reported as information, ``total_gap``); what
  is implied, by the triangle inequality and a union bound, is
  ``P(||X_t - x*_t|| >= rho_TaSIL + kappa) <= delta_TaSIL + delta_L1`` at every ``t``
  (``total_tail``).

Every check has a ``status``: ``holds`` (a finite bound compared and not violated at the stated
confidence), ``violated`` (the one-sided lower confidence bound of the empirical quantity exceeds
the bound) or ``not_checked`` with its ``reason`` (no bound, infinite bound, non-finite data, too
few paths, inconclusive because of diverged paths, not at certified parameters, or information
only). The per-time checks test every recorded time at a Bonferroni-corrected level, so a false
``violated`` has probability at most ``1 - level`` over the whole family (up to the CLT
approximation of the t bounds). The report's ``status`` is ``holds`` only when at least one check
holds and none is violated, ``violated`` when one is, else ``nothing_checked``; ``holds`` is
``status == "holds"``. The ratio ``bound / empirical`` is reported for every check, because a
bound that holds but is a thousand times too loose is a finding too.

When the certified ``T_s`` is too small to simulate (more than :data:`MAX_STEPS` steps), the run
is made at a practical ``T_s`` and every check that involves the L1-DRAC parameters is
``not_checked`` ("not at certified parameters"): such results never validate the certificate.
The policy radius involves only the two nominal processes, which do not depend on them.
"""

from __future__ import annotations

import math
from dataclasses import replace
from pathlib import Path
from typing import Any

import numpy as np

from drip_cert.errors import SpecError
from drip_cert.model.system import System
from drip_cert.numerics import stats as _stats
from drip_cert.spec.settings import SimSettings

MAX_STEPS = 200_000  #: largest number of Euler steps per path accepted for a certified-T_s run
SHORT_STEPS = 2_000  #: steps of the short-horizon run at the certified T_s (dt = T_s)
SHORT_PATHS = 200  #: paths of the short-horizon run
MIN_SIMULABLE_TS = 1e-9
#: below this T_s an Euler step changes an O(1) state by less than ~1e-9 relative: with float64
#: (eps 2.2e-16) the drift of one step keeps fewer than 7 digits, and below ~1e-15 it is lost
#: entirely, so a run at such T_s says nothing about the certificate

HOLDS = "holds"  #: a finite bound was compared and not violated at the stated confidence
VIOLATED = "violated"  #: the one-sided lower confidence bound exceeds the bound
NOT_CHECKED = "not_checked"  #: nothing was compared (the check's ``reason`` says why)
NOTHING_CHECKED = "nothing_checked"  #: report status: no check holds and none is violated


def x0_sampler(box) -> Any:
    """Uniform initial law on the box ``D`` (jax key -> state)."""
    from drip_cert._jax import jax, jnp

    b = np.array(box, dtype=float)
    lo, hi = jnp.asarray(b[:, 0]), jnp.asarray(b[:, 1])

    def sample(key):
        return jax.random.uniform(key, (b.shape[0],), minval=lo, maxval=hi, dtype=jnp.float64)

    return sample


# ----------------------------------------------------------------------------------------------
# the checks: one statistic against one certified number, with a status


def _bound_problem(bound: float | None, what: str = "bound") -> str | None:
    """Why ``bound`` cannot be compared (``None`` when it can)."""
    if bound is None:
        return f"no {what} certified"
    if math.isnan(bound):
        return f"{what} is NaN"
    if math.isinf(bound):
        return f"{what} is vacuous (infinite)"
    return None


def _delta_problem(delta: float | None, what: str = "delta") -> str | None:
    if delta is None:
        return f"no {what} certified"
    if not 0.0 < delta < 1.0:
        return f"{what} = {delta!r} is not a probability in (0, 1): the claim is vacuous"
    return None


def _num(x: Any) -> float | None:
    return None if x is None else float(x)


def _ratio(bound: float | None, empirical: float | None) -> float | None:
    """``bound / empirical`` when both are finite numbers (``inf`` for an empirical zero)."""
    if (
        bound is None
        or empirical is None
        or not (math.isfinite(bound) and math.isfinite(empirical))
    ):
        return None
    if empirical > 0:
        return bound / empirical
    return math.inf if bound > 0 else None


def _make(
    name: str,
    kind: str,
    what: str,
    *,
    bound: float | None,
    empirical: float | None,
    confidence_low: float | None,
    confidence_high: float | None,
    level: float | None,
    violated: bool = False,
    reason: str | None = None,
    note: str = "",
    **extra: Any,
) -> dict[str, Any]:
    """One check as a JSON-ready dict; ``status`` from ``reason`` / ``violated`` / the data.

    Precedence: a ``reason`` (no comparable bound, no valid data, inconclusive) gives
    ``not_checked``; else ``violated`` gives ``violated``; else a non-finite ``empirical`` or
    ``confidence_low`` gives ``not_checked``; else ``holds``.

    Returns
    -------
    dict
        ``name``; ``kind`` (``radius``, ``expectation``, ``moment``, ``tail`` or
        ``information``); ``what`` (the comparison in words); ``bound`` (the certified number
        the statistic is compared with); ``empirical`` (the statistic's point estimate);
        ``confidence_low`` / ``confidence_high`` (its one-sided lower / upper confidence bounds,
        in the units of ``bound``; the lower one decides ``violated``); ``level`` (their
        confidence level; familywise over the recorded times for per-time checks);
        ``ratio`` (``bound / empirical``); ``status`` (``holds`` / ``violated`` /
        ``not_checked``); ``holds`` (``status == "holds"``); ``reason`` (why not checked, else
        None); ``note``; and the kind's own keys (``delta``, ``n``, ``n_unknown``,
        ``threshold``, ``time``, ``per_time_level``, ``exceed_*``, ...).
    """
    if reason is None and not violated:
        for label, v in (("empirical value", empirical), ("confidence bound", confidence_low)):
            if v is None or not math.isfinite(v):
                reason = f"{label} is {'missing' if v is None else v} (non-finite data)"
                break
    if reason is not None:
        status = NOT_CHECKED
    else:
        status = VIOLATED if violated else HOLDS
    return {
        "name": name,
        "kind": kind,
        "what": what,
        "bound": _num(bound),
        "empirical": _num(empirical),
        "confidence_low": _num(confidence_low),
        "confidence_high": _num(confidence_high),
        "level": _num(level),
        "ratio": _ratio(bound, empirical),
        "status": status,
        "holds": status == HOLDS,
        "reason": reason,
        "note": note,
        **extra,
    }


def information(
    name: str, what: str, bound: float | None, empirical: float | None, why: str, **extra: Any
) -> dict[str, Any]:
    """A number reported beside a bound but NOT checked against it (status ``not_checked``)."""
    return _make(
        name,
        "information",
        what,
        bound=bound,
        empirical=empirical,
        confidence_low=None,
        confidence_high=None,
        level=None,
        reason=f"information only: {why}",
        **extra,
    )


def check_radius(
    name: str,
    path_max: np.ndarray,
    rho: float | None,
    delta: float | None,
    level: float,
    *,
    n_total: int | None = None,
    what: str = "",
    note: str = "",
) -> dict[str, Any]:
    """A ``(1 - delta)`` radius against per-path maxima: ``P(max_t r_t > rho) <= delta``?

    Parameters
    ----------
    name, what, note
        Labels.
    path_max
        ``max_t r_t`` of each valid path (NaN entries are unknown).
    rho, delta
        The radius and its probability (``rho_TaSIL``, ``delta_TaSIL``).
    level
        Confidence level of the one-sided bounds (one test: no multiplicity correction).
    n_total
        Number of simulated paths (``>= len(path_max)``); the missing ones (diverged) are
        unknown.

    Returns
    -------
    dict
        ``bound = rho``; ``empirical``: the empirical ``(1 - delta)``-quantile of the per-path
        maxima; ``confidence_low``/``confidence_high``: distribution-free one-sided bounds on
        that quantile (:func:`~drip_cert.numerics.stats.upper_quantile_bounds`). ``violated`` when
        ``confidence_low > rho``, which is the same event as the Clopper-Pearson lower bound of
        the exceedance frequency ``#{max_t r_t > rho} / n`` being ``> delta`` (reported as
        ``exceed_*``). Unknown paths count as within the radius for ``violated`` and as outside
        it for ``confidence_high``; when they could turn the verdict the check is
        ``not_checked`` (inconclusive).
    """
    pm = np.asarray(path_max, dtype=np.float64).reshape(-1)
    n = int(pm.size if n_total is None else n_total)
    known = pm[~np.isnan(pm)]
    unknown = n - known.size
    common = {"delta": delta, "n": n, "n_unknown": unknown}
    reason = _bound_problem(rho, "radius") or _delta_problem(delta)
    if reason is None and known.size == 0:
        reason = "no valid paths (every path diverged or the data are NaN)"
    if reason is not None:
        q = (
            float(np.quantile(known, 1 - delta, method="inverted_cdf"))
            if (known.size and _delta_problem(delta) is None)
            else None
        )
        return _make(
            name,
            "radius",
            what,
            bound=rho,
            empirical=q,
            confidence_low=None,
            confidence_high=None,
            level=level,
            reason=reason,
            note=note,
            **common,
        )
    q_hat, q_low, q_high = _stats.upper_quantile_bounds(known, delta, level, n_total=n)
    k = int(np.sum(known > rho))
    ex_low = float(_stats.clopper_pearson_lower(k, n, level))
    ex_high = float(_stats.clopper_pearson_upper(k + unknown, n, level))
    # the decision is the frequency test; q_low > rho is the same event in radius units
    violated = ex_low > delta
    reason = None
    if not violated and float(_stats.clopper_pearson_lower(n, n, level)) <= delta:
        reason = f"too few paths ({n}): even all of them outside rho would not show a violation"
    elif not violated and unknown:
        if float(_stats.clopper_pearson_lower(k + unknown, n, level)) > delta:
            reason = (
                f"inconclusive: {unknown} of {n} paths are unknown (diverged or NaN); counted "
                "as outside the radius they would make it violated"
            )
    return _make(
        name,
        "radius",
        what,
        bound=rho,
        empirical=q_hat,
        confidence_low=q_low,
        confidence_high=q_high,
        level=level,
        violated=violated,
        reason=reason,
        note=note,
        quantile=1.0 - delta,
        exceed_count=k,
        exceed_frequency=k / known.size,
        exceed_confidence_low=ex_low,
        exceed_confidence_high=ex_high,
        **common,
    )


def _per_time(values: np.ndarray, times: np.ndarray | None) -> tuple[float, float | None]:
    """Max over the finite entries and its time (NaN when there is none)."""
    v = np.asarray(values, dtype=np.float64)
    fin = np.isfinite(v)
    if not fin.any():
        return math.nan, None
    i = int(np.argmax(np.where(fin, v, -np.inf)))
    return float(v[i]), None if times is None else float(np.asarray(times)[i])


def _bonferroni_note(m: int, level: float) -> str:
    return (
        f"the violation test runs at each of the {m} recorded times at level "
        f"{_stats.bonferroni_level(level, m):.6g} (Bonferroni), so a false 'violated' anywhere "
        f"has probability <= {1 - level:.3g}; confidence_low/high are the max over t of the "
        "per-time bounds (simultaneous)"
    )


def check_tail(
    name: str,
    counts: np.ndarray,
    n_valid: int,
    threshold: float | None,
    delta: float | None,
    level: float,
    *,
    n_total: int | None = None,
    times: np.ndarray | None = None,
    what: str = "",
    note: str = "",
) -> dict[str, Any]:
    """A per-time tail claim ``P(r_t >= threshold) <= delta`` for every recorded ``t``.

    Parameters
    ----------
    counts
        ``(n_times,)``: ``#{valid paths: r_t >= threshold}``.
    n_valid, n_total
        Valid paths, and all simulated paths (the others are unknown).
    threshold, delta
        The claim.
    level
        Familywise confidence level; each time is tested at
        :func:`~drip_cert.numerics.stats.bonferroni_level` ``(level, n_times)``.

    Returns
    -------
    dict
        ``bound = delta``; ``empirical``: ``max_t`` of the frequency among valid paths;
        ``confidence_low``: ``max_t`` of the one-sided Clopper-Pearson lower bounds (unknown
        paths counted below the threshold); ``violated`` when it exceeds ``delta``;
        ``confidence_high``: ``max_t`` of the upper bounds (unknown paths counted above).
    """
    c = np.asarray(counts, dtype=np.float64).reshape(-1)
    n = int(n_valid if n_total is None else n_total)
    unknown = n - int(n_valid)
    m = max(1, c.size)
    common = {"threshold": _num(threshold), "n": n, "n_unknown": unknown, "time": None}
    reason = _bound_problem(threshold, "threshold") or _delta_problem(delta)
    if reason is None and n_valid < 1:
        reason = "no valid paths (every path diverged)"
    if reason is None and not np.all(np.isfinite(c)):
        reason = "tail counts are not finite"
    freq, t_freq = _per_time(c / max(n_valid, 1), times) if n_valid >= 1 else (math.nan, None)
    common["time"] = t_freq if freq > 0 else None  # no worst time when nothing exceeds
    if reason is not None:
        return _make(
            name,
            "tail",
            what,
            bound=delta,
            empirical=freq,
            confidence_low=None,
            confidence_high=None,
            level=level,
            reason=reason,
            note=note,
            **common,
        )
    lvl = _stats.bonferroni_level(level, m)
    low = np.asarray(_stats.clopper_pearson_lower(c, n, lvl), dtype=np.float64)
    high = np.asarray(_stats.clopper_pearson_upper(c + unknown, n, lvl), dtype=np.float64)
    c_low, t_low = _per_time(low, times)
    violated = bool(np.any(low > delta))
    reason = None
    if not violated and float(_stats.clopper_pearson_lower(n, n, lvl)) <= delta:
        reason = f"too few paths ({n}) for a test at the per-time level {lvl:.6g}"
    elif not violated and unknown:
        worst = np.asarray(_stats.clopper_pearson_lower(c + unknown, n, lvl))
        if np.any(worst > delta):
            reason = (
                f"inconclusive: {unknown} of {n} paths diverged; counted above the threshold "
                "they would make it violated"
            )
    return _make(
        name,
        "tail",
        what,
        bound=delta,
        empirical=freq,
        confidence_low=c_low,
        confidence_high=float(np.max(high)),
        level=level,
        violated=violated,
        reason=reason,
        note=(note + "; " if note else "") + _bonferroni_note(m, level),
        confidence_low_time=t_low,
        per_time_level=lvl,
        **common,
    )


def check_mean(
    name: str,
    s1: np.ndarray,
    s2: np.ndarray,
    n_valid: int,
    bound: float | None,
    level: float,
    *,
    n_total: int | None = None,
    times: np.ndarray | None = None,
    power: float = 1.0,
    kind: str = "expectation",
    what: str = "",
    note: str = "",
) -> dict[str, Any]:
    """``sup_t (E Z_t)^{1/power} <= bound`` from ``s1 = sum Z_t``, ``s2 = sum Z_t^2``, ``Z >= 0``.

    ``power = 1`` compares a mean (``Z = r``); ``power = 2p`` with ``Z = r^{2p}`` compares the
    ``L_{2p}`` norm of L1-DRAC Theorem 4.1. At each recorded time the one-sided Student-t lower
    bound of ``E Z_t`` at the Bonferroni level is raised to ``1/power`` (a monotone map keeps the
    confidence); ``violated`` when that exceeds ``bound`` at some time. Unknown (diverged) paths
    enter as ``Z = 0``: ``Z 1[valid] <= Z`` path by path, so the lower bound stays a lower bound
    of the whole mean; they make a non-violated check inconclusive (their ``Z`` is unbounded).
    For right-skewed ``Z`` (a ``2p``-th power is) the t statistic is left-skewed, so the LOWER
    t bound errs on the conservative side; it is still a CLT approximation, not exact.
    """
    a1 = np.asarray(s1, dtype=np.float64).reshape(-1)
    a2 = None if s2 is None else np.asarray(s2, dtype=np.float64).reshape(-1)
    n = int(n_valid if n_total is None else n_total)
    unknown = n - int(n_valid)
    m = max(1, a1.size)
    common = {"n": n, "n_unknown": unknown, "time": None}
    with np.errstate(invalid="ignore", divide="ignore", over="ignore"):
        point = (a1 / n_valid) ** (1.0 / power) if n_valid >= 1 else np.full(a1.shape, np.nan)
    emp, t_emp = _per_time(point, times)
    common["time"] = t_emp
    nonfinite = (not np.all(np.isfinite(point))) or (a2 is not None and not np.all(np.isfinite(a2)))
    reason = _bound_problem(bound)
    if reason is None and n_valid < 2:
        reason = "fewer than 2 valid paths: no confidence bound"
    if reason is None and a2 is None:
        reason = f"no second moment of Z = r^{power:g} recorded (simulate with larger p_max)"
    if reason is not None:
        return _make(
            name,
            kind,
            what,
            bound=bound,
            empirical=emp,
            confidence_low=None,
            confidence_high=None,
            level=level,
            reason=reason,
            note=note,
            **common,
        )
    lvl = _stats.bonferroni_level(level, m)
    _, low, high = _stats.t_one_sided(a1, a2, n, lvl)
    with np.errstate(invalid="ignore", over="ignore"):
        low_r = np.maximum(low, 0.0) ** (1.0 / power)
        high_r = np.maximum(high, 0.0) ** (1.0 / power)
    c_low, t_low = _per_time(low_r, times)
    violated = bool(np.any(np.isfinite(low_r) & (low_r > bound)))
    reason = None
    if not violated and nonfinite:
        reason = "non-finite moments at some recorded times (overflow or NaN)"
    elif not violated and unknown:
        reason = (
            f"inconclusive: {unknown} of {n} paths diverged; their contribution to the moment "
            "is unbounded"
        )
    return _make(
        name,
        kind,
        what,
        bound=bound,
        empirical=emp,
        confidence_low=c_low,
        confidence_high=float(np.max(high_r)) if unknown == 0 else math.inf,
        level=level,
        violated=violated,
        reason=reason,
        note=(note + "; " if note else "") + _bonferroni_note(m, level),
        confidence_low_time=t_low,
        per_time_level=lvl,
        **common,
    )


def overall_status(checks: list[dict[str, Any]]) -> str:
    """``violated`` if any check is, else ``holds`` if at least one is, else ``nothing_checked``."""
    statuses = [c["status"] for c in checks]
    if VIOLATED in statuses:
        return VIOLATED
    if HOLDS in statuses:
        return HOLDS
    return NOTHING_CHECKED


def _not_at_certified(check: dict[str, Any], why: str) -> dict[str, Any]:
    """Demote a check made away from the certified L1-DRAC parameters to ``not_checked``."""
    out = dict(check)
    label = f"not at certified parameters ({why})" if why else "not at certified parameters"
    if out["status"] == NOT_CHECKED:
        out["reason"] = f"{out['reason']}; {label}"
        tail = "not at certified parameters"
    else:
        out["reason"] = label
        tail = f"not at certified parameters: there the comparison gives '{out['status']}'"
    out["note"] = (out["note"] + "; " if out["note"] else "") + tail
    out["status"] = NOT_CHECKED
    out["holds"] = False
    return out


def _index(values: tuple[float, ...], x: float | None) -> int | None:
    if x is None or not math.isfinite(x):
        return None
    for i, v in enumerate(values):
        if v == float(x):
            return i
    return None


def checks_from_result(
    res: Any,
    *,
    rho_tasil: float | None,
    delta_tasil: float | None,
    rho_l1: float | None,
    p: int,
    kappa: float | None,
    delta_l1: float | None,
    at_certified_l1: bool = True,
    not_certified_why: str = "",
    policy: bool = True,
    with_l1: bool = True,
) -> list[dict[str, Any]]:
    """The validation checks of one simulation result against the certified numbers.

    Parameters
    ----------
    res
        A :class:`~drip_cert.sim.engine.SimResult` (or an object with ``gap(name)``,
        ``n_paths_done`` and ``config.ci_level``).
    rho_tasil, delta_tasil
        ``rho_TaSIL`` and its probability: ``P[max_t ||x'_t - x*_t|| > rho] <= delta``.
    rho_l1, p
        ``rho_L1(p)``: ``||X_t - x'_t||_{L_2p} < rho_L1(p)`` at every ``t`` (Theorem 4.1).
    kappa, delta_l1
        ``P(||X_t - x'_t|| >= kappa) <= delta`` at every ``t`` (L1-DRAC (130a)).
    at_certified_l1, not_certified_why
        Whether the L1-DRAC parameters of the run are the certified ones; the checks that
        involve them are ``not_checked`` otherwise (the policy radius does not involve them:
        both nominal processes are simulated exactly as certified).
    policy
        Include the checks of the policy gap (off for the short-horizon run).
    with_l1
        Compare the L1-DRAC process (else the true process without L1, for information).

    Returns
    -------
    list of dict
        See :func:`_make` for the keys. Checks: ``policy_radius`` (checked), ``policy_gap``
        (information), ``uncertainty_gap``, ``uncertainty_L{2p}_norm``, ``tail_frequency``,
        ``total_tail`` (checked) and ``total_gap`` (information).
    """
    level = float(res.config.ci_level)
    n_total = int(res.n_paths_done)
    out: list[dict[str, Any]] = []
    if policy:
        pol = res.gap("policy")
        out.append(
            check_radius(
                "policy_radius",
                pol.path_max,
                rho_tasil,
                delta_tasil,
                level,
                n_total=n_total,
                what="(1-delta_TaSIL)-quantile of max_t ||x'_t - x*_t|| over paths vs rho_TaSIL",
                note="TaSIL's radius holds jointly over the training data and xi ~ D: for this "
                "one trained policy a frequency above delta is a violation unless the data draw "
                "was one of the unlucky ones the certificate allows (probability <= delta); the "
                "maximum is over the recorded times, below the true sup, so a violation on the "
                "grid is one in continuous time",
            )
        )
        out.append(
            information(
                "policy_gap",
                "max_t E||x'_t - x*_t|| vs rho_TaSIL",
                rho_tasil,
                pol.max_mean,
                "rho_TaSIL is a (1-delta) radius of max_t ||x'_t - x*_t||, not a bound on its "
                "mean (compared in policy_radius)",
                time=pol.argmax_time,
            )
        )
    unc = res.gap("uncertainty_l1" if with_l1 else "uncertainty_true")
    tot = res.gap("total_l1" if with_l1 else "total_true")
    l1_checks: list[dict[str, Any]] = []
    common = {"n_total": n_total, "times": unc.times}
    l1_checks.append(
        check_mean(
            "uncertainty_gap",
            unc.power_sums[0],
            unc.power_sums[1],
            unc.n,
            rho_l1,
            level,
            what="max_t E||X_t - x'_t|| vs rho_L1(p) (E|.| <= L_2p norm)",
            **common,
        )
    )
    q, q2 = 2 * int(p), 4 * int(p)
    z1 = unc.power_sums[unc.powers.index(q)] if q in unc.powers else None
    z2 = unc.power_sums[unc.powers.index(q2)] if q2 in unc.powers else None
    lp_name, lp_what = f"uncertainty_L{q}_norm", f"max_t (E||X_t - x'_t||^{q})^(1/{q}) vs rho_L1(p)"
    if z1 is None:
        l1_checks.append(
            _make(
                lp_name,
                "moment",
                lp_what,
                bound=rho_l1,
                empirical=None,
                confidence_low=None,
                confidence_high=None,
                level=level,
                reason=f"moment of order {q} not simulated",
            )
        )
    else:
        l1_checks.append(
            check_mean(
                lp_name,
                z1,
                z2,
                unc.n,
                rho_l1,
                level,
                power=q,
                kind="moment",
                what=lp_what,
                **common,
            )
        )
    j = _index(unc.kappas, kappa)
    tail_what = "max_t P(||X_t - x'_t|| >= kappa) vs delta_L1 (L1-DRAC (130a))"
    if j is None:
        l1_checks.append(
            _make(
                "tail_frequency",
                "tail",
                tail_what,
                bound=delta_l1,
                empirical=None,
                confidence_low=None,
                confidence_high=None,
                level=level,
                reason=_bound_problem(kappa, "kappa") or "kappa was not simulated",
                threshold=_num(kappa),
            )
        )
    else:
        l1_checks.append(
            check_tail(
                "tail_frequency",
                unc.tail_counts[j],
                unc.n,
                kappa,
                delta_l1,
                level,
                what=tail_what,
                **common,
            )
        )
    total_what = (
        "max_t P(||X_t - x*_t|| >= rho_TaSIL + kappa) vs delta_TaSIL + delta_L1 "
        "(triangle inequality + union bound)"
    )
    thr = dsum = None
    reason = (
        _bound_problem(rho_tasil, "rho_TaSIL")
        or _bound_problem(kappa, "kappa")
        or _delta_problem(delta_tasil, "delta_TaSIL")
        or _delta_problem(delta_l1, "delta_L1")
    )
    if reason is None:
        thr = float(rho_tasil) + float(kappa)
        dsum = float(delta_tasil) + float(delta_l1)
        reason = _delta_problem(dsum, "delta_TaSIL + delta_L1")
    jt = _index(tot.kappas, thr)
    if reason is None and jt is None:
        reason = "the threshold rho_TaSIL + kappa was not simulated"
    if reason is not None:
        l1_checks.append(
            _make(
                "total_tail",
                "tail",
                total_what,
                bound=dsum,
                empirical=None,
                confidence_low=None,
                confidence_high=None,
                level=level,
                reason=reason,
                threshold=thr,
            )
        )
    else:
        l1_checks.append(
            check_tail(
                "total_tail",
                tot.tail_counts[jt],
                tot.n,
                thr,
                dsum,
                level,
                what=total_what,
                note="if ||x'_t - x*_t|| <= rho_TaSIL (probability >= 1 - delta_TaSIL, every t) "
                "and ||X_t - x'_t|| < kappa (probability >= 1 - delta_L1 at this t), then "
                "||X_t - x*_t|| < rho_TaSIL + kappa",
                **common,
            )
        )
    if not at_certified_l1:
        l1_checks = [_not_at_certified(c, not_certified_why) for c in l1_checks]
    out.extend(l1_checks)
    rho_total = None
    if rho_tasil is not None and rho_l1 is not None:
        rho_total = float(rho_tasil) + float(rho_l1)
    out.append(
        information(
            "total_gap",
            "max_t E||X_t - x*_t|| vs rho = rho_TaSIL + rho_L1",
            rho_total,
            tot.max_mean,
            "rho adds a (1-delta) radius (rho_TaSIL) to an L_2p moment bound (rho_L1), so "
            "max_t E||X_t - x*_t|| <= rho is not implied (E max_t ||x'_t - x*_t|| is not bounded "
            "by rho_TaSIL); the implied claim is checked in total_tail",
            time=tot.argmax_time,
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

    Returns
    -------
    dict
        JSON-ready report: ``status`` (``holds`` / ``violated`` / ``nothing_checked``, over the
        main and the short-horizon checks), ``holds`` (``status == "holds"``), ``counts`` (checks
        per status), ``checks``, ``certificate``, ``empirical``, ``at_certified_parameters``,
        ``horizon`` and ``certified_horizon``, ``short_horizon_at_certified_parameters``,
        ``l1_parameters``, ``diverged_fraction``, ``simulation``, ``notes`` and ``_result``
        (the :class:`~drip_cert.sim.engine.SimResult`, not JSON).
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
    rho_tasil = cert.rho_tasil
    delta_tasil = cert.tasil.delta if cert.tasil is not None else None
    rho_l1 = cert.rho_l1
    p = design.p if design is not None else 1
    kappa = design.kappa if design is not None else None
    delta_l1 = design.delta if design is not None else None
    why = "no feasible L1-DRAC design" if design is None else "practical T_s, see the notes"
    kappas = _thresholds(kappa, rho_tasil)
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
        kappas=kappas,
        p_max=max(4, 2 * p),  # E r^{4p} gives the variance of r^{2p} for the L_2p check
        w2_times=(T,),
        run_dir=run_dir,
        progress=progress,
    )
    checks = checks_from_result(
        res,
        rho_tasil=rho_tasil,
        delta_tasil=delta_tasil,
        rho_l1=rho_l1,
        p=p,
        kappa=kappa,
        delta_l1=delta_l1,
        at_certified_l1=at_cert,
        not_certified_why=why,
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
                p_max=max(4, 2 * p),
            )
            short = {
                "horizon": t_short,
                "paths": SHORT_PATHS,
                "checks": checks_from_result(
                    sres,
                    rho_tasil=rho_tasil,
                    delta_tasil=delta_tasil,
                    rho_l1=rho_l1,
                    p=p,
                    kappa=kappa,
                    delta_l1=delta_l1,
                    policy=False,
                ),
                "note": f"short horizon [0, {t_short:.3g}] s at the certified parameters",
            }
            short["status"] = overall_status(short["checks"])
        else:
            notes.append(
                f"no short-horizon run at the certified T_s = {design.Ts:.3g} s either: "
                f"below {MIN_SIMULABLE_TS:g} s an Euler step is lost in float64 rounding"
            )
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
    every = checks + (short["checks"] if short is not None else [])
    status = overall_status(every)
    if status == NOTHING_CHECKED:
        notes.insert(
            0,
            "nothing was checked: no finite certified bound could be compared at certified "
            "parameters (see each check's reason)",
        )
    return {
        "status": status,
        "holds": status == HOLDS,
        "counts": {
            st: sum(c["status"] == st for c in every) for st in (HOLDS, VIOLATED, NOT_CHECKED)
        },
        "certificate": cert.to_dict(),
        "empirical": emp,
        "checks": checks,
        "at_certified_parameters": at_cert,
        "horizon": T,
        "certified_horizon": float(s.horizon),
        "short_horizon_at_certified_parameters": short,
        "l1_parameters": {
            "omega": params.omega,
            "lambda_s": params.lambda_s,
            "Ts": params.Ts,
            "dt": params.dt,
        },
        "diverged_fraction": {st.name: st.diverged_fraction for st in res.status},
        "simulation": res.to_dict(),
        "notes": notes,
        "_result": res,
    }


def _thresholds(kappa: float | None, rho_tasil: float | None) -> tuple[float, ...]:
    """Tail thresholds to simulate: ``kappa`` and ``rho_TaSIL + kappa`` where finite."""
    out: list[float] = []
    if kappa is not None and math.isfinite(kappa) and kappa > 0:
        out.append(float(kappa))
        if rho_tasil is not None and math.isfinite(rho_tasil) and rho_tasil >= 0:
            out.append(float(rho_tasil) + float(kappa))
    return tuple(dict.fromkeys(out))


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
    from drip_cert.learn.imitation import train_on_system
    from drip_cert.spec import load_spec

    spec = load_spec(spec_path)
    s = spec.system
    notes = []
    if s.learned is None:
        st = spec.settings.tasil
        if quick:
            st = replace(st, steps=min(st.steps, 300))
        tp = train_on_system(s, st, progress=progress)
        s = tp.system
        notes.append(
            f"no learned policy in the spec: trained {st.method} ({st.steps} steps, "
            f"{st.trajectories} trajectories, seed {st.seed})"
        )
        spec = spec.with_system(s)
    cert = certify(spec)
    sim = spec.settings.simulation
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
        from drip_cert.numerics.atomic_io import atomic_write_json

        atomic_write_json(out / "validation.json", rep)
    return rep
