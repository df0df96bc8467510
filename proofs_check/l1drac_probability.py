"""DRIP Theorem "L1DRAC" (drip_paper.tex ~l.1096) and L1-DRAC Thm 4.1 (130): the probability steps.

* ``L_p`` inclusion: ``E||Z|| <= E[||Z||^{2p}]^{1/(2p)}`` (Jensen; symbolic convexity of
  ``x^{2p}`` and random / adversarial laws);
* Markov step: with ``kappa = e rho`` and ``p = log sqrt(1/delta)``,
  ``P(||Z|| >= kappa) <= (rho/kappa)^{2p} = delta`` (symbolic, and extremal two-point laws);
* integer-p variant (docs/math/l1drac.md, [derived]): ``p = ceil(log(1/delta)/2)``,
  ``kappa = rho(p) delta^{-1/(2p)} <= e rho(p)`` and ``(rho/kappa)^{2p} = delta`` for every
  ``delta in (0, 1)``.
"""

from __future__ import annotations

import math

import numpy as np
import sympy as sp
from scipy.optimize import minimize
from scipy.special import logsumexp

from proofs_check._core import CheckResult, Context, register, result

LABEL = "DRIP Thm. L1DRAC (thm:L1DRAC) / L1-DRAC Thm 4.1"

LP_REL_TOL = 1e-12  # E|Z| vs ||Z||_2p evaluated with logsumexp on <= 2000 samples: rounding
MARKOV_TOL = 1e-12  # tail frequency vs delta: both computed exactly up to rounding
KAPPA_REL_TOL = 1e-14  # delta^{-1/(2p)} vs e: one exp/log in double precision


def _lp_norm(z: np.ndarray, w: np.ndarray, r: float) -> float:
    """``(sum_i w_i z_i^r)^{1/r}`` for z >= 0 in log space (no overflow for large r)."""
    pos = z > 0
    if not pos.any():
        return 0.0
    return float(np.exp(logsumexp(r * np.log(z[pos]), b=w[pos]) / r))


@register("l1drac.lp_inclusion", LABEL + ", L_p inclusion E|Z| <= ||Z||_{L_2p}")
def check_lp_inclusion(ctx: Context) -> CheckResult:
    """Jensen: symbolic convexity of x^{2p}; random heavy-tailed laws; adversarial 3-point laws."""
    name = "l1drac.lp_inclusion"
    x = sp.symbols("x", positive=True)
    p = sp.symbols("p", positive=True, integer=True)
    d2 = sp.simplify(sp.diff(x ** (2 * p), x, 2))
    sym_ok = bool(d2.is_nonnegative)
    rng = ctx.rng
    worst = -np.inf
    n_laws = ctx.count(600, 60)
    for k in range(n_laws):
        size = int(rng.integers(1, 2000))
        kind = k % 4
        if kind == 0:
            z = rng.lognormal(0.0, rng.uniform(0.1, 3.0), size)
        elif kind == 1:
            z = rng.pareto(rng.uniform(0.5, 5.0), size)
        elif kind == 2:
            z = np.linalg.norm(rng.normal(size=(size, int(rng.integers(1, 6)))), axis=1)
        else:
            z = rng.choice([0.0, float(rng.exponential())], size=size, p=[0.3, 0.7])
        w = rng.dirichlet(np.ones(size))
        mean = float(w @ z)
        for pp in (1, 2, 3, 5, 8, 20):
            nrm = _lp_norm(z, w, 2 * pp)
            if nrm > 0:
                worst = max(worst, (mean - nrm) / nrm)
    # adversarial: three-point laws, maximise E|Z| / ||Z||_{2p} (sup is 1, at constants)
    best = 0.0
    for pp in (1, 4):

        def neg(zz, pp=pp):
            vals = np.exp(zz[:3])
            wts = np.exp(zz[3:]) / np.exp(zz[3:]).sum()
            return -float(wts @ vals) / _lp_norm(vals, wts, 2 * pp)

        for _ in range(ctx.count(6, 2)):
            r = minimize(neg, rng.normal(size=6), method="Nelder-Mead")
            best = max(best, -float(r.fun))
    worst = max(worst, best - 1.0)
    ok = sym_ok and worst <= LP_REL_TOL
    return result(
        name,
        LABEL + ", L_p inclusion E|Z| <= ||Z||_{L_2p}",
        holds=bool(ok),
        residual=worst,
        detail=(
            f"d^2/dx^2 x^(2p) = {d2} >= 0; {n_laws} random laws x p in {{1,2,3,5,8,20}} and "
            f"Nelder-Mead on 3-point laws (best ratio {best:.12f}): max rel violation {worst:.2e}"
        ),
    )


