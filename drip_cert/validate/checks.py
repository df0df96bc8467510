"""The empirical checks of a certificate, compared like with like.


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
* ``rho_mean = min_{q <= p} rho(q)`` (docs/math/l1drac.md 5.6.1: every order's radius at the
  certified controller, Jensen) bounds the mean ``max_t E||X_t - x'_t||`` itself: the same
  one-sided t bound of the mean against it (``uncertainty_gap_rho_mean``), the like-with-like
  tightness of the mean statistic;
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
from collections.abc import Mapping, Sequence
from dataclasses import dataclass, field, replace
from types import MappingProxyType
from typing import Any, Protocol

import numpy as np

from drip_cert.numerics import stats as _stats
from drip_cert.provenance import ValidationStatus

# the statuses (drip_cert.provenance.ValidationStatus, str-valued: the JSON is unchanged)
HOLDS = ValidationStatus.HOLDS
VIOLATED = ValidationStatus.VIOLATED
NOT_CHECKED = ValidationStatus.NOT_CHECKED
NOTHING_CHECKED = ValidationStatus.NOTHING_CHECKED


class GapEvidence(Protocol):
    """What a validation reads of its evidence: a simulation
    (:class:`~drip_cert.sim.result.SimResult`) or recorded data
    (:class:`~drip_cert.validate.data.DataResult`) alike."""

    @property
    def n_paths_done(self) -> int: ...

    @property
    def times(self) -> np.ndarray: ...

    def gap(self, name: str) -> _stats.GapStats: ...

    def to_dict(self) -> dict[str, Any]: ...


#: what to change in the spec for a number the certificate lacks (the reason of a not_checked)
_HOW_TO_CERTIFY = {
    "kappa": "set [l1drac] delta (the tail probability kappa is certified for, L1-DRAC (130a))",
    "delta_L1": "set [l1drac] delta (a probability in (0, 1))",
    "delta_TaSIL": "set [tasil] delta (a probability in (0, 1))",
    "rho_TaSIL": "give the spec a learned policy ([policy] learned; drip-cert train writes one)",
}


def _not_certified(what: str) -> str:
    """``no kappa certified: set [l1drac] delta ...`` (the fix, where one is known)."""
    fix = _HOW_TO_CERTIFY.get(what)
    return f"no {what} certified" + (f": {fix}" if fix else "")


def _bound_problem(bound: float | None, what: str = "bound") -> str | None:
    """Why ``bound`` cannot be compared (``None`` when it can)."""
    if bound is None:
        return _not_certified(what)
    if math.isnan(bound):
        return f"{what} is NaN"
    if math.isinf(bound):
        return f"{what} is vacuous (infinite)"
    return None


def _delta_problem(delta: float | None, what: str = "delta") -> str | None:
    if delta is None:
        return _not_certified(what)
    if not 0.0 < delta < 1.0:
        return f"{what} = {delta!r} is not a probability in (0, 1): the claim is vacuous"
    return None


def total_tail_claim(
    rho_tasil: float | None,
    kappa: float | None,
    delta_tasil: float | None,
    delta_l1: float | None,
    rho_sde: float | None = None,
    p: int = 1,
) -> tuple[float | None, float | None, str | None]:
    """The total tail claim ``P(||X_t - x*_t|| >= thr) <= delta`` at every ``t``: ``(thr, delta,
    None)``, or ``(None, None, why)`` when it cannot be formed.

    By the triangle inequality ``||X - x*|| <= ||X - N|| + ||N - x'|| + ||x' - x*||`` with ``N``
    L1-DRAC's nominal process, and the union bound: ``||X_t - N_t|| < kappa`` with probability
    ``>= 1 - delta_L1`` (L1-DRAC (130a)), ``max_t ||x'_t - x*_t|| <= rho_TaSIL`` with probability
    ``>= 1 - delta_TaSIL`` (DRIP Theorem thm:TaSIL). Without a known diffusion ``N = x'`` and
    ``thr = rho_TaSIL + kappa``, ``delta = delta_TaSIL + delta_L1``. With a known diffusion ``N``
    is the nominal SDE ``X*`` and ``sup_t ||X*_t - x'_t||_{L_2p} <= rho_sde``
    (docs/math/contraction.md 6.6); Markov's inequality on the ``2p``-th moment gives
    ``P(||X*_t - x'_t|| >= r) <= (rho_sde / r)^{2p}``, so at ``delta_sde = delta_L1`` (the
    confidence the user asked of L1-DRAC) the radius is ``r = rho_sde delta_L1^(-1/(2p))``
    (rounded up): ``thr = rho_TaSIL + kappa + r``, ``delta = delta_TaSIL + 2 delta_L1``.
    """
    reason = (
        _bound_problem(rho_tasil, "rho_TaSIL")
        or _bound_problem(kappa, "kappa")
        or _delta_problem(delta_tasil, "delta_TaSIL")
        or _delta_problem(delta_l1, "delta_L1")
    )
    if reason is None and rho_sde is not None:
        reason = _bound_problem(rho_sde, "rho_sde")
    if reason is not None:
        return None, None, reason
    assert rho_tasil is not None and kappa is not None  # checked by _bound_problem
    assert delta_tasil is not None and delta_l1 is not None  # checked by _delta_problem
    thr = float(rho_tasil) + float(kappa)
    dsum = float(delta_tasil) + float(delta_l1)
    what = "delta_TaSIL + delta_L1"
    if rho_sde is not None:
        # pow is libm (not correctly rounded): 4 ulps up; a larger threshold is a weaker claim
        r_sde = _up(float(rho_sde) * float(delta_l1) ** (-1.0 / (2 * p)), 4)
        thr = _up(thr + r_sde, 1)
        dsum = float(delta_tasil) + 2.0 * float(delta_l1)
        what = "delta_TaSIL + 2 delta_L1"
    bad = _delta_problem(dsum, what)
    if bad is not None:
        return None, None, bad
    return thr, dsum, None


def _up(x: float, ulps: int) -> float:
    for _ in range(ulps):
        x = math.nextafter(x, math.inf)
    return x


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


@dataclass(frozen=True)
class EmpiricalCheck:
    """One comparison of a certified number with its empirical counterpart.

    ``bound`` is the certified number; ``empirical`` the statistic's point estimate;
    ``confidence_low`` / ``confidence_high`` its one-sided confidence bounds in the units of
    ``bound`` (the lower one decides ``violated``) at confidence ``level`` (familywise over the
    recorded times for per-time checks); ``status`` is ``holds`` / ``violated`` /
    ``not_checked``, ``reason`` says why a check is not checked; ``kind`` is ``radius``,
    ``expectation``, ``moment``, ``tail`` or ``information``; ``extra`` holds the kind's own
    values (``delta``, ``n``, ``n_unknown``, ``threshold``, ``time``, ``per_time_level``,
    ``exceed_*``, ...).
    """

    name: str
    kind: str
    what: str
    bound: float | None
    empirical: float | None
    confidence_low: float | None
    confidence_high: float | None
    level: float | None
    status: ValidationStatus
    reason: str | None
    note: str
    extra: Mapping[str, Any] = field(default_factory=lambda: MappingProxyType({}))

    @property
    def holds(self) -> bool:
        """``status == "holds"``."""
        return self.status == HOLDS

    @property
    def ratio(self) -> float | None:
        """``bound / empirical`` when both are finite (``inf`` for an empirical zero)."""
        return _ratio(self.bound, self.empirical)

    @property
    def ratio_at_confidence(self) -> float | None:
        """``bound / confidence_high``: the bound's ratio to the statistic's one-sided upper
        confidence bound, the tightness one can claim at ``level`` (``ratio`` is the point
        estimate's)."""
        return _ratio(self.bound, self.confidence_high)

    def to_dict(self) -> dict[str, Any]:
        """JSON-ready: the fields, ``ratio``, ``ratio_at_confidence`` and ``holds``, then the
        kind's own keys."""
        return {
            "name": self.name,
            "kind": self.kind,
            "what": self.what,
            "bound": self.bound,
            "empirical": self.empirical,
            "confidence_low": self.confidence_low,
            "confidence_high": self.confidence_high,
            "level": self.level,
            "ratio": self.ratio,
            "ratio_at_confidence": self.ratio_at_confidence,
            "status": self.status,
            "holds": self.holds,
            "reason": self.reason,
            "note": self.note,
            **self.extra,
        }


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
) -> EmpiricalCheck:
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
    return EmpiricalCheck(
        name=name,
        kind=kind,
        what=what,
        bound=_num(bound),
        empirical=_num(empirical),
        confidence_low=_num(confidence_low),
        confidence_high=_num(confidence_high),
        level=_num(level),
        status=status,
        reason=reason,
        note=note,
        extra=MappingProxyType(dict(extra)),
    )


