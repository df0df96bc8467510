"""L1-DRAC certificate calculator: the paper's constants, its design conditions, and a designer.

Source: A. Gahlawat, S. H. Karumanchi, N. Hovakimyan, "L1-DRAC: Distributionally Robust Adaptive
Control -- Global Results", arXiv:2509.04619 (2025-09-04). Sec. 3.2 (conditions (16), (21), (24)),
Sec. 4 (Lemma 4.4, Theorem 4.1), Appendix A (constants, in :mod:`drip_cert.bounds.l1drac_appendix`).
The transcription used is ``docs/math/l1drac.md``; every formula was re-checked against the PDF.

Public surface
--------------
* :class:`L1Constants` -- the constants of Assumptions 1-8 plus alpha, eps_r, eps_a (validated).
* :class:`DesignRequest` -- p, lambda_s and whichever of omega, Ts, rho_r, rho_a are fixed.
* :class:`ConditionResult` -- one condition in the paper's form, with a signed float margin and
  its Arb-verified enclosure (:mod:`drip_cert.bounds.l1drac_verify`).
* :func:`evaluate_conditions` -- (16a), (16b), (21a), (21b), (24) at a fully specified point.
* :func:`smallest_rho_r`, :func:`smallest_rho_a`, :func:`largest_Ts` -- the three root searches.
* :func:`design` -- find the free parameters; returns an :class:`L1Design` (never raises for an
  infeasible design: ``feasible=False`` and ``reason``).
* :func:`tradeoff_table` -- (rho_a, Ts_max, rho) rows: a larger rho_a buys a larger Ts.
* :func:`p_for_delta`, :func:`kappa_markov`, :func:`ultimate_bound` -- Theorem 4.1's radii.

Root searches (how and to what tolerance)
-----------------------------------------
Each unknown is found by bisection in log space on a bracket ``[lo, hi]`` whose ``hi`` end always
satisfies the condition and whose ``lo`` end never does; the search stops when
``hi / lo - 1 <= ROOT_RTOL`` and returns ``hi`` (``lo`` for the largest Ts). The returned point was
itself evaluated with the same function that the final re-check uses, so the certificate never
rests on a point that fails its own re-check; it is minimal (maximal for Ts) to a relative
``ROOT_RTOL``. Why bisection is correct: see :func:`smallest_rho_r`, :func:`smallest_rho_a` and
:func:`largest_Ts`, which prove that each feasible set is an interval reaching to infinity (to
zero for Ts).

Back-off and rigorous verification
----------------------------------
A float root sits on the boundary of its condition: its float64 margin is rounding noise, whose
sign another transcription may flip. :func:`design` therefore never returns a root as found. It
moves each *free* parameter into the interior by a relative ``f = BACKOFF_START`` (rho_r and
rho_a multiplied by ``1 + f``, Ts divided by ``1 + f``), in the order rho_r, rho_a, Ts (rho_a
and Ts are re-solved after the parameters before them moved), and re-checks the conditions that
parameter closes in Arb ball arithmetic (:func:`drip_cert.bounds.l1drac_verify.verify_conditions`,
the same formulas) and in float64; unless the margin ball's lower end is > 0 and the float64
margin is positive too, it retries with ``f`` multiplied by ``BACKOFF_GROWTH``, at most
``BACKOFF_STEPS`` times (so ``f <= 1e-3``), and otherwise reports the design infeasible with the
reason (details in :func:`_back_off`). Every feasible set is an up-set in rho_r and rho_a and,
on the monotone envelope of (24), a down-set in Ts (the proofs in :func:`smallest_rho_r`,
:func:`smallest_rho_a`, :func:`largest_Ts`), so a step into the interior keeps every condition
and makes its margin strictly positive. Parameters the user fixed are never changed: for them
the verdict is the Arb-verified one. ``feasible`` means every condition is *verified* (the
exact margin at the returned float values is > 0), not merely that its float64 margin is.
"""

from __future__ import annotations

import dataclasses
import math
import numbers
import time
from collections.abc import Callable, Mapping
from dataclasses import dataclass, field
from typing import Any, ClassVar

from drip_cert.bounds.l1drac_appendix import (
    FLOAT,
    RELATIONS,
    FloatOps,
    RefConstants,
    TrueConstants,
    budget_a,
    gamma_r,
    margin_of,
    reference_constants,
    sampling_constants,
    sides_16a,
    sides_16b,
    sides_21a,
    sides_21b,
    sides_24,
    theta_r,
    true_constants,
    unmatched_gain_a,
    unmatched_gain_r,
    upsilon_sum,
)
from drip_cert.bounds.l1drac_verify import (
    ARB_PREC,
    ArbMargin,
    budget_24_lower,
    verify_conditions,
)
from drip_cert.errors import AssumptionViolation, SpecError
from drip_cert.provenance import How, json_float, weakest

__all__ = [
    "CONSTANT_NAMES",
    "ROOT_RTOL",
    "BACKOFF_START",
    "BACKOFF_GROWTH",
    "BACKOFF_STEPS",
    "VERIFY_METHOD",
    "L1Constants",
    "DesignRequest",
    "ConditionResult",
    "L1Design",
    "TradeoffRow",
    "condition_16a",
    "condition_16b",
    "condition_21a",
    "condition_21b",
    "condition_24",
    "evaluate_conditions",
    "smallest_rho_r",
    "smallest_rho_a",
    "largest_Ts",
    "design",
    "tradeoff_table",
    "p_for_delta",
    "kappa_markov",
    "ultimate_bound",
]

#: Relative tolerance of every root search (the returned root is within this of the true one).
ROOT_RTOL = 1e-12
#: First relative back-off of a free parameter from its float root: 1000 x ROOT_RTOL, so that it
#: clears the root's own uncertainty and the float64 rounding of the margins (~1e-16 relative)
#: by orders of magnitude, while moving rho by a negligible 1e-9 relative.
BACKOFF_START = 1e-9
#: Factor by which the relative back-off grows at each retry (geometric: a few retries span any
#: plausible loss of digits).
BACKOFF_GROWTH = 10.0
#: Retries per parameter before the design is declared infeasible; the largest relative back-off
#: is BACKOFF_START * BACKOFF_GROWTH**(BACKOFF_STEPS - 1) = 1e-3 (a margin not resolved by then
#: is not a rounding matter).
BACKOFF_STEPS = 7
#: The method by which a design's verdict is obtained: every condition evaluated in Arb ball
#: arithmetic from the exact float inputs ("verified in rigorous arithmetic" is How.EXACT in
#: drip_cert.provenance). A design's label is weakest(VERIFY_METHOD, inputs): see L1Design.label.
VERIFY_METHOD = How.EXACT
#: Largest radius tried before a condition is declared infeasible for every rho.
_RHO_CAP = 1e60
#: Smallest positive radius / sampling period tried.
_TINY = 1e-200
#: e^{x} overflows float64 beyond x = 709.78; omega*Ts and lambda_s*Ts are kept below this.
_EXP_ARG_MAX = 700.0
#: Default search interval for omega, as multiples of lambda (log-uniform grid + refinement).
_OMEGA_BOUNDS_REL = (1e-3, 1e7)
#: Default search interval for lambda_s, as multiples of lambda.
_LAMBDA_S_BOUNDS_REL = (1e-3, 1e5)
#: Points of the log-uniform grid scanned before the local refinement of omega / lambda_s.
_GRID_POINTS = 41
#: Grid points of the inner lambda_s search when omega and lambda_s are both free (Ts fixed).
_NESTED_GRID_POINTS = 13

