"""The L1-DRAC solver at one objective: the searches behind the designer's ``design``.

Source: A. Gahlawat, S. H. Karumanchi, N. Hovakimyan, "L1-DRAC: Distributionally Robust Adaptive
Control -- Global Results", arXiv:2509.04619 (2025-09-04). Sec. 3.2 (conditions (16), (21), (24);
Remarks 3.1, 3.2), Theorem 4.1 (kappa). The transcription used is ``docs/math/l1drac.md``; every
formula was re-checked against the PDF.

Public surface (of the package; users call :func:`~drip_cert.bounds.l1drac.designer.design`)
----------------------------------------------------------------------------------------------
* :func:`solve` -- the free parameters at a fixed ``Ts`` (smallest rho, L1-DRAC (16), (21),
  (24)) or, with ``Ts`` free, the smallest radii and the largest ``Ts`` (24) allows with them;
  returns an :class:`~drip_cert.bounds.l1drac.result.L1Design` (never raises for an infeasible
  design: ``feasible=False`` and ``reason``).
* :func:`params_at_Ts` -- a cheaper (omega, lambda_s) search at a fixed ``Ts`` (coordinate
  search), used for the points of the (Ts, rho) front.

How a design is found: the root searches of :mod:`drip_cert.bounds.l1drac.searches` at fixed
(omega, lambda_s), a log-grid search over the free omega and lambda_s, then the back-off of
:mod:`drip_cert.bounds.l1drac.backoff` into the interior, and a final re-check of every
condition in float64 and in Arb (:mod:`drip_cert.bounds.l1drac.verify`). ``feasible`` means every
condition is *verified* (the exact margin at the returned float values is > 0), not merely that
its float64 margin is.
"""

from __future__ import annotations

import functools
import math
import time
from collections.abc import Callable
from dataclasses import dataclass

from drip_cert.bounds.l1drac.appendix import (
    RefConstants,
    TrueConstants,
    reference_constants,
    true_constants,
)
from drip_cert.bounds.l1drac.backoff import back_off
from drip_cert.bounds.l1drac.conditions import (
    EXP_ARG_MAX,
    check_omega,
    check_p,
    check_Ts,
    float_24,
    float_conditions,
    with_arb_margins,
)
from drip_cert.bounds.l1drac.constants import L1Constants
from drip_cert.bounds.l1drac.radii import kappa_markov, p_for_delta
from drip_cert.bounds.l1drac.request import DesignRequest
from drip_cert.bounds.l1drac.result import L1Design
from drip_cert.bounds.l1drac.searches import RHO_CAP, max_Ts, min_rho_a, min_rho_r
from drip_cert.bounds.l1drac.sides import budget_24, budget_a
from drip_cert.bounds.l1drac.verify import CONDITIONS

__all__ = ["solve", "params_at_Ts"]

#: Default search interval for omega, as multiples of lambda (log-uniform grid + refinement).
_OMEGA_BOUNDS_REL = (1e-3, 1e7)
#: Default search interval for lambda_s, as multiples of lambda.
_LAMBDA_S_BOUNDS_REL = (1e-3, 1e5)
#: Points of the log-uniform grid scanned before the local refinement of omega / lambda_s.
_GRID_POINTS = 41
#: Grid points of the inner lambda_s search when omega and lambda_s are both free (Ts fixed).
_NESTED_GRID_POINTS = 13


@dataclass(frozen=True)
class _Point:
    """Inner result at one (omega, lambda_s)."""

    rho_r: float | None
    rho_a: float | None
    Ts: float | None
    reason: str


_MEMO_SIZE = 1 << 14
"""Entries of each memo of the radii at one omega (:func:`_rho_r_at`, :func:`_rho_a_floor`):
more than the omegas one design visits (~ 20 front points x ~ 60 omegas)."""


@functools.lru_cache(maxsize=_MEMO_SIZE)
def _rho_r_at(c: L1Constants, rc: RefConstants, omega: float) -> float | None:
    """``min_rho_r(c, rc, omega, ("16a", "21a"))``, memoised: a function of its (hashable,
    frozen) arguments' values, which every search over lambda_s and Ts at one omega repeats."""
    return min_rho_r(c, rc, omega, ("16a", "21a"))


