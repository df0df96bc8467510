"""Constants a :class:`~drip_cert.system.System` determines (DRIP Assumption 1, L1-DRAC
Assumptions 1, 4, 6, 7).

Each constant is a :class:`~drip_cert.provenance.Quantity` that records how it was obtained:

* input operator ``g``: for a constant ``g`` every constant is exact (closed form, outward
  rounded); for a time-varying ``g`` the sup over ``t in [0, T]`` is a rigorous interval bound
  over :data:`TIME_PIECES` pieces of ``[0, T]`` (sound, scope ``t in [0, T]``); the unmatched
  parts use the projector ``P_perp(t) = I - g(t) Theta_ad(t)``, a closed form in ``t``; for a
  state-dependent ``g(t, x)`` the suprema (and the infimum of ``sigma_min``) are taken over a box
  the caller names (the set the trajectories are proved to stay in), by interval branch and
  bound (sound, scope that box), and the L1-DRAC-only constants (``g'``, ``Theta_ad``) are not
  computed (docs/math/contraction.md section 6);
* ``Theta_ad = [I_m 0] gbar^{-1}``: with ``g_perp`` an orthonormal basis of ``ker g^T`` this is
  the pseudo-inverse ``(g^T g)^{-1} g^T`` (the matched part does not depend on the choice of
  ``g_perp``), computed symbolically;
* growth and regularity constants of the uncertainty (``Delta_mu``, ``Delta_sigma``, their
  matched/unmatched parts of L1-DRAC (7), ``L_mu``, the 1/2-Hoelder ``L_sigma``): the paper asks
  for bounds over all of ``R^n``. When an uncertainty depends on the state only through
  ``r = ||x||`` (as in the paper's example), the supremum reduces to one dimension and is
  computed soundly; so is any uncertainty bounded on all of ``R^n`` or globally Lipschitz (see
  :mod:`drip_cert.analysis.growth.regularity` for the routes); otherwise it is a sampled estimate
  over a
  large region, labelled ``estimate``, and the certificate lists it as such. A value the user
  gives in the ``[constants]`` table is taken as given.
"""

from __future__ import annotations

import functools
import math
from collections.abc import Callable, Mapping
from dataclasses import dataclass
from typing import Any

import numpy as np
import sympy as sp

from drip_cert.analysis.contraction.lognorm import mu2_interval_upper
from drip_cert.analysis.growth.regularity import (
    growth_bound,
    holder_half_bound,
    lipschitz_bound,
    sup_bound,
)
from drip_cert.model.system import System
from drip_cert.numerics.bnb import maximize
from drip_cert.numerics.interval import (
    MatrixEnclosure,
    UnsupportedExpression,
    enclose_expr,
    interval_add,
    interval_mul,
)
from drip_cert.numerics.rounding import mul_up, sqrt_down, sqrt_up, sum_sq_up
from drip_cert.provenance import How, Quantity, Scope
from drip_cert.spec.settings import ConstantsTable


def g_perp_at(s: System, t: float = 0.0, x: np.ndarray | None = None) -> np.ndarray:
    """Orthonormal basis of ``ker g(t, x)^T`` (n x (n-m)), from the SVD of ``g(t, x)``."""
    G = s.g_at(t, x)
    u, _, _ = np.linalg.svd(G, full_matrices=True)
    return u[:, s.m :]


#: pieces of [0, T] over which a time-varying g is enclosed (interval bounds of sup over t)
TIME_PIECES = 256


