"""The :class:`System`: everything the DRIP guarantee is about, as sympy expressions.

Notation of the DRIP paper (drip_paper.tex, Definitions "Vector Fields" and "Systems"):
known drift ``f(t, x)`` (without any policy), input operator ``g(t, x)`` (n x m; the L1-DRAC
layer needs it to depend on ``t`` only, docs/math/contraction.md section 6),
expert ``pi*(x)``, learned ``pi_IL(x)``, known diffusion ``p(t, x)`` (n x d), unknown
uncertainties ``Lambda_mu(t, x)`` (n) and ``Lambda_sigma(t, x)`` (n x d) or only their growth
bounds ``Delta_mu``, ``Delta_sigma`` (DRIP Assumption 1 / L1-DRAC Assumption 4), the support box
of the initial law ``D`` (and optionally of ``D_bar``), and the horizon ``T``.

The nominal closed loop is ``fbar(t, x, pi(x)) = f(t, x) + g(t, x) pi(x)``; the true system adds
``Lambda_mu`` to the drift and has diffusion ``p + Lambda_sigma``.
"""

from __future__ import annotations

import math
from collections.abc import Mapping, Sequence
from dataclasses import dataclass, field
from functools import cached_property
from types import MappingProxyType
from typing import TYPE_CHECKING, Any

import numpy as np
import sympy as sp

from drip_cert.errors import SpecError
from drip_cert.model.blocks import Block, block_applications
from drip_cert.model.lower import lower
from drip_cert.model.statespace import statespace_system
from drip_cert.numerics.rounding import mul_up, sqrt_up, sum_sq_up

if TYPE_CHECKING:
    from drip_cert.model.numeric import SimModel

RANK_TOL = 1e-10  #: relative singular-value threshold for the full-column-rank check of g
RANK_CHECK_CORNERS = 64  #: support corners at which a state-dependent g's rank is checked at load


def _matrix(value: Any, rows: int, cols: int, what: str) -> sp.ImmutableMatrix:
    try:
        mat = sp.ImmutableMatrix(value)
    except (TypeError, ValueError) as exc:
        raise SpecError(f"{what}: cannot form a matrix: {exc}") from None
    if cols == 1 and mat.shape == (1, rows) and rows != 1:
        mat = mat.T
    if mat.shape != (rows, cols):
        raise SpecError(f"{what} must be {rows} x {cols}, got {mat.shape[0]} x {mat.shape[1]}")
    return mat