@functools.lru_cache(maxsize=_MEMO_SIZE)
def _rho_a_floor(
    c: L1Constants, tc: TrueConstants, p: int, omega: float, rho_r: float
) -> float | None:
    """``min_rho_a(..., ("16b", "21b"))`` at (omega, rho_r), memoised like :func:`_rho_r_at`."""
    return min_rho_a(c, tc, p, omega, rho_r, None, None, ("16b", "21b"))


def _point(
    c: L1Constants,
    rc: RefConstants,
    tc: TrueConstants,
    req: DesignRequest,
    omega: float,
    lambda_s: float | None,
    *,
    find_Ts: bool,
) -> _Point:
    """rho_r, rho_a (and Ts when ``find_Ts``) at fixed omega, lambda_s; reasons for failures."""
    gap = abs(2.0 * c.lam - omega)
    rho_r: float | None
    rho_a: float | None
    if req.rho_r is not None:
        rho_r = req.rho_r
    else:
        rho_r = _rho_r_at(c, rc, omega)
        if rho_r is None:
            lim = 1.0 - c.k_r - (rc.oast_2 + rc.oast_3) / gap
            return _Point(
                None,
                None,
                None,
                f"(21a) fails for every rho_r at omega = {omega:.6g}: its normalised margin tends "
                f"to 1 - k_r - (Delta^r_oast2 + Delta^r_oast3)/|2 lambda - omega| = {lim:.6g} <= 0",
            )
    Ts = req.Ts
    if req.rho_a is not None:
        rho_a = req.rho_a
    else:
        # = min_rho_a(..., ("16b", "21b", "24")); the first two searches depend on omega and
        # rho_r only, not on the lambda_s and Ts the outer searches vary: memoised
        rho_a = _rho_a_floor(c, tc, req.p, omega, rho_r)
        if rho_a is not None and Ts is not None and lambda_s is not None:
            rho_a = min_rho_a(c, tc, req.p, omega, rho_r, lambda_s, Ts, ("24",), start=rho_a)
        if rho_a is None:
            lim = 1.0 - c.k_a - (tc.oast_2 + tc.oast_3) / gap
            which = "(21b)" if Ts is None else "(21b) and (24)"
            return _Point(
                rho_r,
                None,
                None,
                f"{which} fail for every rho_a <= {RHO_CAP:g} at omega = {omega:.6g} "
                f"(the normalised margin of (21b) tends to {lim:.6g})",
            )
    if Ts is None and find_Ts and lambda_s is not None:
        Ts = max_Ts(c, tc, req.p, omega, lambda_s, rho_r, rho_a)
        if Ts is None:
            budget = budget_24(c, tc, omega, rho_r, rho_a)
            return _Point(
                rho_r,
                rho_a,
                None,
                f"(24) cannot hold for any Ts: its right side (1-k_a) rho_a^2 - Gamma_a - "
                f"Theta_a/|2 lambda - omega| = {budget:.6g} is not positive; increase rho_a "
                "or eps_a",
            )
    return _Point(rho_r, rho_a, Ts, "")


