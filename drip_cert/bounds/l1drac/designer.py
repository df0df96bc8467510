"""The L1-DRAC designer: the user's objective, the (Ts, rho) Pareto front, the rho_a / Ts trade-off.

Source: A. Gahlawat, S. H. Karumanchi, N. Hovakimyan, "L1-DRAC: Distributionally Robust Adaptive
Control -- Global Results", arXiv:2509.04619 (2025-09-04). Sec. 3.2 (conditions (16), (21), (24);
Remarks 3.1, 3.2), Theorem 4.1 (kappa). The transcription used is ``docs/math/l1drac.md``; every
formula was re-checked against the PDF. The objectives and the front: ``docs/math/l1drac.md``
section 5.4.

Public surface
--------------
* :func:`design` -- find the free parameters for the request's objective
  (:data:`~drip_cert.bounds.l1drac.request.OBJECTIVES`): ``Ts`` given -> the smallest rho;
  ``rho_budget`` given -> the largest ``Ts``; neither -> the smallest rho at the practical
  ``Ts`` (:data:`~drip_cert.bounds.l1drac.request.PRACTICAL_TS`) when a design there is
  verified and not a knife edge, else the largest-``Ts`` front point that is not one. Returns an
  :class:`~drip_cert.bounds.l1drac.result.L1Design` carrying the objective, the reason for the
  choice and the front (never raises for an infeasible design: ``feasible=False``, ``reason``).
* :func:`pareto_front` -- the verified (Ts, rho) Pareto front over omega, lambda_s and rho_a.
* :func:`knife_edge` -- why a design is a knife edge (re-exported from
  :mod:`~drip_cert.bounds.l1drac.result`).
* :class:`TradeoffRow`, :func:`tradeoff_table` -- (rho_a, Ts_max, rho) rows at one (omega,
  lambda_s): a larger rho_a buys a larger Ts.

Every design returned, and every point of the front, went through
:func:`~drip_cert.bounds.l1drac.solve.solve`: radii re-solved at full tolerance, moved into the
interior (:mod:`~drip_cert.bounds.l1drac.backoff`) and verified in Arb ball arithmetic
(:mod:`~drip_cert.bounds.l1drac.verify`); the searches that pick (omega, lambda_s) are
heuristics whose answers are never trusted unchecked.
"""

from __future__ import annotations

import dataclasses
import math
import time
from dataclasses import dataclass
from typing import Any

from drip_cert.bounds.l1drac.appendix import reference_constants, true_constants
from drip_cert.bounds.l1drac.conditions import (
    EXP_ARG_MAX,
    check_omega,
    check_p,
    float_16b,
    float_21b,
)
from drip_cert.bounds.l1drac.constants import L1Constants
from drip_cert.bounds.l1drac.request import DesignRequest
from drip_cert.bounds.l1drac.result import FrontPoint, L1Design, knife_edge
from drip_cert.bounds.l1drac.searches import max_Ts, min_rho_a, min_rho_r
from drip_cert.bounds.l1drac.solve import (
    _LAMBDA_S_BOUNDS_REL,
    _OMEGA_BOUNDS_REL,
    _log_search,
    params_at_Ts,
    solve,
)

__all__ = [
    "FRONT_TS_GRID",
    "design",
    "pareto_front",
    "knife_edge",
    "TradeoffRow",
    "tradeoff_table",
]

#: The sampling periods (seconds) at which the front looks for the smallest rho: every decade
#: from KNIFE_EDGE_TS_MIN = 1 ns (below it every design is a knife edge) to 1 s (slower than any
#: loop this calculator designs for; the front usually ends well before, where (24) cannot hold
#: for any rho_a). The practical Ts and a given Ts are added to it.
FRONT_TS_GRID = tuple(10.0**k for k in range(-9, 1))
#: Relative margin by which the ``Ts_at_rho`` objective keeps rho_r above its smallest value when
#: it splits the budget (rho_a = budget - rho_r (1 + this)): twice the largest back-off of rho_r
#: (1e-3, :data:`~drip_cert.bounds.l1drac.backoff.BACKOFF_STEPS`), so the design verified after
#: the back-off still has rho <= budget.
BUDGET_SPLIT_SLACK = 2e-3