# The constants of Assumptions 1-8 (ASCII names as in the TOML file; 'lambda' is the attribute
# ``lam``), each with the assumption that defines it.
_REAL_FIELDS: tuple[tuple[str, str], ...] = (
    ("lambda", "Assumption 2 (contraction rate, > 0)"),
    ("Delta_f", "Assumption 1 (growth of f)"),
    ("Delta_p", "Assumption 1 (bound of p)"),
    ("L_p", "Assumption 1 (Hoelder constant of p in x)"),
    ("L_p_hat", "Assumption 1 (Lipschitz constant of p in t)"),
    ("Delta_g", "Assumption 1 (bound of g)"),
    ("Delta_g_dot", "Assumption 1 (bound of dg/dt)"),
    ("Delta_g_perp", "Assumption 1 (bound of g_perp)"),
    ("Delta_Theta", "Assumption 1 (bound of Theta_ad)"),
    ("Delta_star", "Assumption 3 (2p*-moment bound of the nominal state)"),
    ("Delta_mu", "Assumption 4 (growth of Lambda_mu)"),
    ("Delta_sigma", "Assumption 4 (growth of Lambda_sigma)"),
    ("Delta_mu_par", "Assumption 4 (growth of the matched Lambda_mu)"),
    ("Delta_mu_perp", "Assumption 4 (growth of the unmatched Lambda_mu)"),
    ("Delta_sigma_par", "Assumption 4 (growth of the matched Lambda_sigma)"),
    ("Delta_sigma_perp", "Assumption 4 (growth of the unmatched Lambda_sigma)"),
    ("Delta_p_par", "Assumption 5 (bound of p^par)"),
    ("Delta_p_perp", "Assumption 5 (bound of p^perp)"),
    ("L_p_par", "Assumption 5 (Hoelder constant of p^par in x)"),
    ("L_p_perp", "Assumption 5 (Hoelder constant of p^perp in x)"),
    ("L_p_par_hat", "Assumption 5 (Lipschitz constant of p^par in t)"),
    ("L_p_perp_hat", "Assumption 5 (Lipschitz constant of p^perp in t)"),
    ("L_mu", "Assumption 6 (Lipschitz constant of Lambda_mu in x)"),
    ("L_mu_hat", "Assumption 6 (Lipschitz constant of Lambda_mu in t)"),
    ("L_mu_par", "Assumption 6 (Lipschitz constant of Lambda_mu^par in x)"),
    ("L_mu_par_hat", "Assumption 6 (Lipschitz constant of Lambda_mu^par in t)"),
    ("L_mu_perp", "Assumption 6 (Lipschitz constant of Lambda_mu^perp in x)"),
    ("L_mu_perp_hat", "Assumption 6 (Lipschitz constant of Lambda_mu^perp in t)"),
    ("L_sigma", "Assumption 6 (Hoelder constant of Lambda_sigma in x)"),
    ("L_sigma_hat", "Assumption 6 (Lipschitz constant of Lambda_sigma in t)"),
    ("L_sigma_par", "Assumption 6 (Hoelder constant of Lambda_sigma^par in x)"),
    ("L_sigma_par_hat", "Assumption 6 (Lipschitz constant of Lambda_sigma^par in t)"),
    ("L_sigma_perp", "Assumption 6 (Hoelder constant of Lambda_sigma^perp in x)"),
    ("L_sigma_perp_hat", "Assumption 6 (Lipschitz constant of Lambda_sigma^perp in t)"),
    ("L_f", "Assumption 8 (Lipschitz constant of f in x; used only when lip_f = true)"),
    ("alpha", "(18a) (initial distance W_2p or ||X0 - X0*||_L2p)"),
    ("eps_r", "(16a) (slack, > 0)"),
    ("eps_a", "(16b) (slack, > 0)"),
)
_INT_FIELDS: tuple[tuple[str, str], ...] = (
    ("p_star", "Assumption 1 (highest moment order, integer >= 1)"),
    ("m", "Definition 1 (number of inputs, integer >= 1)"),
)
_BOOL_FIELDS: tuple[tuple[str, str], ...] = (("lip_f", "Assumption 8 holds (true/false)"),)
_STRICTLY_POSITIVE = ("lambda", "eps_r", "eps_a")

#: Every key of the ``[constants]`` table, in the order of the paper's assumptions.
CONSTANT_NAMES: tuple[str, ...] = tuple(n for n, _ in _REAL_FIELDS + _INT_FIELDS + _BOOL_FIELDS)


def _attr(name: str) -> str:
    """Attribute name of a constant ('lambda' is a Python keyword)."""
    return "lam" if name == "lambda" else name


def _is_real(value: Any) -> bool:
    return isinstance(value, numbers.Real) and not isinstance(value, bool)


def _check_real(name: str, value: Any, *, positive: bool, where: str, path: str | None) -> float:
    if not _is_real(value):
        raise SpecError(
            f"{value!r} is not a real number; {name} is the constant of {where}: give a number",
            field=name,
            path=path,
        )
    v = float(value)
    if not math.isfinite(v):
        raise SpecError(
            f"{value!r} is not finite; {name} ({where}) must be a finite number",
            field=name,
            path=path,
        )
    if positive and not v > 0.0:
        raise SpecError(f"{v!r} must be > 0 ({where})", field=name, path=path)
    if v < 0.0:
        raise SpecError(
            f"{v!r} is negative; {name} bounds a norm ({where}) and must be >= 0",
            field=name,
            path=path,
        )
    return v


def _check_int(name: str, value: Any, *, where: str, path: str | None) -> int:
    if isinstance(value, bool) or not isinstance(value, numbers.Integral):
        if _is_real(value) and float(value).is_integer():
            value = int(value)
        else:
            raise SpecError(
                f"{value!r} is not an integer; {name} ({where}) must be an integer >= 1",
                field=name,
                path=path,
            )
    if value < 1:
        raise SpecError(f"{value!r} must be an integer >= 1 ({where})", field=name, path=path)
    return int(value)


