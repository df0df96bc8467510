"""The jitted kernel: one batch of paths of every scenario, a block of recorded times per call.

Discretisation: Euler-Maruyama with step ``dt`` for the SDEs and explicit Euler with the SAME
``dt`` for the nominal ODEs (:mod:`drip_cert.sim.engine` explains why). Time-major: one flat
``lax.scan`` over the ``records_per_call * record_every`` steps of a call with the whole batch
in the carry, and the recorded states written into a buffer carried along (slot
``(j - j0) // record_every`` after step ``j``; the last write into a slot is the state at its
recorded time). A nested scan over the recorded times cost up to 73 ns per path-step of ~257
(issue 26). The model's weights are compile-time constants of the program (closed over at
trace time). A batch is simulated by one
call of :meth:`CompiledChunk.start` (initial states, codes and L1-DRAC states) and
``n_calls`` calls of :meth:`CompiledChunk.advance`, each returning its block of recorded states;
between two calls the host may report progress. The carry stays on the device, and every call
runs the same step on the same numbers, so the split into calls changes no bit.

Arithmetic: float64, or float32 end to end with ``SimConfig(dtype="float32")``: every model
function re-evaluated in float32 (:func:`drip_cert.sim.precision.in_dtype`), float32 normals
from the same counters, float32 states and L1-DRAC; the records are float32 and the host
accumulates them in float64. The float32 step writes its per-path small products (the noise
term, ``Theta lam_hat``, ``g u``) and row sums (the guard, small sums inside the model) as
multiply-adds over the batch and draws its normals column by column (:func:`_diffuse`,
:func:`_times_g`, :func:`_guard`): XLA's CPU backend vectorizes a ``(B, 4)`` loop, a batched
4x4 product or a 4-column reduction across the 4 columns only, as many lanes as in float64, so
in those forms float32 was no cheaper (issue 26: kernel 195 -> 155 CPU ns per path-step, 2.1x ->
2.6x float64 on one core). The float64 step keeps its forms and its numbers.

Randomness: path ``i`` draws its initial states from ``fold_in(k_x0, i)`` (and
``fold_in(k_x0bar, i)``) and its Brownian increments from the counter-based
:func:`drip_cert.sim.noise.normals` under ``k_bm``, with ``k_* = fold_in(PRNGKey(seed), const)``.
"""

from __future__ import annotations

import dataclasses
import math
from collections.abc import Callable
from dataclasses import dataclass
from functools import partial
from typing import Any

import numpy as np
from jax import export as jexport

from drip_cert._jax import jax, jnp
from drip_cert.control.l1drac import L1State, l1_init, l1_step
from drip_cert.errors import SpecError
from drip_cert.model.numeric import SimModel
from drip_cert.sim.config import STATUS_CAP, STATUS_NONFINITE, STATUS_OK, SimConfig
from drip_cert.sim.noise import normal_columns, normals
from drip_cert.sim.precision import in_dtype, lower_precision

__all__ = ["ChunkKernel", "CompiledChunk", "ExportedChunk", "build_chunk_fn"]

MIN_CALL_PATH_STEPS = 1 << 18
"""Least work of one kernel call, in path-steps of all scenarios together. A call costs up to
about 0.25 ms of dispatch and synchronisation (measured on the 4-D benchmark system, 2000 paths,
100 calls against 1); 2^18 path-steps take about 60 ms at the engine's 4.4e6 path-steps/s on
that system, so the calls cost under 0.5 % of a run while a long chunk still reports its
progress many times."""

_TRUE_SCENARIOS = ("learned_true", "learned_l1_true")
_NOISY_SCENARIOS = (*_TRUE_SCENARIOS, "nominal_sde")  #: driven by the Brownian path

# the step counter of L1-DRAC depends on time only: one copy for the whole batch
# (Theta_ad is kept per path: Theta lam_hat is then a batched matrix-vector product, which XLA
# computes path by path whatever the batch size; shared, it became one (m, n) x (n, B) product
# whose float32 rounding depended on B through XLA's choice of kernel: 1 ulp, chunk-dependent.
# It costs ~10-20 CPU ns per path-step, measured in benchmarks/mc_throughput.py's units)
_SHARED: L1State[int | None] = L1State(x_hat=0, eta=0, lam_hat=0, theta=0, step=None)
# float32: Theta_ad shared too. l1_step then writes Theta lam_hat as n elementwise products per
# path (drip_cert.control.l1drac._matvec): no matrix product, so no rounding that depends on B,
# and no (B, m, n) copy of Theta to select and read every step (~10 CPU ns per path-step)
_SHARED32: L1State[int | None] = L1State(x_hat=0, eta=0, lam_hat=0, theta=None, step=None)


