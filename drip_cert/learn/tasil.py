"""Training imitation policies by TaSIL or behaviour cloning (BC), and measuring the gap.

:func:`train_policy` fits an MLP policy ``pi_hat`` with smooth activations to expert demonstrations
(:class:`~drip_cert.learn.data.Demonstrations`) by minimising the TaSIL loss of DRIP eq.
(LossTaSIL) (value + Jacobian matching, order 1, optionally + Hessian, order 2) or the BC loss
(value matching only); see :mod:`drip_cert.learn.losses`. The optimiser is Adam (optax) on seeded
mini-batches (drawn with replacement from a pool of more than ``PERMUTE_MAX`` entries), with
jit-compiled steps run ``eval_every`` at a time under ``lax.scan``. A seeded share of the
trajectories is held out; the held-out loss (over a fixed seeded subset of at most ``EVAL_STATES``
states for the mean reduction) is evaluated every ``eval_every`` steps and training stops when it
has not improved for ``patience`` steps; the best parameters are restored. Same seed and data ->
bit-identical weights.

:func:`evaluate_gap` measures the imitation gap the TaSIL code reports: expert and learner
closed loops from the same initial states, the same integrator, and per trajectory
``max_t ||x_hat_t - x*_t||_2`` over the sample grid.
"""

from __future__ import annotations

import math
import sys
import time
from collections.abc import Callable, Sequence
from dataclasses import dataclass
from functools import partial
from typing import Any

import numpy as np
import optax
from tqdm.auto import tqdm

from drip_cert._jax import jax, jnp
from drip_cert.errors import SpecError
from drip_cert.learn.data import DEFAULT_SUBSTEPS, Demonstrations, simulate_closed_loop
from drip_cert.learn.losses import (
    LossSpec,
    Targets,
    expert_targets,
    imitation_loss,
    tube_loss,
)
from drip_cert.learn.losses import tube_points as draw_tube_points
from drip_cert.model.activations import get_activation
from drip_cert.model.mlp import ACTIVATIONS, MLP, apply_params, init_mlp, mlp_from_params

METHODS = ("tasil", "bc")
SCHEDULES = ("constant", "cosine")


@dataclass(frozen=True)
class TrainSettings:
    """Every setting of one training run (recorded in :class:`TrainResult`).

    ``order`` is the effective Taylor order: 0 for BC. ``batch`` counts states for the
    ``"mean"`` reduction and trajectories for ``"max"``.
    """

    method: str = "tasil"
    order: int = 1
    hidden: tuple[int, ...] = (64, 64)
    activation: str = "tanh"
    output_activation: str | None = None
    seed: int = 0
    steps: int = 5000
    lr: float = 3e-3
    schedule: str = "cosine"
    batch: int = 128
    val_fraction: float = 0.2
    patience: int = 1000
    eval_every: int = 50
    lambda_j: float = 1.0
    lambda_h: float = 10.0
    reduction: str = "mean"
    skip: bool = False
    lipschitz_budget: float = float("inf")
    tube_weight: float = 0.0
    tube_points: int = 128
    tube_radius: float = 1.0

    @staticmethod
    def _known(name: str) -> bool:
        try:
            get_activation(name)
        except SpecError:
            return False
        return True

    def __post_init__(self) -> None:
        if self.method not in METHODS:
            raise SpecError(f"method must be one of {METHODS}, got {self.method!r}", field="method")
        try:
            hidden_act = get_activation(self.activation)
        except SpecError as exc:
            raise SpecError(str(exc), field="activation") from None
        if not hidden_act.smooth:
            raise SpecError(
                f"activation must be smooth (the TaSIL certificate's lemma route needs a "
                f"Lipschitz Jacobian), got {self.activation!r}; use tanh, gelu, sigmoid, "
                f"softplus, silu or elu(1.0)",
                field="activation",
            )
        if self.output_activation is not None and not self._known(self.output_activation):
            raise SpecError(
                f"output_activation must be None or one of {ACTIVATIONS}, "
                f"got {self.output_activation!r}",
                field="output_activation",
            )
        hidden = tuple(self.hidden)
        if any(int(h) != h or h < 1 for h in hidden):
            raise SpecError(f"hidden sizes must be positive integers, got {hidden}", field="hidden")
        object.__setattr__(self, "hidden", tuple(int(h) for h in hidden))
        for name in ("steps", "batch", "patience", "eval_every"):
            value = getattr(self, name)
            if int(value) != value or value < 1:
                raise SpecError(f"{name} must be a positive integer, got {value!r}", field=name)
        if not (np.isfinite(self.lr) and self.lr > 0):
            raise SpecError(f"lr must be a positive number, got {self.lr!r}", field="lr")
        if self.schedule not in SCHEDULES:
            raise SpecError(
                f"schedule must be one of {SCHEDULES}, got {self.schedule!r}", field="schedule"
            )
        if not (self.lipschitz_budget > 0):  # NaN fails too
            raise SpecError(
                f"lipschitz_budget must be > 0 (inf: none), got {self.lipschitz_budget!r}",
                field="lipschitz_budget",
            )
        if not (math.isfinite(self.tube_weight) and self.tube_weight >= 0):
            raise SpecError(
                f"tube_weight must be finite and >= 0 (0: off), got {self.tube_weight!r}",
                field="tube_weight",
            )
        if int(self.tube_points) != self.tube_points or self.tube_points < 1:
            raise SpecError(
                f"tube_points must be a positive integer, got {self.tube_points!r}",
                field="tube_points",
            )
        if not (math.isfinite(self.tube_radius) and self.tube_radius >= 0):
            raise SpecError(
                f"tube_radius must be finite and >= 0, got {self.tube_radius!r}",
                field="tube_radius",
            )
        if not (0.0 <= self.val_fraction < 1.0):
            raise SpecError(
                f"val_fraction must be in [0, 1), got {self.val_fraction!r}", field="val_fraction"
            )
        self.loss_spec()  # validates order, lambdas and reduction

    def loss_spec(self) -> LossSpec:
        """The :class:`~drip_cert.learn.losses.LossSpec` these settings minimise."""
        return LossSpec(
            order=0 if self.method == "bc" else self.order,
            lambda_j=self.lambda_j,
            lambda_h=self.lambda_h,
            reduction=self.reduction,
        )


