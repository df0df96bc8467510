"""Euclidean contraction rate of a closed loop: DRIP Assumption 2.

DRIP Assumption 2 (eq. ``eqn:ILFConditions``) asks for a known ``lambda > 0`` with
``mu_2(d/dx Fbar(t, x, pi*(x))) <= -lambda`` for **all** ``(t, x)``, ``mu_2`` the log norm induced
by the Euclidean norm. :func:`contraction_rate` returns the largest ``lambda`` it can establish:

* ``'exact-linear'``: the Jacobian is a constant matrix (linear or affine closed loop):
  ``lambda = -mu_2(J)`` exactly, for all ``x`` and ``t``.
* ``'interval-bnb'``: a *sound* lower bound on the rate over a box of states (and a time range):
  rigorous interval enclosures of the Jacobian entries on sub-boxes
  (:class:`~drip_cert.numerics.interval.MatrixEnclosure`), a rigorous Rohn-type bound of ``mu_2`` of
  the interval matrix (:func:`~drip_cert.analysis.contraction.lognorm.mu2_interval_upper`), and
  branch and bound
  that splits the worst sub-box along its widest (relative) side until the global upper bound is
  within ``tol`` of the best sampled value or the box budget is spent. A Jacobian that depends on
  ``t`` only is treated the same way over the time range, and then holds for all ``x``.
* ``'mlp-bnb'``: a *sound* bound over a box for a Jacobian affine in the Jacobians of MLP blocks
  applied to the state (``J = A + sum_k C_k D h_k(x)``, the learned loops of the paper's
  example), when the MLPs are passed as ``mlps``: the vectorised branch and bound of
  :mod:`drip_cert.analysis.contraction.mlp_loop` (Hessian enclosures of the networks, a centred
  linearisation whose ``mu_2`` is convex in ``x`` and so bounded at the vertices, the remainder
  by Weyl; second order in the sub-box size). ``'auto'`` prefers it when it applies.
* ``'sampled'``: dense grid + random points + local maximisation (scipy L-BFGS-B). This is an
  **estimate** (:attr:`How.ESTIMATE`), never a bound; it is what is left when an expression has no
  rigorous enclosure (an undefined function without an ``enclose`` callback).

A box is weaker than the paper's "for all x": the rate then holds only while trajectories stay in
the box; the result's ``region`` says so.
"""

from __future__ import annotations

import math
import time
from collections.abc import Callable, Mapping, Sequence
from dataclasses import dataclass
from types import MappingProxyType
from typing import Any, Protocol

import numpy as np
import sympy as sp

from drip_cert.analysis.contraction.lognorm import mu2_constant_bounds, mu2_interval_upper, mu_2
from drip_cert.analysis.contraction.mlp_loop import DEFAULT_BATCH, box_bounds, decompose_jacobian
from drip_cert.errors import SolverError, SpecError
from drip_cert.model.mlp import MLP
from drip_cert.numerics.bnb import maximize
from drip_cert.numerics.bnb_batch import maximize_batch
from drip_cert.numerics.interval import (
    EncloseCallback,
    MatrixEnclosure,
    UnsupportedExpression,
    opaque_functions,
)
from drip_cert.provenance import GLOBAL, How, Quantity, Scope, json_float
from drip_cert.vocabulary import CONTRACTION_AUTO, CONTRACTION_METHODS, CONTRACTION_ROUTE_NAMES

__all__ = [
    "ContractionResult",
    "ROUTES",
    "Route",
    "SamplingOptions",
    "contraction_rate",
    "sampled_max_mu2",
    "jacobian_function",
    "DEFAULT_TOL",
    "DEFAULT_MAX_BOXES",
    "DEFAULT_MAX_TIME_S",
]