@dataclass(frozen=True)
class InputConstants:
    """Constants of the input operator (DRIP Assumption 1, L1-DRAC Assumption 1).

    Every bound is rigorous: entries of ``g(t)``, ``g'(t)`` and ``Theta_ad(t)`` are enclosed by
    outward-rounded interval arithmetic (over pieces of ``[0, T]`` when they depend on ``t``), the
    norms bounded with Arb (:func:`~drip_cert.analysis.contraction.lognorm.mu2_interval_upper`).
    """

    Delta_g: Quantity  #: sup_t ||g(t)||_F (the paper's)
    Delta_g_spectral: Quantity  #: sup_t ||g(t)||_2 (tighter; used by the comparison bound)
    Delta_g_dot: Quantity  #: sup_t ||g'(t)||_F
    Delta_g_perp: Quantity  #: ||g_perp||_F = sqrt(n - m) for orthonormal g_perp
    Delta_Theta: Quantity  #: sup_t ||Theta_ad(t)||_F
    Theta_spectral: Quantity  #: sup_t ||Theta_ad(t)||_2
    rank: Quantity  #: rank of g(t) proved for every t (m when the smallest singular value > 0)
    min_singular_value: Quantity  #: a lower bound of inf_t sigma_min(g(t))
    g_perp: tuple[tuple[float, ...], ...]  #: at t = 0
    theta_ad: tuple[tuple[float, ...], ...]  #: at t = 0
    #: g depends on the state: the L1-DRAC-only constants (g', Theta_ad) are not computed
    state_dependent: bool = False

    def quantities(self) -> tuple[Quantity, ...]:
        """The constants a certificate rests on (without the ones not computed for g(t, x))."""
        if self.state_dependent:
            return (self.Delta_g, self.Delta_g_spectral, self.Delta_g_perp)
        return (
            self.Delta_g,
            self.Delta_g_spectral,
            self.Delta_g_dot,
            self.Delta_g_perp,
            self.Delta_Theta,
        )

    def to_dict(self) -> dict[str, Any]:
        return {
            **{q.name: q.to_dict() for q in self.quantities()},
            "Theta_spectral": self.Theta_spectral.to_dict(),
            "rank": int(self.rank.value),
            "min_singular_value": self.min_singular_value.value,
            "g_perp": [list(r) for r in self.g_perp],
            "theta_ad": [list(r) for r in self.theta_ad],
        }


def _time_pieces(s: System, mats) -> list[tuple[float, float]]:
    if not any(e.has(s.t) for M in mats for e in M):
        return [(0.0, 0.0)]
    edges = np.linspace(0.0, float(s.horizon), TIME_PIECES + 1)
    return [(float(a), float(b)) for a, b in zip(edges[:-1], edges[1:], strict=True)]


def _enclose_t(M: sp.MatrixBase, t: sp.Symbol, piece: tuple[float, float]):
    """Entry-wise rigorous enclosure ``(lo, hi)`` of a matrix of ``t`` over ``piece``."""
    lo = np.empty(M.shape)
    hi = np.empty(M.shape)
    for i in range(M.shape[0]):
        for j in range(M.shape[1]):
            lo[i, j], hi[i, j] = enclose_expr(M[i, j], [t], [piece])
    return lo, hi


def _fro_up(lo: np.ndarray, hi: np.ndarray) -> float:
    """Upper bound of ``||M||_F`` over the interval matrix (outward rounded)."""
    return sqrt_up(sum_sq_up(np.maximum(np.abs(lo), np.abs(hi)).ravel()))


def _spectral_up(lo: np.ndarray, hi: np.ndarray) -> float:
    """Upper bound of ``||M||_2`` over the interval matrix: ``lambda_max`` of the symmetric
    dilation ``[[0, M], [M^T, 0]]`` (its eigenvalues are ``+-sigma_i`` and zeros)."""
    r, c = lo.shape
    Lo = np.zeros((r + c, r + c))
    Hi = np.zeros((r + c, r + c))
    Lo[:r, r:], Hi[:r, r:] = lo, hi
    Lo[r:, :r], Hi[r:, :r] = lo.T, hi.T
    return max(0.0, float(mu2_interval_upper(Lo, Hi)))


def _sigma_min_down(lo: np.ndarray, hi: np.ndarray) -> float:
    """Lower bound of ``sigma_min(M)`` (M tall, n x m) over the interval matrix:
    ``sqrt(lambda_min(M^T M))``, ``M^T M`` enclosed by interval products and
    ``lambda_min(S) = -lambda_max(-S) >= -mu2_upper(-S)``."""
    n, m = lo.shape
    Glo = np.empty((m, m))
    Ghi = np.empty((m, m))
    for a in range(m):
        for b in range(m):
            acc = (0.0, 0.0)
            for k in range(n):
                acc = interval_add(acc, interval_mul((lo[k, a], hi[k, a]), (lo[k, b], hi[k, b])))
            Glo[a, b], Ghi[a, b] = acc
    lam_min = -float(mu2_interval_upper(-Ghi, -Glo))
    return sqrt_down(lam_min) if lam_min > 0 else 0.0