@dataclass(frozen=True)
class TrainHistory:
    """Losses at the evaluation steps: training-set and held-out loss after ``steps[i]``
    optimiser steps (``steps[0] = 0`` is the initial network), each over the whole split or,
    for the mean reduction of a split with more than ``EVAL_STATES`` states, over a fixed
    seeded subset of that many (:func:`_eval_subset`)."""

    steps: tuple[int, ...]
    train_loss: tuple[float, ...]
    val_loss: tuple[float, ...]


@dataclass(frozen=True)
class TrainResult:
    """Outcome of :func:`train_policy`.

    Attributes
    ----------
    mlp
        The restored best policy (save it with ``mlp.save(path)``).
    method, order
        ``"tasil"`` / ``"bc"`` and the effective Taylor order (0 for BC).
    history
        :class:`TrainHistory`.
    best_step, best_val_loss
        Step of the restored parameters and their held-out loss (training loss when
        ``val_fraction = 0``).
    stop_reason
        ``"steps"`` (the budget ran out), ``"patience"`` (early stopping) or
        ``"non-finite loss"`` (the held-out loss became NaN/inf; the best finite parameters are
        kept).
    wall_time_s
        Wall-clock seconds of the whole call, jit compilation included.
    settings
        :class:`TrainSettings`.
    train_index, val_index
        Trajectory indices of the two splits.
    linear
        ``(m, n)`` matrix ``K`` of the learned linear term when ``settings.skip``: the policy is
        ``x -> K x + mlp(x)``; ``None`` otherwise.
    """

    mlp: MLP
    method: str
    order: int
    history: TrainHistory
    best_step: int
    best_val_loss: float
    stop_reason: str
    wall_time_s: float
    settings: TrainSettings
    train_index: tuple[int, ...]
    val_index: tuple[int, ...]
    linear: np.ndarray | None = None

    def policy(self) -> Callable:
        """The learned policy ``x -> u`` as a jax-traceable function (``K x + mlp(x)`` with a
        linear term)."""
        if self.linear is None:
            return self.mlp.apply_jax
        K = jnp.asarray(self.linear)
        apply = self.mlp.apply_jax
        return lambda x: apply(x) + x @ K.T