@dataclass(frozen=True, eq=False)
class System:
    """A control system with expert and learned policies and its uncertainty (frozen).

    Parameters
    ----------
    name
        Label used in reports.
    states
        State symbols ``x_1..x_n``.
    f
        Known drift, n expressions in ``t`` and the states; must not contain the policy.
    g
        Input operator, n x m expressions in ``t`` and the states. A ``g`` that depends on the
        state keeps DRIP's contraction, delta-ISS and TaSIL parts (every ``sup ||g||`` is then
        taken over a box the trajectories are proved to stay in); L1-DRAC needs ``g(t)``.
    expert
        Expert policy ``pi*``, m expressions in the states.
    support
        Box ``[(lo_1, hi_1), ...]`` supporting the initial law ``D``.
    horizon
        ``T > 0``.
    t
        Time symbol (default ``t``).
    inputs
        Names of the m inputs (default ``u1..um``).
    learned
        Learned policy ``pi_IL`` (m expressions) or ``None``.
    diffusion
        Known diffusion ``p`` (n x d), default zero.
    lambda_mu, lambda_sigma
        Uncertainties (n and n x d expressions) or ``None``.
    Delta_mu, Delta_sigma
        Given growth bounds, used when the expressions are not given.
    brownian_dim
        ``d``; defaults to the column count of the diffusion expressions, else ``n``.
    true_support
        Box supporting ``D_bar`` (default: the same as ``D``; identity coupling).
    blocks
        Blocks (neural networks) used in the expressions, by name.
    """

    name: str
    states: tuple[sp.Symbol, ...]
    f: sp.ImmutableMatrix
    g: sp.ImmutableMatrix
    expert: sp.ImmutableMatrix
    support: tuple[tuple[float, float], ...]
    horizon: float
    t: sp.Symbol = sp.Symbol("t", real=True)
    inputs: tuple[str, ...] = ()
    learned: sp.ImmutableMatrix | None = None
    diffusion: sp.ImmutableMatrix | None = None
    lambda_mu: sp.ImmutableMatrix | None = None
    lambda_sigma: sp.ImmutableMatrix | None = None
    Delta_mu: float | None = None
    Delta_sigma: float | None = None
    brownian_dim: int | None = None
    true_support: tuple[tuple[float, float], ...] | None = None
    blocks: Mapping[str, Block] = field(default_factory=dict)

    def __post_init__(self) -> None:
        states = tuple(self.states)
        if not states:
            raise SpecError("a system needs at least one state", field="system.states")
        if len(set(states)) != len(states):
            raise SpecError("state names must be distinct", field="system.states")
        object.__setattr__(self, "states", states)
        n = len(states)
        f = _matrix(self.f, n, 1, "dynamics.f")
        g_raw = sp.ImmutableMatrix(self.g)
        m = g_raw.shape[1] if g_raw.shape[0] == n else None
        if m is None or m < 1:
            raise SpecError(f"dynamics.g must be {n} x m with m >= 1, got {g_raw.shape}")
        g = _matrix(self.g, n, m, "dynamics.g")
        expert = _matrix(self.expert, m, 1, "policy.expert")
        learned = None if self.learned is None else _matrix(self.learned, m, 1, "policy.learned")
        d = self.brownian_dim
        for mat in (self.diffusion, self.lambda_sigma):
            if mat is not None and d is None:
                d = sp.ImmutableMatrix(mat).shape[1]
        d = n if d is None else int(d)
        if d < 1:
            raise SpecError(
                f"the Brownian dimension must be >= 1, got {d}", field="system.brownian_dim"
            )
        p = (
            sp.ImmutableMatrix.zeros(n, d)
            if self.diffusion is None
            else _matrix(self.diffusion, n, d, "dynamics.diffusion")
        )
        lam_mu = (
            None if self.lambda_mu is None else _matrix(self.lambda_mu, n, 1, "uncertainty.drift")
        )
        lam_sigma = (
            None
            if self.lambda_sigma is None
            else _matrix(self.lambda_sigma, n, d, "uncertainty.diffusion")
        )
        inputs = tuple(self.inputs) or tuple(f"u{i + 1}" for i in range(m))
        if len(inputs) != m:
            raise SpecError(
                f"{len(inputs)} input names for an input operator with {m} columns",
                field="system.inputs",
            )
        for attr, val in (
            ("f", f),
            ("g", g),
            ("expert", expert),
            ("learned", learned),
            ("diffusion", p),
            ("lambda_mu", lam_mu),
            ("lambda_sigma", lam_sigma),
            ("inputs", inputs),
            ("brownian_dim", d),
        ):
            object.__setattr__(self, attr, val)
        allowed_x = set(states) | {self.t}
        self._check_symbols(f, allowed_x, "dynamics.f")
        self._check_symbols(g, allowed_x, "dynamics.g")
        self._check_symbols(expert, set(states), "policy.expert")
        if learned is not None:
            self._check_symbols(learned, set(states), "policy.learned")
        self._check_symbols(p, allowed_x, "dynamics.diffusion")
        if lam_mu is not None:
            self._check_symbols(lam_mu, allowed_x, "uncertainty.drift")
        if lam_sigma is not None:
            self._check_symbols(lam_sigma, allowed_x, "uncertainty.diffusion")
        for key in ("Delta_mu", "Delta_sigma"):
            v = getattr(self, key)
            if v is not None:
                v = _nonneg_float(v, f"uncertainty.{key}")
                object.__setattr__(self, key, v)
        object.__setattr__(self, "support", _box(self.support, n, "initial.support"))
        if self.true_support is not None:
            object.__setattr__(
                self, "true_support", _box(self.true_support, n, "initial.true_support")
            )
        T = _nonneg_float(self.horizon, "system.horizon")
        if T <= 0:
            raise SpecError(
                f"the horizon must be > 0, got {self.horizon!r}", field="system.horizon"
            )
        object.__setattr__(self, "horizon", T)
        object.__setattr__(self, "blocks", MappingProxyType(dict(self.blocks)))
        self._check_rank()

    # ------------------------------------------------------------------ validation helpers
    def _check_symbols(self, mat: sp.MatrixBase, allowed: set, what: str) -> None:
        free = set().union(*(e.free_symbols for e in mat)) if len(mat) else set()
        bad = free - allowed
        if bad:
            names = ", ".join(sorted(str(s) for s in bad))
            raise SpecError(f"{what} uses symbols not allowed there: {names}")
        for e in mat:
            for app in block_applications(e):
                if app.block_name not in self.blocks:
                    raise SpecError(f"{what} calls an undeclared block '{app.block_name}'")

    def _check_rank(self) -> None:
        n, m = self.g.shape
        if m > n:
            raise SpecError(
                f"g is {n} x {m}: more inputs than states cannot have full column rank",
                field="dynamics.g",
            )
        points = self.rank_check_points()
        for tt in self.rank_check_times():
            for x in points:
                self._check_rank_at(tt, x)

    def _check_rank_at(self, tt: float, x: np.ndarray | None) -> None:
        m = self.m
        G = self.g_at(tt, x)
        where = f"{tt:g}" if x is None else f"{tt:g}, x = {np.array2string(x, precision=4)}"
        if not np.all(np.isfinite(G)):
            raise SpecError(f"g({where}) is not finite", field="dynamics.g")
        s = np.linalg.svd(G, compute_uv=False)
        rank = int(np.sum(s > RANK_TOL * max(1.0, s[0])))
        if rank < m:
            raise SpecError(
                f"g({where}) has rank {rank} < m = {m} columns (singular values "
                f"{np.array2string(s, precision=3)}); DRIP Assumption 1 needs full column "
                "rank: remove dependent inputs",
                field="dynamics.g",
            )

    # ------------------------------------------------------------------ sizes
    @property
    def n(self) -> int:
        return len(self.states)

    @property
    def m(self) -> int:
        return int(self.g.shape[1])

    @property
    def d(self) -> int:
        assert self.brownian_dim is not None  # set to an int by __post_init__
        return int(self.brownian_dim)

    @property
    def g_is_constant(self) -> bool:
        return not any(e.free_symbols for e in self.g)

    @property
    def g_depends_on_x(self) -> bool:
        """Whether the input operator depends on the state (``g(t, x)``, not ``g(t)``)."""
        states = set(self.states)
        return any(e.free_symbols & states for e in self.g)

    def rank_check_times(self) -> np.ndarray:
        """Times at which time-varying quantities of g are checked (all of them if constant)."""
        if not any(self.t in e.free_symbols for e in self.g):
            return np.array([0.0])
        return np.linspace(0.0, self.horizon, 65)

    def rank_check_points(self) -> list[np.ndarray | None]:
        """States at which a state-dependent g is checked at load: the support's centre and
        corners (at most :data:`RANK_CHECK_CORNERS` of them); ``[None]`` for ``g(t)``. A quick
        sanity check only: the certificate bounds ``sigma_min(g)`` from below on a box
        (analysis/growth/constants.py)."""
        if not self.g_depends_on_x:
            return [None]
        box = np.asarray(self.support, dtype=float)
        pts = [box.mean(axis=1)]
        for k in range(min(RANK_CHECK_CORNERS, 2**self.n)):
            pts.append(np.array([box[i, (k >> i) & 1] for i in range(self.n)]))
        return pts

    # ------------------------------------------------------------------ symbolic closed loops
    def policy(self, which: str = "expert") -> sp.ImmutableMatrix:
        """``pi*`` (``which='expert'``) or ``pi_IL`` (``'learned'``) as an m-vector."""
        if which == "expert":
            return self.expert
        if which == "learned":
            if self.learned is None:
                raise SpecError(
                    "no learned policy is given (policy.learned)", field="policy.learned"
                )
            return self.learned
        raise ValueError(f"policy must be 'expert' or 'learned', got {which!r}")

    def closed_loop(self, which: str = "expert") -> sp.ImmutableMatrix:
        """``fbar(t, x, pi(x)) = f(t, x) + g(t, x) pi(x)`` (DRIP eq. NominalVectorFields)."""
        return sp.ImmutableMatrix(self.f + self.g * self.policy(which))

    def closed_loop_jacobian(self, which: str = "expert") -> sp.ImmutableMatrix:
        """``nabla_x fbar(t, x, pi(x))``, the matrix of DRIP Assumption 2.

        The exact symbolic Jacobian of the closed loop, so for a state-dependent ``g`` it holds
        ``nabla_x [g(t, x) pi(x)] = g nabla pi + sum_j pi_j nabla_x g_{:, j}`` (product rule).
        """
        return sp.ImmutableMatrix(self.closed_loop(which).jacobian(self.states))

    @property
    def has_blocks(self) -> bool:
        return bool(self.blocks)

    # ------------------------------------------------------------------ numerics
    def g_at(self, tt: float, x: Sequence[float] | np.ndarray | None = None) -> np.ndarray:
        """``g(t, x)`` as a float array (sympy evaluation; ``x`` is needed when g depends on
        the state)."""
        subs: dict[sp.Symbol, Any] = {self.t: tt}
        if x is not None:
            subs.update(zip(self.states, (float(v) for v in x), strict=True))
        elif self.g_depends_on_x:
            raise ValueError("g depends on the state: give x")
        return np.array(self.g.subs(subs).evalf(), dtype=float)

    def lower(self, exprs: sp.MatrixBase):
        """jax function ``(t, x) -> array`` for expressions of this system (see :func:`lower`)."""
        return lower(exprs, self.t, self.states, self.blocks)

    @cached_property
    def theta_ad(self) -> sp.ImmutableMatrix:
        """``Theta_ad(t) = [I_m 0] gbar(t)^{-1} = (g^T g)^{-1} g^T`` (L1-DRAC Assumption 1).

        With ``gbar = [g, g_perp]`` and ``Im g_perp = ker g^T``, any ``v = g a + g_perp b`` has
        ``g^T v = g^T g a``, so the first m rows of ``gbar^{-1}`` are the pseudo-inverse of ``g``
        whatever basis ``g_perp`` is chosen (docs/math/l1drac.md).
        """
        if self.g_depends_on_x:
            raise SpecError(
                "Theta_ad is L1-DRAC's and needs g(t); this g depends on the state",
                field="dynamics.g",
            )
        g = sp.Matrix(self.g)
        gtg = g.T * g
        inv = gtg.inv() if self.g_is_constant else sp.simplify(gtg.inv())
        return sp.ImmutableMatrix(sp.simplify(inv * g.T))

    @cached_property
    def perp_projector(self) -> sp.ImmutableMatrix:
        """``P_perp(t) = I - g(t) Theta_ad(t) = g_perp(t) g_perp(t)^T``, the orthogonal projector
        onto ``ker g(t)^T``.

        For orthonormal ``g_perp``, ``||g_perp^T v|| = ||P_perp v||`` and
        ``||g_perp^T M||_F = ||P_perp M||_F`` (``P_perp^T P_perp = P_perp``), so every growth and
        regularity constant of the unmatched part ``g_perp^T Lambda`` (L1-DRAC (7)) equals that of
        ``P_perp Lambda``, a closed form in ``t`` even when ``g`` varies with time (no basis has to
        be chosen at each ``t``).
        """
        g = sp.Matrix(self.g)
        return sp.ImmutableMatrix(sp.eye(self.n) - g * sp.Matrix(self.theta_ad))

    @cached_property
    def numeric(self) -> SimModel:
        """The numeric view of this system: jax callables of every part (built once, lazily).

        Lowers ``f``, ``g``, ``p``, the uncertainties (zero when not given), both policies, the
        closed-loop Jacobians of DRIP Assumption 2 and ``Theta_ad`` into one
        :class:`~drip_cert.model.numeric.SimModel`, the view the analysis and the Monte-Carlo
        engine share.
        """
        from drip_cert._jax import jnp  # jax: keep off the CLI start-up path
        from drip_cert.model.numeric import (  # jax: keep off the CLI start-up path
            SimModel,
            theta_ad_from_g,
        )

        n, d = self.n, self.d
        g_fn = self.lower(self.g)
        exp_fn = self.lower(list(self.expert))
        # Theta_ad is L1-DRAC's (needs g(t)): for g(t, x) the numeric pseudo-inverse at x = 0
        # only fills the view (never used: the engine and the controller refuse L1 for g(x))
        th = None if self.g_depends_on_x else self.lower(self.theta_ad)
        learned = None if self.learned is None else self.lower(list(self.learned))
        return SimModel(
            n=n,
            m=self.m,
            d=d,
            f=self.lower(list(self.f)),
            g=g_fn,
            g_state=self.g_depends_on_x,
            p=self.lower(self.diffusion),
            lam_mu=(
                self.lower(list(self.lambda_mu))
                if self.lambda_mu is not None
                else (lambda t, x: jnp.zeros(n))
            ),
            lam_sigma=(
                self.lower(self.lambda_sigma)
                if self.lambda_sigma is not None
                else (lambda t, x: jnp.zeros((n, d)))
            ),
            expert=lambda x: exp_fn(0.0, x),
            learned=None if learned is None else (lambda x: learned(0.0, x)),
            theta_ad=(theta_ad_from_g(g_fn, n) if th is None else (lambda t: th(t, jnp.zeros(n)))),
            name=self.name,
            jac_expert=self.lower(self.closed_loop_jacobian("expert")),
            jac_learned=(
                None if self.learned is None else self.lower(self.closed_loop_jacobian("learned"))
            ),
        )

    def transformed(self, Theta: Any, *, suffix: str = "z") -> System:
        """The equivalent system in the coordinates ``z = Theta x`` (docs/math/contraction.md
        Proposition 5.1).

        ``Theta`` is any invertible constant ``n x n`` matrix; its entries are taken as the exact
        rationals they denote (a float is the binary rational it stores), and ``Theta^{-1}`` is
        computed exactly, so the new system is exactly equivalent to this one, not an
        approximation. ``f_z(t, z) = Theta f(t, Theta^{-1} z)``,
        ``g_z(t, z) = Theta g(t, Theta^{-1} z)``, policies ``pi(Theta^{-1} z)``, uncertainties and
        the known diffusion ``Theta (.)(t, Theta^{-1} z)``;
        blocks are composed with ``Theta^{-1}`` (their arguments become linear combinations of
        ``z``), not re-fitted. The support box maps to a parallelotope: the new support is the
        smallest box enclosing it, rounded outward (a larger set: every bound over the support
        stays sound, and the initial law in ``z`` is the push-forward of the old one, NOT uniform
        on that box). Given growth bounds ``Delta_mu``, ``Delta_sigma`` become
        ``||Theta||_2 max(1, ||Theta^{-1}||_2) Delta`` (rounded up; the Frobenius norm bounds
        ``||.||_2`` here, which keeps them sound) since
        ``||x||^2 <= ||Theta^{-1}||^2 ||z||^2``.
        """
        n = self.n
        Th = sp.Matrix(Theta) if not isinstance(Theta, np.ndarray) else sp.Matrix(Theta.tolist())
        if Th.shape != (n, n):
            raise SpecError(f"Theta must be {n} x {n}, got {Th.shape[0]} x {Th.shape[1]}")
        try:
            Th = Th.applyfunc(_exact_rational)
        except (TypeError, ValueError) as exc:
            raise SpecError(f"Theta must have finite numeric entries: {exc}") from None
        if Th.det() == 0:
            raise SpecError("Theta is singular: a change of coordinates must be invertible")
        Ti = Th.inv()
        zs = tuple(sp.Symbol(f"{suffix}{i + 1}", real=True) for i in range(n))
        back = dict(zip(self.states, list(Ti * sp.Matrix(zs)), strict=True))

        def sub(mat: sp.MatrixBase | None) -> sp.ImmutableMatrix | None:
            if mat is None:
                return None
            # expanded: cancellations that were visible in x (a closed loop linear after the
            # policy cancels a nonlinearity) stay visible in z
            return sp.ImmutableMatrix(sp.Matrix(mat).xreplace(back).applyfunc(sp.expand))

        def lift(mat: sp.MatrixBase | None) -> sp.ImmutableMatrix | None:
            inner = sub(mat)
            if inner is None:
                return None
            return sp.ImmutableMatrix((Th * sp.Matrix(inner)).applyfunc(sp.expand))

        given = {}
        if self.Delta_mu is not None or self.Delta_sigma is not None:
            fro = sqrt_up(sum_sq_up(_float_up_abs(e) for e in Th))
            fro_inv = sqrt_up(sum_sq_up(_float_up_abs(e) for e in Ti))
            k = mul_up(fro, max(1.0, fro_inv))
            for key in ("Delta_mu", "Delta_sigma"):
                v = getattr(self, key)
                given[key] = None if v is None else mul_up(k, v)
        return System(
            name=f"{self.name} in z = Theta x",
            states=zs,
            f=lift(self.f),
            g=lift(self.g),
            expert=sub(self.expert),
            support=box_image(Th, self.support),
            horizon=self.horizon,
            t=self.t,
            inputs=self.inputs,
            learned=sub(self.learned),
            diffusion=lift(self.diffusion),
            lambda_mu=lift(self.lambda_mu),
            lambda_sigma=lift(self.lambda_sigma),
            Delta_mu=given.get("Delta_mu", self.Delta_mu),
            Delta_sigma=given.get("Delta_sigma", self.Delta_sigma),
            brownian_dim=self.d,
            true_support=None if self.true_support is None else box_image(Th, self.true_support),
            blocks=self.blocks,
        )

    @classmethod
    def from_statespace(
        cls,
        sys_or_AB: Any,
        *,
        expert: Any,
        support: Sequence[Sequence[float]],
        horizon: float,
        states: Sequence[str] | None = None,
        inputs: Sequence[str] | None = None,
        name: str = "statespace",
        learned: Any = None,
        **uncertainty: Any,
    ) -> System:
        """A linear system ``dx/dt = A x + B u`` from a state-space object or ``(A, B)`` arrays.

        Parameters
        ----------
        sys_or_AB
            Anything with attributes ``.A`` and ``.B`` (``control.ss(...)``,
            ``scipy.signal.StateSpace``; continuous time: a ``.dt`` other than ``None``/``0``
            is refused), or a pair ``(A, B)`` of arrays. Read by duck typing: python-control
            is never imported. Every entry is taken as the exact rational of its double
            (:func:`~drip_cert.model.literals.exact_number`), as the TOML route
            (``[dynamics] A, B``, :mod:`drip_cert.spec.linear`) takes its decimals.
        expert, learned
            A gain matrix ``K`` (``m x n`` numbers: the policy ``u = -K x``, the sign of
            ``control.lqr`` and ``scipy``), a list of ``m`` expressions (sympy, or text in the
            state names), or (``learned`` only) an :class:`~drip_cert.model.mlp.MLP` (a block
            named ``pi_il``).
        support, horizon
            The initial law's support box and ``T``, as for :class:`System`.
        states, inputs
            Names; default: the object's ``state_labels`` / ``input_labels`` when it has them
            (python-control >= 0.10), else ``x1..xn`` / ``u1..um``.
        name
            Label for reports.
        **uncertainty
            ``lambda_mu``, ``lambda_sigma``, ``diffusion`` (expressions or text),
            ``Delta_mu``, ``Delta_sigma``, ``brownian_dim``, ``true_support``: as for
            :class:`System`.

        Returns
        -------
        System
            ``f = A x``, ``g = B``, the expert (and learned) policies.
        """
        return statespace_system(
            cls,
            sys_or_AB,
            expert=expert,
            support=support,
            horizon=horizon,
            states=states,
            inputs=inputs,
            name=name,
            learned=learned,
            **uncertainty,
        )

    def with_learned(
        self, learned: Sequence[sp.Expr] | sp.MatrixBase, blocks: Mapping[str, Block] | None = None
    ) -> System:
        """A copy with the learned policy replaced (and blocks added)."""
        merged = dict(self.blocks)
        merged.update(blocks or {})
        return _replace(self, learned=sp.ImmutableMatrix(learned), blocks=merged)

    def to_dict(self) -> dict[str, Any]:
        """A JSON-ready description (expressions as strings)."""

        def strs(mat):
            return None if mat is None else [[str(e) for e in row] for row in mat.tolist()]

        return {
            "name": self.name,
            "n": self.n,
            "m": self.m,
            "d": self.d,
            "states": [str(s) for s in self.states],
            "inputs": list(self.inputs),
            "horizon": self.horizon,
            "f": [str(e) for e in self.f],
            "g": strs(self.g),
            "expert": [str(e) for e in self.expert],
            "learned": None if self.learned is None else [str(e) for e in self.learned],
            "diffusion": strs(self.diffusion),
            "uncertainty_drift": None
            if self.lambda_mu is None
            else [str(e) for e in self.lambda_mu],
            "uncertainty_diffusion": strs(self.lambda_sigma),
            "Delta_mu_given": self.Delta_mu,
            "Delta_sigma_given": self.Delta_sigma,
            "support": [list(b) for b in self.support],
            "true_support": None
            if self.true_support is None
            else [list(b) for b in self.true_support],
            "blocks": [b.to_dict() for b in self.blocks.values()],
        }