def _not_evaluated(
    name: str, kind: str, what: str, *, bound: float | None, **rest: Any
) -> EmpiricalCheck:
    """A check whose statistic could not be computed (no data for it, no comparable bound): no
    empirical value and no confidence bounds; ``rest`` carries ``level`` and the ``reason``."""
    return _make(
        name,
        kind,
        what,
        bound=bound,
        empirical=None,
        confidence_low=None,
        confidence_high=None,
        **rest,
    )


def information(
    name: str, what: str, bound: float | None, empirical: float | None, why: str, **extra: Any
) -> EmpiricalCheck:
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
) -> EmpiricalCheck:
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
    common: dict[str, Any] = {"delta": delta, "n": n, "n_unknown": unknown}
    reason = _bound_problem(rho, "radius") or _delta_problem(delta)
    if reason is None and known.size == 0:
        reason = "no valid paths (every path diverged or the data are NaN)"
    if reason is not None:
        q = (
            float(np.quantile(known, 1 - delta, method="inverted_cdf"))
            if (known.size and delta is not None and _delta_problem(delta) is None)
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
    assert rho is not None and delta is not None  # else a reason was returned above
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
) -> EmpiricalCheck:
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
    common: dict[str, Any] = {
        "threshold": _num(threshold),
        "n": n,
        "n_unknown": unknown,
        "time": None,
    }
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
    assert delta is not None  # else a reason was returned above
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
    s2: np.ndarray | None,
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
) -> EmpiricalCheck:
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
    common: dict[str, Any] = {"n": n, "n_unknown": unknown, "time": None}
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