def _log_search(
    f: Callable[[float], float],
    lo: float,
    hi: float,
    avoid: float | None,
    n: int = _GRID_POINTS,
) -> tuple[float, float]:
    """Minimise f over [lo, hi] on a log-uniform grid of n points, then golden section in
    log x between the neighbours of the best grid point (not across ``avoid``).

    Returns (x, f(x)). f may return inf (infeasible). A heuristic for the *optimum*: the
    certificate never depends on it, only on the re-checked conditions at the returned point.
    """
    la, lb = math.log(lo), math.log(hi)
    xs = [math.exp(la + (lb - la) * i / (n - 1)) for i in range(n)]
    if avoid is not None:
        xs = [x * (1.0 + 1e-6) if abs(x / avoid - 1.0) < 1e-9 else x for x in xs]
    vals = [f(x) for x in xs]
    i = min(range(len(xs)), key=lambda j: (vals[j], -xs[j]))
    best_x, best_v = xs[i], vals[i]
    if not math.isfinite(best_v):
        return best_x, best_v
    a = math.log(xs[max(i - 1, 0)])
    b = math.log(xs[min(i + 1, len(xs) - 1)])
    if avoid is not None:
        la_ = math.log(avoid)
        if a < la_ < b:
            if math.log(best_x) < la_:
                b = la_ - 1e-9
            else:
                a = la_ + 1e-9
    g = (math.sqrt(5.0) - 1.0) / 2.0
    x1, x2 = b - g * (b - a), a + g * (b - a)
    f1, f2 = f(math.exp(x1)), f(math.exp(x2))
    for _ in range(40):
        if b - a < 1e-4:
            break
        if f1 <= f2:
            b, x2, f2 = x2, x1, f1
            x1 = b - g * (b - a)
            f1 = f(math.exp(x1))
        else:
            a, x1, f1 = x1, x2, f2
            x2 = a + g * (b - a)
            f2 = f(math.exp(x2))
    for x, v in ((math.exp(x1), f1), (math.exp(x2), f2)):
        if v < best_v:
            best_x, best_v = x, v
    return best_x, best_v