def train_policy(
    demos: Demonstrations,
    expert: Callable,
    method: str = "tasil",
    order: int = 1,
    hidden: Sequence[int] = (64, 64),
    activation: str = "tanh",
    seed: int = 0,
    steps: int = 5000,
    lr: float = 3e-3,
    batch: int = 128,
    val_fraction: float = 0.2,
    patience: int = 1000,
    progress: bool = True,
    *,
    expert_jac: Callable | None = None,
    eval_every: int = 50,
    schedule: str = "cosine",
    lambda_j: float = 1.0,
    lambda_h: float = 10.0,
    reduction: str = "mean",
    output_activation: str | None = None,
    skip: bool = False,
    lipschitz_budget: float = float("inf"),
    tube_weight: float = 0.0,
    tube_points: int = 128,
    tube_radius: float = 1.0,
) -> TrainResult:
    """Train an MLP policy on expert demonstrations by TaSIL (DRIP eq. (LossTaSIL)) or BC.

    Parameters
    ----------
    demos
        Expert demonstrations; the loss uses the samples ``t in partition \\ {T}`` as in
        eq. (LossTaSIL) (the last sample of each trajectory is not used).
    expert
        ``expert(x) -> u`` (jax-traceable), for the expert derivatives.
    method
        ``"tasil"`` or ``"bc"`` (behaviour cloning, value matching only; ``order`` is ignored).
    order
        TaSIL order: 1 (value + Jacobian, DRIP's choice p = 1) or 2 (+ Hessian).
    hidden, activation
        Hidden layer widths and the smooth activation (``"tanh"`` or ``"gelu"``).
    seed
        Seed of the initial weights, the train/validation split and the mini-batches.
    steps, lr, batch
        Adam steps, learning rate (peak of the cosine decay when ``schedule="cosine"``), and
        mini-batch size (states for ``reduction="mean"``, trajectories for ``"max"``).
    val_fraction
        Share of the trajectories held out for early stopping (at least one when > 0 and there
        are two or more trajectories; 0 selects on the training loss).
    patience
        Stop when the held-out loss has not improved for this many steps.
    progress
        Show a tqdm bar (also off when stderr is not a terminal).
    expert_jac
        Optional analytic Jacobian ``x -> (m, n)`` of the expert (else ``jax.jacrev``).
    eval_every
        Steps between two evaluations of the training and held-out losses (for the mean
        reduction, each over a fixed seeded subset of at most ``EVAL_STATES`` states of its
        split, drawn once: the cost of an evaluation does not grow with the samples per
        trajectory).
    schedule
        ``"cosine"`` (decay to 0 over ``steps``) or ``"constant"`` learning rate.
    lambda_j, lambda_h, reduction
        Loss weights and reduction, see :class:`~drip_cert.learn.losses.LossSpec`.
    output_activation
        Optional activation of the output layer (``None``: affine output).
    skip
        Learn ``x -> K x + mlp(x)`` (a linear term beside the network; ``K`` and the output bias
        start at the least-squares fit of the training actions, the last layer at 0).
    lipschitz_budget
        After every Adam step each layer ``W_k`` of the network is scaled by
        ``min(1, b / ||W_k||_2)`` with ``b = budget^(1/L)`` (projected gradient), so the product
        of spectral norms -- an upper bound of the network's Lipschitz constant for 1-Lipschitz
        activations -- stays within the budget (up to float rounding; the certificate re-bounds
        it rigorously). ``inf``: no constraint.
    tube_weight, tube_points, tube_radius
        Weight ``w`` of the matching on the tube (docs/math/tasil.md section 5.1,
        :func:`~drip_cert.learn.losses.tube_loss`): each step adds
        ``w mean_j (||pi_hat(y_j) - pi*(y_j)|| + ||d pi_hat(y_j) - d pi*(y_j)||_F)`` over
        ``tube_points`` points ``y_j`` drawn uniformly on the box of the training states enlarged
        by ``tube_radius``, from a key of their own (``fold_in`` of the seed's key: same seed,
        same points). The recorded training and held-out losses (early stopping, the restored
        step) add the term at a fixed draw of ``TUBE_EVAL_POINTS`` points. ``0`` (default): no
        term, no draw, the training of earlier versions bit for bit. Behaviour cloning (order 0)
        ignores the term.

    Returns
    -------
    TrainResult
    """
    t_start = time.perf_counter()
    settings = TrainSettings(
        method=method,
        order=0 if method == "bc" else order,
        hidden=tuple(hidden),
        activation=activation,
        output_activation=output_activation,
        seed=seed,
        steps=steps,
        lr=lr,
        schedule=schedule,
        batch=batch,
        val_fraction=val_fraction,
        patience=patience,
        eval_every=eval_every,
        lambda_j=lambda_j,
        lambda_h=lambda_h,
        reduction=reduction,
        skip=skip,
        lipschitz_budget=lipschitz_budget,
        tube_weight=tube_weight,
        tube_points=tube_points,
        tube_radius=tube_radius,
    )
    if not isinstance(demos, Demonstrations):
        raise SpecError(
            f"demos must be a Demonstrations object, got {type(demos).__name__}; build one with "
            "generate_demonstrations(...) or load_demonstrations(path)",
            field="demos",
        )
    spec = settings.loss_spec()
    rng = np.random.default_rng(seed)
    train_idx, val_idx = _split(demos.n_traj, settings.val_fraction, rng)
    mlp0 = init_mlp(
        (demos.state_dim, *settings.hidden, demos.input_dim),
        rng,
        settings.activation,
        settings.output_activation,
    )
    # eq. (LossTaSIL): the loss runs over the partition without its last point T
    all_targets = expert_targets(
        expert, demos.states[:, :-1], demos.actions[:, :-1], spec.order, expert_jac
    )
    train_t = all_targets.take(jnp.asarray(train_idx))
    val_t = all_targets.take(jnp.asarray(val_idx)) if len(val_idx) else train_t
    pool = train_t.flat() if spec.reduction == "mean" else train_t
    axis = 1 if spec.reduction == "mean" else 0
    batch_size = min(settings.batch, int(pool.states.shape[axis]))

    net = _Net(
        settings.activation,
        settings.output_activation,
        settings.skip,
        settings.lipschitz_budget,
    )
    lr_args = (jnp.asarray(float(settings.lr)), jnp.asarray(float(settings.steps)))
    params: Any = [(jnp.asarray(w), jnp.asarray(b)) for w, b in mlp0.params()]
    if settings.skip:
        params = _skip_init(
            params, demos.states[:, :-1][train_idx], demos.actions[:, :-1][train_idx]
        )
    params = net.project(params)
    opt_state = _adam(*lr_args, settings.schedule).init(params)
    key = jax.random.PRNGKey(seed)
    tube = None
    tube_box = jnp.zeros((2, demos.state_dim))
    if settings.tube_weight > 0 and spec.order >= 1:  # TaSIL only: BC stays BC
        tube = _Tube(
            settings.tube_weight,
            settings.tube_points,
            expert,
            expert_jac if expert_jac is not None else jax.jacrev(expert),
            spec.floor,
        )
        flat = train_t.states.reshape(-1, demos.state_dim)
        tube_box = jnp.stack(
            [flat.min(axis=0) - settings.tube_radius, flat.max(axis=0) + settings.tube_radius]
        )

    def run_chunk(params, opt_state, step0, n_steps):
        return _run_chunk(
            params, opt_state, key, jnp.asarray(step0), pool, lr_args, tube_box, net=net,
            spec=spec, schedule=settings.schedule,
            n_steps=n_steps, batch_size=batch_size, axis=axis, tube=tube,
            replace=_draw_with_replacement(int(pool.states.shape[axis])),
        )  # fmt: skip

    # with the tube term, the recorded losses (and so early stopping and the restored step) add
    # the term at a fixed draw of points, the same for every evaluation
    eval_points = (
        None
        if tube is None
        else draw_tube_points(
            jax.random.fold_in(jax.random.PRNGKey(seed), TUBE_EVAL_STREAM),
            tube_box[0],
            tube_box[1],
            TUBE_EVAL_POINTS,
        )
    )

    # the recorded losses of the mean reduction run over a fixed, seeded subset of at most
    # EVAL_STATES states of each split (all of them when the split is smaller)
    train_e = _eval_subset(train_t, spec.reduction, seed, EVAL_STREAM_TRAIN)
    val_e = _eval_subset(val_t, spec.reduction, seed, EVAL_STREAM_VAL) if len(val_idx) else train_e

    def eval_loss(p, targets):
        value = _eval_loss(p, targets, net=net, spec=spec)
        if tube is not None:
            value = value + _eval_tube(p, eval_points, net=net, tube=tube)
        return value

    hist_steps, hist_train, hist_val = [], [], []

    def record(step, p):
        tr = float(eval_loss(p, train_e))
        va = float(eval_loss(p, val_e))
        hist_steps.append(step)
        hist_train.append(tr)
        hist_val.append(va)
        return va

    best_val = record(0, params)
    best_params, best_step = params, 0
    step = 0
    stop_reason = "steps"
    disable = (not progress) or not _stderr_is_tty()
    with tqdm(total=settings.steps, desc=f"{settings.method}", disable=disable) as bar:
        while step < settings.steps:
            n = min(settings.eval_every, settings.steps - step)
            params, opt_state = run_chunk(params, opt_state, step, n)
            step += n
            bar.update(n)
            va = record(step, params)
            if not np.isfinite(va):
                stop_reason = "non-finite loss"
                break
            if va < best_val:
                best_val, best_params, best_step = va, params, step
            bar.set_postfix(train=f"{hist_train[-1]:.3e}", val=f"{va:.3e}", best=best_step)
            if step - best_step >= settings.patience and step < settings.steps:
                stop_reason = "patience"
                break
    linear = None
    if settings.skip:
        best_params, K = best_params
        linear = np.asarray(K, dtype=float)
    mlp = mlp_from_params(best_params, settings.activation, settings.output_activation)
    return TrainResult(
        mlp=mlp,
        linear=linear,
        method=settings.method,
        order=spec.order,
        history=TrainHistory(tuple(hist_steps), tuple(hist_train), tuple(hist_val)),
        best_step=best_step,
        best_val_loss=float(best_val),
        stop_reason=stop_reason,
        wall_time_s=time.perf_counter() - t_start,
        settings=settings,
        train_index=tuple(int(i) for i in train_idx),
        val_index=tuple(int(i) for i in val_idx),
    )