#: absolute tolerance on the gap (sound upper bound - sampled max) of ``mu_2``
DEFAULT_TOL = 1e-3
#: budget of sub-boxes for branch and bound
DEFAULT_MAX_BOXES = 20_000
#: wall-time guard of branch and bound: none. The searches stop on a count of work (``max_boxes``)
#: so that the same inputs give the same rate on any machine; a finite guard, when a caller sets
#: one and it fires, makes the result depend on the machine's speed (``stop == 'max_time'``)
DEFAULT_MAX_TIME_S = math.inf

JacobianFn = Callable[[np.ndarray, np.ndarray], np.ndarray]

_SOURCE = "DRIP Assumption 2 (eqn:ILFConditions), Euclidean log norm"


@dataclass(frozen=True)
class SamplingOptions:
    """How the sampled estimate of ``max mu_2`` is computed.

    Parameters
    ----------
    n_grid
        Approximate number of grid points (odd count per side so the centre is on the grid).
    n_random
        Uniform random points in the box.
    n_local
        Local maximisations (L-BFGS-B) started from the best grid/random points.
    seed
        Seed of the ``np.random.Generator`` used for the random points.
    """

    n_grid: int = 4096
    n_random: int = 2048
    n_local: int = 5
    seed: int = 0

    def __post_init__(self) -> None:
        for name in ("n_grid", "n_random", "n_local"):
            if getattr(self, name) < 0:
                raise SpecError(f"must be >= 0, got {getattr(self, name)}", field=name)


@dataclass(frozen=True)
class ContractionResult:
    """Contraction rate ``lambda`` with ``mu_2(J) <= -lambda`` on ``region``.

    Attributes
    ----------
    rate
        The rate; ``<= 0`` when Assumption 2 is not established (for ``how == SOUND`` it is
        ``-max_mu_upper``, for ``ESTIMATE`` it is ``-max_mu_sampled``).
    how
        ``EXACT`` (constant Jacobian), ``SOUND`` (interval branch and bound or verified LMI),
        ``ESTIMATE`` (sampled).
    method
        ``'exact-linear'``, ``'interval-bnb'``, ``'mlp-bnb'``, ``'sampled'`` or ``'lmi-metric'``.
    scope
        Where the rate holds (:class:`~drip_cert.provenance.Scope`): all states and times, or a
        box and/or a time range (weaker than the paper's "for all x and t").
    max_mu_upper
        Sound upper bound on ``max mu_2(J)`` over the region (NaN for an estimate).
    max_mu_sampled
        Largest sampled ``mu_2(J)`` (a lower bound on the true maximum up to rounding).
    witness
        ``(x..., t)`` where the sampled ``mu_2`` is largest (NaN-free; ``None`` if not sampled).
    tolerance
        Requested gap ``max_mu_upper - max_mu_sampled``.
    n_boxes
        Sub-boxes evaluated by branch and bound.
    time_s
        Wall time (a timing: kept out of the certificate's reproducible part).
    stop
        Why the search stopped: ``'exact'`` (closed form), ``'sampled'`` (an estimate), or the
        branch and bound's reason (``'converged'``, ``'max_boxes'``, ``'min_width'``,
        ``'max_time'``: the wall-time guard fired, so the rate depends on the machine's speed).
    note
        Free text (why a fallback happened, whether the gap met the tolerance, ...).
    """

    rate: float
    how: How
    method: str
    scope: Scope
    max_mu_upper: float
    max_mu_sampled: float
    witness: tuple[float, ...] | None
    tolerance: float
    n_boxes: int
    time_s: float
    note: str = ""
    stop: str = "converged"

    @property
    def machine_dependent(self) -> bool:
        """Whether the search stopped on wall time (its bound then depends on the machine)."""
        return self.stop == "max_time"

    @property
    def holds(self) -> bool:
        """Whether Assumption 2 is established (``rate > 0``) by this result's method."""
        return self.rate > 0

    @property
    def region(self) -> str:
        """Where the rate holds, as text (``"all x, all t"``, ``"box [...], all t"``)."""
        return self.scope.describe()

    @property
    def gap(self) -> float:
        """``max_mu_upper - max_mu_sampled`` (NaN for an estimate)."""
        return self.max_mu_upper - self.max_mu_sampled

    def to_quantity(self) -> Quantity:
        """The rate as a :class:`~drip_cert.provenance.Quantity` named ``lambda``."""
        return Quantity(
            "lambda",
            self.rate,
            self.how,
            _SOURCE,
            f"{self.method} on {self.region}. {self.note}".strip(),
            self.scope,
        )

    def to_dict(self) -> dict[str, Any]:
        """JSON-ready dictionary."""
        return {
            "rate": json_float(self.rate),
            "how": How(self.how).value,
            "method": self.method,
            "region": self.region,
            "scope": self.scope.to_dict(),
            "max_mu_upper": json_float(self.max_mu_upper),
            "max_mu_sampled": json_float(self.max_mu_sampled),
            "witness": None if self.witness is None else [float(w) for w in self.witness],
            "tolerance": json_float(self.tolerance),
            "n_boxes": int(self.n_boxes),
            "stop": self.stop,
            "time_s": float(self.time_s),
            "note": self.note,
            "holds": self.holds,
        }