def _internal(req: DesignRequest, objective: str, **changes: Any) -> DesignRequest:
    """``req`` with ``changes`` and ``objective``, no budget and no front (for :func:`solve`)."""
    return dataclasses.replace(req, objective=objective, rho_budget=None, front=False, **changes)


def _infeasible(req: DesignRequest, reason: str) -> L1Design:
    """A result for a request the solver cannot even evaluate (no conditions)."""
    return L1Design(
        feasible=False,
        p=req.p,
        omega=req.omega,
        lambda_s=req.lambda_s,
        Ts=req.Ts,
        rho_r=req.rho_r,
        rho_a=req.rho_a,
        rho=None,
        kappa=None,
        conditions=(),
        reason=reason,
        delta=req.delta,
    )


def _safe_solve(c: L1Constants, req: DesignRequest) -> L1Design:
    """:func:`solve`, with a ``Ts`` too long for the fixed omega / lambda_s (exponentials
    overflow: ``check_Ts``) turned into an infeasible result instead of an exception."""
    if req.Ts is not None and max(req.omega or 0.0, req.lambda_s or 0.0) * req.Ts > EXP_ARG_MAX:
        return _infeasible(
            req,
            f"T_s = {req.Ts:.6g} s is too long for the fixed omega = {req.omega} / lambda_s = "
            f"{req.lambda_s}: max(omega, lambda_s) T_s exceeds {EXP_ARG_MAX:g}, where the "
            "exponentials of (A.13)-(A.19) overflow; (24) cannot hold there",
        )
    return solve(c, req)


def _point_of(d: L1Design, source: str) -> FrontPoint:
    """The front point of a feasible design (every field present: (24) was verified)."""
    assert d.Ts is not None and d.rho is not None and d.rho_r is not None
    assert d.rho_a is not None and d.omega is not None and d.lambda_s is not None
    return FrontPoint(
        Ts=d.Ts,
        rho=d.rho,
        rho_r=d.rho_r,
        rho_a=d.rho_a,
        omega=d.omega,
        lambda_s=d.lambda_s,
        verified=d.verified,
        knife_edge=knife_edge(d),
        source=source,
    )


def _pareto(cands: list[tuple[str, L1Design]]) -> list[tuple[str, L1Design]]:
    """The non-dominated feasible designs, sorted by Ts: no other has Ts >= and rho <= with
    one of them strict (equal points: the first listed is kept)."""
    ok = [(s, d) for s, d in cands if d.feasible and d.Ts is not None and d.rho is not None]
    ok.sort(key=lambda sd: (-(sd[1].Ts or 0.0), sd[1].rho))
    out: list[tuple[str, L1Design]] = []
    best = math.inf
    for s, d in ok:
        assert d.rho is not None
        if d.rho < best:
            out.append((s, d))
            best = d.rho
    return out[::-1]


def _front_designs(
    c: L1Constants, req: DesignRequest, grid: tuple[float, ...]
) -> tuple[list[tuple[str, L1Design]], L1Design]:
    """Every verified candidate of the front, with its source, and the ``min_rho`` design.

    Candidates: the ``min_rho`` design (the infimum of rho; with rho_a fixed, the largest Ts at
    the user's radii), then, for each grid Ts in increasing order, :func:`solve` at the
    (omega, lambda_s) of :func:`~drip_cert.bounds.l1drac.solve.params_at_Ts`. The scan stops at
    the first infeasible Ts after a feasible one: on the monotone envelope of (24) the left side
    grows with Ts at every (omega, lambda_s, rho_a) (docs/math/l1drac.md section 5.3), so a larger
    Ts is infeasible too (up to the envelope's relative O(lambda_s Ts) slack).
    """
    p = check_p(c, req.p)
    rc, tc = reference_constants(c, p), true_constants(c, p)
    d0 = _safe_solve(c, _internal(req, "min_rho", Ts=None))
    out: list[tuple[str, L1Design]] = []
    if d0.feasible:
        out.append(("fixed radii" if req.rho_a is not None else "min_rho", d0))
    seen = False
    for Ts in sorted(set(grid)):
        pr = params_at_Ts(c, rc, tc, req, Ts)
        d = None
        if pr is not None:
            d = _safe_solve(c, _internal(req, "rho_at_Ts", Ts=Ts, omega=pr[0], lambda_s=pr[1]))
        if d is not None and d.feasible:
            out.append(("Ts grid", d))
            seen = True
        elif seen:
            break
    return out, d0