def input_constants(s: System, box: Any = None) -> InputConstants:
    """Compute :class:`InputConstants` with rigorous bounds.

    For a constant ``g`` the entries are enclosed once (exact closed forms, outward rounded:
    ``how = exact``); for a time-varying ``g`` the suprema over ``[0, T]`` are interval bounds over
    :data:`TIME_PIECES` pieces (``how = sound``, scope ``t in [0, T]``). For a state-dependent
    ``g(t, x)`` ``box`` (n pairs ``(lo, hi)``) is required: the suprema are over
    ``box x [0, T]`` (:func:`_input_constants_on_box`).
    """
    if s.g_depends_on_x:
        if box is None:
            raise ValueError("g depends on the state: give the box the sup is taken over")
        return _input_constants_on_box(s, np.asarray(box, dtype=float))
    g = sp.Matrix(s.g)
    th = sp.Matrix(s.theta_ad)
    gdot = g.diff(s.t)
    pieces = _time_pieces(s, [g])
    const = s.g_is_constant
    method = How.EXACT if const else How.SOUND
    scope = Scope(None, None if const else (0.0, float(s.horizon)))
    text = (
        "constant g" if const else f"interval bound over {len(pieces)} pieces of [0, {s.horizon}]"
    )
    fro = spec = dot = tfro = tspec = 0.0
    smin = math.inf
    for piece in pieces:
        lo, hi = _enclose_t(g, s.t, piece)
        fro = max(fro, _fro_up(lo, hi))
        # both are upper bounds of ||g||_2 (||.||_2 <= ||.||_F): keep the smaller
        spec = max(spec, min(_spectral_up(lo, hi), _fro_up(lo, hi)))
        smin = min(smin, _sigma_min_down(lo, hi))
        if not const:
            dlo, dhi = _enclose_t(gdot, s.t, piece)
            dot = max(dot, _fro_up(dlo, dhi))
        tlo, thi = _enclose_t(th, s.t, piece)
        tfro = max(tfro, _fro_up(tlo, thi))
        tspec = max(tspec, _spectral_up(tlo, thi))
    n, m = s.n, s.m
    gp = g_perp_at(s, 0.0)
    th0 = np.array(th.subs(s.t, 0.0).evalf(), dtype=float)

    def q(name: str, value: float, source: str, note: str = text) -> Quantity:
        return Quantity.derive(name, value, method=method, source=source, note=note, scope=scope)

    return InputConstants(
        Delta_g=q("Delta_g", fro, "DRIP Assumption 1 (Frobenius)"),
        Delta_g_spectral=q("Delta_g_spectral", spec, "spectral-norm bound of g (this project)"),
        Delta_g_dot=q("Delta_g_dot", dot, "L1-DRAC Assumption 1"),
        Delta_g_perp=Quantity.derive(
            "Delta_g_perp",
            sqrt_up(float(n - m)),
            source="L1-DRAC Assumption 1",
            note="orthonormal g_perp: ||g_perp||_F = sqrt(n - m)",
        ),
        Delta_Theta=q(
            "Delta_Theta", tfro, "L1-DRAC Assumption 1", "Theta_ad = (g^T g)^{-1} g^T; " + text
        ),
        Theta_spectral=q("Theta_spectral", tspec, "L1-DRAC Assumption 1 (spectral norm)"),
        rank=q(
            "rank_g",
            float(m if smin > 0 else 0),
            "DRIP Assumption 1",
            f"sigma_min(g(t)) >= {smin:.6g} for every t ({text})",
        ),
        min_singular_value=q("sigma_min_g", smin, "DRIP Assumption 1"),
        g_perp=tuple(tuple(float(v) for v in row) for row in gp),
        theta_ad=tuple(tuple(float(v) for v in row) for row in th0),
    )


#: sub-boxes the branch and bound of one supremum of a state-dependent g may evaluate (a count
#: of work: the same box gives the same bound on any machine; the bound is sound at any count)
G_MAX_BOXES = 400
#: the branch and bound stops when its bound is within this relative distance of a sampled value
G_RTOL = 1e-3


def _box_sup(
    enc: MatrixEnclosure, norm: Callable[[np.ndarray, np.ndarray], float], box: np.ndarray
) -> tuple[float, float, int]:
    """``(upper, sampled lower, boxes)`` of ``sup_{v in box} norm(M(v))`` by branch and bound on
    the entry-wise enclosures of ``M`` (``norm(lo, hi)`` an upper bound of the norm over the
    interval matrix; at a point box it is the norm rounded up, the sampled value)."""

    def upper(b: np.ndarray) -> float:
        try:
            return norm(*enc(b))
        except (UnsupportedExpression, ZeroDivisionError, OverflowError, ValueError):
            return math.inf

    def value(p: np.ndarray) -> float:
        pb = np.stack([p, p], axis=1)
        try:
            return norm(*enc(pb))
        except (UnsupportedExpression, ZeroDivisionError, OverflowError, ValueError):
            return math.nan

    res = maximize(box, upper, value, rtol=G_RTOL, max_boxes=G_MAX_BOXES, corners=True)
    return res.upper, res.lower, res.n_boxes


