"""Monte-Carlo engine: the four processes of the DRIP paper, simulated pathwise in one pass.

Scenarios (DRIP Definition "Systems", eqs. NominalProcesses and L1DRACProcess):

``expert_nominal``   ``dx*  = (f(t,x*) + g(t) pi*(x*)) dt``,           ``x*_0 = xi ~ D``
``learned_nominal``  ``dx'  = (f(t,x') + g(t) pi_IL(x')) dt``,         ``x'_0 = xi``
``learned_true``     ``dX   = (f + g pi_IL + Lambda_mu)(t,X) dt + (p + Lambda_sigma)(t,X) dW``
``learned_l1_true``  as ``learned_true`` with ``pi_ad = pi_IL + U_L1`` (L1-DRAC (15)).
``nominal_sde``      ``dX* = (f + g pi_IL)(t,X*) dt + p(t,X*) dW``,   ``X*_0 = xi`` (only on
                     request: L1-DRAC's nominal process (4b) when the known diffusion ``p != 0``)

Discretisation: Euler-Maruyama with step ``dt`` for the SDEs and explicit Euler with the SAME
``dt`` for the nominal ODEs. Using one scheme for all four makes the gaps measure the difference
of the processes, not of integrators: with ``pi_IL = pi*`` and no uncertainty every gap is
exactly zero. Euler is first order for the ODEs; choose ``dt`` accordingly.

Couplings. Identity coupling of the initial laws by default: ``X_0 = x'_0 = x*_0 = xi`` (the
DRIP paper's ``D = D_bar``). With ``x0_bar_sampler`` the true processes start from
``xi_bar ~ D_bar`` drawn INDEPENDENTLY of ``xi`` (the product coupling, one admissible coupling
in Definition "ImitationGap"). ``learned_true`` and ``learned_l1_true`` are driven by the SAME
Brownian path (common random numbers); each process has the law the paper defines, and the
comparison with/without L1 has less Monte-Carlo noise. ``nominal_sde`` is driven by that same
path too (a synchronous coupling of (4a) and (4b): one admissible coupling, so its moments of
``||X_t - X*_t||`` bound the Wasserstein distance of the laws from above); the other scenarios'
numbers do not depend on whether it is simulated.

Randomness. Path ``i`` draws its initial states from ``fold_in(k_x0, i)`` (and
``fold_in(k_x0bar, i)``), with ``k_* = fold_in(PRNGKey(seed), const)``. Component ``c`` of its
standard normal increment at step ``j`` is ``sqrt(2) erfinv(u)``, ``u`` in (-1, 1) built from the
64 bits of ``threefry2x32(k_bm; (i, j d + c))`` -- the counter-based hash behind ``jax.random``,
unrolled so that XLA fuses it into the step (:mod:`drip_cert.sim.noise`); a vmapped
``fold_in`` + ``normal`` per path and step costs more (the benchmark prints both). The numbers
of a path depend only on the seed, its global index and the step, so neither the chunk size nor
the number of concurrent workers changes them; the statistics are summed path by path in global
order (:mod:`drip_cert.numerics.stats`), so they do not change either, bit for bit.

Divergence. After every step a path whose state is non-finite or whose norm exceeds
``divergence_cap`` is frozen at its last good state and gets a status code (``STATUS_NONFINITE``
or ``STATUS_CAP``); it is excluded from every gap that involves its scenario, and the fraction is
reported per scenario. The run never stops because of a path.

Resume. With ``run_dir`` the settings are hashed (configuration, model name, a numerical
fingerprint of the model and the samplers) and the accumulators are written atomically after
each chunk; a rerun with the same settings continues after the last finished chunk, and its result
is bit-for-bit that of an uninterrupted run (:mod:`drip_cert.sim.resume`).

Backends. ``backend=Backend("dask", scheduler)`` computes the chunks as tasks on a Dask cluster
(:mod:`drip_cert.sim.dask_backend`: the kernel travels as exported StableHLO, a lost worker costs
only its chunks); the chunks are absorbed here in the same order, so the statistics and the
resume files are the local backend's, bit for bit. ``backend=Backend("processes")`` runs one
worker process per core, each pinned to its core before it imports jax
(:mod:`drip_cert.sim.process_backend`: XLA's thread pool then stays on that core; start-up of a
few seconds per call), with the same sub-batches and the same bits.

Float32. ``SimConfig(policy_dtype="float32")`` evaluates the learned policy in float32
(:mod:`drip_cert.sim.precision`), everything else in float64; ``SimConfig(dtype="float32")``
runs the whole simulation in float32 (states, noise, vector fields, policy, L1-DRAC; about 2x
the float64 rate, ``benchmarks/mc_throughput.py``). Both are opt-in and bit-for-bit independent
of chunking and workers too, and their effect on the gaps is measured against float64 by
:func:`drip_cert.sim.dtype_effect.dtype_effect`.

Progress. The bar counts path-steps. The kernel runs a batch in calls of a few recorded times each
(:mod:`drip_cert.sim.kernel`), and the bar advances after each call, so a run of one chunk moves
smoothly too; without a bar the calls are queued without waiting on any of them.
"""

