"""Imitation on a :class:`~drip_cert.model.system.System`: expert demonstrations, training, the
learned system.

* the ``[tasil]`` settings are :class:`~drip_cert.spec.settings.TasilSettings` (validated when
  the spec is loaded: ``spec.settings.tasil``; :func:`tasil_settings` reads a bare table);
* :func:`demonstrations` draws expert trajectories of the nominal model (DRIP Definition
  "Training Data"); :func:`train_on_system` trains TaSIL or BC on them and returns the policy as
  an MLP block for ``System.with_learned`` (:func:`learned_system`).
"""

from __future__ import annotations

from collections.abc import Mapping
from dataclasses import dataclass
from typing import Any

import numpy as np

from drip_cert._jax import jax
from drip_cert.errors import SpecError
from drip_cert.learn.data import Demonstrations, generate_demonstrations
from drip_cert.model.blocks import mlp_block
from drip_cert.model.mlp import MLP
from drip_cert.model.system import System
from drip_cert.spec.settings import TasilSettings

POLICY_BLOCK = "pi_il"  #: block name of a trained policy inside the System


def tasil_settings(table: Mapping[str, Any] | None) -> TasilSettings:
    """Validate a ``[tasil]`` table; a loaded spec already holds it as ``spec.settings.tasil``."""
    return TasilSettings.from_table(table)


def nominal_field(s: System):
    """``(t, x, u) -> f(t, x) + g(t) u``, the nominal drift of DRIP (NominalVectorFields)."""
    num = s.numeric

    def field(t, x, u):
        return num.f(t, x) + num.g(t) @ u

    return field


def demonstrations(s: System, n: int, k: int, seed: int, stream: int = 0) -> Demonstrations:
    """``n`` expert trajectories of the nominal model from ``xi_i ~ D`` (uniform on the box),
    sampled on the uniform partition of ``[0, T]`` with ``k`` intervals (DRIP Def. "Training
    Data"). ``stream`` separates training (0) from held-out (1) draws of the same seed."""
    key = jax.random.fold_in(jax.random.PRNGKey(seed), stream)
    return generate_demonstrations(
        nominal_field(s), s.numeric.expert, np.array(s.support), n, s.horizon, k, key
    )


def learned_system(s: System, mlp: MLP, name: str = POLICY_BLOCK, source: str = "") -> System:
    """``s`` with ``pi_IL = mlp`` as a block named ``name`` (``pi_il(x)[j]``)."""
    if mlp.in_dim != s.n or mlp.out_dim != s.m:
        raise SpecError(
            f"the policy maps R^{mlp.in_dim} -> R^{mlp.out_dim}, the system needs "
            f"R^{s.n} -> R^{s.m}"
        )
    block = mlp_block(name, mlp, source=source)
    exprs = [block.component(j)(*s.states) for j in range(s.m)]
    return s.with_learned(exprs, {name: block})


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
) -> TrainedPolicy:
    """Train TaSIL (or BC, ``method``) on expert demonstrations and attach the policy to ``s``.

    ``demonstrations`` are drawn by :func:`demonstration_set` from ``settings`` when not given;
    training uses ``settings.seed`` for its own randomness (initialisation, batches).
    """
    from drip_cert.learn.tasil import train_policy  # optax: keep off the API's import path

    method = method or settings.method
    demos = demonstration_set(s, settings) if demonstrations is None else demonstrations
    res = train_policy(
        demos.train,
        s.numeric.expert,
        method=method,
        order=settings.order,
        hidden=settings.hidden,
        activation=settings.activation,
        seed=settings.seed,
        steps=settings.steps,
        lr=settings.lr,
        batch=settings.batch,
        progress=progress,
    )
    return TrainedPolicy(learned_system(s, res.mlp), res.mlp, res, demos, settings, method)