# --------------------------------------------------------------------------------------------
# input validation
# --------------------------------------------------------------------------------------------


def _check_inputs(J, states, box, t, t_range):
    if not isinstance(J, sp.MatrixBase) or J.shape[0] != J.shape[1]:
        raise SpecError(f"J must be a square sympy Matrix, got {type(J).__name__}", field="J")
    n = J.shape[0]
    states = tuple(states)
    if len(states) != n:
        raise SpecError(f"{len(states)} state symbols for a {n}x{n} Jacobian", field="states")
    allowed = set(states) | ({t} if t is not None else set())
    extra = J.free_symbols - allowed
    if extra:
        raise SpecError(
            f"J contains symbols {sorted(map(str, extra))} that are neither states nor the time "
            "symbol; substitute parameter values first",
            field="J",
        )
    if box is not None:
        box = np.asarray(box, dtype=float)
        if box.shape != (n, 2) or not np.all(np.isfinite(box)) or np.any(box[:, 0] > box[:, 1]):
            raise SpecError(
                f"box must be a finite (n, 2) = ({n}, 2) array with lo <= hi per row, got {box!r}",
                field="box",
            )
    if t_range is not None:
        a, b = (float(v) for v in t_range)
        if not (math.isfinite(a) and math.isfinite(b) and a <= b):
            raise SpecError(f"t_range must be finite with lo <= hi, got {t_range}", field="t_range")
        t_range = (a, b)
    return n, states, box, t_range


def _scope(box: np.ndarray | None, t_range, depends_t: bool) -> Scope:
    """All x unless ``box``; all t unless the Jacobian depends on t (then ``t_range``)."""
    return Scope(
        None if box is None else tuple(map(tuple, np.asarray(box, dtype=float))),
        tuple(t_range) if depends_t else None,
    )


# --------------------------------------------------------------------------------------------
# numeric Jacobian and sampling
# --------------------------------------------------------------------------------------------


def jacobian_function(J: sp.Matrix, states: Sequence[sp.Symbol], t: sp.Symbol | None) -> JacobianFn:
    """Vectorised numpy Jacobian ``J_num(t, X) -> (N, n, n)`` by ``sympy.lambdify``.

    ``t`` is an array of shape ``(N,)`` (ignored if ``J`` has no time symbol), ``X`` has shape
    ``(N, n)``. Raises :class:`UnsupportedExpression` when ``J`` contains undefined functions
    (pass a ``J_num`` built from the system instead).
    """
    opaque = opaque_functions(J)
    if opaque:
        names = sorted({str(f.func) for f in opaque})
        raise UnsupportedExpression(
            f"J contains undefined functions {names}; pass J_num(t, X) built from the system"
        )
    n = J.shape[0]
    tt = t if t is not None else sp.Dummy("t")
    fns = [sp.lambdify((tt, *states), e, modules="numpy") for e in J]

    def J_num(tv: np.ndarray, X: np.ndarray) -> np.ndarray:
        X = np.asarray(X, dtype=float)
        N = X.shape[0]
        tv = np.broadcast_to(np.asarray(tv, dtype=float), (N,))
        cols = [X[:, i] for i in range(n)]
        out = np.empty((N, n * n))
        for k, f in enumerate(fns):
            out[:, k] = np.broadcast_to(np.asarray(f(tv, *cols), dtype=float), (N,))
        return out.reshape(N, n, n)

    return J_num