def solve(c: L1Constants, req: DesignRequest) -> L1Design:
    """Find the free parameters of an L1-DRAC design at one objective; implements Sec. 3.2.

    Steps, at fixed (omega, lambda_s):

    1. rho_r: the smallest value satisfying (16a) and (21a)
       (:func:`~drip_cert.bounds.l1drac.searches.smallest_rho_r`).
    2. rho_a: the smallest value satisfying (16b), (21b) and -- when Ts is fixed -- (24)
       (:func:`~drip_cert.bounds.l1drac.searches.smallest_rho_a`).
    3. Ts (when free): the largest value satisfying (24) at that rho_a
       (:func:`~drip_cert.bounds.l1drac.searches.largest_Ts`).
       A larger rho_a buys a larger Ts: see :func:`tradeoff_table`.

    omega free: minimise rho = rho_r + rho_a over log omega in ``omega_bounds`` (a grid of 41
    points, then golden section; omega = 2 lambda excluded). When Ts is also free, rho does not
    depend on Ts and (above 2 lambda) does not increase with omega (Remarks 3.1, 3.2), so the
    minimiser sits at the upper bound and Ts shrinks like 1/omega^2 there: fix Ts or narrow
    ``omega_bounds`` to the filter you can implement. lambda_s free: maximise Ts (Ts free) or
    minimise rho_a (Ts fixed) over log lambda_s in ``lambda_s_bounds``, the same way.
    With everything fixed the function only evaluates.

    Returns
    -------
    L1Design
        Infeasible designs are results (``feasible=False``, ``reason``), not exceptions.

    Raises
    ------
    SpecError
        p outside ``{1..p_star}``, omega = 2 lambda, a Ts so long that exponentials overflow.
    """
    t0 = time.perf_counter()
    p = check_p(c, req.p)
    if req.omega is not None:
        check_omega(c, req.omega)
    if req.Ts is not None:
        check_Ts(
            c, req.omega or 1.0, req.lambda_s or 1.0, req.Ts
        )  # overflow guard on the fixed values
    rc = reference_constants(c, p)
    tc = true_constants(c, p)
    notes: list[str] = []
    how = tuple(
        (n, "given" if getattr(req, n) is not None else "found")
        for n in ("omega", "lambda_s", "Ts", "rho_r", "rho_a")
    )
    lam = c.lam
    ls_bounds = req.lambda_s_bounds or (
        _LAMBDA_S_BOUNDS_REL[0] * lam,
        _LAMBDA_S_BOUNDS_REL[1] * lam,
    )

    def at_omega(omega: float, n_ls: int = _GRID_POINTS) -> tuple[_Point, float | None]:
        """Full inner design at omega, choosing lambda_s if free (n_ls grid points)."""
        if req.lambda_s is not None:
            return _point(c, rc, tc, req, omega, req.lambda_s, find_Ts=True), req.lambda_s
        if req.Ts is None:
            base = _point(c, rc, tc, req, omega, None, find_Ts=False)
            base_r, base_a = base.rho_r, base.rho_a
            if base_r is None or base_a is None:  # _point finds rho_a only after rho_r
                return base, None

            def neg_ts(ls: float) -> float:
                t = max_Ts(c, tc, p, omega, ls, base_r, base_a)
                return math.inf if t is None else -t

            ls, v = _log_search(neg_ts, ls_bounds[0], ls_bounds[1], None)
            return _point(c, rc, tc, req, omega, ls, find_Ts=True), ls

        Ts_given = req.Ts  # not None here (the branch above returned)
        # the points of this search by lambda_s: the design at the chosen one is not searched
        # again (with Ts given, _point's find_Ts changes nothing)
        seen: dict[float, _Point] = {}

        def rho_a_of(ls: float) -> float:
            if max(omega, ls) * Ts_given > EXP_ARG_MAX:
                return math.inf
            pt = seen[ls] = _point(c, rc, tc, req, omega, ls, find_Ts=False)
            return math.inf if pt.rho_a is None else pt.rho_a

        ls, v = _log_search(rho_a_of, ls_bounds[0], ls_bounds[1], None, n_ls)
        if not math.isfinite(v) and max(omega, ls) * Ts_given > EXP_ARG_MAX:
            return _Point(
                None,
                None,
                None,
                f"no lambda_s in [{ls_bounds[0]:.6g}, {ls_bounds[1]:.6g}] gives a design at "
                f"omega = {omega:.6g}, T_s = {Ts_given:.6g} s",
            ), ls
        if ls in seen:
            return seen[ls], ls
        return _point(c, rc, tc, req, omega, ls, find_Ts=True), ls

    if req.omega is not None:
        omega = req.omega
        pt, lambda_s = at_omega(omega)
    else:
        lo, hi = req.omega_bounds or (_OMEGA_BOUNDS_REL[0] * lam, _OMEGA_BOUNDS_REL[1] * lam)

        def rho_of(w: float) -> float:
            if w == 2.0 * lam:
                return math.inf
            if req.Ts is not None and max(w, req.lambda_s or 0.0) * req.Ts > EXP_ARG_MAX:
                return math.inf
            if req.lambda_s is None and req.Ts is not None:
                pt_, _ = at_omega(w, _NESTED_GRID_POINTS)  # nested search: coarser grid
            else:
                pt_ = _point(c, rc, tc, req, w, req.lambda_s, find_Ts=False)
            r_r, r_a = pt_.rho_r, pt_.rho_a
            if r_r is None or r_a is None:  # _point finds rho_a only after rho_r
                return math.inf
            if req.Ts is None:  # (24) must be satisfiable for some Ts: a positive budget
                if not budget_24(c, tc, w, r_r, r_a) > 0.0:
                    return math.inf
            return r_r + r_a

        omega, v = _log_search(rho_of, lo, hi, 2.0 * lam)
        if not math.isfinite(v):
            notes.append(
                f"no omega in [{lo:.6g}, {hi:.6g}] (41-point log grid) gave a feasible design"
            )
        if req.Ts is None and omega >= hi * (1 - 1e-3):
            notes.append(
                "omega sits at the upper end of its search interval: with Ts free, rho decreases "
                "with omega (Remarks 3.1-3.2) while Ts_max shrinks like 1/omega^2; narrow "
                "omega_bounds or fix Ts to trade rho against Ts"
            )
        if req.Ts is not None and not math.isfinite(v):
            # nothing feasible on the grid: evaluating at the grid's last omega could overflow
            pt = _Point(
                None,
                None,
                None,
                f"no omega in [{lo:.6g}, {hi:.6g}] gives a design at T_s = {req.Ts:.6g} s: at "
                "every grid point (16), (21) or (24) fails for every rho_a <= "
                f"{RHO_CAP:g}, or max(omega, lambda_s) T_s exceeds {EXP_ARG_MAX:g}",
            )
            lambda_s = req.lambda_s
        else:
            pt, lambda_s = at_omega(omega)

    rho_r, rho_a, Ts = pt.rho_r, pt.rho_a, pt.Ts
    backoff: tuple[tuple[str, float], ...] = ()
    backoff_reason = ""
    if rho_r is not None and rho_a is not None and Ts is not None and lambda_s is not None:
        bo = back_off(c, rc, tc, req, p, omega, lambda_s, rho_r, rho_a, Ts)
        rho_r, rho_a, Ts = bo.rho_r, bo.rho_a, bo.Ts
        backoff, backoff_reason = bo.factors, bo.reason
        if backoff:
            notes.append(
                "moved off the float roots into the interior until every condition was verified "
                "in Arb ball arithmetic: "
                + ", ".join(
                    f"{k} {'divided' if k == 'Ts' else 'multiplied'} by 1 + {f - 1.0:.0e}"
                    for k, f in backoff
                )
            )
    rho = None if rho_r is None or rho_a is None else rho_r + rho_a
    present = {
        "16a": rho_r is not None,
        "21a": rho_r is not None,
        "16b": rho_a is not None,
        "21b": rho_a is not None,
        # rho_r too: (24) reads it (implied: rho_a is only found after rho_r)
        "24": rho_r is not None and rho_a is not None and Ts is not None and lambda_s is not None,
    }
    which = tuple(eq for eq in CONDITIONS if present[eq])
    conditions = float_conditions(
        c, rc, tc, p, omega, which, rho_r=rho_r, rho_a=rho_a, lambda_s=lambda_s, Ts=Ts
    )
    if (
        req.Ts is None
        and rho_r is not None
        and rho_a is not None
        and Ts is not None
        and lambda_s is not None
    ):  # present["24"], spelt out
        env = float_24(c, tc, p, omega, lambda_s, Ts, rho_r, rho_a, envelope=True)
        notes.append(
            f"Ts is the largest value for which the monotone envelope of (24) holds, divided "
            f"by the back-off factor (envelope lhs {env.lhs:.6g}, paper's lhs "
            f"{conditions[-1].lhs:.6g})"
        )
    if conditions:
        conditions = with_arb_margins(
            c, p, conditions, omega, lambda_s=lambda_s, Ts=Ts, rho_r=rho_r, rho_a=rho_a
        )
    failing = [r for r in conditions if not r.holds and not r.verified]
    unverified = [r for r in conditions if r.holds and not r.verified]
    complete = len(conditions) == 5
    feasible = complete and not failing and not unverified
    for r in conditions:
        if r.verified and not r.holds:
            notes.append(
                f"({r.eq}): the float64 margin {r.margin:.6g} is not positive but the Arb "
                f"enclosure of the margin, [{r.margin_lo:.6g}, {r.margin_hi:.6g}], is: the float "
                "evaluation loses digits to cancellation; the verdict is the verified one"
            )
    if feasible:
        reason = ""
    elif failing or unverified:
        reason = "; ".join(
            [
                f"({r.eq}) fails by {-r.margin:.6g} (lhs {r.lhs:.6g} {r.relation} rhs "
                f"{r.rhs:.6g} is false; Arb enclosure of the margin [{r.margin_lo:.6g}, "
                f"{r.margin_hi:.6g}])"
                for r in failing
            ]
            + [
                f"({r.eq}) is not verified: its float64 margin {r.margin:.6g} is positive but the "
                f"Arb enclosure of its margin is [{r.margin_lo:.6g}, {r.margin_hi:.6g}], whose "
                "lower end is not > 0"
                for r in unverified
            ]
        )
        if backoff_reason:
            reason = backoff_reason + "; " + reason
    else:
        reason = pt.reason or "design incomplete"
    if feasible and rho_a is not None and req.Ts is None and req.rho_a is None:
        b, th, _ = budget_a(c, tc, omega, rho_r, rho_a)
        if b - th < 1e-3 * (b + th + 1e-300):
            notes.append(
                "(21b) binds at the smallest rho_a, leaving almost no room for (24); a larger "
                "rho_a (tradeoff_table) or eps_a gives a much larger Ts"
            )
    kappa = None
    if req.delta is not None and rho is not None:
        kappa = kappa_markov(rho, p, req.delta)
        p_paper = p_for_delta(req.delta, 10**9)
        notes.append(
            f"kappa = rho(p) delta^(-1/(2p)) at the design's p = {p} (valid for any delta by the "
            f"Markov step of Theorem 4.1); Theorem 4.1's choice for this delta is "
            f"p = ceil(log sqrt(1/delta)) = {p_paper}, where kappa <= e rho(p)"
        )
    return L1Design(
        feasible=feasible,
        p=p,
        omega=omega,
        lambda_s=lambda_s,
        Ts=Ts,
        rho_r=rho_r,
        rho_a=rho_a,
        rho=rho,
        kappa=kappa,
        conditions=conditions,
        reason=reason,
        notes=tuple(notes),
        delta=req.delta,
        how=how,
        seconds=time.perf_counter() - t0,
        backoff=backoff,
    )


