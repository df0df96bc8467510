"""The numeric view of a system: jax-traceable vector fields, policies and closed-loop Jacobians.

A :class:`SimModel` is the ONE numeric view of a system, used by the analysis, the learning and the
Monte-Carlo engine alike. It holds the known drift ``f`` (without any policy), the input operator
``g``, the known diffusion ``p``, the unknown drift and diffusion ``Lambda_mu``/``Lambda_sigma`` of
Definition "Vector Fields" of the DRIP paper (eq. ``TrueVectorFields``; L1-DRAC eq. (1)), the
expert and learned policies, the closed-loop Jacobians of DRIP Assumption 2 and ``Theta_ad`` of
L1-DRAC Assumption 1. Every callable takes ONE path (unbatched arrays) and must be traceable by jax;
the engine vmaps them.

:attr:`drip_cert.model.system.System.numeric` lowers a ``System``'s expressions into one (built once
per system); :func:`make_model` builds one from plain jax functions. Nothing here imports the
``System``: the view takes callables.
"""

from __future__ import annotations

import inspect
import weakref
from collections.abc import Callable
from dataclasses import dataclass

import numpy as np

from drip_cert._jax import jax, jnp
from drip_cert.errors import SpecError

__all__ = ["SimModel", "closed_loop_jacobian", "make_model", "theta_ad_from_g"]