@dataclass(frozen=True, kw_only=True)
class L1Constants:
    """The constants of L1-DRAC's Assumptions 1-8 (Sec. 2.2), the initial distance and the slacks.

    Every field is keyword-only and required: a forgotten constant must not silently become 0.
    ``lam`` is the paper's lambda (printed and read as ``'lambda'``, see :meth:`from_mapping` and
    :meth:`to_dict`). Validated on construction: reals finite and >= 0, ``lam``, ``eps_r``,
    ``eps_a`` > 0, ``p_star`` and ``m`` integers >= 1, ``lip_f`` a bool
    (:class:`~drip_cert.errors.SpecError` naming the field otherwise), and Assumption 7,
    ``lambda > Delta_g_perp * max(Delta_mu_perp, L_mu_perp)``
    (:class:`~drip_cert.errors.AssumptionViolation` with the numbers otherwise).

    Three constants are accepted but appear in no formula of the paper: ``L_mu_perp_hat``,
    ``L_sigma_perp_hat``, ``L_p_perp_hat`` (and hat-L_f, which is not a field).

    ``num`` (a class attribute, not a field) is the float64 backend of the appendix formulas
    (:data:`drip_cert.bounds.l1drac_appendix.FLOAT`); the Arb view of
    :class:`drip_cert.bounds.l1drac_verify.ArbConstants` carries the Arb one.
    """

    num: ClassVar[FloatOps] = FLOAT

    lam: float
    Delta_f: float
    Delta_p: float
    L_p: float
    L_p_hat: float
    Delta_g: float
    Delta_g_dot: float
    Delta_g_perp: float
    Delta_Theta: float
    Delta_star: float
    p_star: int
    Delta_mu: float
    Delta_sigma: float
    Delta_mu_par: float
    Delta_mu_perp: float
    Delta_sigma_par: float
    Delta_sigma_perp: float
    Delta_p_par: float
    Delta_p_perp: float
    L_p_par: float
    L_p_perp: float
    L_p_par_hat: float
    L_p_perp_hat: float
    L_mu: float
    L_mu_hat: float
    L_mu_par: float
    L_mu_par_hat: float
    L_mu_perp: float
    L_mu_perp_hat: float
    L_sigma: float
    L_sigma_hat: float
    L_sigma_par: float
    L_sigma_par_hat: float
    L_sigma_perp: float
    L_sigma_perp_hat: float
    L_f: float
    lip_f: bool
    m: int
    alpha: float
    eps_r: float
    eps_a: float

    def __post_init__(self) -> None:
        for name, where in _REAL_FIELDS:
            v = _check_real(
                name,
                getattr(self, _attr(name)),
                positive=name in _STRICTLY_POSITIVE,
                where=where,
                path=None,
            )
            object.__setattr__(self, _attr(name), v)
        for name, where in _INT_FIELDS:
            v_int = _check_int(name, getattr(self, name), where=where, path=None)
            object.__setattr__(self, name, v_int)
        if not isinstance(self.lip_f, bool):
            raise SpecError(
                f"{self.lip_f!r} is not a boolean; lip_f says whether Assumption 8 holds: "
                "give true or false",
                field="lip_f",
            )
        # Assumption 7 (unmatched small gain)
        gain = self.Delta_g_perp * max(self.Delta_mu_perp, self.L_mu_perp)
        if not self.lam > gain:
            raise AssumptionViolation(
                "Assumption 7 fails: lambda = "
                f"{self.lam!r} must exceed Delta_g_perp * max(Delta_mu_perp, L_mu_perp) = "
                f"{self.Delta_g_perp!r} * max({self.Delta_mu_perp!r}, {self.L_mu_perp!r}) = "
                f"{gain!r}; the unmatched uncertainty is too strong for the nominal contraction"
            )

    @classmethod
    def from_mapping(cls, data: Mapping[str, Any], *, path: str | None = None) -> L1Constants:
        """Build from a mapping whose keys are exactly :data:`CONSTANT_NAMES` ('lambda', ...).

        Raises
        ------
        SpecError
            Unknown or missing keys, wrong types, NaN/inf, negative values (naming the key and
            ``path`` when given).
        """
        unknown = sorted(set(data) - set(CONSTANT_NAMES))
        if unknown:
            raise SpecError(
                f"unknown constant(s) {unknown}; the allowed keys are {list(CONSTANT_NAMES)}",
                field="constants." + unknown[0],
                path=path,
            )
        missing = [n for n in CONSTANT_NAMES if n not in data]
        if missing:
            raise SpecError(
                f"missing constant(s) {missing}: every constant must be given explicitly "
                "(write 0 for a term that is absent)",
                field="constants." + missing[0],
                path=path,
            )
        kwargs: dict[str, Any] = {}
        for name, where in _REAL_FIELDS:
            kwargs[_attr(name)] = _check_real(
                name,
                data[name],
                positive=name in _STRICTLY_POSITIVE,
                where=where,
                path=path,
            )
        for name, where in _INT_FIELDS:
            value = data[name]
            if isinstance(value, bool) or not isinstance(value, numbers.Integral):
                raise SpecError(
                    f"{value!r} is not an integer; {name} ({where}) must be an integer >= 1",
                    field="constants." + name,
                    path=path,
                )
            kwargs[name] = _check_int(name, value, where=where, path=path)
        for name, where in _BOOL_FIELDS:
            if not isinstance(data[name], bool):
                raise SpecError(
                    f"{data[name]!r} is not a boolean; {name}: {where}",
                    field="constants." + name,
                    path=path,
                )
            kwargs[name] = data[name]
        return cls(**kwargs)

    def to_dict(self) -> dict[str, Any]:
        """JSON-ready dictionary with the TOML key names ('lambda' for ``lam``)."""
        return {n: getattr(self, _attr(n)) for n in CONSTANT_NAMES}

    @property
    def k_r(self) -> float:
        """Delta_g_perp Delta_mu_perp / lambda in [0, 1) (Assumption 7); the factor of (16a)."""
        return unmatched_gain_r(self)

    @property
    def k_a(self) -> float:
        """Delta_g_perp L_mu_perp / lambda in [0, 1) (Assumption 7); the factor of (16b)."""
        return unmatched_gain_a(self)


def _opt_positive(name: str, value: Any) -> float | None:
    if value is None:
        return None
    return _check_real("design." + name, value, positive=True, where="the design", path=None)


@dataclass(frozen=True, kw_only=True)
class DesignRequest:
    """What the user fixes; ``None`` means "find it".

    Parameters
    ----------
    p
        Moment order, an integer in ``{1, ..., p_star}``.
    lambda_s
        Predictor pole (15c); ``None`` = choose it (maximise Ts; minimise rho_a if Ts is fixed).
    omega
        Filter bandwidth (15a), ``!= 2 lambda``; ``None`` = minimise rho over ``omega_bounds``.
    Ts
        Sampling period (15b); ``None`` = the largest Ts satisfying (24).
    rho_r, rho_a
        Radii (16a), (16b); ``None`` = the smallest satisfying their conditions.
    delta
        Violation probability in (0, 1); when given, the design reports kappa (130a).
    omega_bounds, lambda_s_bounds
        Search intervals ``(lo, hi)``; default ``(1e-3, 1e7) * lambda`` and
        ``(1e-3, 1e5) * lambda``.
    """

    p: int
    lambda_s: float | None = None
    omega: float | None = None
    Ts: float | None = None
    rho_r: float | None = None
    rho_a: float | None = None
    delta: float | None = None
    omega_bounds: tuple[float, float] | None = None
    lambda_s_bounds: tuple[float, float] | None = None

    def __post_init__(self) -> None:
        object.__setattr__(self, "p", _check_int("design.p", self.p, where="the design", path=None))
        for name in ("lambda_s", "omega", "Ts", "rho_r", "rho_a", "delta"):
            object.__setattr__(self, name, _opt_positive(name, getattr(self, name)))
        if self.delta is not None and not self.delta < 1.0:
            raise SpecError(
                f"{self.delta!r} is not a probability in (0, 1); give e.g. 1e-3",
                field="design.delta",
            )
        for name in ("omega_bounds", "lambda_s_bounds"):
            b = getattr(self, name)
            if b is None:
                continue
            if len(b) != 2:
                raise SpecError(f"{b!r} must be a pair (lo, hi)", field="design." + name)
            lo = _check_real("design." + name, b[0], positive=True, where="the design", path=None)
            hi = _check_real("design." + name, b[1], positive=True, where="the design", path=None)
            if not lo < hi:
                raise SpecError(f"{b!r}: need lo < hi", field="design." + name)
            object.__setattr__(self, name, (lo, hi))


@dataclass(frozen=True)
class ConditionResult:
    """One condition of L1-DRAC Sec. 3.2 in the paper's form ``lhs REL rhs``.

    ``lhs``, ``rhs``, ``margin`` and ``holds`` are the float64 evaluation: ``margin`` is signed,
    positive = satisfied: ``lhs - rhs`` for (16a, b) (``lhs >= rhs``), ``rhs - lhs`` for (21a, b)
    (``lhs < rhs``, strict) and (24) (``lhs <= rhs``); ``holds`` is the float comparison.

    ``verified``, ``margin_lo`` and ``margin_hi`` are the rigorous evaluation of the same margin
    in Arb ball arithmetic (:func:`drip_cert.bounds.l1drac_verify.verify_conditions`):
    ``[margin_lo, margin_hi]`` encloses the exact margin at the float inputs (lower end rounded
    down, upper end rounded up), and ``verified`` is ``margin_lo > 0`` (the ball's lower end is
    > 0). Only a verified condition counts for :attr:`L1Design.feasible`. Results of the
    internal float-only searches carry ``verified=False`` and NaN ends.
    """

    eq: str
    lhs: float
    rhs: float
    margin: float
    holds: bool
    relation: str = ""
    verified: bool = False
    margin_lo: float = math.nan
    margin_hi: float = math.nan

    def to_dict(self) -> dict[str, Any]:
        """JSON-ready dictionary: eq, lhs, rhs, margin, holds, relation, verified, margin_lo,
        margin_hi."""
        return {
            "eq": self.eq,
            "lhs": json_float(self.lhs),
            "rhs": json_float(self.rhs),
            "margin": json_float(self.margin),
            "holds": bool(self.holds),
            "relation": self.relation,
            "verified": bool(self.verified),
            "margin_lo": json_float(self.margin_lo),
            "margin_hi": json_float(self.margin_hi),
        }


def _result(eq: str, lhs: float, rhs: float) -> ConditionResult:
    relation = RELATIONS[eq]
    margin = margin_of(eq, lhs, rhs)
    if relation == ">=":
        holds = lhs >= rhs
    elif relation == "<":
        holds = lhs < rhs
    else:  # "<="
        holds = lhs <= rhs
    if math.isnan(margin):
        holds = False
    return ConditionResult(eq, lhs, rhs, margin, bool(holds), relation)


def _with_arb(r: ConditionResult, v: ArbMargin) -> ConditionResult:
    """``r`` with the Arb enclosure ``v`` of its margin."""
    return dataclasses.replace(r, verified=v.verified, margin_lo=v.lo, margin_hi=v.hi)