@register("l1drac.markov_step", LABEL + ", Markov step kappa = e rho(log sqrt(1/delta))")
def check_markov(ctx: Context, p_factor: float = 1.0) -> CheckResult:
    """``(rho/kappa)^{2p} = delta`` for kappa = e rho, p = log sqrt(1/delta); extremal laws.

    ``p_factor`` multiplies the moment order (1 is the paper's); a smaller order (a wrong
    Markov exponent) gives a tail probability above delta and must fail.
    """
    name = "l1drac.markov_step"
    dl, rho = sp.symbols("delta rho", positive=True)
    pp = sp.nsimplify(p_factor) * sp.log(sp.sqrt(1 / dl))
    tail = (rho / (sp.E * rho)) ** (2 * pp)
    sym = sp.simplify(sp.powsimp(sp.expand_log(tail, force=True), force=True))
    sym_ok = sp.simplify(sym - dl) == 0 or bool(sp.simplify(sym - dl).is_nonpositive)
    rng = ctx.rng
    worst = -np.inf
    for p_int in range(1, 9):
        delta = math.exp(-2 * p_int)  # the deltas at which the theorem's p is an integer
        p_used = p_factor * p_int
        kappa = math.e  # rho = 1
        # extremal two-point law {0, kappa} with P(kappa) = (rho/kappa)^{2p}, which has
        # E|Z|^{2p} = rho^{2p} exactly: Markov is attained
        mass = (1.0 / kappa) ** (2 * p_used)
        worst = max(worst, mass - delta)
        # random laws scaled to ||Z||_{2p_used} = rho = 1: empirical tail <= delta
        for _ in range(ctx.count(20, 4)):
            z = rng.lognormal(0, rng.uniform(0.1, 2.0), 4000)
            w = np.full(z.size, 1.0 / z.size)
            z = z / _lp_norm(z, w, 2 * p_used)
            worst = max(worst, float(np.mean(z >= kappa)) - delta)
    ok = sym_ok and worst <= MARKOV_TOL
    return result(
        name,
        LABEL + ", Markov step kappa = e rho(log sqrt(1/delta))",
        holds=bool(ok),
        residual=worst,
        detail=(
            f"(rho/(e rho))^(2p) at p = {p_factor}*log sqrt(1/delta) simplifies to {sym}; "
            f"extremal 2-point and random laws at delta = e^(-2p), p = 1..8: max "
            f"P(|Z| >= kappa) - delta = {worst:.2e}"
        ),
    )


@register("l1drac.integer_p", LABEL + ", integer-p variant for general delta")
def check_integer_p(ctx: Context) -> CheckResult:
    """``p = max(1, ceil(log(1/delta)/2))``: ``kappa = rho delta^{-1/(2p)} <= e rho``, tail
    delta."""
    name = "l1drac.integer_p"
    dl, rho = sp.symbols("delta rho", positive=True)
    p = sp.symbols("p", positive=True, integer=True)
    kappa = rho * dl ** (-1 / (2 * p))
    tail = sp.simplify((rho / kappa) ** (2 * p))
    # kappa/rho <= e  <=>  log(1/delta)/(2p) <= 1, which is what p >= log(1/delta)/2 gives
    log_ratio = sp.simplify(sp.expand_log(sp.log(kappa / rho), force=True))
    sym_ok = sp.simplify(tail - dl) == 0 and sp.simplify(log_ratio - sp.log(1 / dl) / (2 * p)) == 0
    rng = ctx.rng
    deltas = np.concatenate(
        [
            np.exp(-rng.uniform(0, 40, size=ctx.count(20000, 2000))),
            np.exp(-2.0 * np.arange(1, 20)),
            np.nextafter(np.exp(-2.0 * np.arange(1, 20)), 0),
            np.nextafter(np.exp(-2.0 * np.arange(1, 20)), 1),
        ]
    )
    deltas = deltas[(deltas > 0) & (deltas < 1)]
    worst = -np.inf
    for d in deltas:
        p_int = max(1, math.ceil(0.5 * math.log(1.0 / d)))
        k = d ** (-1.0 / (2 * p_int))
        worst = max(worst, (k - math.e) / math.e)
    ok = sym_ok and worst <= KAPPA_REL_TOL
    return result(
        name,
        LABEL + ", integer-p variant for general delta",
        holds=bool(ok),
        residual=worst,
        detail=(
            f"(rho/kappa)^(2p) = {tail}; log(kappa/rho) = {log_ratio}; {deltas.size} deltas in "
            f"(0,1) incl. e^(-2k) and neighbours: max (kappa/rho - e)/e = {worst:.2e}"
        ),
    )