@dataclass(frozen=True)
class _Net:
    """Static description of the network (hashable, for jit caching): activations, whether a
    linear term ``K x`` sits beside it (``params = (layers, K)``), and the Lipschitz budget."""

    activation: str
    output_activation: str | None
    skip: bool = False
    budget: float = float("inf")

    def policy(self, params) -> Callable:
        if self.skip:
            layers, K = params
            return lambda x: (
                apply_params(layers, x, self.activation, self.output_activation, xp=jnp) + x @ K.T
            )
        return lambda x: apply_params(params, x, self.activation, self.output_activation, xp=jnp)

    def project(self, params):
        """Scale each layer to spectral norm ``<= budget^(1/L)`` (identity for ``inf``)."""
        if not np.isfinite(self.budget):
            return params
        layers, K = params if self.skip else (params, None)
        b = self.budget ** (1.0 / len(layers))
        out = []
        for w, bias in layers:
            s = jnp.linalg.norm(w, 2)
            out.append((w * jnp.minimum(1.0, b / jnp.maximum(s, 1e-300)), bias))
        return (out, K) if self.skip else out


@dataclass(frozen=True)
class _Tube:
    """Static description of the tube's matching term (hashable, for jit caching): its weight,
    points per step, the expert and its Jacobian ``x -> (m, n)``, and the norm floor."""

    weight: float
    count: int
    expert: Callable
    expert_jac: Callable
    floor: float

    def loss(self, policy: Callable, key, box):
        """``weight * mean_j (||policy(y_j) - pi*(y_j)|| + ||d policy(y_j) - d pi*(y_j)||_F)``
        at ``count`` points drawn from ``key`` uniformly on ``box`` ``(2, n)``."""
        pts = draw_tube_points(key, box[0], box[1], self.count)
        return self.weight * tube_loss(policy, self.expert, self.expert_jac, pts, self.floor)