@dataclass(frozen=True, eq=False)
class SimModel:
    """Sizes and jax-traceable callables of one system (single path, unbatched).

    Parameters
    ----------
    n, m, d
        State, input and Brownian-motion dimensions.
    f
        ``f(t, x) -> (n,)``: known drift WITHOUT the policy (DRIP Definition "Vector Fields").
    g
        ``g(t, x) -> (n, m)``: input operator. L1-DRAC (Definition 1) needs it to depend on ``t``
        only; DRIP's other parts allow the state (``g_state``).
    p
        ``p(t, x) -> (n, d)``: known diffusion (may be identically zero).
    lam_mu
        ``Lambda_mu(t, x) -> (n,)``: unknown drift (DRIP / L1-DRAC (1)); zero when unknown.
    lam_sigma
        ``Lambda_sigma(t, x) -> (n, d)``: unknown diffusion; zero when unknown.
    expert
        ``pi*(x) -> (m,)``: the expert policy of (NominalProcesses).
    learned
        ``pi_IL(x) -> (m,)`` or ``None`` when no learned policy exists yet.
    theta_ad
        ``Theta_ad(t) -> (m, n)``, ``[I_m 0] gbar(t)^{-1}`` of L1-DRAC Assumption 1.
    name
        Free text; part of the resume hash of a Monte-Carlo run.
    g_state
        Whether ``g`` depends on the state. ``False`` (the default) lets the engine evaluate
        ``g(t, x)`` once per step for all paths, at ``x = 0``; ``True`` evaluates it per path.
        The L1-DRAC controller needs ``False``.
    jac_expert, jac_learned
        ``(t, x) -> (n, n)``: ``nabla_x fbar(t, x, pi(x))`` of the expert and of the learned closed
        loop (DRIP Assumption 2). ``None`` (the default) takes them by forward-mode autodiff
        (:func:`closed_loop_jacobian`); ``jac_learned`` stays ``None`` without a learned policy.

    Notes
    -----
    Equality is identity (``eq=False``): callables have no value equality.
    """

    n: int
    m: int
    d: int
    f: Callable
    g: Callable
    p: Callable
    lam_mu: Callable
    lam_sigma: Callable
    expert: Callable
    learned: Callable | None
    theta_ad: Callable
    name: str = "model"
    g_state: bool = False
    jac_expert: Callable | None = None
    jac_learned: Callable | None = None

    def __post_init__(self) -> None:
        for fld in ("n", "m", "d"):
            v = getattr(self, fld)
            if not isinstance(v, int | np.integer) or isinstance(v, bool) or int(v) < 1:
                raise SpecError(f"must be a positive integer, got {v!r}", field=f"SimModel.{fld}")
            object.__setattr__(self, fld, int(v))
        if self.m > self.n:
            raise SpecError(
                f"input dimension m={self.m} exceeds state dimension n={self.n}; g must have "
                "full column rank, so m <= n",
                field="SimModel.m",
            )
        for fld in ("f", "g", "p", "lam_mu", "lam_sigma", "expert", "theta_ad"):
            if not callable(getattr(self, fld)):
                raise SpecError("must be a callable", field=f"SimModel.{fld}")
        for fld in ("learned", "jac_expert", "jac_learned"):
            if getattr(self, fld) is not None and not callable(getattr(self, fld)):
                raise SpecError("must be a callable or None", field=f"SimModel.{fld}")
        if self.learned is None and self.jac_learned is not None:
            raise SpecError(
                "a closed-loop Jacobian of the learned policy without a learned policy",
                field="SimModel.jac_learned",
            )
        if self.jac_expert is None:
            object.__setattr__(
                self, "jac_expert", closed_loop_jacobian(self.f, self.g, self.expert)
            )
        if self.learned is not None and self.jac_learned is None:
            object.__setattr__(
                self, "jac_learned", closed_loop_jacobian(self.f, self.g, self.learned)
            )
        self._check_shapes()

    def jac_batched(self, which: str) -> Callable:
        """``jax.jit(jax.vmap(jac))`` of the ``"expert"`` or ``"learned"`` closed-loop Jacobian:
        ``(T, X) -> (B, n, n)`` for ``T`` of shape ``(B,)`` and ``X`` of shape ``(B, n)``.

        Built once per model and kept (jit caches its traces and compilations on the function
        object, so every later analysis of this model reuses them); ``ValueError`` when the
        model has no such Jacobian (no learned policy)."""
        cache = _JAC_BATCHED.setdefault(self, {})
        if which not in cache:
            jac = self.jac_expert if which == "expert" else self.jac_learned
            if jac is None:
                raise ValueError(f"the {which} closed loop has no Jacobian (no {which} policy)")
            cache[which] = jax.jit(jax.vmap(jac, in_axes=(0, 0)))
        return cache[which]

    def _check_shapes(self) -> None:
        """Trace every callable once (no FLOPs) and compare the output shapes with n, m, d."""
        n, m, d = self.n, self.m, self.d
        t = jax.ShapeDtypeStruct((), jnp.float64)
        x = jax.ShapeDtypeStruct((n,), jnp.float64)
        expected = {
            "f": ((t, x), (n,)),
            "g": ((t, x), (n, m)),
            "p": ((t, x), (n, d)),
            "lam_mu": ((t, x), (n,)),
            "lam_sigma": ((t, x), (n, d)),
            "expert": ((x,), (m,)),
            "theta_ad": ((t,), (m, n)),
        }
        if self.learned is not None:
            expected["learned"] = ((x,), (m,))
            expected["jac_learned"] = ((t, x), (n, n))
        expected["jac_expert"] = ((t, x), (n, n))
        for fld, (args, shape) in expected.items():
            try:
                out = jax.eval_shape(getattr(self, fld), *args)
            except Exception as exc:  # user code: report which callable failed and why
                raise SpecError(
                    f"cannot be traced by jax on a single path ({type(exc).__name__}: {exc}); "
                    "write it with jax.numpy on unbatched arrays",
                    field=f"SimModel.{fld}",
                ) from None
            if getattr(out, "shape", None) != shape:
                got = getattr(out, "shape", type(out).__name__)
                raise SpecError(
                    f"returns shape {got}, expected {shape} for n={n}, m={m}, d={d}",
                    field=f"SimModel.{fld}",
                )


_JAC_BATCHED: weakref.WeakKeyDictionary[SimModel, dict[str, Callable]] = weakref.WeakKeyDictionary()
"""The jitted batched Jacobians of each model (:meth:`SimModel.jac_batched`), kept beside the
model (a frozen dataclass that may be pickled) and dropped with it."""