from __future__ import annotations

import os
import sys
import threading
import time
from collections import deque
from collections.abc import Callable
from concurrent.futures import ThreadPoolExecutor
from pathlib import Path

import numpy as np
from tqdm.auto import tqdm

from drip_cert._jax import jax, jnp
from drip_cert.errors import SpecError
from drip_cert.model.numeric import SimModel
from drip_cert.sim import process_backend
from drip_cert.sim.accumulate import RunState, absorb, new_state
from drip_cert.sim.backend import Backend
from drip_cert.sim.config import SimConfig
from drip_cert.sim.dask_backend import run_chunks
from drip_cert.sim.kernel import build_chunk_fn
from drip_cert.sim.result import SimResult, build_result
from drip_cert.sim.resume import open_run, save_state, settings_hash

__all__ = ["SUB_BATCH_PATHS", "default_workers", "simulate"]

SUB_BATCH_PATHS = 2048
"""Most paths of one compiled call. A chunk is simulated in sub-batches of at most this many
paths, so that a call's hidden activations (a (B, 64) float64 layer is 1 MiB at B = 2048) stay in
a core's L2 cache: on the benchmark system (2 MiB L2 per core) the CPU time per path-step was the
same within the noise from 2048 to 8192 paths and 1.4x higher at 32768 (``benchmarks/
mc_throughput.py``). Sub-batching changes no number: the noise of a path is a function of its
global index."""

_MAX_CHUNK_BYTES = 1 << 30
"""Largest recorded-state block one chunk may return (1 GiB): beyond it the run would swap on
small machines; the error says to reduce chunk_size or record fewer times."""