def pareto_front(
    c: L1Constants, req: DesignRequest, Ts_grid: tuple[float, ...] | None = None
) -> tuple[FrontPoint, ...]:
    """The (Ts, rho) Pareto front of verified L1-DRAC designs, sorted by Ts (Sec. 3.2).

    Over the parameters ``req`` leaves free (omega, lambda_s, rho_r, rho_a): the smallest rho
    at each Ts of ``Ts_grid`` (default :data:`FRONT_TS_GRID` plus ``req.practical_Ts`` and
    ``req.Ts``) and the infimum of rho (objective ``"min_rho"``), every one a design verified in
    Arb (:func:`~drip_cert.bounds.l1drac.solve.solve`), then the non-dominated ones: no point
    of the front has another with ``Ts >=`` and ``rho <=``, one strict. Along it rho increases
    with Ts. Points flagged by :func:`knife_edge` stay on the front (with the reason) but are
    never the default's choice. The (omega, lambda_s) of each grid point comes from a coordinate
    search (a heuristic): a point's rho is the smallest found, a verified upper bound on the
    smallest rho at its Ts.
    """
    grid = _grid(req) if Ts_grid is None else tuple(Ts_grid)
    cands, _ = _front_designs(c, req, grid)
    return tuple(_point_of(d, s) for s, d in _pareto(cands))


def _grid(req: DesignRequest) -> tuple[float, ...]:
    extra = (req.practical_Ts,) + (() if req.Ts is None else (req.Ts,))
    return tuple(sorted(set(FRONT_TS_GRID + extra)))


def _how(req: DesignRequest) -> tuple[tuple[str, str], ...]:
    return tuple(
        (n, "given" if getattr(req, n) is not None else "found")
        for n in ("omega", "lambda_s", "Ts", "rho_r", "rho_a")
    )


def _largest_ts_text(cands: list[tuple[str, L1Design]]) -> str:
    """What the front says about feasibility: its largest verified Ts, rho there."""
    pts = [d for _, d in _pareto(cands)]
    if not pts:
        return "no verified design at any T_s of the front's grid (1 ns to 1 s) either"
    top = pts[-1]
    return (
        f"the largest T_s of the front with a verified design is {top.Ts:.3g} s "
        f"(rho = {top.rho:.6g}, omega = {top.omega:.6g}, lambda_s = {top.lambda_s:.6g})"
    )


def _at_Ts(
    c: L1Constants, req: DesignRequest, Ts: float, cands: list[tuple[str, L1Design]]
) -> L1Design:
    """The smallest rho at ``Ts``: the nested search of :func:`solve` or, when better, the
    front's point at the same Ts (both verified; the searches are heuristics)."""
    d = _safe_solve(c, _internal(req, "rho_at_Ts", Ts=Ts))
    for _, g in cands:
        if g.feasible and g.Ts == Ts and g.rho is not None:
            if not d.feasible or d.rho is None or g.rho < d.rho:
                d = g
    return d