#: Grid points of each one-dimensional pass of :func:`params_at_Ts`: a front point needs a good
#: (omega, lambda_s), not the best one the nested search of :func:`solve` finds at 41 x 13.
_FRONT_GRID_POINTS = 21


def params_at_Ts(
    c: L1Constants, rc: RefConstants, tc: TrueConstants, req: DesignRequest, Ts: float
) -> tuple[float, float] | None:
    """A good (omega, lambda_s) for the smallest rho at the fixed ``Ts``; None if none found.

    Coordinate search: omega minimising rho = rho_r + rho_a (16a), (16b), (21a), (21b), (24) at
    a start lambda_s (the geometric middle of its interval), then lambda_s minimising rho_a at
    that omega, then omega again; each pass a log grid of 21 points and golden section
    (:func:`_log_search`). Parameters ``req`` fixes are kept. A heuristic for the optimum, like
    the nested search of :func:`solve` but about 10 times cheaper; nothing is certified from
    it: the front calls :func:`solve` at the returned values, which re-solves the radii and
    verifies the point in Arb.
    """
    lam = c.lam
    at = DesignRequest(
        p=req.p, Ts=Ts, rho_r=req.rho_r, rho_a=req.rho_a, objective="rho_at_Ts", front=False
    )
    ls_lo, ls_hi = req.lambda_s_bounds or (
        _LAMBDA_S_BOUNDS_REL[0] * lam,
        _LAMBDA_S_BOUNDS_REL[1] * lam,
    )
    w_lo, w_hi = req.omega_bounds or (_OMEGA_BOUNDS_REL[0] * lam, _OMEGA_BOUNDS_REL[1] * lam)

    seen: dict[tuple[float, float], float] = {}  # each (omega, lambda_s) searched once

    def rho(w: float, ls: float) -> float:
        if w == 2.0 * lam or max(w, ls) * Ts > EXP_ARG_MAX:
            return math.inf
        if (w, ls) not in seen:
            pt = _point(c, rc, tc, at, w, ls, find_Ts=False)
            seen[w, ls] = (
                pt.rho_r + pt.rho_a if pt.rho_r is not None and pt.rho_a is not None else math.inf
            )
        return seen[w, ls]

    ls = req.lambda_s if req.lambda_s is not None else math.sqrt(ls_lo * ls_hi)
    omega = req.omega if req.omega is not None else math.sqrt(w_lo * w_hi)

    def omega_pass() -> float:
        if req.omega is not None:
            return omega
        ls_ = ls
        return _log_search(lambda w: rho(w, ls_), w_lo, w_hi, 2.0 * lam, _FRONT_GRID_POINTS)[0]

    def lambda_s_pass() -> float:
        if req.lambda_s is not None:
            return ls
        w_ = omega
        return _log_search(lambda x: rho(w_, x), ls_lo, ls_hi, None, _FRONT_GRID_POINTS)[0]

    omega = omega_pass()
    ls = lambda_s_pass()
    if req.omega is None and req.lambda_s is None:
        omega = omega_pass()
    return (omega, ls) if math.isfinite(rho(omega, ls)) else None