def overall_status(checks: Sequence[EmpiricalCheck]) -> ValidationStatus:
    """``violated`` if any check is, else ``holds`` if at least one is, else ``nothing_checked``."""
    statuses = [c.status for c in checks]
    if VIOLATED in statuses:
        return VIOLATED
    if HOLDS in statuses:
        return HOLDS
    return NOTHING_CHECKED


def _not_at_certified(check: EmpiricalCheck, why: str) -> EmpiricalCheck:
    """Demote a check made away from the certified L1-DRAC parameters to ``not_checked``."""
    label = f"not at certified parameters ({why})" if why else "not at certified parameters"
    if check.status == NOT_CHECKED:
        reason = f"{check.reason}; {label}"
        tail = "not at certified parameters"
    else:
        reason = label
        tail = f"not at certified parameters: there the comparison gives '{check.status}'"
    note = (check.note + "; " if check.note else "") + tail
    return replace(check, status=NOT_CHECKED, reason=reason, note=note)


def _index(values: tuple[float, ...], x: float | None) -> int | None:
    if x is None or not math.isfinite(x):
        return None
    for i, v in enumerate(values):
        if v == float(x):
            return i
    return None


def uncertainty_gap_name(res: Any, with_l1: bool = True) -> str:
    """The gap L1-DRAC's radius bounds: to the nominal SDE (4b) when the run simulated it (a
    known diffusion ``p != 0``), else to the ODE ``x'`` (DRIP's nominal process, ``p = 0``)."""
    base = "uncertainty_l1" if with_l1 else "uncertainty_true"
    names = [g[0] for g in getattr(getattr(res, "config", None), "gaps", ())]
    return base + "_sde" if base + "_sde" in names else base