#: stream of the tube's draws, folded into the seed's key (the mini-batches use the step itself)
TUBE_STREAM = 0x7B0E
#: stream and count of the fixed tube points added to the recorded (early-stopping) losses
TUBE_EVAL_STREAM = 0x7B0F
TUBE_EVAL_POINTS = 1024


#: mini-batches from a pool of at most this many states (or trajectories) are drawn without
#: replacement, as in earlier versions (the same batches bit for bit); larger pools with
#: replacement (:func:`_draw_with_replacement`)
PERMUTE_MAX = 16384
#: at most this many states enter each recorded (training / held-out) loss of the mean reduction
EVAL_STATES = 16384
#: streams of the fixed evaluation subsets, with the seed in numpy's SeedSequence
EVAL_STREAM_TRAIN = 0xE7A1
EVAL_STREAM_VAL = 0xE7A2


def _draw_with_replacement(pool_size: int) -> bool:
    """Whether the mini-batches of a pool of ``pool_size`` entries are drawn with replacement:
    above :data:`PERMUTE_MAX`, where sorting a permutation of the pool every step would cost
    more than the step itself (46 s against 3.4 s for 300 steps on a 320k-state pool, issue 24).
    Up to it the batches are those of earlier versions (no repeated entry within a batch, and the
    results measured with them stand); either draw is uniform per entry, so the loss estimated is
    the same (docs/math/tasil.md section 5)."""
    return pool_size > PERMUTE_MAX


