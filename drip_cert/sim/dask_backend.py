"""The Dask backend of :func:`~drip_cert.sim.engine.simulate`: one task per chunk on a cluster.

Design. The run's kernel is lowered here, for batches of ``chunk_size`` paths, and exported as
serialized StableHLO (:meth:`~drip_cert.sim.kernel.ChunkKernel.export`); those bytes are the task
``drip-job-<hash>-<nonce>`` (one :class:`_ChunkJob`, which compiles them on first use and keeps the
programs for the worker's later tasks), which every chunk task depends on. A task, not scattered
data: Dask's active memory manager keeps only the replicas that waiting tasks need, and scattered
data whose last replica dies with a worker cannot be recomputed (every chunk would be cancelled for
"lost dependencies"); a task is recomputed from its spec, the bytes. No Python code of the model
travels: a system lowered from a spec's sympy expressions runs remotely as well as a hand-written
one, and a worker needs only drip-cert and jax installed. Chunk ``c`` is the task
``drip-chunk-<hash>-<c>``: it simulates the paths ``c * chunk_size ..`` with the same kernel as the
local backend and returns their recorded states and status codes. The caller absorbs the chunks IN
ORDER (:func:`~drip_cert.sim.accumulate.absorb`) and, with a run directory, writes the state after
each one (:mod:`drip_cert.sim.resume`). Since the noise and the initial states of a path are
functions of the seed and its global index, the statistics and the resume files are those of the
local backend, bit for bit, whatever worker computed what (``tests/test_dask_backend.py``).

Flow control. At most ``2 x (worker threads)`` chunks are submitted and not yet absorbed (each
worker has one chunk running and one queued, so none idles between tasks), and never more than
the engine's 1 GiB of recorded states; a finished chunk's result is fetched as soon as it is
done, its future released, and the window refilled.

Failures. A worker that dies loses the chunks it was running or holding; the scheduler re-runs
exactly those on the other workers (chunks already absorbed were released and are not
recomputed). A chunk whose task kills ``distributed.scheduler.allowed-failures`` workers (3 by
default) ends the run with a :class:`~drip_cert.errors.DripCertError`; the run directory keeps
every chunk absorbed before, and the same call resumes after the last one. A chunk whose future
the scheduler cancels (seen once in CI: ``FutureCancelledError ... already forgotten`` for a
chunk whose result was lost with a killed worker) is submitted again, as the task
``drip-chunk-<hash>-<c>-retry<n>``, at most ``MAX_RESUBMIT`` times: a chunk is a function of its
index only, so the numbers do not change.

Progress. The bar (path-steps, on the caller's stderr) advances when a chunk finishes anywhere in
the cluster; Dask's dashboard shows the task stream per worker.

``dask.distributed`` is imported inside the functions only: ``import drip_cert`` never needs it.
"""

from __future__ import annotations

import concurrent.futures
import hashlib
import threading
import time
import uuid
from collections.abc import Callable
from pathlib import Path
from typing import Any

import numpy as np

from drip_cert._jax import jax, jnp
from drip_cert.errors import DripCertError, SpecError
from drip_cert.model.numeric import SimModel
from drip_cert.sim.accumulate import RunState, absorb
from drip_cert.sim.backend import Backend
from drip_cert.sim.config import SimConfig
from drip_cert.sim.kernel import ExportedChunk, build_chunk_fn
from drip_cert.sim.resume import save_state

__all__ = ["run_chunks", "run_indices"]

MAX_RESUBMIT = 3
"""Submissions again of one chunk whose future was cancelled by the cluster, before giving up."""

WINDOW_PER_THREAD = 2
"""Chunks in flight per worker thread: one running, one queued behind it."""