def _l1_axes(ftype) -> L1State[int | None]:
    """The batch axes of the L1-DRAC state in ``ftype``'s engine."""
    return _SHARED32 if ftype == jnp.float32 else _SHARED


def build_chunk_fn(
    model: SimModel,
    config: SimConfig,
    x0_sampler: Callable,
    x0_bar_sampler: Callable | None = None,
) -> ChunkKernel:
    """The kernel of ``config``'s scenarios on ``model``: ``idx (B,) uint32 -> (records, codes)``.

    ``records`` has shape ``(n_records, n_scenarios, B, n)`` (states on the recorded grid, frozen
    after divergence) and ``codes`` ``(n_scenarios, B)`` (status codes). The seed is a traced
    argument and the settings that do not shape the simulation are normalised away, so runs that
    differ only in them reuse one compiled program.

    Raises
    ------
    SpecError
        When a scenario needs the learned policy the model lacks, or ``n_steps * d`` overflows
        the 32-bit noise counter.
    """
    if model.learned is None and any(s != "expert_nominal" for s in config.scenarios):
        raise SpecError(
            "the model has no learned policy; simulate only 'expert_nominal' or give one",
            field="SimModel.learned",
        )
    if config.n_steps * model.d >= 2**32:
        raise SpecError(
            f"n_steps * d = {config.n_steps * model.d} exceeds the 32-bit noise counter; "
            "shorten T or enlarge dt",
            field="SimConfig.dt",
        )
    static = dataclasses.replace(
        config,
        seed=0,
        n_paths=1,
        chunk_size=1,
        n_sample_paths=0,
        p_max=1,
        kappas=(),
        w2_times=(),
        w2_points=1,
        ci_level=0.95,
    )
    return ChunkKernel(
        key=jax.random.PRNGKey(config.seed),
        model=_ByIdentity(model),
        config=static,
        samplers=(_ByIdentity(x0_sampler), _ByIdentity(x0_bar_sampler)),
    )


