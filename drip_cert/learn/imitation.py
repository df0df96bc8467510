"""Imitation on a :class:`~drip_cert.model.system.System`: expert demonstrations, training, the
learned system.

* the ``[tasil]`` settings are :class:`~drip_cert.spec.settings.TasilSettings` (validated when
  the spec is loaded: ``spec.settings.tasil``; :func:`tasil_settings` reads a bare table);
* :func:`demonstrations` draws expert trajectories of the nominal model (DRIP Definition
  "Training Data"); :func:`train_on_system` trains TaSIL, BC, DAgger or DART on them and returns
  the policy as an MLP block for ``System.with_learned`` (:func:`learned_system`).
"""

from __future__ import annotations

import dataclasses
import math
from collections.abc import Mapping, Sequence
from dataclasses import dataclass
from typing import Any

import numpy as np
import sympy as sp

from drip_cert._jax import jax, jnp
from drip_cert.errors import SpecError
from drip_cert.learn.baselines import (
    BASELINES,
    DEFAULT_ITERATIONS,
    BaselineRun,
    train_baseline,
)
from drip_cert.learn.data import Demonstrations, generate_demonstrations
from drip_cert.model.blocks import mlp_block
from drip_cert.model.mlp import MLP
from drip_cert.model.system import System
from drip_cert.spec.settings import TRAIN_METHODS, TasilSettings

POLICY_BLOCK = "pi_il"  #: block name of a trained policy inside the System


def tasil_settings(table: Mapping[str, Any] | None) -> TasilSettings:
    """Validate a ``[tasil]`` table; a loaded spec already holds it as ``spec.settings.tasil``."""
    return TasilSettings.from_table(table)


def nominal_field(s: System):
    """``(t, x, u) -> f(t, x) + g(t, x) u``, the nominal drift of DRIP (NominalVectorFields)."""
    num = s.numeric

    def field(t, x, u):
        return num.f(t, x) + num.g(t, x) @ u

    return field


def demonstrations(s: System, n: int, k: int, seed: int, stream: int = 0) -> Demonstrations:
    """``n`` expert trajectories of the nominal model from ``xi_i ~ D`` (uniform on the box),
    sampled on the uniform partition of ``[0, T]`` with ``k`` intervals (DRIP Def. "Training
    Data"). ``stream`` separates training (0) from held-out (1) draws of the same seed."""
    key = jax.random.fold_in(jax.random.PRNGKey(seed), stream)
    return generate_demonstrations(
        nominal_field(s), s.numeric.expert, np.array(s.support), n, s.horizon, k, key
    )


def learned_system(
    s: System,
    mlp: MLP,
    name: str = POLICY_BLOCK,
    source: str = "",
    *,
    linear: np.ndarray | None = None,
    structure: Sequence[sp.Expr] | None = None,
) -> System:
    """``s`` with ``pi_IL = structure(x) + K x + mlp(x)``, the network a block named ``name``
    (``pi_il(x)[j]``); ``structure`` and the linear term ``K = linear`` are optional (the residual
    policy class, :func:`train_on_system`). ``K``'s entries enter as exact binary floats."""
    if mlp.in_dim != s.n or mlp.out_dim != s.m:
        raise SpecError(
            f"the policy maps R^{mlp.in_dim} -> R^{mlp.out_dim}, the system needs "
            f"R^{s.n} -> R^{s.m}"
        )
    block = mlp_block(name, mlp, source=source)
    exprs = [block.component(j)(*s.states) for j in range(s.m)]
    if linear is not None:
        K = np.asarray(linear, dtype=float)
        exprs = [
            e + sum(sp.Float(float(K[j, i]), 17) * xi for i, xi in enumerate(s.states))
            for j, e in enumerate(exprs)
        ]
    if structure is not None:
        exprs = [sp.sympify(b) + e for b, e in zip(structure, exprs, strict=True)]
    return s.with_learned(exprs, {name: block})


def structure_function(s: System, structure: Sequence[sp.Expr] | None):
    """``x -> structure(x)`` (jax-traceable; zeros when ``None``): the known part of a residual
    policy, lowered like any policy of ``s``."""
    if structure is None:
        m = s.m
        return lambda x: jnp.zeros(x.shape[:-1] + (m,), dtype=x.dtype)
    base = s.with_learned(list(structure)).numeric.learned
    assert base is not None  # with_learned sets it
    return base


@dataclass(frozen=True)
class DemonstrationSet:
    """The training and held-out expert demonstrations of one seed (independent streams 0, 1).

    The pipeline draws them once and hands the same set to training and to the certificate, so
    the TaSIL bound is computed on the data the policy was trained on.
    """

    train: Demonstrations
    heldout: Demonstrations | None
    seed: int


def demonstration_set(s: System, settings: TasilSettings) -> DemonstrationSet:
    """``settings.trajectories`` training and ``settings.heldout`` held-out trajectories of
    ``settings.samples`` intervals, from ``settings.seed``."""
    train = demonstrations(s, settings.trajectories, settings.samples, settings.seed, 0)
    heldout = (
        demonstrations(s, settings.heldout, settings.samples, settings.seed, 1)
        if settings.heldout > 0
        else None
    )
    return DemonstrationSet(train, heldout, settings.seed)