def simulate(
    model: SimModel,
    config: SimConfig,
    x0_sampler: Callable,
    x0_bar_sampler: Callable | None = None,
    run_dir: str | Path | None = None,
    progress: bool | None = None,
    stop_after_chunks: int | None = None,
    workers: int | None = None,
    backend: Backend | None = None,
) -> SimResult:
    """Simulate the scenarios of ``config`` on ``model`` and return their statistics.

    Parameters
    ----------
    model
        The :class:`~drip_cert.model.numeric.SimModel` (``System.numeric`` or
        :func:`~drip_cert.model.numeric.make_model`).
    config
        :class:`~drip_cert.sim.config.SimConfig`.
    x0_sampler
        ``key -> (n,)``: one draw of ``xi ~ D`` (jax-traceable).
    x0_bar_sampler
        Optional ``key -> (n,)`` for ``xi_bar ~ D_bar``, drawn independently of ``xi``; when
        ``None``, ``xi_bar = xi`` (identity coupling).
    run_dir
        Directory for resumable runs (created if missing).
    progress
        Show a tqdm bar of path-steps on stderr; ``None`` shows it only when stderr is a terminal.
        The numbers do not depend on it.
    stop_after_chunks
        Simulate at most this many NEW chunks in this call (the result is then marked
        incomplete unless all chunks are done).
    workers
        Compiled calls run at once from a thread pool (``None``: the usable CPU cores on the CPU
        backend, 1 on an accelerator). Each call is one single-threaded XLA program
        (:mod:`drip_cert._jax`), so that the workers fill the cores side by side. A chunk is
        simulated in sub-batches of at most :data:`SUB_BATCH_PATHS` paths (cache), and fewer
        chunks than workers are split into equal sub-batches. Results do not depend on
        ``workers``, bit for bit: the noise of a path is a function of its global index, and
        chunks are absorbed in order.
    backend
        :class:`~drip_cert.sim.backend.Backend`: ``None`` or ``Backend()`` runs here;
        ``Backend("dask", scheduler)`` runs one task per chunk on a Dask cluster
        (:mod:`drip_cert.sim.dask_backend`; ``workers`` is then the size of the LocalCluster
        started when no scheduler is named); ``Backend("processes")`` runs one worker process
        per core (:mod:`drip_cert.sim.process_backend`; ``workers`` is then the number of
        processes unless ``Backend.n_workers`` gives it). The same numbers and resume files
        whichever backend.

    Returns
    -------
    SimResult
    """
    if not isinstance(model, SimModel):
        raise SpecError(
            "model must be a SimModel (System.numeric, or drip_cert.model.numeric.make_model)"
        )
    if not isinstance(config, SimConfig):
        raise SpecError("config must be a SimConfig")
    cfg = config
    if model.g_state and "learned_l1_true" in cfg.scenarios:
        raise SpecError(
            "scenario 'learned_l1_true' needs an input operator of t only (L1-DRAC), and this "
            "model's g depends on the state: drop the scenario",
            field="SimConfig.scenarios",
        )
    rec_bytes = cfg.n_records * len(cfg.scenarios) * cfg.chunk_size * model.n * 8
    if rec_bytes > _MAX_CHUNK_BYTES:
        raise SpecError(
            f"one chunk would record {rec_bytes / 2**20:.0f} MiB of states "
            f"({cfg.n_records} times x {len(cfg.scenarios)} scenarios x {cfg.chunk_size} paths); "
            "reduce chunk_size or increase record_every",
            field="SimConfig.chunk_size",
        )
    h = settings_hash(model, cfg, x0_sampler, x0_bar_sampler)
    state = new_state(model, cfg)
    rdir = None
    if run_dir is not None:
        rdir, state = open_run(run_dir, h, model.name, cfg, state)

    todo = list(range(state.chunks_done, cfg.n_chunks))
    if stop_after_chunks is not None:
        todo = todo[: max(0, int(stop_after_chunks))]
    compile_s = 0.0
    t_run = 0.0
    backend = Backend() if backend is None else backend
    if not isinstance(backend, Backend):
        raise SpecError("backend must be a drip_cert.sim.backend.Backend", field="backend")
    if todo and backend.kind == "dask":
        n_local = backend.n_workers or (default_workers() if workers is None else int(workers))
        if n_local < 1:
            raise SpecError(f"workers must be >= 1, got {workers!r}", field="workers")
        show = progress if progress is not None else sys.stderr.isatty()
        with _bar(cfg, state, show) as bar:
            state, compile_s, t_run = run_chunks(
                backend,
                model,
                cfg,
                x0_sampler,
                x0_bar_sampler,
                state,
                todo,
                h,
                rdir,
                bar,
                max_in_flight=max(1, _MAX_CHUNK_BYTES // max(rec_bytes, 1)),
                local_workers=n_local,
            )
    elif todo and backend.kind == "processes":
        n_proc = backend.n_workers or (default_workers() if workers is None else int(workers))
        if n_proc < 1:
            raise SpecError(f"workers must be >= 1, got {workers!r}", field="workers")
        parts, sub = _sub_batches(cfg, n_proc, len(todo))
        show = progress if progress is not None else sys.stderr.isatty()
        kern = build_chunk_fn(model, cfg, x0_sampler, x0_bar_sampler)
        with _bar(cfg, state, show) as bar:
            state, compile_s, t_run = process_backend.run_chunks(
                lambda: kern.export(sub),
                cfg,
                state,
                todo,
                rdir,
                bar,
                n_workers=n_proc,
                parts=parts,
                sub=sub,
                max_in_flight=max(1, _MAX_CHUNK_BYTES // max(rec_bytes, 1)),
            )
    elif todo:
        n_workers = default_workers() if workers is None else int(workers)
        if n_workers < 1:
            raise SpecError(f"workers must be >= 1, got {workers!r}", field="workers")
        # memory: at most _MAX_CHUNK_BYTES of records in flight
        n_workers = max(1, min(n_workers, _MAX_CHUNK_BYTES // max(rec_bytes, 1)))
        parts, sub = _sub_batches(cfg, n_workers, len(todo))
        t0 = time.perf_counter()
        kernel = build_chunk_fn(model, cfg, x0_sampler, x0_bar_sampler).compile(sub)
        compile_s = time.perf_counter() - t0
        show = progress if progress is not None else sys.stderr.isatty()
        bar = _bar(cfg, state, show)
        lock = threading.Lock()

        def run_part(idx, n_real: int):
            def on_block(k: int) -> None:
                with lock:
                    bar.update(n_real * k * cfg.record_every)

            # blocks in the worker thread, so concurrent calls really execute concurrently
            return jax.block_until_ready(kernel(idx, on_block if show else None))

        def submit(c: int):
            idx = np.arange(c * cfg.chunk_size, (c + 1) * cfg.chunk_size, dtype=np.uint32)
            padded = np.concatenate([idx, np.full(parts * sub - idx.size, idx[-1], np.uint32)])
            n_real = int(np.sum(idx < cfg.n_paths))
            futs = [
                pool.submit(
                    run_part,
                    jnp.asarray(padded[q * sub : (q + 1) * sub]),
                    min(max(n_real - q * sub, 0), sub),
                )
                for q in range(parts)
            ]
            return idx, futs

        def finish(st: RunState, job) -> RunState:
            idx, futs = job
            outs = [jax.device_get(f.result()) for f in futs]
            recs = np.concatenate([np.concatenate(o[0], axis=0) for o in outs], axis=2)
            recs = recs[:, :, : idx.size]
            codes = np.concatenate([o[1] for o in outs], axis=1)[:, : idx.size]
            st = absorb(st, cfg, idx.astype(np.int64), recs, codes)
            if rdir is not None:
                save_state(rdir, st)
            return st

        t1 = time.perf_counter()
        in_flight = max(1, n_workers // parts)  # chunks computing while the oldest is absorbed
        with bar, ThreadPoolExecutor(max_workers=n_workers) as pool:
            pending: deque = deque()
            for c in todo:
                pending.append(submit(c))
                if len(pending) >= in_flight:
                    state = finish(state, pending.popleft())
            while pending:
                state = finish(state, pending.popleft())
        t_run = time.perf_counter() - t1
    return build_result(model.name, cfg, h, state, compile_s, t_run)


def _sub_batches(cfg: SimConfig, n_workers: int, n_chunks: int) -> tuple[int, int]:
    """``(parts, sub)``: each chunk is simulated as ``parts`` calls of ``sub`` paths (the last
    one padded): enough to keep every worker busy, and at most :data:`SUB_BATCH_PATHS` paths
    for the cache."""
    parts = max(1, min(n_workers // n_chunks, cfg.chunk_size))
    parts = max(parts, -(-cfg.chunk_size // SUB_BATCH_PATHS))
    return parts, -(-cfg.chunk_size // parts)


def _bar(cfg: SimConfig, state: RunState, show: bool) -> tqdm:
    """The progress bar of a run: path-steps on stderr, from those already done."""
    return tqdm(
        total=cfg.n_paths * cfg.n_steps,
        initial=state.n_done * cfg.n_steps,
        disable=not show,
        unit="path-step",
        unit_scale=True,
        file=sys.stderr,
    )


def default_workers() -> int:
    """Usable CPU cores on the CPU backend, else 1."""
    if jax.default_backend() != "cpu":
        return 1
    try:
        return max(1, len(os.sched_getaffinity(0)))
    except AttributeError:  # not on Linux
        return max(1, os.cpu_count() or 1)