def design(c: L1Constants, req: DesignRequest) -> L1Design:
    """Find the free parameters of an L1-DRAC design for ``req.objective`` (Sec. 3.2).

    Objectives (:data:`~drip_cert.bounds.l1drac.request.OBJECTIVES`):

    * ``"rho_at_Ts"`` (``Ts`` given): the smallest rho = rho_r + rho_a (17) over the free omega,
      lambda_s: rho_r the smallest satisfying (16a), (21a), rho_a the smallest satisfying (16b),
      (21b) and (24) at that Ts (:func:`~drip_cert.bounds.l1drac.solve.solve`); no larger than
      the front's point at that Ts. With ``rho_budget`` too, infeasible when rho exceeds it.
      Infeasible: the reason names the largest Ts of the front with a verified design.
    * ``"Ts_at_rho"`` (``rho_budget`` given): the largest Ts with rho <= budget. At each omega,
      rho_r is the smallest and rho_a = budget - rho_r (1 + BUDGET_SPLIT_SLACK): Ts_max is
      non-decreasing in rho_a (:func:`tradeoff_table`), so the whole budget goes to rho_a; then
      omega and lambda_s maximise Ts (coordinate search) and the point is verified.
    * ``"default"``: the smallest rho at ``req.practical_Ts`` (1e-3 s) when that design is
      verified and not a knife edge (:func:`knife_edge`); otherwise the largest-Ts point of the
      front that is not a knife edge, and ``choice`` says why; otherwise infeasible with the
      reason (a knife edge is never the default).
    * ``"min_rho"``: the smallest radii, then the largest Ts (24) allows (the infimum of rho;
      with omega free it sits at the top of the omega interval, Remarks 3.1, 3.2, and Ts
      shrinks like 1/omega^2 there): a knife edge whenever rho_a is found.

    The front (:func:`pareto_front`) is computed for every objective unless ``req.front`` is
    False (the default objective computes it whenever 1e-3 s fails, to choose from it).

    Returns
    -------
    L1Design
        With ``objective``, ``choice``, ``knife_edge`` and ``front`` set. Infeasible designs are
        results (``feasible=False``, ``reason``), not exceptions.

    Raises
    ------
    SpecError
        p outside ``{1..p_star}``, omega = 2 lambda.
    """
    t0 = time.perf_counter()
    check_p(c, req.p)
    if req.omega is not None:
        check_omega(c, req.omega)
    obj = req.objective or "default"
    cands: list[tuple[str, L1Design]] = []
    need_front = req.front

    def front_cands() -> list[tuple[str, L1Design]]:
        nonlocal cands, need_front
        if not cands:
            cands = _front_designs(c, req, _grid(req))[0]
        need_front = True
        return cands

    choice = ""
    if obj == "min_rho":
        d = _safe_solve(c, _internal(req, "min_rho"))
        choice = "the smallest rho over the free parameters, then the largest T_s (24) allows"
    elif obj == "rho_at_Ts":
        assert req.Ts is not None
        d = _at_Ts(c, req, req.Ts, front_cands() if req.front else [])
        choice = f"the smallest rho at the given T_s = {req.Ts:.6g} s"
        if not d.feasible:
            d = dataclasses.replace(
                d, reason=f"{d.reason}; {_largest_ts_text(front_cands())}: use T_s <= that"
            )
        elif req.rho_budget is not None and d.rho is not None and d.rho > req.rho_budget:
            d = dataclasses.replace(
                d,
                feasible=False,
                reason=f"the smallest rho at T_s = {req.Ts:.6g} s is {d.rho:.6g}, above "
                f"rho_budget = {req.rho_budget:.6g}: raise the budget or shorten T_s",
            )
    elif obj == "Ts_at_rho":
        assert req.rho_budget is not None
        d, choice = _ts_at_rho(c, req)
        # the search runs on the envelope of (24), which can be loose where lambda_s Ts is not
        # small: a verified front point within the budget with a larger Ts wins
        within = [
            g
            for _, g in (front_cands() if req.front else [])
            if g.feasible and g.rho is not None and g.rho <= req.rho_budget and g.Ts is not None
        ]
        best = max(within, key=lambda g: (g.Ts or 0.0, -(g.rho or 0.0)), default=None)
        if best is not None and (not d.feasible or d.Ts is None or (best.Ts or 0.0) > d.Ts):
            d = best
            choice = (
                f"the largest T_s with rho <= rho_budget = {req.rho_budget:.6g}: a point of the "
                "(T_s, rho) front (the budget-split search on the envelope of (24) found a "
                "smaller T_s)"
            )
    else:
        d, choice = _default(c, req, front_cands)
    front: tuple[FrontPoint, ...] = ()
    if need_front:
        # the returned design first: an equal grid point is then dropped, not the design
        pool = ([("chosen", d)] if d.feasible else []) + front_cands()
        front = tuple(_point_of(g, s) for s, g in _pareto(pool))
    return dataclasses.replace(
        d,
        objective=obj,
        choice=choice,
        knife_edge=knife_edge(d),
        front=front,
        rho_budget=req.rho_budget,
        practical_Ts=req.practical_Ts,
        how=_how(req),
        seconds=time.perf_counter() - t0,
    )