def closed_loop_jacobian(f: Callable, g: Callable, policy: Callable) -> Callable:
    """``(t, x) -> nabla_x fbar(t, x, pi(x))``, ``fbar = f(t, x) + g(t, x) pi(x)`` (DRIP
    Assumption 2).

    Forward-mode autodiff of the closed loop (through ``g`` too, when it depends on the state);
    :attr:`~drip_cert.model.system.System.numeric` passes the exact symbolic Jacobian instead.
    """

    def jac(t, x):
        return jax.jacfwd(lambda z: f(t, z) + g(t, z) @ policy(z))(x)

    return jac


def theta_ad_from_g(g: Callable, n: int) -> Callable:
    """``Theta_ad(t) = [I_m 0] gbar(t)^{-1} = (g^T g)^{-1} g^T`` (L1-DRAC Assumption 1).

    For any ``g_perp`` with ``Im g_perp = ker g^T`` the first ``m`` rows ``L`` of
    ``gbar^{-1} = [g g_perp]^{-1}`` satisfy ``L g = I_m`` and ``L g_perp = 0``, which the
    left pseudo-inverse ``(g^T g)^{-1} g^T`` does; so ``Theta_ad`` does not depend on the choice of
    ``g_perp`` and equals the pseudo-inverse of ``g``. ``g(t, x)`` is read at ``x = 0`` (L1-DRAC
    needs a ``g`` of ``t`` only).
    """

    def theta_ad(t):
        gt = g(t, jnp.zeros(n))
        return jnp.linalg.solve(gt.T @ gt, gt.T)

    return theta_ad


def make_model(
    n: int,
    m: int,
    d: int,
    f: Callable,
    g: Callable,
    expert: Callable,
    learned: Callable | None = None,
    p: Callable | None = None,
    lam_mu: Callable | None = None,
    lam_sigma: Callable | None = None,
    theta_ad: Callable | None = None,
    name: str = "model",
    g_state: bool = False,
) -> SimModel:
    """Build a :class:`SimModel` from plain jax functions, filling the optional ones.

    ``p``, ``lam_mu`` and ``lam_sigma`` default to zero; ``theta_ad`` defaults to
    :func:`theta_ad_from_g`. ``g`` is a callable ``g(t, x)``, a callable of one argument
    ``g(t)`` (the form before state-dependent input operators; wrapped) or a constant ``(n, m)``
    array; ``g_state`` says whether the callable depends on ``x``.

    Returns
    -------
    SimModel
        The validated model (shapes checked by tracing).
    """
    if not callable(g):
        g_arr = np.asarray(g, dtype=np.float64)
        if g_arr.shape != (n, m):
            raise SpecError(f"constant g has shape {g_arr.shape}, expected {(n, m)}", field="g")
        g_const = jnp.asarray(g_arr)

        def g(t, x):
            return g_const

    elif _positional_arity(g) == 1:
        g_of_t = g

        def g(t, x):
            return g_of_t(t)

    def _zero_drift(t, x):
        return jnp.zeros((n,), dtype=jnp.float64)

    def _zero_diffusion(t, x):
        return jnp.zeros((n, d), dtype=jnp.float64)

    return SimModel(
        n=n,
        m=m,
        d=d,
        f=f,
        g=g,
        p=p if p is not None else _zero_diffusion,
        lam_mu=lam_mu if lam_mu is not None else _zero_drift,
        lam_sigma=lam_sigma if lam_sigma is not None else _zero_diffusion,
        expert=expert,
        learned=learned,
        theta_ad=theta_ad if theta_ad is not None else theta_ad_from_g(g, n),
        name=name,
        g_state=g_state,
    )


def _positional_arity(fn: Callable) -> int | None:
    """The number of positional parameters of ``fn`` (``None`` when unknown or variadic)."""
    try:
        params = inspect.signature(fn).parameters.values()
    except (TypeError, ValueError):
        return None
    kinds = [p.kind for p in params]
    if inspect.Parameter.VAR_POSITIONAL in kinds:
        return None
    return sum(
        k in (inspect.Parameter.POSITIONAL_ONLY, inspect.Parameter.POSITIONAL_OR_KEYWORD)
        for k in kinds
    )