def _grid(full: np.ndarray, n_grid: int) -> np.ndarray:
    d = full.shape[0]
    live = [i for i in range(d) if full[i, 1] > full[i, 0]]
    k = max(3, int(round(n_grid ** (1.0 / max(len(live), 1))))) if live else 1
    if k % 2 == 0:
        k += 1
    axes = [
        np.linspace(full[i, 0], full[i, 1], k) if i in live else np.array([full[i, 0]])
        for i in range(d)
    ]
    mesh = np.meshgrid(*axes, indexing="ij")
    return np.stack([m.ravel() for m in mesh], axis=-1)


def sampled_max_mu2(
    J_num: JacobianFn,
    full_box: np.ndarray,
    n_states: int,
    options: SamplingOptions = SamplingOptions(),
) -> tuple[float, np.ndarray]:
    """Sampled estimate of ``max mu_2(J)`` over a box (ESTIMATE, not a bound).

    Parameters
    ----------
    J_num
        ``J_num(t, X) -> (N, n, n)``.
    full_box
        ``(n [+1], 2)``: the state box, with the time range as a last row when ``J`` depends on t.
    n_states
        ``n``; a row beyond it is time.
    options
        Grid size, random points, local searches and the seed.

    Returns
    -------
    (value, argmax)
        The largest ``mu_2`` found and the point ``(x..., [t])`` where it was found.
    """
    full_box = np.asarray(full_box, dtype=float)
    d = full_box.shape[0]
    rng = np.random.default_rng(options.seed)

    def mu_at(P: np.ndarray) -> np.ndarray:
        P = np.atleast_2d(P)
        tv = P[:, n_states] if d > n_states else np.zeros(P.shape[0])
        vals = mu_2(J_num(tv, P[:, :n_states]))
        return np.where(np.isfinite(vals), vals, np.inf)

    pts = [_grid(full_box, options.n_grid)]
    if options.n_random:
        pts.append(full_box[:, 0] + rng.random((options.n_random, d)) * np.ptp(full_box, axis=1))
    P = np.concatenate(pts)
    vals = mu_at(P)
    order = np.argsort(-vals)
    best_i = int(order[0])
    best, arg = float(vals[best_i]), P[best_i].copy()
    bounds = [(float(a), float(b)) for a, b in full_box]
    from scipy.optimize import minimize  # scipy.optimize: 0.4 CPU-s to import, this route only

    for i in order[: options.n_local]:
        res = minimize(
            lambda z: -float(mu_at(z)[0]),
            P[i],
            method="L-BFGS-B",
            bounds=bounds,
            options={"maxiter": 200},
        )
        z = np.clip(res.x, full_box[:, 0], full_box[:, 1])
        v = float(mu_at(z)[0])
        if v > best:
            best, arg = v, z
    return best, arg