def _ts_at_rho(c: L1Constants, req: DesignRequest) -> tuple[L1Design, str]:
    """The ``"Ts_at_rho"`` objective: the largest Ts with rho <= ``req.rho_budget``."""
    assert req.rho_budget is not None
    B = req.rho_budget
    p = check_p(c, req.p)
    rc, tc = reference_constants(c, p), true_constants(c, p)
    lam = c.lam

    def split(w: float) -> tuple[float, float] | None:
        """(rho_r, rho_a) at omega w: smallest rho_r (with slack), the rest of B to rho_a."""
        if req.rho_r is not None:
            r = req.rho_r
        else:
            r0 = min_rho_r(c, rc, w, ("16a", "21a"))
            if r0 is None:
                return None
            r = r0 * (1.0 + BUDGET_SPLIT_SLACK)
        a = req.rho_a if req.rho_a is not None else B - r
        if not a > 0.0 or r + a > B:
            return None
        a_min = min_rho_a(c, tc, p, w, r, None, None, ("16b", "21b"))
        if a_min is None or a < a_min:
            return None
        return r, a

    def neg_ts(w: float, ls: float) -> float:
        if w == 2.0 * lam:
            return math.inf
        ra = split(w)
        if ra is None:
            return math.inf
        t = max_Ts(c, tc, p, w, ls, ra[0], ra[1])
        return math.inf if t is None else -t

    ls_lo, ls_hi = req.lambda_s_bounds or (
        _LAMBDA_S_BOUNDS_REL[0] * lam,
        _LAMBDA_S_BOUNDS_REL[1] * lam,
    )
    w_lo, w_hi = req.omega_bounds or (_OMEGA_BOUNDS_REL[0] * lam, _OMEGA_BOUNDS_REL[1] * lam)
    ls = req.lambda_s if req.lambda_s is not None else math.sqrt(ls_lo * ls_hi)
    omega = req.omega if req.omega is not None else math.sqrt(w_lo * w_hi)

    def omega_pass(ls_: float) -> float:
        if req.omega is not None:
            return req.omega
        return _log_search(lambda w: neg_ts(w, ls_), w_lo, w_hi, 2.0 * lam)[0]

    def lambda_s_pass(w_: float) -> float:
        if req.lambda_s is not None:
            return req.lambda_s
        return _log_search(lambda x: neg_ts(w_, x), ls_lo, ls_hi, None)[0]

    omega = omega_pass(ls)
    ls = lambda_s_pass(omega)
    omega = omega_pass(ls)
    ra = split(omega)
    if ra is None or not math.isfinite(neg_ts(omega, ls)):
        d0 = _safe_solve(c, _internal(req, "min_rho", Ts=None))
        if d0.feasible and d0.rho is not None:
            why = (
                f"rho_budget = {B:.6g} is below the smallest rho found with a verified design, "
                f"{d0.rho:.6g} (omega = {d0.omega:.6g}, T_s = {d0.Ts:.3g} s): raise rho_budget "
                "above it"
            )
        else:
            why = f"no design satisfies (16), (21), (24) at any rho: {d0.reason}"
        return _infeasible(req, why), "the largest T_s with rho <= rho_budget"
    # the budget split fixes rho_a; rho_r stays free so that the back-off verifies it
    d = _safe_solve(
        c,
        _internal(
            req,
            "min_rho",
            Ts=None,
            omega=omega,
            lambda_s=ls,
            rho_a=ra[1],
        ),
    )
    if d.feasible and d.rho is not None and d.rho > B:
        d = dataclasses.replace(
            d,
            feasible=False,
            reason=f"rho = {d.rho:.17g} exceeds rho_budget = {B:.17g} after the back-off",
        )
    return d, (
        f"the largest T_s with rho <= rho_budget = {B:.6g}: rho_r smallest, the rest of the "
        "budget to rho_a (T_s grows with rho_a), omega and lambda_s maximising T_s"
    )