BEST_ORDER_ETA = 1e-9  # the radii sit this far (relative) above the true norms: Thm 4.1 is strict
#: the paper-4d constants `certify` uses (examples/l1drac_constants/paper_4d_learned.toml), at the
#: controller the default design picks at T_s = 1e-3 s: p = 2 (delta = 0.05) with rho(1) < rho(2)
_PAPER_LEARNED = {
    "lam": 0.09872795918963721, "Delta_f": 0.12833337758050964, "L_f": 0.10124722424790661,
    "Delta_star": 2.0000000319590368, "Delta_g": 0.5000000000000002, "Delta_g_dot": 0.0,
    "Delta_g_perp": 0.0, "Delta_Theta": 8.000000000000004, "Delta_mu": 0.22360679774997913,
    "L_mu_hat": 0.0, "L_mu": 0.10000000000000003, "Delta_mu_par": 0.8944271909999165,
    "L_mu_par_hat": 0.0, "L_mu_par": 0.40000000000000013, "Delta_mu_perp": 0.0,
    "L_mu_perp": 0.0, "L_mu_perp_hat": 0.0, "Delta_sigma": 0.2569759056871061,
    "L_sigma_hat": 0.0, "L_sigma": 0.10000000000000003, "Delta_sigma_par": 1.0279036227484244,
    "L_sigma_par_hat": 0.0, "L_sigma_par": 0.40000000000000013, "Delta_sigma_perp": 0.0,
    "L_sigma_perp": 0.0, "L_sigma_perp_hat": 0.0, "Delta_p": 0.0, "L_p": 0.0, "L_p_hat": 0.0,
    "Delta_p_par": 0.0, "L_p_par": 0.0, "L_p_par_hat": 0.0, "Delta_p_perp": 0.0, "L_p_perp": 0.0,
    "L_p_perp_hat": 0.0, "alpha": 0.0, "eps_r": 0.001, "eps_a": 0.001, "p_star": 2, "m": 4,
    "lip_f": True,
}  # fmt: skip


def _best_order_laws(rng: np.random.Generator, n: int) -> list[tuple[np.ndarray, np.ndarray]]:
    """Laws of ||Z|| (values, weights): constants and two-point {0, k} laws (where Jensen and
    Markov are attained) and random heavy-tailed ones."""
    laws: list[tuple[np.ndarray, np.ndarray]] = []
    for k in range(n):
        kind = k % 3
        if kind == 0:
            laws.append((np.array([float(rng.exponential())]), np.array([1.0])))
        elif kind == 1:
            m = float(np.exp(rng.uniform(-20, -0.1)))
            laws.append((np.array([0.0, float(rng.exponential())]), np.array([1.0 - m, m])))
        else:
            z = rng.lognormal(0.0, rng.uniform(0.1, 2.0), int(rng.integers(2, 500)))
            laws.append((z, rng.dirichlet(np.ones(z.size))))
    return laws