def contraction_rate(
    J: sp.Matrix,
    states: Sequence[sp.Symbol],
    box: np.ndarray | None = None,
    t: sp.Symbol | None = None,
    t_range: tuple[float, float] | None = None,
    *,
    J_num: JacobianFn | None = None,
    enclose: EncloseCallback | None = None,
    method: str = "auto",
    tol: float = DEFAULT_TOL,
    max_boxes: int = DEFAULT_MAX_BOXES,
    max_time_s: float = DEFAULT_MAX_TIME_S,
    sampling: SamplingOptions = SamplingOptions(),
    mlps: Mapping[str, MLP] | None = None,
) -> ContractionResult:
    """Contraction rate ``lambda`` with ``mu_2(J(t, x)) <= -lambda`` (DRIP Assumption 2).

    Parameters
    ----------
    J
        Closed-loop Jacobian ``d/dx [f(t, x) + g(t) pi(x)]``, a square sympy Matrix.
    states
        State symbols ``x1..xn`` (the order of the rows of ``box``).
    box
        ``(n, 2)`` support box of the states; required when ``J`` depends on the states.
    t, t_range
        Time symbol and range; ``t_range`` is required when ``J`` depends on ``t``.
    J_num
        Optional vectorised numeric Jacobian ``J_num(t, X) -> (N, n, n)`` for sampling; built by
        :func:`jacobian_function` when absent.
    enclose
        Interval callback for undefined functions (see :mod:`drip_cert.numerics.interval`).
    method
        ``'auto'`` (the first route of :data:`ROUTES` that applies: exact if ``J`` is constant,
        else ``'mlp-bnb'`` when it applies, else interval branch and bound, falling back to
        sampling when an expression has no sound enclosure), or a route's name
        (:data:`drip_cert.vocabulary.CONTRACTION_ROUTES`): ``'exact-linear'``,
        ``'interval-bnb'``, ``'mlp-bnb'`` or ``'sampled'``. A constant ``J`` is always
        ``'exact-linear'``.
    tol
        Absolute target gap between the sound upper bound and the sampled maximum of ``mu_2``.
    max_boxes, max_time_s
        Budgets of branch and bound: ``max_boxes`` (a count of work, what makes the result the
        same on every machine) and an optional wall-time guard ``max_time_s`` (default none);
        when one is spent the bound is still sound, only looser, and ``stop`` says which.
    sampling
        :class:`SamplingOptions` of the sampled estimate (its seed makes the result reproducible).
    mlps
        The MLPs of the blocks by name (e.g. ``mlp_loop.system_mlps(system)``); enables
        ``'mlp-bnb'`` for a Jacobian affine in their Jacobians (time-invariant, on ``box``).

    Returns
    -------
    ContractionResult
    """
    t0 = time.perf_counter()
    n, states, box, t_range = _check_inputs(J, states, box, t, t_range)
    if method not in CONTRACTION_METHODS:
        raise SpecError(
            f"unknown method {method!r}; use one of {CONTRACTION_METHODS}", field="method"
        )
    if tol <= 0:
        raise SpecError(f"tol must be > 0, got {tol}", field="tol")
    depends_x = bool(J.free_symbols & set(states)) or bool(opaque_functions(J))
    depends_t = t is not None and J.has(t)
    if not depends_x and not depends_t:
        return _exact_linear(t0, J)  # whatever the method: the closed form is best
    if method == "exact-linear":
        raise SpecError(
            "method 'exact-linear' needs a Jacobian constant in x and t; use 'auto'", field="method"
        )
    if depends_t and t_range is None:
        raise SpecError(
            "J depends on the time symbol; give t_range=(t0, T) (the paper asks for all t >= 0, "
            "a finite range is weaker)",
            field="t_range",
        )
    if depends_x and box is None:
        raise SpecError(
            "J depends on the states; give a support box of shape (n, 2) (the paper asks for all "
            "x: a box is weaker and the report says so)",
            field="box",
        )
    # the box of the search: states (a dummy 0-width box when J is free of x), then time
    sbox = box if box is not None else np.zeros((n, 2))
    if J_num is None:
        try:
            J_num = jacobian_function(J, states, t)
        except UnsupportedExpression:
            J_num = None
    problem = _Problem(
        t0=t0,
        J=J,
        n=n,
        box=box,
        full=np.vstack([sbox, [t_range]]) if depends_t else sbox.copy(),
        variables=[*states, t] if depends_t else list(states),
        states=list(states),
        depends_x=depends_x,
        depends_t=depends_t,
        scope=_scope(box if depends_x else None, t_range, depends_t),
        J_num=J_num,
        enclose=enclose,
        tol=tol,
        max_boxes=max_boxes,
        max_time_s=max_time_s,
        sampling=sampling,
        mlps=mlps,
    )
    if method != CONTRACTION_AUTO:
        out = ROUTES[method](problem, explicit=True, reason="")
        if isinstance(out, str):
            raise SpecError(out, field="method")
        return out
    reason = ""
    for route in _AUTO_ROUTES:
        got = route(problem, explicit=False, reason=reason)
        if not isinstance(got, str):
            return got
        reason = got
    raise AssertionError("the sampled route always applies")  # pragma: no cover