def _check_omega(c: L1Constants, omega: float) -> None:
    if not (_is_real(omega) and math.isfinite(omega) and omega > 0):
        raise SpecError(f"{omega!r} must be a finite number > 0", field="omega")
    if omega == 2.0 * c.lam:
        raise SpecError(
            f"omega = {omega!r} equals 2*lambda: every bandwidth term of (18b), (18c), (21) and "
            "(24) divides by |2 lambda - omega|, which is zero there; choose another omega",
            field="omega",
        )


def _check_p(c: L1Constants, p: Any) -> int:
    p = _check_int("p", p, where="moment order", path=None)
    if p > c.p_star:
        raise SpecError(
            f"p = {p} exceeds p_star = {c.p_star}: the constants of Appendix A need the 2p-th "
            "moment bound Delta_star of Assumption 3; use p <= p_star",
            field="p",
        )
    return p


# --------------------------------------------------------------------------------------------
# The conditions, in the paper's form (private versions take precomputed constants)
# --------------------------------------------------------------------------------------------


# The float64 conditions (the searches' oracle): the two sides come from the generic
# transcription of l1drac_appendix (the Arb verifier evaluates the same code).


def _c16a(c: L1Constants, rc: RefConstants, omega: float, rho_r: float) -> ConditionResult:
    return _result("16a", *sides_16a(c, rc, omega, rho_r))


def _c16b(c: L1Constants, tc: TrueConstants, omega: float, rho_a: float) -> ConditionResult:
    return _result("16b", *sides_16b(c, tc, omega, rho_a))


def _c21a(c: L1Constants, rc: RefConstants, omega: float, rho_r: float) -> ConditionResult:
    # Theta_r is divided by |2 lambda - omega| exactly once (the authors' Julia code: twice).
    return _result("21a", *sides_21a(c, rc, omega, rho_r))


def _budget_a(
    c: L1Constants, tc: TrueConstants, omega: float, rho_r: float, rho_a: float
) -> tuple[float, float, float]:
    """((1 - k_a) rho_a^2 - Gamma_a, Theta_a / |2 lambda - omega|, Gamma_a)."""
    return budget_a(c, tc, omega, rho_r, rho_a)


def _c21b(
    c: L1Constants, tc: TrueConstants, omega: float, rho_r: float, rho_a: float
) -> ConditionResult:
    return _result("21b", *sides_21b(c, tc, omega, rho_r, rho_a))


def _c24(
    c: L1Constants,
    tc: TrueConstants,
    p: int,
    omega: float,
    lambda_s: float,
    Ts: float,
    rho_r: float,
    rho_a: float,
    *,
    envelope: bool = False,
) -> ConditionResult:
    return _result("24", *sides_24(c, tc, p, omega, lambda_s, Ts, rho_r, rho_a, envelope=envelope))


def _verified(
    c: L1Constants,
    p: int,
    results: tuple[ConditionResult, ...],
    omega: float,
    *,
    lambda_s: float | None = None,
    Ts: float | None = None,
    rho_r: float | None = None,
    rho_a: float | None = None,
) -> tuple[ConditionResult, ...]:
    """``results`` with their Arb-verified margins (one Arb evaluation for all of them)."""
    v = verify_conditions(
        c,
        p,
        omega,
        lambda_s=lambda_s,
        Ts=Ts,
        rho_r=rho_r,
        rho_a=rho_a,
        which=tuple(r.eq for r in results),
    )
    return tuple(_with_arb(r, v[r.eq]) for r in results)


def condition_16a(c: L1Constants, p: int, omega: float, rho_r: float) -> ConditionResult:
    """(16a): ``(1 - Dgp Dmup / lambda) rho_r^2 >= alpha^2 + Gamma_r(rho_r, p, omega) + eps_r``.

    Float64 verdict plus the Arb-verified margin (:class:`ConditionResult`).
    """
    p = _check_p(c, p)
    _check_omega(c, omega)
    r = _c16a(c, reference_constants(c, p), omega, rho_r)
    return _verified(c, p, (r,), omega, rho_r=rho_r)[0]


def condition_16b(c: L1Constants, p: int, omega: float, rho_a: float) -> ConditionResult:
    """(16b): ``(1 - Dgp Lmup / lambda) rho_a^2 >= Gamma_a(rho_a, p, omega) + eps_a``.

    Float64 verdict plus the Arb-verified margin (:class:`ConditionResult`).
    """
    p = _check_p(c, p)
    _check_omega(c, omega)
    r = _c16b(c, true_constants(c, p), omega, rho_a)
    return _verified(c, p, (r,), omega, rho_a=rho_a)[0]


def condition_21a(c: L1Constants, p: int, omega: float, rho_r: float) -> ConditionResult:
    """(21a): ``Theta_r / |2 lambda - omega| < (1 - k_r) rho_r^2 - alpha^2 - Gamma_r``.

    Float64 verdict plus the Arb-verified margin (:class:`ConditionResult`).
    """
    p = _check_p(c, p)
    _check_omega(c, omega)
    r = _c21a(c, reference_constants(c, p), omega, rho_r)
    return _verified(c, p, (r,), omega, rho_r=rho_r)[0]


def condition_21b(
    c: L1Constants, p: int, omega: float, rho_r: float, rho_a: float
) -> ConditionResult:
    """(21b): ``Theta_a / |2 lambda - omega| < (1 - Dgp Lmup / lambda) rho_a^2 - Gamma_a``.

    Float64 verdict plus the Arb-verified margin (:class:`ConditionResult`).
    """
    p = _check_p(c, p)
    _check_omega(c, omega)
    r = _c21b(c, true_constants(c, p), omega, rho_r, rho_a)
    return _verified(c, p, (r,), omega, rho_r=rho_r, rho_a=rho_a)[0]


def condition_24(
    c: L1Constants,
    p: int,
    omega: float,
    lambda_s: float,
    Ts: float,
    rho_r: float,
    rho_a: float,
) -> ConditionResult:
    """(24): ``sum_i Upsilon_{a_i}(rho', rho_a) <= (1 - k_a) rho_a^2 - Gamma_a - Theta_a/|2l - w|``.

    ``rho' = rho_a + rho_r + Delta_star``; the Upsilon maps are (25a-c) with (A.13)-(A.19).
    Float64 verdict plus the Arb-verified margin (:class:`ConditionResult`).
    """
    p = _check_p(c, p)
    _check_omega(c, omega)
    _check_Ts(c, omega, lambda_s, Ts)
    r = _c24(c, true_constants(c, p), p, omega, lambda_s, Ts, rho_r, rho_a)
    return _verified(c, p, (r,), omega, lambda_s=lambda_s, Ts=Ts, rho_r=rho_r, rho_a=rho_a)[0]


def _check_Ts(c: L1Constants, omega: float, lambda_s: float, Ts: float) -> None:
    for name, v in (("lambda_s", lambda_s), ("Ts", Ts)):
        if not (_is_real(v) and math.isfinite(v) and v > 0):
            raise SpecError(f"{v!r} must be a finite number > 0", field=name)
    if max(omega, lambda_s, 2.0 * c.lam) * Ts > _EXP_ARG_MAX:
        raise SpecError(
            f"Ts = {Ts!r} is so long that e^(max(omega, lambda_s, 2 lambda) Ts) overflows; such a "
            "sampling period can never satisfy (24): use a Ts several orders smaller",
            field="Ts",
        )


def evaluate_conditions(
    c: L1Constants,
    p: int,
    omega: float,
    lambda_s: float,
    Ts: float,
    rho_r: float,
    rho_a: float,
) -> tuple[ConditionResult, ...]:
    """(16a), (16b), (21a), (21b), (24) at one fully specified point, in that order.

    Each result carries the float64 verdict and the Arb-verified margin (:class:`ConditionResult`).
    """
    p = _check_p(c, p)
    _check_omega(c, omega)
    _check_Ts(c, omega, lambda_s, Ts)
    rc = reference_constants(c, p)
    tc = true_constants(c, p)
    floats = (
        _c16a(c, rc, omega, rho_r),
        _c16b(c, tc, omega, rho_a),
        _c21a(c, rc, omega, rho_r),
        _c21b(c, tc, omega, rho_r, rho_a),
        _c24(c, tc, p, omega, lambda_s, Ts, rho_r, rho_a),
    )
    return _verified(c, p, floats, omega, lambda_s=lambda_s, Ts=Ts, rho_r=rho_r, rho_a=rho_a)