class _ChunkJob:
    """What every worker needs for any chunk of one run: the kernel as serialized StableHLO.

    Pickled as its :class:`~drip_cert.sim.kernel.ExportedChunk` alone (plain bytes: no model code
    travels, so any system, also one lowered from a spec's sympy expressions, runs remotely). On
    a worker the programs are compiled once per process and kept in :data:`_COMPILED` under the
    hash of their bytes, so the later tasks of the run, and later runs of the same programs
    (another seed, a resumed run), reuse them.
    """

    def __init__(self, exported: ExportedChunk) -> None:
        self.exported = exported
        self.digest = hashlib.sha256(exported.start + exported.advance).hexdigest()

    def __reduce__(self):
        return (_ChunkJob, (self.exported,))

    def kernel(self) -> Callable:
        """The programs compiled for this worker process (on first use)."""
        with _COMPILED_LOCK:
            k = _COMPILED.pop(self.digest, None)
            if k is None:
                k = self.exported.load()
            _COMPILED[self.digest] = k  # most recently used last
            while len(_COMPILED) > _COMPILED_MAX:
                _COMPILED.pop(next(iter(_COMPILED)))
            return k


_COMPILED: dict[str, Callable] = {}
"""Worker-process cache of compiled chunk programs by the hash of their exported bytes (the one
piece of process state here: it only saves compile time, never changes a result)."""
_COMPILED_MAX = 8
_COMPILED_LOCK = threading.Lock()


def _compile_task(job: _ChunkJob) -> float:
    """Compile the kernel on this worker; return the seconds it took (0 when already done)."""
    t0 = time.perf_counter()
    job.kernel()
    return time.perf_counter() - t0