@dataclass(frozen=True)
class _Problem:
    """A rate problem prepared for the routes: ``J`` on the search box ``full`` (states, then
    the time range when ``J`` depends on ``t``)."""

    t0: float  #: start of the wall clock (a timing)
    J: sp.Matrix
    n: int
    box: np.ndarray | None
    full: np.ndarray
    variables: list[sp.Symbol]
    states: list[sp.Symbol]
    depends_x: bool
    depends_t: bool
    scope: Scope
    J_num: JacobianFn | None
    enclose: EncloseCallback | None
    tol: float
    max_boxes: int
    max_time_s: float
    sampling: SamplingOptions
    mlps: Mapping[str, MLP] | None


class Route(Protocol):
    """A route of :func:`contraction_rate`: its result, or why it does not apply (a sentence).

    ``explicit``: the caller named this route (a route that cannot run raises, rather than
    stepping aside for the next); ``reason``: why the previous route did not apply.
    """

    def __call__(self, p: _Problem, *, explicit: bool, reason: str) -> ContractionResult | str: ...


def _exact_linear(t0: float, J: sp.Matrix) -> ContractionResult:
    """A constant Jacobian: ``mu_2 = lambda_max(sym J)`` isolated exactly."""
    # rational characteristic polynomial, roots in Arb; float eigvalsh of the rounded matrix can
    # have the wrong sign when mu_2 is within rounding of 0
    try:
        lo_mu, ub = mu2_constant_bounds(sp.Matrix(J))
    except (TypeError, ValueError) as exc:
        raise SpecError(f"J is constant but not real-valued: {J}", field="J") from exc
    mid = float(lo_mu)
    return _result(
        t0,
        How.EXACT,
        "exact-linear",
        GLOBAL,
        upper=ub,
        sampled=mid,
        witness=None,
        tolerance=0.0,
        n_boxes=0,
        stop="exact",
        note="constant Jacobian (linear or affine closed loop): mu_2 = lambda_max(sym J) "
        "isolated exactly (rational characteristic polynomial, roots in Arb); the rate is "
        "the rigorous lower end",
    )


def _exact_linear_route(p: _Problem, *, explicit: bool, reason: str) -> ContractionResult | str:
    """``'exact-linear'`` as a route: applies only to a Jacobian constant in ``x`` and ``t``."""
    if p.depends_x or p.depends_t:
        return "method 'exact-linear' needs a Jacobian constant in x and t; use 'auto'"
    return _exact_linear(p.t0, p.J)


def _mlp_bnb_route(p: _Problem, *, explicit: bool, reason: str) -> ContractionResult | str:
    """``'mlp-bnb'``: a time-invariant ``J = A + sum_k C_k Dh_k(x)`` of MLP blocks on a box."""
    if not p.depends_t and p.box is not None:
        dec = decompose_jacobian(p.J, p.states, p.mlps) if p.mlps else None
        if dec is not None:
            return _mlp_bnb(
                p.t0, dec, p.box, p.J_num, p.scope, p.tol, p.max_boxes, p.max_time_s, p.sampling
            )
    return (
        "method 'mlp-bnb' needs a time-invariant Jacobian A + sum_k C_k Dh_k(x) of MLP blocks "
        "applied to the state, their MLPs passed as mlps=..., and a box; use 'auto'"
    )