# --------------------------------------------------------------------------------------------
# Root searches
# --------------------------------------------------------------------------------------------


def _smallest(ok: Callable[[float], bool], lo: float) -> float | None:
    """Smallest x >= lo with ok(x), for an up-set {ok} = [x*, inf) or (x*, inf); None if > cap.

    Doubling from ``lo`` brackets the root, then bisection in log space keeps ``ok(hi)`` True and
    ``ok(lo)`` False until ``hi / lo - 1 <= ROOT_RTOL``; returns ``hi``.
    """
    if ok(lo):
        return lo
    hi = max(2.0 * lo, lo + _TINY)
    while not ok(hi):
        lo = hi
        hi *= 2.0
        if hi > _RHO_CAP:
            return None
    while hi / lo - 1.0 > ROOT_RTOL:
        mid = math.sqrt(lo * hi)
        if not lo < mid < hi:  # adjacent floats
            break
        if ok(mid):
            hi = mid
        else:
            lo = mid
    return hi


def smallest_rho_r(
    c: L1Constants, p: int, omega: float, which: tuple[str, ...] = ("16a", "21a")
) -> float | None:
    """The smallest rho_r satisfying (16a) and/or (21a) at (p, omega); None if none does.

    Monotonicity (why bisection finds *the* smallest). Write ``x = rho_r > 0``,
    ``k = Delta_g_perp Delta_mu_perp / lambda in (0, 1)`` (Assumption 7), ``D = Delta_star >= 0``.
    (16a) holds iff ``psi(x) = (1 - k) - (alpha^2 + eps_r + Gamma_r(x)) / x^2 >= 0``. By (18b),
    ``Gamma_r(x)`` is a non-negative combination of ``1, (x+D)^{1/2}, (x+D), x, (x+D)^{3/2}``, and
    each of these divided by ``x^2`` is non-increasing in x (for ``(x+D)^q / x^2`` with ``q < 2``:
    ``d/dx log = q/(x+D) - 2/x < 0``). Hence psi is non-decreasing, -> -inf as x -> 0
    (``eps_r > 0``), -> 1 - k > 0 as x -> inf: the feasible set is ``[x*, inf)`` with a single
    root x*. For (21a), ``x^2 psi`` is the rhs - lhs of (21a); (22) adds the non-negative terms
    ``(x+D)^{1/2} x``, ``(x+D)^2`` and ``(x+D) x``, whose quotients by x^2,
    ``(x+D)^{1/2}/x``, ``(1 + D/x)^2``, ``1 + D/x``, are non-increasing too; so again psi is
    non-decreasing and the strict set ``{psi > 0}`` is an interval ``(x*, inf)``, non-empty iff
    ``lim psi = 1 - k - (Delta^r_oast2 + Delta^r_oast3) / |2 lambda - omega| > 0``.
    Checked on grids in tests/test_l1drac_design.py.

    The lower end of the bracket is ``sqrt((alpha^2 + eps_r) / (1 - k))`` (below it (16a) fails
    because Gamma_r >= 0) for (16a), and ``max(alpha / sqrt(1-k), 1e-200)`` for (21a) alone.
    """
    p = _check_p(c, p)
    _check_omega(c, omega)
    return _smallest_rho_r(c, reference_constants(c, p), omega, which)


def _smallest_rho_r(
    c: L1Constants, rc: RefConstants, omega: float, which: tuple[str, ...]
) -> float | None:
    out = 0.0
    if "16a" in which:
        lo = math.sqrt((c.alpha**2 + c.eps_r) / (1.0 - c.k_r))
        r = _smallest(lambda x: _c16a(c, rc, omega, x).holds, lo)
        if r is None:
            return None
        out = max(out, r)
    if "21a" in which:
        lo = max(c.alpha / math.sqrt(1.0 - c.k_r), _TINY)
        lo = max(lo, out)  # the joint set is an up-set: start at the (16a) root when known
        r = _smallest(lambda x: _c21a(c, rc, omega, x).holds, lo)
        if r is None:
            return None
        out = max(out, r)
    return out


def smallest_rho_a(
    c: L1Constants,
    p: int,
    omega: float,
    rho_r: float,
    *,
    lambda_s: float | None = None,
    Ts: float | None = None,
    which: tuple[str, ...] = ("16b", "21b", "24"),
) -> float | None:
    """The smallest rho_a satisfying (16b), (21b) and, when Ts is given, (24); None if none does.

    Monotonicity. With ``y = rho_a``, ``k = Delta_g_perp L_mu_perp / lambda in (0, 1)``:
    (16b) is ``psi(y) = (1-k) - Delta_odot1/(2 lambda y) - omega Delta_odot4/(|2l-w| y)
    - Delta_otimes1/(2 sqrt(lambda) sqrt(y)) - eps_a / y^2 >= 0`` with psi increasing, -> -inf at
    0, -> 1 - k > 0 at inf: one root. (21b): (23) is a non-negative combination of ``y^{1/2}``,
    ``rho'' y^{1/2}``, ``y^{3/2}``, ``y``, ``rho'' y``, ``y^2`` with ``rho'' = y + 2(rho_r + D)``;
    divided by y^2 each is non-increasing, so (rhs - lhs)/y^2 is non-decreasing and the feasible
    set is an interval (y*, inf). (24) at fixed Ts: with ``xi1 = y + rho_r + D``, ``xi2 = y``,
    every term of (25a-c) is a non-negative multiple of ``xi2^a xi1^b`` with ``a in {1/2, 1}``,
    ``b in {0, 1/4, 1/2, 1}`` and ``a + b <= 2`` (ring-Upsilon is ``O(xi2^{1/2} + xi2)``, the
    primed maps are ``O(1 + xi1^{1/4} + xi1^{1/2} + xi1)``), and
    ``xi2^a xi1^b / y^2 = y^{a-2} (y + rho_r + D)^b`` is non-increasing in y when
    ``a + b <= 2`` (log-derivative ``(a-2)/y + b/(y + r) <= (a + b - 2)/y <= 0``). So
    ``(rhs - lhs)/y^2`` of (24) is non-decreasing too: an interval [y*, inf).
    The joint set is the intersection of up-sets, an up-set: its left end is the largest root.
    """
    p = _check_p(c, p)
    _check_omega(c, omega)
    if Ts is not None:
        if lambda_s is None:
            raise SpecError("lambda_s is needed to evaluate (24) at a given Ts", field="lambda_s")
        _check_Ts(c, omega, lambda_s, Ts)
    return _smallest_rho_a(c, true_constants(c, p), p, omega, rho_r, lambda_s, Ts, which)


def _smallest_rho_a(
    c: L1Constants,
    tc: TrueConstants,
    p: int,
    omega: float,
    rho_r: float,
    lambda_s: float | None,
    Ts: float | None,
    which: tuple[str, ...],
) -> float | None:
    out = _TINY
    if "16b" in which:
        lo = math.sqrt(c.eps_a / (1.0 - c.k_a))
        r = _smallest(lambda y: _c16b(c, tc, omega, y).holds, lo)
        if r is None:
            return None
        out = max(out, r)
    if "21b" in which:
        r = _smallest(lambda y: _c21b(c, tc, omega, rho_r, y).holds, out)
        if r is None:
            return None
        out = max(out, r)
    if "24" in which and Ts is not None and lambda_s is not None:
        r = _smallest(
            lambda y: _c24(c, tc, p, omega, lambda_s, Ts, rho_r, y).holds,
            out,
        )
        if r is None:
            return None
        out = max(out, r)
    return out