def _input_constants_on_box(s: System, box: np.ndarray) -> InputConstants:
    """:class:`InputConstants` of a state-dependent ``g(t, x)`` over ``box x [0, T]``.

    Every supremum is an interval branch and bound (:func:`drip_cert.numerics.bnb.maximize`) of
    an upper bound of the norm over the entry-wise enclosure of ``g`` on a sub-box (Frobenius:
    :func:`_fro_up`; spectral: the smaller of :func:`_spectral_up` and :func:`_fro_up`); the
    smallest singular value is bounded below the same way (the branch and bound maximises
    ``-sigma_min``). Labels: ``sound``, scope ``box`` (and ``[0, T]`` when g depends on ``t``).
    ``Delta_g_perp = sqrt(n - m)`` holds for an orthonormal basis at every point, as for
    ``g(t)``. ``g'`` and ``Theta_ad`` enter only L1-DRAC, which needs ``g(t)``: NaN, named.
    """
    n, m = s.n, s.m
    g = sp.Matrix(s.g)
    has_t = any(e.has(s.t) for e in g)
    t_rng = (0.0, float(s.horizon)) if has_t else (0.0, 0.0)
    variables = [*s.states, s.t]
    full = np.vstack([box, np.array([t_rng])])
    enc = MatrixEnclosure(g, variables)
    scope = Scope(tuple((float(a), float(b)) for a, b in box), t_rng if has_t else None)
    fro, fro_lo, k1 = _box_sup(enc, _fro_up, full)
    spec, spec_lo, k2 = _box_sup(
        enc, lambda lo, hi: min(_spectral_up(lo, hi), _fro_up(lo, hi)), full
    )
    neg_smin, _, k3 = _box_sup(enc, lambda lo, hi: -_sigma_min_down(lo, hi), full)
    smin = max(0.0, -neg_smin)
    where = f"x in {[[float(a), float(b)] for a, b in box]}" + (
        f", t in [0, {s.horizon:g}]" if has_t else ""
    )
    text = (
        f"g depends on the state: interval branch and bound over {where} (at most "
        f"{G_MAX_BOXES} sub-boxes each)"
    )

    def q(name: str, value: float, source: str, note: str) -> Quantity:
        return Quantity.derive(name, value, method=How.SOUND, source=source, note=note, scope=scope)

    def na(name: str, source: str) -> Quantity:
        return Quantity(
            name,
            math.nan,
            How.ESTIMATE,
            source,
            "not computed: g depends on the state, and only L1-DRAC (which needs g(t)) uses it",
        )

    return InputConstants(
        Delta_g=q(
            "Delta_g",
            fro,
            "DRIP Assumption 1 (Frobenius)",
            f"{text}; sampled sup {fro_lo:.6g} ({k1} boxes)",
        ),
        Delta_g_spectral=q(
            "Delta_g_spectral",
            spec,
            "spectral-norm bound of g (this project)",
            f"{text}; sampled sup {spec_lo:.6g} ({k2} boxes)",
        ),
        Delta_g_dot=na("Delta_g_dot", "L1-DRAC Assumption 1"),
        Delta_g_perp=Quantity.derive(
            "Delta_g_perp",
            sqrt_up(float(n - m)),
            source="L1-DRAC Assumption 1",
            note="orthonormal g_perp: ||g_perp||_F = sqrt(n - m)",
        ),
        Delta_Theta=na("Delta_Theta", "L1-DRAC Assumption 1"),
        Theta_spectral=na("Theta_spectral", "L1-DRAC Assumption 1 (spectral norm)"),
        rank=q(
            "rank_g",
            float(m if smin > 0 else 0),
            "DRIP Assumption 1",
            f"sigma_min(g(t, x)) >= {smin:.6g} on {where} ({k3} boxes)",
        ),
        min_singular_value=q("sigma_min_g", smin, "DRIP Assumption 1", text),
        g_perp=tuple(tuple(float(v) for v in row) for row in g_perp_at(s, 0.0, box.mean(axis=1))),
        theta_ad=tuple(tuple(math.nan for _ in range(n)) for _ in range(m)),
        state_dependent=True,
    )