def _interval_bnb_route(p: _Problem, *, explicit: bool, reason: str) -> ContractionResult | str:
    """``'interval-bnb'``: interval enclosures of ``J`` and branch and bound of the Rohn-type
    bound of ``mu_2``; without a sound enclosure, named: raises, else steps aside (why)."""
    try:
        menc = MatrixEnclosure(p.J, p.variables, p.enclose)
        menc(p.full)  # domain errors and callback refusals surface here
    except UnsupportedExpression as exc:
        if explicit:
            raise
        return str(exc)
    n, full, J_num, depends_t = p.n, p.full, p.J_num, p.depends_t
    if J_num is not None:
        lb, arg = sampled_max_mu2(J_num, full, n, p.sampling)
    else:
        lb, arg = -math.inf, 0.5 * (full[:, 0] + full[:, 1])

    def point_mu(z: np.ndarray) -> float:
        if J_num is not None:
            tv = np.array([z[n]]) if depends_t else np.zeros(1)
            return float(mu_2(J_num(tv, z[None, :n]))[0])
        lo, hi = menc(np.stack([z, z], axis=1))
        return float(mu_2(0.5 * (lo + hi)))

    if not math.isfinite(lb):
        lb = point_mu(arg)

    def upper(b: np.ndarray) -> float:
        lo, hi = menc(b)
        return mu2_interval_upper(lo, hi)

    res = maximize(
        full,
        upper,
        point_mu,
        atol=p.tol,
        max_boxes=p.max_boxes,
        max_time_s=p.max_time_s,
        active=[p.J.has(v) for v in p.variables],
        initial=(lb, arg),
    )
    ub, lb, witness, n_boxes = res.upper, res.lower, res.argmax, res.n_boxes
    assert witness is not None  # maximize was given initial=(lb, arg): it returns a point
    if lb > ub + 1e-9 * (1.0 + abs(ub)):
        raise SolverError(
            f"a sampled mu_2 = {lb:.17g} at {list(witness)} exceeds the sound bound {ub:.17g}: "
            "J_num does not evaluate the same Jacobian as J (or an enclose callback is unsound)"
        )
    gap = ub - lb
    tol = p.tol
    note = (
        f"sound bound {ub:.6g} vs sampled {lb:.6g}, gap {gap:.3g}"
        + (" <= tol" if gap <= tol else f" > tol {tol:g}: {_spent(res.stop, n_boxes)}")
        + ("" if p.depends_x else "; J is independent of x, so the rate holds for all x")
    )
    if p.depends_x:
        note += "; holds only on the box (the paper asks for all x)"
    return _result(
        p.t0,
        How.SOUND,
        "interval-bnb",
        p.scope,
        upper=ub,
        sampled=lb,
        witness=witness,
        tolerance=tol,
        n_boxes=n_boxes,
        stop=res.stop,
        note=note,
    )


def _sampled_route(p: _Problem, *, explicit: bool, reason: str) -> ContractionResult | str:
    """``'sampled'``: grid + random points + local search, an estimate (never a bound);
    ``reason``: why no sound route applied, for the note."""
    if p.J_num is None:
        raise UnsupportedExpression(
            f"no sound enclosure ({reason}) and no J_num to sample: "
            "pass J_num or an enclose callback"
        )
    lb, arg = sampled_max_mu2(p.J_num, p.full, p.n, p.sampling)
    return _result(
        p.t0,
        How.ESTIMATE,
        "sampled",
        p.scope,
        upper=math.nan,
        sampled=lb,
        witness=arg,
        tolerance=p.tol,
        n_boxes=0,
        stop="sampled",
        note=(
            "sampled estimate (grid + random + local search), NOT a bound"
            + (f"; no sound enclosure: {reason}" if reason else "")
        ),
    )