def run_indices(job: _ChunkJob, idx: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """The paths ``idx`` (``(batch,)`` uint32 global indices): ``(records (n_records, S, batch,
    n), codes (S, batch))``, on host. The one chunk function of the out-of-process backends
    (this one and :mod:`drip_cert.sim.process_backend`)."""
    blocks, codes = job.kernel()(jnp.asarray(idx))
    blocks, codes = jax.device_get((blocks, codes))
    return np.concatenate(blocks, axis=0), np.asarray(codes)


def _chunk_task(job: _ChunkJob, c: int) -> tuple[np.ndarray, np.ndarray]:
    """Chunk ``c``: ``(records (n_records, S, chunk_size, n), codes (S, chunk_size))``."""
    cs = job.exported.batch
    return run_indices(job, np.arange(c * cs, (c + 1) * cs, dtype=np.uint32))


def _connect(backend: Backend, local_workers: int):
    """``(client, cluster)``: a client of the backend's scheduler, or of a new LocalCluster of
    ``local_workers`` single-threaded worker processes on the loopback interface (``cluster`` is
    then that cluster, to be closed with the client)."""
    from distributed import Client, LocalCluster  # distributed: keep off the import path

    addr = backend.address
    if addr is not None:
        try:
            return Client(addr, timeout=backend.connect_timeout), None
        except (OSError, TimeoutError) as exc:
            raise SpecError(
                f"cannot reach the Dask scheduler at {addr!r} ({exc}); start one with "
                "`dask scheduler` and `dask worker ADDRESS`, or drop --scheduler (and unset "
                "DASK_SCHEDULER_ADDRESS) for a local cluster",
                field="scheduler",
            ) from None
    cluster = LocalCluster(
        n_workers=local_workers,
        threads_per_worker=1,
        processes=True,
        host="127.0.0.1",
        dashboard_address=":0",
    )
    return Client(cluster), cluster


def run_chunks(
    backend: Backend,
    model: SimModel,
    cfg: SimConfig,
    x0_sampler: Callable,
    x0_bar_sampler: Callable | None,
    state: RunState,
    todo: list[int],
    settings_hash: str,
    run_dir: Path | None,
    bar: Any,
    max_in_flight: int,
    local_workers: int,
) -> tuple[RunState, float, float]:
    """Simulate the chunks ``todo`` (consecutive) on Dask and absorb them in order into ``state``.

    Parameters
    ----------
    backend
        A ``dask`` :class:`~drip_cert.sim.backend.Backend`.
    model, cfg, x0_sampler, x0_bar_sampler
        The run (as for :func:`~drip_cert.sim.engine.simulate`).
    state
        The state before the first chunk of ``todo``.
    todo
        Chunk indices, consecutive and increasing.
    settings_hash
        The run's hash (names the tasks).
    run_dir
        Where to save the state after each chunk (``None``: nowhere).
    bar
        A tqdm bar of path-steps (may be disabled).
    max_in_flight
        Memory cap on chunks submitted and not absorbed.
    local_workers
        Worker processes of the LocalCluster started when the backend names no scheduler.

    Returns
    -------
    tuple of RunState, float, float
        The final state, the compile seconds (all workers, concurrently) and the run seconds.
    """
    from distributed import KilledWorker, as_completed  # distributed: keep off the import path

    client, cluster = _connect(backend, local_workers)
    try:
        exported = build_chunk_fn(model, cfg, x0_sampler, x0_bar_sampler).export(cfg.chunk_size)
        tag = settings_hash[:12]
        # The job is a task, not scattered data: Dask's active memory manager drops replicas that
        # no waiting task needs, so a scattered job may live on one worker only, and when that
        # worker dies, every chunk is cancelled for "lost dependencies" (seen in CI). A task's
        # result is recomputed from its spec (the exported bytes) when its last replica is lost.
        job = client.submit(_ChunkJob, exported, key=f"drip-job-{tag}-{uuid.uuid4().hex[:8]}")
        workers = client.scheduler_info(n_workers=-1)["workers"]
        if not workers:
            raise SpecError(
                f"the Dask scheduler {backend.address!r} has no workers; start some with "
                "`dask worker ADDRESS`",
                field="scheduler",
            )
        threads = sum(int(w.get("nthreads", 1)) for w in workers.values())
        t0 = time.perf_counter()
        # one compilation per worker, up front; allow_other_workers: a worker that dies while it
        # compiles must not leave its task waiting forever for it (a chunk compiles lazily anyway)
        client.gather(
            [
                client.submit(_compile_task, job, workers=[w], allow_other_workers=True, pure=False)
                for w in workers
            ]
        )
        compile_s = time.perf_counter() - t0
        window = max(1, min(WINDOW_PER_THREAD * threads, max_in_flight))
        t1 = time.perf_counter()
        done: dict[int, tuple[np.ndarray, np.ndarray]] = {}
        chunk_of: dict[str, int] = {}
        ac = as_completed()
        nxt = 0  # position in todo of the next chunk to submit
        absorbed = 0
        resubmitted: dict[int, int] = {}

        def submit(c: int) -> None:
            n = resubmitted.get(c, 0)  # a key of its own per try: a cancelled key may linger
            key = f"drip-chunk-{tag}-{c}" + (f"-retry{n}" if n else "")
            fut = client.submit(_chunk_task, job, c, key=key, pure=False)
            chunk_of[fut.key] = c
            ac.add(fut)

        while absorbed < len(todo):
            while nxt < len(todo) and nxt - absorbed < window:
                submit(todo[nxt])
                nxt += 1
            fut = next(ac)
            c = chunk_of.pop(fut.key)
            try:
                done[c] = fut.result()
            except KilledWorker as exc:
                raise DripCertError(
                    f"the workers computing chunk {c} died repeatedly ({exc}); the chunks "
                    "before it are saved in the run directory (with --out / run_dir) and the "
                    "same command resumes after them"
                ) from None
            except concurrent.futures.CancelledError as exc:
                fut.release()
                resubmitted[c] = resubmitted.get(c, 0) + 1
                if resubmitted[c] > MAX_RESUBMIT:
                    raise DripCertError(
                        f"the cluster cancelled chunk {c} {resubmitted[c]} times ({exc}); the "
                        "chunks before it are saved in the run directory (with --out / "
                        "run_dir) and the same command resumes after them"
                    ) from None
                submit(c)  # a chunk is a function of its index only: the same numbers
                continue
            fut.release()
            n_real = min(cfg.n_paths - c * cfg.chunk_size, cfg.chunk_size)
            bar.update(n_real * cfg.n_steps)
            while absorbed < len(todo) and todo[absorbed] in done:
                c0 = todo[absorbed]
                recs, codes = done.pop(c0)
                idx = np.arange(c0 * cfg.chunk_size, (c0 + 1) * cfg.chunk_size, dtype=np.int64)
                state = absorb(state, cfg, idx, recs, codes)
                if run_dir is not None:
                    save_state(run_dir, state)
                absorbed += 1
        return state, compile_s, time.perf_counter() - t1
    finally:
        client.close()
        if cluster is not None:
            cluster.close()