@dataclass(frozen=True)
class TrainedPolicy:
    """A trained policy with the data it was trained on."""

    system: System  #: the system with pi_IL set to the trained policy
    mlp: MLP
    result: Any  #: drip_cert.learn.tasil.TrainResult
    demonstrations: DemonstrationSet
    settings: TasilSettings
    method: str
    #: DAgger / DART: the aggregated data and the iterations (``None`` for TaSIL and BC)
    baseline: BaselineRun | None = None

    @property
    def train(self) -> Demonstrations:
        return self.demonstrations.train

    @property
    def heldout(self) -> Demonstrations | None:
        return self.demonstrations.heldout


def train_on_system(
    s: System,
    settings: TasilSettings,
    method: str | None = None,
    progress: bool = False,
    demonstrations: DemonstrationSet | None = None,
    structure: Sequence[sp.Expr] | None = None,
    *,
    iterations: int = DEFAULT_ITERATIONS,
    noise_cov: np.ndarray | None = None,
) -> TrainedPolicy:
    """Train TaSIL, BC, DAgger or DART (``method``, :data:`TRAIN_METHODS`) on expert
    demonstrations and attach the policy to ``s``.

    DAgger and DART (:mod:`drip_cert.learn.baselines`) spend the label budget of the training
    demonstrations (their ``n`` trajectories) over ``iterations`` rounds of data collection
    (learner rollouts labelled by the expert; expert rollouts with the noise ``noise_cov``, fitted
    to the learner's error when ``None``) and use the BC loss.

    ``demonstrations`` are drawn by :func:`demonstration_set` from ``settings`` when not given;
    training uses ``settings.seed`` for its own randomness (initialisation, batches).

    ``settings.architecture == "residual"``: the policy is ``structure(x) + K x + N(x)`` with the
    known ``structure`` (``[policy] structure``; 0 when ``None``), a learned matrix ``K`` and an
    MLP ``N`` whose product of layer spectral norms stays within ``settings.lipschitz_budget``.
    The loss is the same TaSIL/BC loss, on the residual targets ``pi*(x) - structure(x)`` and
    their derivatives (the structure is fixed, so matching the residual is matching ``pi*``).
    ``settings.lipschitz_budget`` bounds the product of layer spectral norms of the network of
    either architecture (projected after every step), which bounds its Lipschitz constant and,
    with the activation's curvature, the certificate's ``L_dpi``.
    """
    from drip_cert.learn.tasil import train_policy  # optax: keep off the API's import path

    method = method or settings.method
    if method not in TRAIN_METHODS:
        raise SpecError(
            f"unknown training method {method!r}; use one of {', '.join(TRAIN_METHODS)}",
            field="tasil.method",
        )
    demos = demonstration_set(s, settings) if demonstrations is None else demonstrations
    residual = settings.architecture == "residual"
    full_expert = s.numeric.expert
    base = structure_function(s, structure) if residual else None

    def fit(data: Demonstrations, steps: int, loss: str):
        """Train on ``data`` (actions: the whole expert's labels); the result and the whole
        learned policy ``structure(x) + res.policy()(x)``."""
        expert = full_expert
        if base is not None:

            def expert(x):
                return full_expert(x) - base(x)

            st = data.states
            offset = np.asarray(jax.vmap(base)(st.reshape(-1, st.shape[-1]))).reshape(
                *st.shape[:-1], s.m
            )
            data = dataclasses.replace(data, actions=data.actions - offset)
        res = train_policy(
            data,
            expert,
            method=loss,
            order=settings.order,
            hidden=settings.hidden,
            activation=settings.activation,
            seed=settings.seed,
            steps=steps,
            lr=settings.lr,
            batch=settings.batch,
            progress=progress,
            skip=residual,
            lipschitz_budget=settings.lipschitz_budget,
            tube_weight=settings.tube_weight,
            tube_points=settings.tube_points,
            # the margin of the certificate's box for L_Delta (bounds/tasil/section.py)
            tube_radius=settings.tube_radius if math.isfinite(settings.tube_radius) else 1.0,
        )
        net = res.policy()
        if base is None:
            return res, net
        known = base
        return res, lambda x: known(x) + net(x)

    baseline = None
    if method in BASELINES:
        baseline = train_baseline(
            method,
            demos.train,
            nominal_field(s),
            full_expert,
            np.array(s.support),
            lambda data, steps: fit(data, steps, "bc"),
            settings.steps,
            settings.seed,
            iterations=iterations,
            noise_cov=noise_cov,
        )
        res = baseline.result
    else:
        res, _ = fit(demos.train, settings.steps, method)
    system = learned_system(
        s, res.mlp, linear=res.linear, structure=structure if residual else None
    )
    return TrainedPolicy(system, res.mlp, res, demos, settings, method, baseline)