def largest_Ts(
    c: L1Constants, p: int, omega: float, lambda_s: float, rho_r: float, rho_a: float
) -> float | None:
    """The largest Ts for which the monotone envelope of (24) holds; None if (24) cannot hold.

    The paper's left side of (24) is *not* monotone in Ts for every parameter value: gamma_2
    (A.13b) decreases in Ts when omega < lambda_s, and the factors ``Ts e^{-lambda_s Ts}`` and
    ``Ts gamma_1(Ts) e^{-lambda_s Ts}`` of (A.15) rise and then fall. We therefore search on the
    *envelope* (``sampling_constants(..., envelope=True)``): ``e^{-lambda_s Ts} -> 1`` in (A.15),
    ``gamma_2 -> max(gamma_2, 1)``. Proof that the envelope's left side is non-decreasing in Ts:
    it is a sum of products of non-negative factors, each non-decreasing in Ts -- ``Ts``,
    ``sqrt(Ts)``, ``1 - e^{-x Ts}``, ``e^{omega Ts} - 1``; ``Ts gamma_1(Ts)`` (with
    ``u = lambda_s Ts``, ``(Ts gamma_1)^2 = u^2 coth(u/2) / lambda_s`` and
    ``d/du [u^2 coth(u/2)] = u (sinh u - u/2) / sinh^2(u/2) > 0``); ``max(gamma_2, 1)``
    (equal to 1 when omega < lambda_s; when omega >= lambda_s, ``(e^{a T}-1)/(e^{b T}-1)``
    increases for a >= b because ``a / (1 - e^{-a T})`` increases in a, and
    ``e^{(omega - lambda_s) Ts}`` increases);
    gamma'_2 (both arguments of its max are ``1 - (decreasing)`` or ``(increasing) - 1`` around
    the value 1 at Ts = 0); gamma'_1 and the square roots of these. The right side does not
    depend on Ts. So the feasible set of the envelope is an interval ``(0, T*]`` and bisection
    finds T*. Because the envelope bounds the paper's left side from above, (24) itself holds at
    the returned Ts (re-checked in :func:`design`); the true largest Ts can be larger by a
    relative ``O(lambda_s Ts)``, negligible in the regime (24) forces (Ts << 1/lambda_s).

    The bracket starts at ``T_cap = min(1e3, 700 / max(omega, lambda_s, 2 lambda))`` (returned
    as is when (24) holds there) and shrinks by 10 until feasible, down to 1e-200.
    """
    p = _check_p(c, p)
    _check_omega(c, omega)
    _check_Ts(c, omega, lambda_s, 1e-12 / max(omega, lambda_s, 1.0))
    return _largest_Ts(c, true_constants(c, p), p, omega, lambda_s, rho_r, rho_a)


def _largest_Ts(
    c: L1Constants,
    tc: TrueConstants,
    p: int,
    omega: float,
    lambda_s: float,
    rho_r: float,
    rho_a: float,
    budget: float | None = None,
) -> float | None:
    """:func:`largest_Ts` on precomputed constants; ``budget`` replaces the float64 right side
    of (24) when given (the back-off passes its rigorous lower bound)."""
    if budget is None:
        b, th, _ = _budget_a(c, tc, omega, rho_r, rho_a)
        budget = b - th
    if not budget > 0.0:
        return None
    xi1 = rho_a + rho_r + c.Delta_star

    def env_ok(T: float) -> bool:
        s = sampling_constants(c, p, omega, T, lambda_s, envelope=True)
        return upsilon_sum(xi1, rho_a, s) <= budget

    t_cap = min(1e3, _EXP_ARG_MAX / max(omega, lambda_s, 2.0 * c.lam))
    if env_ok(t_cap):
        return t_cap
    hi = t_cap
    lo = t_cap / 10.0
    while not env_ok(lo):
        hi = lo
        lo /= 10.0
        if lo < _TINY:
            return None
    while hi / lo - 1.0 > ROOT_RTOL:
        mid = math.sqrt(lo * hi)
        if not lo < mid < hi:
            break
        if env_ok(mid):
            lo = mid
        else:
            hi = mid
    return lo


# --------------------------------------------------------------------------------------------
# The designer
# --------------------------------------------------------------------------------------------


@dataclass(frozen=True)
class L1Design:
    """Result of :func:`design`: the control parameters, the radii and every condition's verdict.

    ``feasible`` is True iff all five conditions are in ``conditions`` and every one is
    *verified*: re-evaluated at the returned point in Arb ball arithmetic, with a margin ball
    whose lower end is > 0 (:class:`ConditionResult`). ``kappa`` is ``rho * delta^{-1/(2p)}``
    (the Markov step of Theorem 4.1, valid for any delta in (0, 1) at this p; see
    :func:`kappa_markov`), None unless delta was given. ``how`` says for each parameter whether
    it was "given" or "found" (not a provenance label: see :meth:`label`). ``reason`` names the
    failing or unverified condition and by how much when infeasible. ``backoff`` gives, for each
    free parameter moved off its float root, the factor applied (rho_r and rho_a were
    multiplied by it, Ts divided by it; see the module docstring).
    """

    feasible: bool
    p: int
    omega: float | None
    lambda_s: float | None
    Ts: float | None
    rho_r: float | None
    rho_a: float | None
    rho: float | None
    kappa: float | None
    conditions: tuple[ConditionResult, ...]
    reason: str
    notes: tuple[str, ...] = ()
    delta: float | None = None
    how: tuple[tuple[str, str], ...] = ()
    seconds: float = field(default=math.nan, compare=False)
    backoff: tuple[tuple[str, float], ...] = ()

    @property
    def verified(self) -> bool:
        """All five conditions present and Arb-verified (the same as :attr:`feasible`)."""
        return len(self.conditions) == 5 and all(r.verified for r in self.conditions)

    @property
    def min_verified_margin(self) -> float:
        """The smallest rigorous lower end of the margins (``-inf`` without conditions)."""
        return min((r.margin_lo for r in self.conditions), default=-math.inf)

    def label(self, inputs: Any = ()) -> How:
        """The provenance of this design's verdict: ``weakest(VERIFY_METHOD, inputs)``.

        ``inputs`` are the labels of the constants the design was computed from
        (:class:`~drip_cert.provenance.Quantity`, :class:`~drip_cert.provenance.How` or their
        strings); the constants object itself holds plain floats and carries none.
        """
        return weakest(VERIFY_METHOD, inputs)

    def to_dict(self) -> dict[str, Any]:
        """JSON-ready dictionary (keys: feasible, p, omega, lambda_s, Ts, rho_r, rho_a, rho,
        kappa, delta, conditions, reason, notes, how, tolerance, seconds, verified, backoff,
        verification)."""

        def f(x: float | None) -> float | str | None:
            return None if x is None else json_float(x)

        return {
            "feasible": bool(self.feasible),
            "p": self.p,
            "omega": f(self.omega),
            "lambda_s": f(self.lambda_s),
            "Ts": f(self.Ts),
            "rho_r": f(self.rho_r),
            "rho_a": f(self.rho_a),
            "rho": f(self.rho),
            "kappa": f(self.kappa),
            "delta": f(self.delta),
            "conditions": [r.to_dict() for r in self.conditions],
            "reason": self.reason,
            "notes": list(self.notes),
            "how": dict(self.how),
            "tolerance": {
                "root_rtol": ROOT_RTOL,
                "note": "before the back-off, found radii are minimal and Ts maximal to this "
                "relative tolerance; every condition was re-evaluated at the returned point",
            },
            "seconds": json_float(self.seconds),
            "verified": bool(self.verified),
            "backoff": {k: json_float(v) for k, v in self.backoff},
            "verification": {
                "arithmetic": f"Arb ball arithmetic (python-flint), {ARB_PREC} bits",
                "rule": "a condition is verified when the lower end of its margin ball is > 0",
                "min_margin_lo": json_float(self.min_verified_margin),
                "backoff_start": BACKOFF_START,
                "backoff_growth": BACKOFF_GROWTH,
                "backoff_steps": BACKOFF_STEPS,
            },
        }