@register("l1drac.best_order", LABEL + ", best order at one controller (l1drac.md 5.6)")
def check_best_order(
    ctx: Context, bound_factor: float = 1.0, same_controller: bool = True
) -> CheckResult:
    """Steps 5.6.1-5.6.2 of docs/math/l1drac.md: ``E||Z|| < min_q rho(q)`` and
    ``P(||Z|| >= min_q rho(q) delta^{-1/(2q)}) < delta`` whenever ``||Z||_{L_2q} < rho(q)`` for
    every ``q <= p``; and drip-cert's ``rho(q)`` are designs verified at the design's controller.

    ``bound_factor`` scales both claimed bounds (1 is the proved one; 0.99 must fail on the
    tight laws); ``same_controller=False`` takes each ``rho(q)`` from a design that re-optimises
    omega for its own order (a different controller: not a bound for the one that runs), which
    the controller check must reject.
    """
    name = "l1drac.best_order"
    rng = ctx.rng
    worst = -np.inf
    for z, w in _best_order_laws(rng, ctx.count(600, 90)):
        p = int(rng.integers(1, 6))
        rho = [(1 + BEST_ORDER_ETA) * _lp_norm(z, w, 2 * q) for q in range(1, p + 1)]
        mean_bound = bound_factor * min(rho)
        worst = max(worst, (float(w @ z) - mean_bound) / mean_bound)  # must be < 0
        # the delta of the tight two-point law is its mass; elsewhere a random level
        delta = float(w[-1]) if z.size == 2 else float(np.exp(rng.uniform(-12, -0.1)))
        kappa = bound_factor * min(r * delta ** (-1.0 / (2 * q)) for q, r in enumerate(rho, 1))
        tail = float(w[z >= kappa].sum())
        worst = max(worst, (tail - delta) / delta)  # must be < 0 (strict)
    impl = _best_order_impl(same_controller)
    ok = worst < 0 and impl[0]
    return result(
        name,
        LABEL + ", best order at one controller (l1drac.md 5.6)",
        holds=bool(ok),
        residual=worst,
        detail=(
            f"constant, two-point and random laws, p <= 5, radii (1 + {BEST_ORDER_ETA:g}) x the "
            f"norms, bounds x {bound_factor}: max relative (E|Z| - bound, tail - delta) = "
            f"{worst:.2e}; {impl[1]}"
        ),
    )


def _best_order_impl(same_controller: bool) -> tuple[bool, str]:
    """drip-cert's mean_gap_bound on the paper-4d constants: every rho(q) it uses re-designed
    here at the design's controller and verified, the value their minimum, rho(1) < rho(2)."""
    from drip_cert.bounds.l1drac import DesignRequest, L1Constants, design, mean_gap_bound

    c = L1Constants(**_PAPER_LEARNED)  # type: ignore[arg-type]
    d = design(c, DesignRequest(p=2, lambda_s=10.0, Ts=1e-3, delta=0.05, front=False))
    m = mean_gap_bound(c, d)
    if m is None:
        return False, "mean_gap_bound returned None on a feasible design"
    rho_q = []
    for q in range(1, d.p + 1):
        fixed = {"omega": d.omega} if same_controller else {}
        dq = design(c, DesignRequest(p=q, lambda_s=10.0, Ts=1e-3, front=False, **fixed))
        same = (dq.omega, dq.lambda_s, dq.Ts) == (m.omega, m.lambda_s, m.Ts)
        if not (dq.feasible and dq.verified and same):
            return False, f"rho({q}) not verified at the design's controller (omega {dq.omega})"
        rho_q.append(min(dq.rho, d.rho) if q == d.p else dq.rho)
    agree = all(math.isclose(a, b, rel_tol=1e-12) for a, b in zip(rho_q, m.by_p, strict=True))
    gain = m.value < d.rho and m.kappa is not None and m.kappa < d.kappa
    ok = agree and gain and m.value == min(rho_q)
    return ok, (
        f"paper-4d constants at omega = {d.omega:.6g}, T_s = 1e-3: rho(q) = "
        f"{', '.join(f'{r:.6g}' for r in rho_q)} re-verified (drip-cert: {m.by_p}), mean bound "
        f"{m.value:.6g} < rho(p) = {d.rho:.6g}, kappa {m.kappa:.6g} < {d.kappa:.6g}"
    )