ROUTES: Mapping[str, Route] = MappingProxyType(
    {
        "exact-linear": _exact_linear_route,
        "mlp-bnb": _mlp_bnb_route,
        "interval-bnb": _interval_bnb_route,
        "sampled": _sampled_route,
    }
)
"""The implementations of the routes named in :data:`drip_cert.vocabulary.CONTRACTION_ROUTES`
(their meanings), in the order ``'auto'`` tries them."""

#: ``'auto'`` after the constant case: the routes that can apply to a ``J`` varying in x or t
_AUTO_ROUTES = tuple(ROUTES[name] for name in CONTRACTION_ROUTE_NAMES if name != "exact-linear")


def _mlp_bnb(
    t0: float,
    dec: Any,
    box: np.ndarray,
    J_num: JacobianFn | None,
    scope: Scope,
    tol: float,
    max_boxes: int,
    max_time_s: float,
    sampling: SamplingOptions,
) -> ContractionResult:
    """The ``'mlp-bnb'`` route: :func:`~drip_cert.numerics.bnb_batch.maximize_batch` of the
    vertex bound :func:`~drip_cert.analysis.contraction.mlp_loop.box_bounds` (sound on every
    sub-box), started
    from the sampled maximum."""
    n = box.shape[0]

    def jnum(tv: np.ndarray, X: np.ndarray) -> np.ndarray:
        return dec.evaluate(X)

    lb, arg = sampled_max_mu2(J_num if J_num is not None else jnum, box, n, sampling)
    res = maximize_batch(
        box,
        lambda bs: box_bounds(dec, bs, "mu2"),
        atol=tol,
        max_boxes=max_boxes,
        max_time_s=max_time_s,
        batch=DEFAULT_BATCH,
        initial=(lb, arg),
    )
    ub, lb = res.upper, res.lower
    witness = res.argmax
    if lb > ub + 1e-9 * (1.0 + abs(ub)):
        raise SolverError(
            f"a sampled mu_2 = {lb:.17g} at {witness} exceeds the sound bound {ub:.17g}: "
            "J_num does not evaluate the same Jacobian as J"
        )
    gap = ub - lb
    note = (
        f"sound bound {ub:.6g} vs sampled {lb:.6g}, gap {gap:.3g}"
        + (" <= tol" if gap <= tol else f" > tol {tol:g}: {_spent(res.stop, res.n_boxes)}")
        + f"; blocks {', '.join(dec.names)}; holds only on the box (the paper asks for all x)"
    )
    return _result(
        t0,
        How.SOUND,
        "mlp-bnb",
        scope,
        upper=ub,
        sampled=lb,
        witness=witness,
        tolerance=tol,
        n_boxes=res.n_boxes,
        stop=res.stop,
        note=note,
    )


def _result(
    t0: float,
    how: How,
    method: str,
    scope: Scope,
    *,
    upper: float,
    sampled: float,
    witness: Sequence[float] | np.ndarray | None,
    tolerance: float,
    n_boxes: int,
    stop: str,
    note: str,
) -> ContractionResult:
    """The result of a method started at ``t0``: the rate is ``-upper`` for a bound (exact or
    sound) and ``-sampled`` for an estimate."""
    return ContractionResult(
        rate=-sampled if how is How.ESTIMATE else -upper,
        how=how,
        method=method,
        scope=scope,
        max_mu_upper=upper,
        max_mu_sampled=sampled,
        witness=None if witness is None else tuple(float(v) for v in witness),
        tolerance=tolerance,
        n_boxes=n_boxes,
        time_s=time.perf_counter() - t0,
        note=note,
        stop=stop,
    )


def _spent(stop: str, n_boxes: int) -> str:
    """Which budget ended a search that did not meet its tolerance, for the note."""
    if stop == "max_time":
        return (
            f"the wall-time guard fired after {n_boxes} boxes (this bound depends on the "
            "machine's speed: raise or remove [contraction] max_time)"
        )
    if stop == "min_width":
        return f"the sub-boxes reached the smallest width after {n_boxes} boxes"
    return f"work budget spent ({n_boxes} boxes; raise [contraction] max_boxes)"