@dataclass(frozen=True)
class _Point:
    """Inner result at one (omega, lambda_s)."""

    rho_r: float | None
    rho_a: float | None
    Ts: float | None
    reason: str


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
    if req.rho_r is not None:
        rho_r = req.rho_r
    else:
        rho_r = _smallest_rho_r(c, rc, omega, ("16a", "21a"))
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
        rho_a = _smallest_rho_a(c, tc, req.p, omega, rho_r, lambda_s, Ts, ("16b", "21b", "24"))
        if rho_a is None:
            lim = 1.0 - c.k_a - (tc.oast_2 + tc.oast_3) / gap
            which = "(21b)" if Ts is None else "(21b) and (24)"
            return _Point(
                rho_r,
                None,
                None,
                f"{which} fail for every rho_a <= {_RHO_CAP:g} at omega = {omega:.6g} "
                f"(the normalised margin of (21b) tends to {lim:.6g})",
            )
    if Ts is None and find_Ts and lambda_s is not None:
        Ts = _largest_Ts(c, tc, req.p, omega, lambda_s, rho_r, rho_a)
        if Ts is None:
            b, th, _ = _budget_a(c, tc, omega, rho_r, rho_a)
            return _Point(
                rho_r,
                rho_a,
                None,
                f"(24) cannot hold for any Ts: its right side (1-k_a) rho_a^2 - Gamma_a - "
                f"Theta_a/|2 lambda - omega| = {b - th:.6g} is not positive; increase rho_a "
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


def design(c: L1Constants, req: DesignRequest) -> L1Design:
    """Find the free parameters of an L1-DRAC design; implements Sec. 3.2 of L1-DRAC.

    Steps, at fixed (omega, lambda_s):

    1. rho_r: the smallest value satisfying (16a) and (21a) (:func:`smallest_rho_r`).
    2. rho_a: the smallest value satisfying (16b), (21b) and -- when Ts is fixed -- (24)
       (:func:`smallest_rho_a`).
    3. Ts (when free): the largest value satisfying (24) at that rho_a (:func:`largest_Ts`).
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
    p = _check_p(c, req.p)
    if req.omega is not None:
        _check_omega(c, req.omega)
    if req.Ts is not None:
        _check_Ts(
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
            if base.rho_a is None:
                return base, None

            def neg_ts(ls: float) -> float:
                t = _largest_Ts(c, tc, p, omega, ls, base.rho_r, base.rho_a)
                return math.inf if t is None else -t

            ls, v = _log_search(neg_ts, ls_bounds[0], ls_bounds[1], None)
            return _point(c, rc, tc, req, omega, ls, find_Ts=True), ls

        def rho_a_of(ls: float) -> float:
            if max(omega, ls) * req.Ts > _EXP_ARG_MAX:
                return math.inf
            pt = _point(c, rc, tc, req, omega, ls, find_Ts=False)
            return math.inf if pt.rho_a is None else pt.rho_a

        ls, v = _log_search(rho_a_of, ls_bounds[0], ls_bounds[1], None, n_ls)
        return _point(c, rc, tc, req, omega, ls, find_Ts=True), ls

    if req.omega is not None:
        omega = req.omega
        pt, lambda_s = at_omega(omega)
    else:
        lo, hi = req.omega_bounds or (_OMEGA_BOUNDS_REL[0] * lam, _OMEGA_BOUNDS_REL[1] * lam)

        def rho_of(w: float) -> float:
            if w == 2.0 * lam:
                return math.inf
            if req.Ts is not None and max(w, req.lambda_s or 0.0) * req.Ts > _EXP_ARG_MAX:
                return math.inf
            if req.lambda_s is None and req.Ts is not None:
                pt_, _ = at_omega(w, _NESTED_GRID_POINTS)  # nested search: coarser grid
            else:
                pt_ = _point(c, rc, tc, req, w, req.lambda_s, find_Ts=False)
            if pt_.rho_a is None:
                return math.inf
            if req.Ts is None:  # (24) must be satisfiable for some Ts: a positive budget
                b, th, _ = _budget_a(c, tc, w, pt_.rho_r, pt_.rho_a)
                if not b - th > 0.0:
                    return math.inf
            return pt_.rho_r + pt_.rho_a

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
        pt, lambda_s = at_omega(omega)

    rho_r, rho_a, Ts = pt.rho_r, pt.rho_a, pt.Ts
    backoff: tuple[tuple[str, float], ...] = ()
    backoff_reason = ""
    if rho_r is not None and rho_a is not None and Ts is not None and lambda_s is not None:
        bo = _back_off(c, rc, tc, req, p, omega, lambda_s, rho_r, rho_a, Ts)
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
    conditions: tuple[ConditionResult, ...] = ()
    if rho_r is not None:
        conditions += (_c16a(c, rc, omega, rho_r), _c21a(c, rc, omega, rho_r))
    if rho_a is not None:
        conditions += (_c16b(c, tc, omega, rho_a), _c21b(c, tc, omega, rho_r, rho_a))
    if rho_a is not None and Ts is not None and lambda_s is not None:
        conditions += (_c24(c, tc, p, omega, lambda_s, Ts, rho_r, rho_a),)
        env = _c24(c, tc, p, omega, lambda_s, Ts, rho_r, rho_a, envelope=True)
        if req.Ts is None:
            notes.append(
                f"Ts is the largest value for which the monotone envelope of (24) holds, divided "
                f"by the back-off factor (envelope lhs {env.lhs:.6g}, paper's lhs "
                f"{conditions[-1].lhs:.6g})"
            )
    order = ("16a", "16b", "21a", "21b", "24")
    conditions = tuple(sorted(conditions, key=lambda r: order.index(r.eq)))
    if conditions:
        conditions = _verified(
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
        b, th, _ = _budget_a(c, tc, omega, rho_r, rho_a)
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


@dataclass(frozen=True)
class _BackOff:
    """The design point after :func:`_back_off` (the last one tried when ``reason`` is set)."""

    rho_r: float
    rho_a: float
    Ts: float
    factors: tuple[tuple[str, float], ...]
    reason: str


def _backoff_factors() -> tuple[float, ...]:
    """1 + BACKOFF_START * BACKOFF_GROWTH^k, k = 0 .. BACKOFF_STEPS - 1."""
    return tuple(1.0 + BACKOFF_START * BACKOFF_GROWTH**k for k in range(BACKOFF_STEPS))


def _float_conditions(
    c: L1Constants,
    rc: RefConstants,
    tc: TrueConstants,
    p: int,
    omega: float,
    which: tuple[str, ...],
    *,
    rho_r: float | None = None,
    rho_a: float | None = None,
    lambda_s: float | None = None,
    Ts: float | None = None,
) -> tuple[ConditionResult, ...]:
    """The float64 results of the conditions ``which`` at one point (the searches' oracle)."""
    make = {
        "16a": lambda: _c16a(c, rc, omega, rho_r),
        "21a": lambda: _c21a(c, rc, omega, rho_r),
        "16b": lambda: _c16b(c, tc, omega, rho_a),
        "21b": lambda: _c21b(c, tc, omega, rho_r, rho_a),
        "24": lambda: _c24(c, tc, p, omega, lambda_s, Ts, rho_r, rho_a),
    }
    return tuple(make[eq]() for eq in which)


def _back_off(
    c: L1Constants,
    rc: RefConstants,
    tc: TrueConstants,
    req: DesignRequest,
    p: int,
    omega: float,
    lambda_s: float,
    rho_r: float,
    rho_a: float,
    Ts: float,
) -> _BackOff:
    """Move the free parameters of a complete float design off their roots, into the interior.

    In the order rho_r, rho_a, Ts (the module docstring): for each free parameter, the relative
    back-off ``f`` runs through :func:`_backoff_factors` until the conditions that parameter
    closes are Arb-verified -- (16a), (21a) for rho_r; (16b), (21b) (and (24) when Ts is fixed)
    for rho_a; (24) for Ts -- and hold in float64 as well. The second requirement keeps the
    margin above the float64 rounding of the conditions, which is what any other float
    transcription sees: near the smallest rho_a the right side of (24) is a small difference of
    large terms, and a margin that Arb resolves can still be below that rounding. If no step
    meets both, the first Arb-verified step is taken (the verdict is the verified one; the
    design notes the float disagreement); if none is verified, the design is infeasible. rho_a is
    re-solved at the moved rho_r and Ts at the moved radii (both feasible sets shrink as rho_r
    grows). Given parameters are not touched.

    The Ts search of this stage compares the envelope of (24) with the Arb lower bound of its
    right side (:func:`~drip_cert.bounds.l1drac_verify.budget_24_lower`), not with its float64
    value, which can be off in its leading digits for the reason above and would put the float
    root of Ts far from the verified one.
    """
    factors: list[tuple[str, float]] = []

    def search(
        name: str, which: tuple[str, ...], point: Callable[[float], dict[str, float | None]]
    ) -> tuple[float, dict[str, float | None], str]:
        first_verified: tuple[float, dict[str, float | None]] | None = None
        fac, pt = 1.0, point(1.0)
        for fac in _backoff_factors():
            pt = point(fac)
            v = verify_conditions(c, p, omega, which=which, **pt)
            if not all(m.verified for m in v.values()):
                continue
            fl = _float_conditions(c, rc, tc, p, omega, which, **pt)
            if all(r.holds for r in fl):
                return fac, pt, ""
            if first_verified is None:
                first_verified = (fac, pt)
        if first_verified is not None:  # verified, but float64 rounding still hides the margin
            return first_verified[0], first_verified[1], ""
        v = verify_conditions(c, p, omega, which=which, **pt)
        fl = _float_conditions(c, rc, tc, p, omega, which, **pt)
        bad = [(r, v[r.eq]) for r in fl if not v[r.eq].verified]
        return (
            fac,
            pt,
            "; ".join(
                f"({r.eq}) is not verified with a positive margin after backing {name} off its "
                f"float root by a relative {fac - 1.0:.0e} (float64 margin {r.margin:.6g}, Arb "
                f"enclosure [{m.lo:.6g}, {m.hi:.6g}])"
                for r, m in bad
            ),
        )

    def fail(reason: str) -> _BackOff:
        return _BackOff(rho_r, rho_a, Ts, tuple(factors), reason)

    if req.rho_r is None:
        r0 = rho_r
        fac, _, why = search("rho_r", ("16a", "21a"), lambda f: {"rho_r": r0 * f})
        rho_r = r0 * fac
        factors.append(("rho_r", fac))
        if why:
            return fail(why)
        if req.rho_a is None:
            a = _smallest_rho_a(c, tc, p, omega, rho_r, lambda_s, req.Ts, ("16b", "21b", "24"))
            if a is None:
                return fail(f"no rho_a satisfies (16b), (21b) at the moved rho_r = {rho_r:.17g}")
            rho_a = a
    if req.rho_a is None:
        a0 = rho_a
        which = ("16b", "21b") + (("24",) if req.Ts is not None else ())
        fac, _, why = search(
            "rho_a",
            which,
            lambda f: {"rho_r": rho_r, "rho_a": a0 * f, "lambda_s": lambda_s, "Ts": req.Ts},
        )
        rho_a = a0 * fac
        factors.append(("rho_a", fac))
        if why:
            return fail(why)
    if req.Ts is None:
        budget = budget_24_lower(c, p, omega, rho_r, rho_a)
        t = _largest_Ts(c, tc, p, omega, lambda_s, rho_r, rho_a, budget)
        if t is None:
            return fail(
                f"(24) cannot hold for any Ts at rho_r = {rho_r:.17g}, rho_a = {rho_a:.17g}: "
                f"the rigorous lower bound of its right side is {budget:.6g}"
            )
        t0 = t
        fac, _, why = search(
            "Ts",
            ("24",),
            lambda f: {"rho_r": rho_r, "rho_a": rho_a, "lambda_s": lambda_s, "Ts": t0 / f},
        )
        Ts = t0 / fac
        factors.append(("Ts", fac))
        if why:
            return fail(why)
    return _BackOff(rho_r, rho_a, Ts, tuple(factors), "")


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
    Ts_max is :func:`largest_Ts`; it is non-decreasing in rho_a, because (24) at fixed Ts holds on
    an up-set of rho_a (proof in :func:`smallest_rho_a`; the envelope has the same structure).
    """
    p = _check_p(c, p)
    _check_omega(c, omega)
    rc = reference_constants(c, p)
    tc = true_constants(c, p)
    rho_r = _smallest_rho_r(c, rc, omega, ("16a", "21a"))
    if rho_r is None:
        return ()
    a_min = _smallest_rho_a(c, tc, p, omega, rho_r, None, None, ("16b", "21b"))
    if a_min is None:
        return ()
    if rho_a_values is None:
        a0 = a_min * (1.0 + 1e-6)
        rho_a_values = tuple(a0 * max_factor ** (i / max(n - 1, 1)) for i in range(n))
    rows = []
    for a in rho_a_values:
        ok = _c16b(c, tc, omega, a).holds and _c21b(c, tc, omega, rho_r, a).holds
        ts = _largest_Ts(c, tc, p, omega, lambda_s, rho_r, a) if ok else None
        rows.append(TradeoffRow(float(a), ts, rho_r + float(a)))
    return tuple(rows)


# --------------------------------------------------------------------------------------------
# Theorem 4.1: high-probability and ultimate radii
# --------------------------------------------------------------------------------------------


def p_for_delta(delta: float, p_star: int) -> int:
    """The integer moment order Theorem 4.1 needs for a violation probability delta.

    The paper sets ``p = log sqrt(1/delta)``, an integer only for ``delta = e^{-2p}``. The valid
    integer variant (docs/math/l1drac.md section 7; erratum E9 in section 8) is
    ``p = max(1, ceil(0.5 log(1/delta)))``, for
    which ``kappa_markov(rho, p, delta) <= e rho(p)``.

    Raises
    ------
    SpecError
        delta not in (0, 1), or the p it needs exceeds p_star.
    """
    if not (_is_real(delta) and 0.0 < delta < 1.0):
        raise SpecError(f"{delta!r} is not a probability in (0, 1)", field="delta")
    p = max(1, math.ceil(0.5 * math.log(1.0 / delta)))
    if p > 1 and delta >= math.exp(-2.0 * (p - 1)):  # rounding of the log at delta = e^{-2k}
        p -= 1
    if p > p_star:
        raise SpecError(
            f"delta = {delta!r} needs p = ceil(0.5 log(1/delta)) = {p} > p_star = {p_star}: the "
            "nominal process has no bounded moment of that order (Assumption 3); use a larger "
            f"delta (>= {math.exp(-2 * p_star):.3g}) or raise p_star",
            field="delta",
        )
    return p


def kappa_markov(rho: float, p: int, delta: float) -> float:
    """kappa = rho(p) delta^{-1/(2p)}: P(||X_t - X*_t|| >= kappa) < delta (Theorem 4.1, (130a)).

    This is the Markov step of the proof of Theorem 4.1 at an integer p, valid for every delta in
    (0, 1) (``P(|Z| >= k) <= E|Z|^{2p} / k^{2p} < (rho/k)^{2p} = delta``). The paper's
    ``e * rho(log sqrt(1/delta))`` is the case ``p = log sqrt(1/delta)``; with
    ``p = p_for_delta(delta, .)`` this value is ``<= e rho(p)``. Requires the hypotheses with
    ``alpha = ||X0 - X0*||_{L_2p}`` (a coupling), as Theorem 4.1 states.
    """
    if not (0.0 < delta < 1.0):
        raise SpecError(f"{delta!r} is not a probability in (0, 1)", field="delta")
    return rho * delta ** (-1.0 / (2 * p))


def ultimate_bound(c: L1Constants, d: L1Design, t_hat: float) -> float:
    """hat-rho(p, omega, t_hat) = hat-rho_r + rho_a, the ultimate bound (129b) on [t_hat, T].

    hat-rho_r is (85) of Lemma 4.4: ``(e^{-2 lambda t_hat} alpha^2 + Dgp Dmup/lambda rho_r^2 +
    Gamma_r(rho_r) + Theta_r(rho_r)/|2 lambda - omega|)^{1/2}`` (alpha in the role of
    W_2p(xi_0, xi_0*)). Strictly below rho(p) for a feasible design (Lemma 4.4).
    """
    if not d.feasible:
        raise SpecError("the ultimate bound needs a feasible design", field="design")
    if not (_is_real(t_hat) and t_hat >= 0.0 and math.isfinite(t_hat)):
        raise SpecError(f"{t_hat!r} must be a finite time >= 0", field="t_hat")
    rc = reference_constants(c, d.p)
    w = d.omega
    inner = (
        math.exp(-2.0 * c.lam * t_hat) * c.alpha**2
        + c.k_r * d.rho_r**2
        + gamma_r(d.rho_r, w, rc)
        + theta_r(d.rho_r, w, rc) / abs(2.0 * c.lam - w)
    )
    return math.sqrt(inner) + d.rho_a