def _default(c: L1Constants, req: DesignRequest, front_cands: Any) -> tuple[L1Design, str]:
    """The ``"default"`` objective: the practical Ts, else the front's largest non-knife-edge Ts."""
    Tp = req.practical_Ts
    cands: list[tuple[str, L1Design]] = front_cands() if req.front else []
    d1 = _at_Ts(c, req, Tp, cands)
    edge = knife_edge(d1)
    if d1.feasible and not edge:
        # a front point with no larger rho at a longer Ts dominates it (e.g. radii fixed by the
        # user, where rho does not depend on Ts): the longest such Ts
        dom = [
            (src, g)
            for src, g in _pareto(front_cands())
            if not knife_edge(g)
            and (g.Ts or 0.0) > Tp
            and g.rho is not None
            and d1.rho is not None
            and g.rho <= d1.rho
        ]
        if dom:
            src, g = max(dom, key=lambda sd: sd[1].Ts or 0.0)
            return g, (
                f"a design at T_s = {g.Ts:.3g} s with rho no larger than the smallest rho at the "
                f"practical T_s = {Tp:g} s (it dominates that design on the (T_s, rho) front; "
                f"source: {src})"
            )
        return d1, (
            f"the smallest rho at the practical T_s = {Tp:g} s (PRACTICAL_TS; a knife edge is "
            "never the default)"
        )
    why1 = edge if d1.feasible else d1.reason
    cands = front_cands()
    ok = [(s, d) for s, d in _pareto(cands) if not knife_edge(d)]
    if ok:
        s, d = max(ok, key=lambda sd: (sd[1].Ts or 0.0, -(sd[1].rho or math.inf)))
        return d, (
            f"no design at the practical T_s = {Tp:g} s ({why1}); returned the largest-T_s "
            f"design of the (T_s, rho) front that is not a knife edge (T_s = {d.Ts:.3g} s, "
            f"source: {s})"
        )
    edges = [d for _, d in _pareto(cands)]
    tail = (
        f"every verified design of the (T_s, rho) front is a knife edge (the largest T_s is "
        f"{edges[-1].Ts:.3g} s, rho = {edges[-1].rho:.6g}: {knife_edge(edges[-1])})"
        if edges
        else "no verified design at any T_s of the front's grid (1 ns to 1 s)"
    )
    fix = (
        'to accept a knife-edge design, set objective = "min_rho" or give Ts or rho_budget '
        "explicitly; a larger eps_a or a fixed larger rho_a leaves (24) more room"
    )
    reason = f"no default design: at the practical T_s = {Tp:g} s, {why1}; {tail}; {fix}"
    if d1.feasible:  # verified but a knife edge: not returned as feasible
        d1 = dataclasses.replace(d1, feasible=False)
    return dataclasses.replace(d1, reason=reason), "none: " + reason


@dataclass(frozen=True)
class TradeoffRow:
    """One row of :func:`tradeoff_table`: a rho_a, the largest Ts (24) allows with it, rho."""

    rho_a: float
    Ts_max: float | None
    rho: float


def tradeoff_table(
    c: L1Constants,
    p: int,
    omega: float,
    lambda_s: float,
    rho_a_values: tuple[float, ...] | None = None,
    *,
    n: int = 12,
    max_factor: float = 100.0,
) -> tuple[TradeoffRow, ...]:
    """Rows (rho_a, Ts_max, rho = rho_r + rho_a): a larger rho_a buys a larger admissible Ts.

    rho_r is the smallest satisfying (16a) and (21a). ``rho_a_values`` default: ``n`` values,
    log-uniform from the smallest rho_a satisfying (16b) and (21b) (times 1 + 1e-6) to
    ``max_factor`` times it; values below that smallest rho_a are kept and get ``Ts_max = None``.
    Ts_max is :func:`~drip_cert.bounds.l1drac.searches.largest_Ts`; it is non-decreasing in
    rho_a, because (24) at fixed Ts holds on an up-set of rho_a (proof in
    :func:`~drip_cert.bounds.l1drac.searches.smallest_rho_a`; the envelope has the same
    structure).
    """
    p = check_p(c, p)
    check_omega(c, omega)
    rc = reference_constants(c, p)
    tc = true_constants(c, p)
    rho_r = min_rho_r(c, rc, omega, ("16a", "21a"))
    if rho_r is None:
        return ()
    a_min = min_rho_a(c, tc, p, omega, rho_r, None, None, ("16b", "21b"))
    if a_min is None:
        return ()
    if rho_a_values is None:
        a0 = a_min * (1.0 + 1e-6)
        rho_a_values = tuple(a0 * max_factor ** (i / max(n - 1, 1)) for i in range(n))
    rows = []
    for a in rho_a_values:
        ok = float_16b(c, tc, omega, a).holds and float_21b(c, tc, omega, rho_r, a).holds
        ts = max_Ts(c, tc, p, omega, lambda_s, rho_r, a) if ok else None
        rows.append(TradeoffRow(float(a), ts, rho_r + float(a)))
    return tuple(rows)