@dataclass(frozen=True, eq=False)
class ChunkKernel:
    """The kernel of one run's settings, not yet compiled for a batch size.

    Attributes
    ----------
    key
        ``PRNGKey(seed)``, a traced argument of every call.
    model, config, samplers
        Static arguments of the jitted functions: the model, the config with the settings that do
        not shape the simulation normalised away, and the two initial samplers (the model and
        the samplers wrapped so that they compare by identity).
    """

    key: Any
    model: _ByIdentity
    config: SimConfig
    samplers: tuple[_ByIdentity, _ByIdentity]

    def records_per_call(self, batch: int) -> int:
        """Recorded times per :meth:`CompiledChunk.advance` call for ``batch`` paths.

        The smallest divisor of ``n_records - 1`` whose calls do at least
        :data:`MIN_CALL_PATH_STEPS` path-steps (all of them in one call when none does): every
        call has the same length, so one program serves them all.
        """
        cfg = self.config
        n_out = cfg.n_records - 1
        per_record = cfg.record_every * batch * len(cfg.scenarios)
        for k in range(1, n_out + 1):
            if n_out % k == 0 and k * per_record >= MIN_CALL_PATH_STEPS:
                return k
        return n_out

    def compile(self, batch: int) -> CompiledChunk:
        """Compile both programs for batches of ``batch`` paths (ahead of time)."""
        k = self.records_per_call(batch)
        idx = jax.ShapeDtypeStruct((batch,), jnp.uint32)
        start = _start_jit.lower(
            self.key, idx, model=self.model, config=self.config, samplers=self.samplers
        ).compile()
        carry = start.out_info[0]  # shapes and dtypes of the carry
        r0 = jax.ShapeDtypeStruct((), jnp.uint32)
        advance = _advance_jit.lower(
            self.key, carry, r0, model=self.model, config=self.config, records_per_call=k
        ).compile()
        return CompiledChunk(self.key, start, advance, k, (self.config.n_records - 1) // k)

    def export(self, batch: int) -> ExportedChunk:
        """Both programs for batches of ``batch`` paths as serialized StableHLO (``jax.export``).

        What a remote worker needs to simulate any chunk of this run without the model's Python
        code: the programs are lowered here, from the same functions as :meth:`compile`, and
        compiled where they run (:meth:`ExportedChunk.load`). The carry crosses the boundary as
        its flat list of arrays.
        """
        k = self.records_per_call(batch)
        start = partial(_start_impl, model=self.model, config=self.config, samplers=self.samplers)
        advance = partial(_advance_impl, model=self.model, config=self.config, records_per_call=k)
        key = jax.ShapeDtypeStruct(self.key.shape, self.key.dtype)
        idx = jax.ShapeDtypeStruct((batch,), jnp.uint32)
        r0 = jax.ShapeDtypeStruct((), jnp.uint32)
        carry_shape, _ = jax.eval_shape(start, key, idx)
        leaves, treedef = jax.tree_util.tree_flatten(carry_shape)

        def start_flat(key, idx):
            carry, rec0 = start(key, idx)
            return jax.tree_util.tree_leaves(carry), rec0

        def advance_flat(key, flat, r0):
            carry, recs = advance(key, jax.tree_util.tree_unflatten(treedef, flat), r0)
            return jax.tree_util.tree_leaves(carry), recs

        s = len(self.config.scenarios)
        # the carry is (states, codes, L1 states, idx): its leaves s..2s-1 are the codes
        assert all(leaf.dtype == jnp.int8 for leaf in leaves[s : 2 * s])
        return ExportedChunk(
            key=np.asarray(self.key),
            start=bytes(jexport.export(jax.jit(start_flat))(key, idx).serialize()),
            advance=bytes(jexport.export(jax.jit(advance_flat))(key, leaves, r0).serialize()),
            batch=batch,
            n_scenarios=s,
            records_per_call=k,
            n_calls=(self.config.n_records - 1) // k,
        )

    def __call__(self, idx) -> tuple[jax.Array, jax.Array]:
        """Compile for ``idx.shape[0]`` paths and simulate them (see :func:`build_chunk_fn`)."""
        recs, codes = self.compile(idx.shape[0])(idx)
        return jnp.concatenate(recs, axis=0), codes


@dataclass(frozen=True, eq=False)
class CompiledChunk:
    """The kernel compiled for one batch size.

    Attributes
    ----------
    key
        ``PRNGKey(seed)``.
    start
        ``(key, idx) -> (carry, records0)``: initial states (recorded at ``t = 0``), codes and
        L1-DRAC states.
    advance
        ``(key, carry, r0) -> (carry, records)``: the states at the ``records_per_call`` recorded
        times after record ``r0``.
    records_per_call, n_calls
        Their product is ``n_records - 1``.
    """

    key: Any
    start: Callable
    advance: Callable
    records_per_call: int
    n_calls: int

    def __call__(
        self, idx, on_block: Callable[[int], None] | None = None
    ) -> tuple[list[jax.Array], jax.Array]:
        """Simulate the paths ``idx``; return the record blocks (in time order) and the codes.

        ``on_block(k)`` is called after each finished call with its ``k`` recorded times. One
        call is dispatched ahead of the one waited for, so the device never idles on the host.
        """
        carry, rec0 = self.start(self.key, idx)
        blocks = [rec0]
        for c in range(self.n_calls):
            carry, recs = self.advance(self.key, carry, np.uint32(c * self.records_per_call))
            if on_block is not None and c:
                jax.block_until_ready(blocks[-1])  # the previous call, this one queued behind it
                on_block(self.records_per_call)
            blocks.append(recs)
        if on_block is not None:
            jax.block_until_ready(blocks[-1])
            on_block(self.records_per_call)
        return blocks, jnp.stack(carry[1])


@dataclass(frozen=True)
class ExportedChunk:
    """The kernel of one run for one batch size, serialized (:meth:`ChunkKernel.export`).

    Picklable plain data: the key, the two programs as ``jax.export`` bytes and the call
    schedule. :meth:`load` deserializes and compiles them for this machine's default device.
    """

    key: np.ndarray
    start: bytes
    advance: bytes
    batch: int
    n_scenarios: int
    records_per_call: int
    n_calls: int

    def load(self) -> Callable:
        """``idx (batch,) uint32 -> (record blocks in time order, codes (S, batch))``."""
        start = jexport.deserialize(bytearray(self.start))
        advance = jexport.deserialize(bytearray(self.advance))
        start_c = jax.jit(start.call).lower(*start.in_avals).compile()
        advance_c = (
            jax.jit(lambda k, *rest: advance.call(k, list(rest[:-1]), rest[-1]))
            .lower(*advance.in_avals)
            .compile()
        )
        key = jnp.asarray(self.key)
        s = self.n_scenarios

        def run(idx) -> tuple[list[jax.Array], jax.Array]:
            flat, rec0 = start_c(key, idx)
            blocks = [rec0]
            for c in range(self.n_calls):
                flat, recs = advance_c(key, *flat, np.uint32(c * self.records_per_call))
                blocks.append(recs)
            return blocks, jnp.stack(flat[s : 2 * s])

        return run


class _ByIdentity:
    """Static-argument wrapper hashed and compared by the identity of what it holds.

    jit caches compiled programs by static arguments; user callables need not be hashable,
    and the same model object must hit the cache.
    """

    __slots__ = ("obj",)

    def __init__(self, obj) -> None:
        self.obj = obj

    def __hash__(self) -> int:
        return id(self.obj)

    def __eq__(self, other) -> bool:
        return isinstance(other, _ByIdentity) and other.obj is self.obj


def _guard(x_old, x_new, code, inv_cap: float):
    """Freeze the paths whose new state is non-finite or beyond the cap; update their codes.

    In float32 the two row reductions are written column by column (XLA's CPU reduction of a
    ``(B, 4)`` array over its 4 columns cost ~10 CPU ns per path-step in float32, more than in
    float64; the column form ~1 ns); float64 keeps ``jnp.all`` / ``jnp.sum``.
    """
    scaled = x_new * inv_cap  # ||x|| > cap without overflowing the square
    if x_new.dtype == jnp.float32:
        cols = [x_new[:, k] for k in range(x_new.shape[-1])]
        finite = jnp.isfinite(cols[0])
        sq = scaled[:, 0] * scaled[:, 0]
        for k in range(1, len(cols)):
            finite = finite & jnp.isfinite(cols[k])
            sq = sq + scaled[:, k] * scaled[:, k]
        nonfinite, capped = ~finite, sq > 1.0
    else:
        nonfinite = ~jnp.all(jnp.isfinite(x_new), axis=-1)
        capped = jnp.sum(scaled * scaled, axis=-1) > 1.0
    new_code = jnp.where(
        code != STATUS_OK,
        code,
        jnp.where(nonfinite, STATUS_NONFINITE, jnp.where(capped, STATUS_CAP, STATUS_OK)),
    )
    frozen = new_code != STATUS_OK
    return jnp.where(frozen[:, None], x_old, x_new), new_code.astype(code.dtype)


def _start_impl(key, idx, *, model, config, samplers):
    """Initial carry ``(states, codes, L1 states, idx)`` and the records at ``t = 0``."""
    model = model.obj
    x0_sampler, x0_bar_sampler = (w.obj for w in samplers)
    scen = config.scenarios
    inv_cap = 1.0 / config.divergence_cap
    k_x0 = jax.random.fold_in(key, 0)
    k_x0bar = jax.random.fold_in(key, 1)
    x0 = jax.vmap(lambda i: x0_sampler(jax.random.fold_in(k_x0, i)))(idx)
    if x0_bar_sampler is not None:
        x0b = jax.vmap(lambda i: x0_bar_sampler(jax.random.fold_in(k_x0bar, i)))(idx)
    else:
        x0b = x0
    ftype = jnp.dtype(config.dtype)
    x0 = x0.astype(jnp.float64).astype(ftype)
    x0b = x0b.astype(jnp.float64).astype(ftype)
    xs = tuple(x0b if s in _TRUE_SCENARIOS else x0 for s in scen)
    zero = jnp.zeros(idx.shape, dtype=jnp.int8)
    # a non-finite or too large initial state is a divergence at t = 0
    codes = tuple(_guard(x, x, zero, inv_cap)[1] for x in xs)
    l1s = None
    if "learned_l1_true" in scen:
        l1s = jax.vmap(l1_init, in_axes=(0, None), out_axes=_l1_axes(ftype))(
            x0b, model.theta_ad(jnp.float64(0.0))
        )
        l1s = jax.tree_util.tree_map(
            lambda v: v.astype(ftype) if jnp.issubdtype(v.dtype, jnp.floating) else v, l1s
        )
    return (xs, codes, l1s, idx), jnp.stack(xs)[None]


def _diffuse(sig, dw):
    """The noise term ``sig dW`` of every path: ``sig`` ``(B, n, d)``, ``dw`` ``(B, d)``.

    float64: one batched matrix-vector product (``einsum``). float32: ``dw`` comes as its ``d``
    columns (:func:`drip_cert.sim.noise.normal_columns`) and the product is written as ``d``
    elementwise multiply-adds over the batch; XLA's CPU batched product of 4x4 blocks cost the
    same in float32 as in float64 (~6 and ~2.4 CPU ns per path-step), the multiply-adds ~1.2 ns.
    The sum runs over ``k = 0 .. d-1`` in order, path by path, so no number depends on the batch.
    """
    if isinstance(dw, tuple):
        acc = sig[:, :, 0] * dw[0][:, None]
        for k in range(1, len(dw)):
            acc = acc + sig[:, :, k] * dw[k][:, None]
        return acc
    return jnp.einsum("bnd,bd->bn", sig, dw)


def _times_g(v, g_t):
    """``g(t) v`` of every path: ``v`` ``(B, m)``, ``g_t`` ``(n, m)`` shared; ``(B, n)``.

    float64: ``v @ g_t.T``. float32: the ``m`` column products summed in order ``k = 0 .. m-1``
    (elementwise over the paths; XLA's CPU product with a 4-wide contraction cost ~3-9 CPU ns per
    path-step in float32, about what it costs in float64).
    """
    if v.dtype != jnp.float32:
        return v @ g_t.T
    acc = v[:, 0:1] * g_t[:, 0]
    for k in range(1, v.shape[-1]):
        acc = acc + v[:, k : k + 1] * g_t[:, k]
    return acc


@dataclass(frozen=True)
class _Fields:
    """The model's functions in the run's arithmetic (float64, or float32 end to end)."""

    f: Callable
    g: Callable
    p: Callable
    lam_mu: Callable
    lam_sigma: Callable
    expert: Callable
    learned: Callable | None
    theta_ad: Callable


def _fields(model: SimModel, config: SimConfig) -> _Fields:
    """``model``'s functions for ``config``: as they are in float64 (the learned policy in
    float32 with ``policy_dtype="float32"``), or all of them re-evaluated in float32 with
    ``dtype="float32"`` (:func:`drip_cert.sim.precision.in_dtype`: constants, weights, inputs
    and outputs in float32)."""
    learned = model.learned
    if config.dtype == "float64":
        if learned is not None and config.policy_dtype != "float64":
            # opt-in: pi_IL's arithmetic in float32, its input and output float64
            learned = lower_precision(learned, model.n, jnp.dtype(config.policy_dtype))
        return _Fields(
            model.f,
            model.g,
            model.p,
            model.lam_mu,
            model.lam_sigma,
            model.expert,
            learned,
            model.theta_ad,
        )
    lo = jnp.dtype(config.dtype)
    t = jnp.zeros((), jnp.float64)
    x = jnp.zeros((model.n,), jnp.float64)
    return _Fields(
        f=in_dtype(model.f, (t, x), lo),
        g=in_dtype(model.g, (t, x), lo),
        p=in_dtype(model.p, (t, x), lo),
        lam_mu=in_dtype(model.lam_mu, (t, x), lo),
        lam_sigma=in_dtype(model.lam_sigma, (t, x), lo),
        expert=in_dtype(model.expert, (x,), lo),
        learned=None if learned is None else in_dtype(learned, (x,), lo),
        theta_ad=in_dtype(model.theta_ad, (t,), lo),
    )


def _advance_impl(key, carry, r0, *, model, config, records_per_call):
    """Records ``r0 + 1 .. r0 + records_per_call``: ``(carry, (records_per_call, S, B, n))``."""
    sim_model = model.obj
    model = _fields(sim_model, config)
    ftype = jnp.dtype(config.dtype)
    scen = config.scenarios
    dt = config.dt
    sqrt_dt = math.sqrt(dt)
    inv_cap = 1.0 / config.divergence_cap
    stride = config.record_every
    l1p = config.l1
    has_noise = any(s in _NOISY_SCENARIOS for s in scen)
    d = sim_model.d
    k_bm = jax.random.fold_in(key, 2)

    f_b = jax.vmap(model.f, in_axes=(None, 0))
    lam_mu_b = jax.vmap(model.lam_mu, in_axes=(None, 0))
    diff_b = jax.vmap(lambda t, x: model.p(t, x) + model.lam_sigma(t, x), in_axes=(None, 0))
    known_diff_b = jax.vmap(model.p, in_axes=(None, 0))
    expert_b = jax.vmap(model.expert)
    learned = model.learned
    learned_b = jax.vmap(learned) if learned is not None else None
    l1_b = (
        jax.vmap(
            lambda st, x, fk, g_t, th: l1_step(l1p, st, x, fk, g_t, th),
            in_axes=(_l1_axes(ftype), 0, 0, None, 0 if ftype != jnp.float32 else None),
            out_axes=(0, _l1_axes(ftype)),
        )
        if l1p is not None
        else None
    )

    g_b = jax.vmap(model.g, in_axes=(None, 0))

    def known_drift(t, x, g_t, policy_b):
        # f(t,x) + g(t, x) pi(x), batched: (B, n); g_t is g(t) shared by every path, or None
        # when g depends on the state (then evaluated per path)
        if g_t is None:
            return f_b(t, x) + jnp.einsum("bnm,bm->bn", g_b(t, x), policy_b(x))
        return f_b(t, x) + _times_g(policy_b(x), g_t)

    def step(carry, j):
        xs, codes, l1s, idx, buf = carry
        t = (j.astype(jnp.float64) * dt).astype(ftype)
        # g(t) shared by every path, or None when g depends on the state (then per path)
        g_t = None if sim_model.g_state else model.g(t, jnp.zeros(sim_model.n, ftype))
        new_xs, new_codes = [], []
        dw = None
        if has_noise and ftype == jnp.float32:  # the d columns, each (B,): see _diffuse
            dw = tuple(sqrt_dt * z for z in normal_columns(k_bm, idx, j, d, ftype))
        elif has_noise:
            dw = sqrt_dt * normals(k_bm, idx, j, d, ftype)
        for i, s in enumerate(scen):
            x = xs[i]
            if s == "expert_nominal":
                x_new = x + dt * known_drift(t, x, g_t, expert_b)
            elif s == "learned_nominal":
                x_new = x + dt * known_drift(t, x, g_t, learned_b)
            elif s == "nominal_sde":  # L1-DRAC (4b): the known diffusion only, same dW
                noise = _diffuse(known_diff_b(t, x), dw)
                x_new = x + dt * known_drift(t, x, g_t, learned_b) + noise
            elif s == "learned_true":
                drift = known_drift(t, x, g_t, learned_b) + lam_mu_b(t, x)
                noise = _diffuse(diff_b(t, x), dw)
                x_new = x + dt * drift + noise
            else:  # learned_l1_true
                fk = known_drift(t, x, g_t, learned_b)
                th = model.theta_ad(t)
                if ftype != jnp.float32:
                    th = jnp.broadcast_to(th, (x.shape[0], *th.shape))
                u, l1s = l1_b(l1s, x, fk, g_t, th)
                drift = fk + _times_g(u, g_t) + lam_mu_b(t, x)
                noise = _diffuse(diff_b(t, x), dw)
                x_new = x + dt * drift + noise
            x_new, c_new = _guard(x, x_new, codes[i], inv_cap)
            new_xs.append(x_new)
            new_codes.append(c_new)
        # the state after step j goes to slot (j - j0) // stride; the last write into a slot is
        # the state at its recorded time (an unconditional write: cheaper than a branch)
        k = ((j - j0) // jnp.uint32(stride)).astype(jnp.int32)
        zero = jnp.int32(0)
        buf = jax.lax.dynamic_update_slice(buf, jnp.stack(new_xs)[None], (k, zero, zero, zero))
        return (tuple(new_xs), tuple(new_codes), l1s, idx, buf), None

    xs0 = carry[0]
    buf0 = jnp.zeros((records_per_call, len(xs0), *xs0[0].shape), dtype=xs0[0].dtype)
    j0 = r0 * jnp.uint32(stride)
    js = j0 + jnp.arange(records_per_call * stride, dtype=jnp.uint32)
    (xs, codes, l1s, idx, buf), _ = jax.lax.scan(step, (*carry, buf0), js)
    return (xs, codes, l1s, idx), buf


_start_jit = jax.jit(_start_impl, static_argnames=("model", "config", "samplers"))
_advance_jit = jax.jit(_advance_impl, static_argnames=("model", "config", "records_per_call"))
