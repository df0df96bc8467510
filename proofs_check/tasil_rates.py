"""Rates of rho_TaSIL(delta, n) = (6 gamma0 / delta) R_0(n, delta/3)
(docs/math/tasil.md Sec. 3.3-3.4).

``R_0(n, delta) = tau_0 + (b_0/n) (2 + q log(1 + 2 B L n / b_0) + log(2/delta))``.

DRIP Theorem "TaSIL" claims ``rho_TaSIL in O(log n / n)`` as n grows and ``O(1/delta)`` as
delta shrinks. TaSIL's own constant (its Thm 4.3) is not available, so these checks are about
the construction drip-cert implements. With sympy:

* n -> oo: ``lim rho n / log n = 6 gamma0 b0 q / delta`` (finite, nonzero) when tau_0 = 0 (the
  realizable case); with tau_0 > 0 the limit of rho itself is ``6 gamma0 tau0 / delta`` > 0;
* delta -> 0: ``lim rho delta = oo`` and ``lim rho delta / log(1/delta) = 6 gamma0 b0 / n``:
  the construction is Theta(log(1/delta)/delta), NOT O(1/delta) (erratum/finding E7).
"""

from __future__ import annotations

import sympy as sp

from proofs_check._core import CheckResult, Context, register, result

LABEL = "DRIP Thm. TaSIL (thm:TaSIL), rates of rho_TaSIL"

g0, b0, q, B, L, n, delta, tau0 = sp.symbols(
    "gamma_0 b_0 q B_theta L_theta n delta tau_0", positive=True
)


def R0(n_, delta_, tau=0):
    """Expectation-form generalization term of docs/math/tasil.md Sec. 3.3(b), j = 0."""
    return tau + (b0 / n_) * (2 + q * sp.log(1 + 2 * B * L * n_ / b0) + sp.log(2 / delta_))


def rho_tasil(n_, delta_, tau=0):
    """``rho_TaSIL(delta, n) = (6 gamma0 / delta) R_0(n, delta / 3)``."""
    return 6 * g0 / delta_ * R0(n_, delta_ / 3, tau)


@register("tasil.rho_rate_n", LABEL + ", O(log n / n) as n -> oo")
def check_rate_n(ctx: Context) -> CheckResult:
    """``lim_{n->oo} rho n / log n`` is finite and nonzero (tau_0 = 0)."""
    name = "tasil.rho_rate_n"
    rho = rho_tasil(n, delta)
    lim = sp.simplify(sp.limit(rho * n / sp.log(n), n, sp.oo))
    expected = 6 * g0 * b0 * q / delta
    lim_faster = sp.limit(rho * n / sp.log(n) ** sp.Rational(1, 2), n, sp.oo)  # not o(...)
    lim_tau = sp.simplify(sp.limit(rho_tasil(n, delta, tau0), n, sp.oo))
    ok = (
        sp.simplify(lim - expected) == 0
        and lim_faster == sp.oo
        and sp.simplify(lim_tau - 6 * g0 * tau0 / delta) == 0
    )
    return result(
        name,
        LABEL + ", O(log n / n) as n -> oo",
        holds=bool(ok),
        residual=0.0 if ok else float("nan"),
        detail=(
            f"lim rho n/log n = {lim} (finite, nonzero: the rate is exactly log n/n); "
            f"with a training tolerance tau_0 > 0: lim rho = {lim_tau} (then no decay in n)"
        ),
    )


@register("tasil.rho_rate_delta", LABEL + ", O(1/delta) as delta -> 0")
def check_rate_delta(ctx: Context) -> CheckResult:
    """The construction is Theta(log(1/delta)/delta): DRIP's O(1/delta) does not hold for it."""
    name = "tasil.rho_rate_delta"
    rho = rho_tasil(n, delta)
    lim_1 = sp.limit(rho * delta, delta, 0, "+")
    lim_log = sp.simplify(sp.limit(rho * delta / sp.log(1 / delta), delta, 0, "+"))
    expected = 6 * g0 * b0 / n
    lim_log_tau = sp.simplify(
        sp.limit(rho_tasil(n, delta, tau0) * delta / sp.log(1 / delta), delta, 0, "+")
    )
    ok = (
        lim_1 == sp.oo
        and sp.simplify(lim_log - expected) == 0
        and sp.simplify(lim_log_tau - expected) == 0
    )
    return result(
        name,
        LABEL + ", O(1/delta) as delta -> 0",
        holds=bool(ok),
        residual=0.0 if ok else float("nan"),
        detail=(
            f"lim rho*delta = {lim_1} (so rho is not O(1/delta)); "
            f"lim rho*delta/log(1/delta) = {lim_log} (Theta(log(1/delta)/delta)), "
            "also with tau_0 > 0"
        ),
        erratum="E7",
    )