def _eval_subset(targets: Targets, reduction: str, seed: int, stream: int) -> Targets:
    """The targets a recorded loss is evaluated on: for the ``"mean"`` reduction with more than
    :data:`EVAL_STATES` states, that many states drawn once without replacement from
    ``numpy.random.default_rng((seed, stream))`` (sorted; shape ``(1, EVAL_STATES, ...)``), else
    ``targets`` itself.

    The recorded loss is then the mean over a fixed uniform sample of the split's states: an
    unbiased estimate of the full mean, the same function of the parameters at every
    evaluation, so that early stopping compares like with like, at a cost independent of the
    number of samples per trajectory. The ``"max"`` reduction needs every state of a trajectory
    for its per-trajectory maxima and always uses all of them.
    """
    n_traj, n_time = targets.states.shape[:2]
    if reduction != "mean" or n_traj * n_time <= EVAL_STATES:
        return targets
    rng = np.random.default_rng((seed, stream))
    idx = np.sort(rng.choice(n_traj * n_time, EVAL_STATES, replace=False))
    return targets.flat().map_arrays(lambda a: a[:, jnp.asarray(idx)])


def _skip_init(layers, states, actions):
    """``(layers, K)``: ``K`` from the least-squares fit ``u ~ K x + c`` of the training pairs
    (``c`` added to the output bias); the network starts at its seeded initialisation, so the
    policy starts as that fit plus the network's initial output."""
    X = np.asarray(states, dtype=float).reshape(-1, np.shape(states)[-1])
    U = np.asarray(actions, dtype=float).reshape(-1, np.shape(actions)[-1])
    A = np.hstack([X, np.ones((X.shape[0], 1))])
    coef = np.linalg.lstsq(A, U, rcond=None)[0]  # (n + 1, m)
    K, c = coef[:-1].T, coef[-1]
    w_last, b_last = layers[-1]
    return [*layers[:-1], (w_last, b_last + jnp.asarray(c))], jnp.asarray(K)


def _adam(lr, total_steps, schedule: str) -> optax.GradientTransformation:
    """Adam whose step size is ``lr`` (constant) or ``lr (1 + cos(pi min(i/total, 1))) / 2``
    (cosine decay to 0, as ``optax.cosine_decay_schedule``). ``lr`` and ``total_steps`` may be
    traced, so one compiled training step serves every learning rate and budget."""

    def step_size(count):
        if schedule == "constant":
            return lr
        frac = jnp.minimum(count / total_steps, 1.0)
        return lr * 0.5 * (1.0 + jnp.cos(jnp.pi * frac))

    return optax.adam(step_size)


@partial(jax.jit, static_argnames=("net", "tube"))
def _eval_tube(params, points, *, net: _Net, tube: _Tube):
    return tube.weight * tube_loss(
        net.policy(params), tube.expert, tube.expert_jac, points, tube.floor
    )


@partial(jax.jit, static_argnames=("net", "spec"))
def _eval_loss(params, targets: Targets, *, net: _Net, spec):
    return imitation_loss(net.policy(params), targets, spec)