def _replace(sys_: System, **changes: Any) -> System:
    kwargs = {k: getattr(sys_, k) for k in System.__dataclass_fields__}
    kwargs.update(changes)
    return System(**kwargs)


def _nonneg_float(v: Any, fieldname: str) -> float:
    if isinstance(v, bool) or not isinstance(v, int | float | np.floating | np.integer):
        raise SpecError(f"expected a number, got {v!r}", field=fieldname)
    x = float(v)
    if not math.isfinite(x):
        raise SpecError(f"expected a finite number, got {v!r}", field=fieldname)
    if x < 0:
        raise SpecError(f"must be >= 0, got {v!r}", field=fieldname)
    return x


def _box(value: Any, n: int, fieldname: str) -> tuple[tuple[float, float], ...]:
    try:
        arr = np.array(value, dtype=object)
    except Exception:  # pragma: no cover
        raise SpecError(f"expected {n} pairs [lo, hi], got {value!r}", field=fieldname) from None
    if arr.shape != (n, 2):
        raise SpecError(
            f"expected {n} pairs [lo, hi] (one per state), got {value!r}", field=fieldname
        )
    out = []
    for i, (lo, hi) in enumerate(arr):
        for v in (lo, hi):
            if isinstance(v, bool) or not isinstance(v, int | float | np.floating | np.integer):
                raise SpecError(f"bound {v!r} of state {i} is not a number", field=fieldname)
            if not math.isfinite(float(v)):
                raise SpecError(
                    f"bound {v!r} of state {i} is not finite: the support must be a bounded box",
                    field=fieldname,
                )
        if float(lo) > float(hi):
            raise SpecError(f"interval {i} is empty: lo = {lo} > hi = {hi}", field=fieldname)
        out.append((float(lo), float(hi)))
    return tuple(out)