def claim_arguments(claims: Any) -> dict[str, Any]:
    """The keyword arguments of :func:`checks_from_result` that a certificate's
    :class:`~drip_cert.bounds.certificate.Claims` give (the same for ``validate`` and
    ``validate --data``)."""
    return {
        "rho_tasil": claims.rho_tasil,
        "delta_tasil": claims.delta_tasil,
        "rho_l1": claims.rho_l1,
        "p": claims.p,
        "kappa": claims.kappa,
        "delta_l1": claims.delta_l1,
        "rho_mean": claims.rho_mean,
        "rho_sde": claims.rho_sde,
    }


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
    rho_mean: float | None = None,
    rho_sde: float | None = None,
) -> list[EmpiricalCheck]:
    """The validation checks of one simulation result against the certified numbers.

    Parameters
    ----------
    res
        A :class:`~drip_cert.sim.result.SimResult` (or an object with ``gap(name)``,
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
    rho_mean
        ``rho_mean = min_{q <= p} rho(q)`` at the certified controller: ``max_t E||X_t -
        x'_t|| < rho_mean`` (docs/math/l1drac.md 5.6.1; the certificate's
        ``l1drac.decomposition.rho_mean``, in the same coordinates as ``rho_l1``); ``None``
        when the certificate has none (the check is then ``not_checked``).
    rho_sde
        ``sup_t ||X*_t - x'_t||_{L_2p} <= rho_sde`` with a known diffusion (the certificate's
        ``rho.rho_sde``), else ``None``: the total tail then passes through ``X*``
        (:func:`total_tail_claim`).

    Returns
    -------
    list of dict
        See :func:`_make` for the keys. Checks: ``policy_radius`` (checked), ``policy_gap``
        (information), ``uncertainty_gap``, ``uncertainty_gap_rho_mean``,
        ``uncertainty_L{2p}_norm``, ``tail_frequency``, ``total_tail`` (checked) and
        ``total_gap`` (information).
    """
    level = float(res.config.ci_level)
    n_total = int(res.n_paths_done)
    out: list[EmpiricalCheck] = []
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
    unc_name = uncertainty_gap_name(res, with_l1)
    unc = res.gap(unc_name)
    xn = "X*_t" if unc_name.endswith("_sde") else "x'_t"  # the nominal SDE (4b) or the ODE
    tot = res.gap("total_l1" if with_l1 else "total_true")
    l1_checks: list[EmpiricalCheck] = []
    common: dict[str, Any] = {"n_total": n_total, "times": unc.times}
    l1_checks.append(
        check_mean(
            "uncertainty_gap",
            unc.power_sums[0],
            unc.power_sums[1],
            unc.n,
            rho_l1,
            level,
            what=f"max_t E||X_t - {xn}|| vs rho_L1(p) (E|.| <= L_2p norm)",
            **common,
        )
    )
    l1_checks.append(
        check_mean(
            "uncertainty_gap_rho_mean",
            unc.power_sums[0],
            unc.power_sums[1],
            unc.n,
            rho_mean,
            level,
            what=f"max_t E||X_t - {xn}|| vs rho_mean = min_(q <= p) rho(q) (the mean bound)",
            note="rho(q): the verified radius of order q at the certified omega, lambda_s, T_s; "
            "E||Z|| <= ||Z||_L2q (Jensen) for each, so the smallest bounds the mean "
            "(docs/math/l1drac.md 5.6.1)",
            **common,
        )
    )
    q, q2 = 2 * int(p), 4 * int(p)
    z1 = unc.power_sums[unc.powers.index(q)] if q in unc.powers else None
    z2 = unc.power_sums[unc.powers.index(q2)] if q2 in unc.powers else None
    lp_name = f"uncertainty_L{q}_norm"
    lp_what = f"max_t (E||X_t - {xn}||^{q})^(1/{q}) vs rho_L1(p)"
    if z1 is None:
        l1_checks.append(
            _not_evaluated(
                lp_name,
                "moment",
                lp_what,
                bound=rho_l1,
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
    tail_what = f"max_t P(||X_t - {xn}|| >= kappa) vs delta_L1 (L1-DRAC (130a))"
    if j is None:
        l1_checks.append(
            _not_evaluated(
                "tail_frequency",
                "tail",
                tail_what,
                bound=delta_l1,
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
    if rho_sde is not None:
        total_what = (
            "max_t P(||X_t - x*_t|| >= rho_TaSIL + kappa + rho_sde delta_L1^(-1/2p)) vs "
            "delta_TaSIL + 2 delta_L1 (triangle inequality through X*, Markov, union bound)"
        )
    thr, dsum, reason = total_tail_claim(rho_tasil, kappa, delta_tasil, delta_l1, rho_sde, p)
    total_note = (
        "if ||x'_t - x*_t|| <= rho_TaSIL (probability >= 1 - delta_TaSIL, every t) "
        "and ||X_t - x'_t|| < kappa (probability >= 1 - delta_L1 at this t), then "
        "||X_t - x*_t|| < rho_TaSIL + kappa"
    )
    if rho_sde is not None:
        total_note = (
            "if ||x'_t - x*_t|| <= rho_TaSIL (probability >= 1 - delta_TaSIL, every t), "
            "||X_t - X*_t|| < kappa (probability >= 1 - delta_L1 at this t) and "
            "||X*_t - x'_t|| < rho_sde delta_L1^(-1/2p) (Markov, probability >= 1 - delta_L1), "
            "then ||X_t - x*_t|| < the threshold"
        )
    jt = _index(tot.kappas, thr)
    if reason is None and jt is None:
        reason = "the threshold rho_TaSIL + kappa was not simulated"
    if reason is not None:
        l1_checks.append(
            _not_evaluated(
                "total_tail",
                "tail",
                total_what,
                bound=dsum,
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
                note=total_note,
                **common,
            )
        )
    if not at_certified_l1:
        l1_checks = [_not_at_certified(c, not_certified_why) for c in l1_checks]
    out.extend(l1_checks)
    rho_total = None
    if rho_tasil is not None and rho_l1 is not None:
        rho_total = float(rho_tasil) + float(rho_l1)
        if rho_sde is not None:
            rho_total += float(rho_sde)
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