# ---------------------------------------------------------------------- sampled sup estimates
def batch_fn(s: System, exprs: sp.MatrixBase) -> Callable[[float, np.ndarray], np.ndarray]:
    """numpy-facing batched evaluation ``(t, X (N, n)) -> (N, ...)`` of system expressions.

    The expressions are lowered to jax and compiled on the first call only: a constant that a
    sound route bounds never evaluates them, and then jax (0.3 CPU-s to import) is not imported.
    """

    @functools.cache
    def compiled() -> Callable[[float, np.ndarray], np.ndarray]:
        from drip_cert._jax import jax, jnp  # jax: keep off the API's import path

        fn = jax.jit(jax.vmap(s.lower(exprs), in_axes=(None, 0)))
        return lambda tt, X: fn(jnp.float64(tt), jnp.asarray(X, dtype=jnp.float64))

    def call(tt: float, X: np.ndarray) -> np.ndarray:
        return np.asarray(compiled()(tt, X))

    return call


@dataclass(frozen=True)
class UncertaintyConstants:
    """Growth and regularity constants of the uncertainty (DRIP Assumption 1, L1-DRAC
    Assumptions 4 and 6) and of the known diffusion (L1-DRAC Assumptions 1 and 5)."""

    values: Mapping[str, Quantity]

    def __getitem__(self, key: str) -> Quantity:
        return self.values[key]

    def to_dict(self) -> dict[str, Any]:
        return {k: q.to_dict() for k, q in self.values.items()}