def _exact_rational(v: Any) -> sp.Rational:
    """The exact rational a number denotes (a float: the binary rational it stores)."""
    if isinstance(v, sp.Rational):
        return v
    if isinstance(v, sp.Float | float | int | np.floating | np.integer):
        x = float(v) if not isinstance(v, int | np.integer) else int(v)
        if isinstance(x, float) and not math.isfinite(x):
            raise ValueError(f"{v!r} is not finite")
        return sp.Rational(x)
    e = sp.sympify(v)
    if e.is_Rational:
        return e
    raise TypeError(f"{v!r} is not a rational number (give Theta numerically)")


def _float_up_abs(r: sp.Rational) -> float:
    """A float ``>= |r|`` (exact rational comparison)."""
    a = abs(sp.Rational(r))
    x = float(a)
    return x if sp.Rational(x) >= a else math.nextafter(x, math.inf)


def _float_down(r: sp.Rational) -> float:
    x = float(r)
    return x if sp.Rational(x) <= r else math.nextafter(x, -math.inf)


def _float_up(r: sp.Rational) -> float:
    x = float(r)
    return x if sp.Rational(x) >= r else math.nextafter(x, math.inf)


def box_image(Th: sp.Matrix, box: Sequence[Sequence[float]]) -> tuple[tuple[float, float], ...]:
    """The smallest box containing ``Th @ box`` (exact interval arithmetic, rounded outward)."""
    out = []
    for i in range(Th.shape[0]):
        lo = hi = sp.Rational(0)
        for j, (a, b) in enumerate(box):
            c = Th[i, j]
            ends = (c * sp.Rational(a), c * sp.Rational(b))
            lo += min(ends)
            hi += max(ends)
        out.append((_float_down(lo), _float_up(hi)))
    return tuple(out)