@partial(
    jax.jit,
    static_argnames=("net", "spec", "schedule", "n_steps", "batch_size", "axis", "tube", "replace"),
)
def _run_chunk(
    params, opt_state, key, step0, pool: Targets, lr_args: tuple[jax.Array, jax.Array],
    tube_box, *, net, spec, schedule, n_steps, batch_size, axis, tube: _Tube | None = None,
    replace: bool = True,
):  # fmt: skip
    """``n_steps`` Adam steps on seeded mini-batches of ``batch_size`` indices drawn uniformly
    from ``pool`` along ``axis`` (states for the mean reduction, trajectories for the max
    reduction), with replacement when ``replace`` (:func:`_draw_with_replacement`), without
    otherwise; with ``tube``, plus its matching term at points drawn on ``tube_box`` ``(2, n)``.

    Drawing with replacement costs ``O(batch)`` per step whatever the pool's size; drawing
    without replacement sorts a permutation of the whole pool every step (320k states at 4000
    samples per trajectory). The loss estimated is the same: each drawn index is uniform on the
    pool, so the expected mini-batch loss is the full loss of eq. (LossTaSIL) in either
    reduction (docs/math/tasil.md section 5). The key of step ``i`` is ``fold_in(key, i)``: the
    same seed gives the same batches."""
    opt = _adam(*lr_args, schedule)
    pool_size = pool.states.shape[axis]
    tube_key = jax.random.fold_in(key, TUBE_STREAM)

    def loss_of(p, targets, step):
        value = imitation_loss(net.policy(p), targets, spec)
        if tube is not None:
            value = value + tube.loss(net.policy(p), jax.random.fold_in(tube_key, step), tube_box)
        return value

    def body(carry, step):
        p, s = carry
        step_key = jax.random.fold_in(key, step)
        if replace:  # O(batch) per step
            idx = jax.random.randint(step_key, (batch_size,), 0, pool_size)
        else:  # sorts a permutation of the whole pool
            idx = jax.random.choice(step_key, pool_size, (batch_size,), replace=False)
        value, grads = jax.value_and_grad(loss_of)(p, _take_axis(pool, idx, axis), step)
        updates, s = opt.update(grads, s, p)
        return (net.project(optax.apply_updates(p, updates)), s), value

    (params, opt_state), _ = jax.lax.scan(body, (params, opt_state), step0 + jnp.arange(n_steps))
    return params, opt_state


def _stderr_is_tty() -> bool:
    try:
        return sys.stderr.isatty()
    except (AttributeError, ValueError):
        return False


def _split(n_traj: int, val_fraction: float, rng: np.random.Generator):
    """Seeded split of trajectory indices into (train, validation)."""
    perm = rng.permutation(n_traj)
    n_val = int(round(val_fraction * n_traj))
    if val_fraction > 0 and n_traj >= 2:
        n_val = min(max(n_val, 1), n_traj - 1)
    else:
        n_val = 0
    return np.sort(perm[n_val:]), np.sort(perm[:n_val])


def _take_axis(targets: Targets, idx, axis: int) -> Targets:
    return targets.map_arrays(lambda a: jnp.take(a, idx, axis=axis))


def evaluate_gap(
    field: Callable,
    expert: Callable,
    policy_apply: Callable,
    x0s: np.ndarray,
    T: float,
    k: int,
    substeps: int = DEFAULT_SUBSTEPS,
) -> np.ndarray:
    """Per-trajectory imitation gap ``max_{t in grid} ||x_hat_t - x*_t||_2``.

    Rolls out the expert closed loop ``x*' = field(t, x*, expert(x*))`` and the learner closed
    loop ``x_hat' = field(t, x_hat, policy_apply(x_hat))`` from the same initial states with the
    same fixed-step RK4 integrator, sampled on ``{0, T/k, ..., T}``; this is the ``delta_err`` of
    the TaSIL reference code and the policy imitation gap of DRIP's decomposition on the nominal
    model. The max runs over the sample grid only, so it can underestimate the continuous-time
    supremum between samples.

    Returns
    -------
    numpy.ndarray
        ``(N,)`` gaps; ``inf`` for a learner trajectory that diverges (NaN/inf states).
    """
    x_star = simulate_closed_loop(field, expert, x0s, T, k, substeps)
    x_hat = simulate_closed_loop(field, policy_apply, x0s, T, k, substeps)
    with np.errstate(invalid="ignore", over="ignore"):
        gaps = np.max(np.linalg.norm(x_hat - x_star, axis=-1), axis=1)
    finite = np.all(np.isfinite(x_hat), axis=(1, 2))
    return np.where(finite, gaps, np.inf)