def uncertainty_constants(
    s: System, given: ConstantsTable | Mapping[str, Any] | None = None
) -> UncertaintyConstants:
    """Estimate (or take as given) the uncertainty and diffusion constants.

    For a state-dependent ``g`` the matched / unmatched parts (``_par``, ``_perp``, L1-DRAC (7))
    are absent: only L1-DRAC uses them, and it needs ``g(t)``.

    Parameters
    ----------
    s
        The system.
    given
        The spec's ``[constants]`` (``spec.settings.constants``, or a plain mapping, validated
        here the same way); any key there overrides the computed value and is labelled
        ``given``.
    """
    if not isinstance(given, ConstantsTable):
        given = ConstantsTable.from_table(given)
    given = dict(given.values)
    n, m = s.n, s.m
    times = np.array([0.0]) if not _depends_on_t(s) else np.array([0.0, float(s.horizon)])
    # the matched / unmatched parts (L1-DRAC (7)) exist only for g(t): L1-DRAC's split
    g_x = s.g_depends_on_x
    th = None if g_x else s.theta_ad
    pperp = None if g_x else s.perp_projector
    theta_spectral = None if g_x else input_constants(s).Theta_spectral
    out: dict[str, Quantity] = {}

    def put(name: str, value: float, how: How, source: str, nt: str, scope=None) -> None:
        if name in given:
            out[name] = Quantity(name, given[name], How.GIVEN, source, "given in [constants]")
        else:
            out[name] = Quantity.derive(
                name, value, method=how, source=source, note=nt, scope=scope
            )

    hat_src = "L1-DRAC Assumptions 1, 5, 6 (time-Lipschitz constant)"

    diffusion = s.diffusion
    assert diffusion is not None  # System.__post_init__ makes an absent diffusion the zero matrix
    parts: dict[str, tuple[sp.MatrixBase | None, float, float | None]] = {
        "mu": (s.lambda_mu, 1.0, s.Delta_mu),
        "sigma": (s.lambda_sigma, 0.5, s.Delta_sigma),
        "p": (diffusion if any(e != 0 for e in diffusion) else None, 0.5, 0.0),
    }
    for key, (mat, power, given_bound) in parts.items():
        growth_src = {
            "mu": "DRIP Assumption 1 / L1-DRAC Assumption 4",
            "sigma": "DRIP Assumption 1 / L1-DRAC Assumption 4",
            "p": "L1-DRAC Assumption 1",
        }[key]
        lip_src = {
            "mu": "L1-DRAC Assumption 6",
            "sigma": "L1-DRAC Assumption 6",
            "p": "L1-DRAC Assumptions 1, 5",
        }[key]
        lip_exp = 1.0 if key == "mu" else 0.5
        if mat is None:
            if given_bound is not None and key != "p":
                # only the bound is known: matched/unmatched parts bounded through the norms of
                # Theta_ad and g_perp^T (||Theta Lambda|| <= sup_t ||Theta(t)||_2 ||Lambda||)
                gb = Quantity(
                    f"Delta_{key}", given_bound, How.GIVEN, growth_src, "given in [uncertainty]"
                )
                put(gb.name, gb.value, gb.how, growth_src, gb.note)
                if theta_spectral is None:
                    _not_split(out, key)
                    continue
                par = Quantity.derive(
                    f"Delta_{key}_par",
                    mul_up(theta_spectral.value, given_bound),
                    inputs=[theta_spectral, gb],
                    note="sup_t ||Theta_ad(t)||_2 * Delta (only the bound is known)",
                )
                put(par.name, par.value, par.how, growth_src + " / (7)", par.note)
                put(
                    f"Delta_{key}_perp",
                    given_bound if n > m else 0.0,
                    gb.how,
                    growth_src + " / (7)",
                    "||g_perp^T||_2 = 1 times Delta",
                )
                for sub in ("", "_par", "_perp"):
                    for nm in (f"L_{key}{sub}", f"L_{key}{sub}_hat"):
                        if nm in given:
                            put(nm, 0.0, How.GIVEN, lip_src, "")
                        else:
                            out[nm] = Quantity(
                                nm,
                                math.nan,
                                How.ESTIMATE,
                                lip_src,
                                "unknown: only Delta is given; give it in [constants]",
                            )
                continue
            for sub in ("", "_par", "_perp"):
                put(f"Delta_{key}{sub}", 0.0, How.EXACT, growth_src, "no such term")
                put(f"L_{key}{sub}", 0.0, How.EXACT, lip_src, "no such term")
                put(f"L_{key}{sub}_hat", 0.0, How.EXACT, hat_src, "no such term")
            continue
        full = sp.Matrix(mat)
        parts_of: tuple[tuple[str, sp.Matrix | None], ...] = (("", full),)
        if th is not None and pperp is not None:
            par = sp.Matrix(th) * full
            # the unmatched part g_perp^T Lambda has the norms of P_perp Lambda (see
            # System.perp_projector): a closed form in t also for a time-varying g
            perp = sp.Matrix(pperp) * full if n > m else None
            parts_of += (("_par", par), ("_perp", perp))
        else:
            _not_split(out, key)
        t_sym = s.t if len(times) > 1 else None
        t_rng = (0.0, float(s.horizon)) if len(times) > 1 else (0.0, 0.0)
        for sub, expr in parts_of:
            if expr is None:
                put(
                    f"Delta_{key}{sub}",
                    0.0,
                    How.EXACT,
                    growth_src + " / (7)",
                    "m = n: no unmatched part",
                )
                put(f"L_{key}{sub}", 0.0, How.EXACT, lip_src, "m = n: no unmatched part")
                put(f"L_{key}{sub}_hat", 0.0, How.EXACT, hat_src, "m = n: no unmatched part")
                continue
            ev = batch_fn(s, expr) if s.blocks else None
            src = growth_src + (" / (7)" if sub else "")
            D = growth_bound(
                expr, s.states, t_sym, t_rng, power, f"Delta_{key}{sub}", source=src, evaluate=ev
            )
            put(D.name, D.value, D.how, src, D.note, D.scope)
            # time-Lipschitz constant: sup_{t, a} ||d/dt (.)|| (mean-value theorem in t); the
            # matched/unmatched parts depend on t through g(t) too
            dt_expr = expr.diff(s.t)
            if t_sym is None or all(e == 0 for e in dt_expr):
                put(f"L_{key}{sub}_hat", 0.0, How.EXACT, hat_src, "independent of t")
            else:
                H = sup_bound(dt_expr, s.states, t_sym, t_rng, f"L_{key}{sub}_hat", source=hat_src)
                put(H.name, H.value, H.how, hat_src, "sup_{t,a} ||d/dt||: " + H.note, H.scope)
            if lip_exp == 1.0:
                L = lipschitz_bound(
                    expr, s.states, t_sym, t_rng, f"L_{key}{sub}", source=lip_src, evaluate=ev
                )
            else:
                L = holder_half_bound(
                    expr, s.states, t_sym, t_rng, f"L_{key}{sub}", source=lip_src, evaluate=ev
                )
            put(L.name, L.value, L.how, lip_src, L.note, L.scope)
    return UncertaintyConstants(values=out)


def _not_split(out: dict[str, Quantity], key: str) -> None:
    """The matched / unmatched constants of L1-DRAC (7) for a state-dependent g: not computed
    (absent; only L1-DRAC uses them, and it needs g(t))."""


def _depends_on_t(s: System) -> bool:
    mats = [s.diffusion, s.lambda_mu, s.lambda_sigma, s.g]
    return any(s.t in e.free_symbols for mat in mats if mat is not None for e in mat)
