"""The ``processes`` backend of :func:`~drip_cert.sim.engine.simulate`: one worker process per core.

Why. On the CPU, XLA runs a compiled program's steps on its client's intra-op thread pool (one
thread per usable core when jax starts), not on the calling thread, even with
``--xla_cpu_multi_thread_eigen=false``: two worker threads' programs then hop between both
cores and share their caches, and a second worker thread gave 1.5x at most
(``benchmarks/mc_workers.py``). A process whose affinity is one core when jax starts has a pool
of one thread on that core, so its program stays in that core's caches; two such processes kept
96-100 % of the CPU efficiency of one alone.

Design. Worker ``k`` is a fresh interpreter (what :mod:`multiprocessing`'s ``spawn`` start
method starts, without its re-import of the caller's ``__main__``: that would run a script
without a ``__main__`` guard again in every worker, and import its modules before the worker
can pin itself). It is started from the caller's thread pinned to core ``k``
(``os.sched_setaffinity``; the thread's affinity is restored right after), so it is on its core
from its first instruction, and it pins itself again as its first statement, before it imports
drip_cert or jax; it runs in its own session and ignores SIGINT (the caller handles Ctrl-C and
ends the workers). Where ``os.sched_setaffinity`` does not exist (macOS) the workers are
started unpinned: still one single-threaded program per process, but the operating system
places them; Windows is not supported (no ``pass_fds``). More workers than usable cores are
pinned round robin. Each worker receives the run's kernel as exported StableHLO
(:meth:`~drip_cert.sim.kernel.ChunkKernel.export`, the Dask backend's path:
:class:`~drip_cert.sim.dask_backend._ChunkJob`), compiles it once, and then simulates sub-batches
of paths given by their global indices (:func:`~drip_cert.sim.dask_backend.run_indices`) - the
same sub-batches as the local backend, so that each call's activations stay in the core's cache.
Serializing the kernel needs the package ``flatbuffers`` (a core dependency, as for Dask); without
it the run stops before any worker starts, with a message saying what to install.
The caller absorbs the chunks IN ORDER (:func:`~drip_cert.sim.accumulate.absorb`), so the
statistics and resume files are the local backend's, bit for bit (``tests/test_engine.py``).

Start-up. The workers are started once per :func:`~drip_cert.sim.engine.simulate` call: a new
interpreter, ``import jax`` and the kernel's compilation in each (concurrently; the caller
lowers the kernel meanwhile). That wall time is the result's ``compile_s``; it is about
2-4 s on a 2-core machine and is paid again by every call (see ``benchmarks/mc_workers.py``), so
the backend pays off only for runs of tens of seconds or more.

Flow control. Each worker holds at most :data:`TASKS_PER_WORKER` sub-batches (one running, one
queued), and never more chunks are computed and not absorbed than the engine's 1 GiB of
recorded states allows.

Failures. An exception in a worker is sent back with its traceback and raised here as a
:class:`~drip_cert.errors.DripCertError` naming the chunk and the original message (the remote
traceback is attached as a note); a worker that dies ends the run with an error naming its exit
code. In every case (also ``KeyboardInterrupt``) the workers are terminated and joined before
the exception leaves :func:`run_chunks`: no process outlives the call. A worker whose caller
dies without cleaning up reads end-of-file on its pipe and exits.
"""

from __future__ import annotations

import importlib.util
import os
import signal
import socket
import subprocess
import sys
import time
import traceback
from collections.abc import Callable
from dataclasses import dataclass
from multiprocessing.connection import Connection, wait
from pathlib import Path
from typing import Any

import numpy as np

from drip_cert.errors import DripCertError, SpecError
from drip_cert.sim.accumulate import RunState, absorb
from drip_cert.sim.config import SimConfig
from drip_cert.sim.dask_backend import _ChunkJob, run_indices
from drip_cert.sim.resume import save_state

__all__ = [
    "TASKS_PER_WORKER",
    "Startup",
    "can_pin",
    "last_startup",
    "last_task_cpu_s",
    "run_chunks",
    "worker_cores",
]

TASKS_PER_WORKER = 2
"""Sub-batches handed to a worker and not yet returned: one running, one queued behind it."""

JOIN_S = 10.0
"""Seconds a worker gets to exit after the stop message (then it is terminated)."""


@dataclass(frozen=True)
class Startup:
    """What starting the workers of one run cost (wall seconds; the workers start concurrently).

    Attributes
    ----------
    total_s
        From the first worker's start to the last worker ready (the run's ``compile_s``).
    import_s
        Per worker: interpreter start to jax imported (spawn + imports).
    compile_s
        Per worker: compiling the exported kernel.
    cores
        Per worker: its affinity when it reported ready (``None``: not pinned).
    """

    total_s: float
    import_s: tuple[float, ...]
    compile_s: tuple[float, ...]
    cores: tuple[tuple[int, ...] | None, ...]


last_startup: Startup | None = None
"""The start-up of the last ``processes`` run in this process (read by the benchmarks)."""

last_task_cpu_s: float = 0.0
"""CPU seconds the workers of the last ``processes`` run spent in their sub-batches (all
workers; start-up excluded; read by the benchmarks)."""


def can_pin() -> bool:
    """Whether this platform can pin a process to a core (``os.sched_setaffinity``)."""
    return hasattr(os, "sched_setaffinity") and hasattr(os, "sched_getaffinity")


def worker_cores(n_workers: int) -> list[int | None]:
    """The core of each of ``n_workers`` workers: the usable cores in order, round robin
    (``None`` for each where the platform cannot pin)."""
    if not can_pin():
        return [None] * n_workers
    cores = sorted(os.sched_getaffinity(0))
    return [cores[k % len(cores)] for k in range(n_workers)]


_ENTRY = (
    "import os, sys\n"
    "core = int(sys.argv[2])\n"
    "if core >= 0:\n"
    "    os.sched_setaffinity(0, {core})\n"
    "from drip_cert.sim.process_backend import _worker\n"
    "_worker(int(sys.argv[1]), None if core < 0 else core, float(sys.argv[3]))\n"
)
"""The worker's program (``python -c``): pin to the core, THEN import drip_cert and jax."""


def _worker(fd: int, core: int | None, t_spawn: float) -> None:
    """A worker process: compile the kernel it is sent, simulate sub-batches until told to stop
    (``None``) or its socket closes. Pinned by :data:`_ENTRY` before it imported this module
    (and with it jax)."""
    signal.signal(signal.SIGINT, signal.SIG_IGN)  # the caller ends the workers on Ctrl-C
    conn = Connection(fd)
    try:
        t_import = time.time() - t_spawn  # spawn + imports (this module imports jax)
        exported = conn.recv()
        t0 = time.perf_counter()
        job = _ChunkJob(exported)
        try:
            job.kernel()
        except Exception as exc:  # noqa: BLE001 - sent to the caller, raised there
            conn.send(("error", -1, f"{type(exc).__name__}: {exc}", traceback.format_exc()))
            return
        t_compile = time.perf_counter() - t0
        aff = tuple(sorted(os.sched_getaffinity(0))) if core is not None else None
        conn.send(("ready", t_import, t_compile, aff))
        while True:
            msg = conn.recv()
            if msg is None:
                return
            seq, idx = msg
            try:
                c0 = time.process_time()
                recs, codes = run_indices(job, idx)
                conn.send(("ok", seq, recs, codes, time.process_time() - c0))
            except Exception as exc:  # noqa: BLE001 - sent to the caller, raised there
                conn.send(("error", seq, f"{type(exc).__name__}: {exc}", traceback.format_exc()))
    except (EOFError, OSError):  # the caller is gone
        return


class _Pool:
    """The worker processes of one run, with their sockets; :meth:`close` ends them all.

    A worker is a fresh interpreter (``python -c`` :data:`_ENTRY`), what the ``spawn`` start
    method of :mod:`multiprocessing` starts, without its re-import of the caller's ``__main__``
    (which would run a script without a ``__main__`` guard again in every worker, and import its
    modules before the worker is pinned). It is started from this thread pinned to the worker's
    core (the child inherits the affinity at its birth; this thread's is restored right after),
    in a new session (Ctrl-C at a terminal reaches only the caller, which ends the workers), with
    the directory of this ``drip_cert`` first on its ``PYTHONPATH``.
    """

    def __init__(self, n_workers: int) -> None:
        if os.name != "posix":
            raise SpecError(
                "backend 'processes' needs a POSIX system (Linux, macOS); use --backend local",
                field="backend",
            )
        root = str(Path(__file__).resolve().parents[2])
        env = dict(os.environ)
        env["PYTHONPATH"] = os.pathsep.join(p for p in (root, env.get("PYTHONPATH")) if p)
        self.procs: list[subprocess.Popen] = []
        self.conns: list[Connection] = []
        self.t0 = time.perf_counter()
        try:
            for core in worker_cores(n_workers):
                mine, theirs = socket.socketpair()
                fd = theirs.fileno()
                cmd = [sys.executable, "-c", _ENTRY, str(fd), str(-1 if core is None else core)]
                old = os.sched_getaffinity(0) if core is not None else None
                try:
                    if core is not None:  # the child inherits this thread's affinity
                        os.sched_setaffinity(0, {core})
                    p = subprocess.Popen(
                        [*cmd, repr(time.time())], pass_fds=(fd,), env=env, start_new_session=True
                    )
                finally:
                    if old is not None:
                        os.sched_setaffinity(0, old)
                    theirs.close()
                self.procs.append(p)
                self.conns.append(Connection(mine.detach()))
        except BaseException:
            self.close(graceful=False)
            raise

    def close(self, graceful: bool) -> None:
        """Stop every worker (the stop message first when ``graceful``), then terminate and
        kill those still alive, and wait for all; close the sockets."""
        if graceful:
            for c in self.conns:
                try:
                    c.send(None)
                except (OSError, ValueError):
                    pass
            deadline = time.monotonic() + JOIN_S
            for p in self.procs:
                try:
                    p.wait(max(0.0, deadline - time.monotonic()))
                except subprocess.TimeoutExpired:
                    pass
        for p in self.procs:
            if p.poll() is None:
                p.terminate()
        for p in self.procs:
            try:
                p.wait(JOIN_S)
            except subprocess.TimeoutExpired:
                p.kill()
                p.wait()
        for c in self.conns:
            c.close()


def _can_serialize() -> bool:
    """Whether ``jax.export`` can serialize here (it needs the package flatbuffers)."""
    return importlib.util.find_spec("flatbuffers") is not None


def _died(pool: _Pool, k: int) -> DripCertError:
    """The error of a worker that died (its pipe closed)."""
    p = pool.procs[k]
    try:
        code = p.wait(JOIN_S)
    except subprocess.TimeoutExpired:
        code = None
    return DripCertError(
        f"worker process {k} (pid {p.pid}) died with exit code {code}; the chunks absorbed "
        "before are saved in the run directory (with --out / run_dir) and the same command "
        "resumes after them"
    )


def _recv(pool: _Pool, k: int) -> tuple:
    """The next message of worker ``k``; an error when it died instead."""
    try:
        return pool.conns[k].recv()
    except (EOFError, OSError):
        raise _died(pool, k) from None


def _send(pool: _Pool, k: int, msg: Any) -> None:
    """Send ``msg`` to worker ``k``; an error when it died."""
    try:
        pool.conns[k].send(msg)
    except OSError:  # BrokenPipeError, ConnectionResetError
        raise _died(pool, k) from None


def run_chunks(
    exported: Callable[[], Any],
    cfg: SimConfig,
    state: RunState,
    todo: list[int],
    run_dir: Path | None,
    bar: Any,
    n_workers: int,
    parts: int,
    sub: int,
    max_in_flight: int,
) -> tuple[RunState, float, float]:
    """Simulate the chunks ``todo`` on ``n_workers`` worker processes; absorb them in order.

    Parameters
    ----------
    exported
        ``() -> ExportedChunk``: the kernel for batches of ``sub`` paths (called while the
        workers start).
    cfg
        The run's configuration.
    state
        The state before the first chunk of ``todo``.
    todo
        Chunk indices, consecutive and increasing.
    run_dir
        Where to save the state after each chunk (``None``: nowhere).
    bar
        A tqdm bar of path-steps (may be disabled).
    n_workers
        Worker processes (pinned round robin to the usable cores).
    parts, sub
        Each chunk is simulated as ``parts`` sub-batches of ``sub`` paths (the last padded with
        its last index), as by the local backend.
    max_in_flight
        Memory cap on chunks computed and not absorbed.

    Returns
    -------
    tuple of RunState, float, float
        The final state, the start-up seconds (:class:`Startup`) and the run seconds.
    """
    global last_startup, last_task_cpu_s
    cs = cfg.chunk_size
    n_tasks = len(todo) * parts

    def task(seq: int) -> tuple[int, int, np.ndarray, int]:
        """Task ``seq``: ``(chunk, part, path indices (sub,), real paths)`` (made when sent:
        a run of 10^9 paths has 10^5-10^6 of them)."""
        c, q = todo[seq // parts], seq % parts
        idx = np.arange(c * cs, (c + 1) * cs, dtype=np.uint32)
        padded = np.concatenate([idx, np.full(parts * sub - cs, idx[-1], np.uint32)])
        n_real = min(max(cfg.n_paths - c * cs - q * sub, 0), sub, max(cs - q * sub, 0))
        return c, q, padded[q * sub : (q + 1) * sub], n_real

    if not _can_serialize():
        raise SpecError(
            "backend 'processes' sends the kernel to its workers as serialized jax.export "
            "programs, which needs the package flatbuffers (a dependency of drip-cert that is "
            "missing here): pip install flatbuffers, or use --backend local",
            field="backend",
        )
    pool = _Pool(n_workers)
    graceful = False
    try:
        job = exported()
        for k in range(n_workers):
            _send(pool, k, job)
        imp, comp, cores = [], [], []
        for k in range(n_workers):
            msg = _recv(pool, k)
            if msg[0] != "ready":
                err = DripCertError(f"worker process {k} could not compile the kernel: {msg[2]}")
                err.add_note(f"worker traceback:\n{msg[3]}")
                raise err
            imp.append(msg[1])
            comp.append(msg[2])
            cores.append(msg[3])
        startup_s = time.perf_counter() - pool.t0
        last_startup = Startup(startup_s, tuple(imp), tuple(comp), tuple(cores))

        t1 = time.perf_counter()
        last_task_cpu_s = 0.0
        outstanding: list[set[int]] = [set() for _ in range(n_workers)]  # tasks per worker
        done: dict[int, dict[int, tuple[np.ndarray, np.ndarray]]] = {c: {} for c in todo}
        nxt = 0  # next task to hand out
        absorbed = 0  # chunks of todo absorbed
        while absorbed < len(todo):
            # hand out: the least busy worker first, chunks within the memory window
            while nxt < n_tasks and nxt // parts < absorbed + max_in_flight:
                k = min(range(n_workers), key=lambda w: len(outstanding[w]))
                if len(outstanding[k]) >= TASKS_PER_WORKER:
                    break
                _send(pool, k, (nxt, task(nxt)[2]))
                outstanding[k].add(nxt)
                nxt += 1
            ready = wait(pool.conns)
            for conn in ready:
                k = pool.conns.index(conn)  # type: ignore[arg-type]
                msg = _recv(pool, k)
                seq = msg[1]
                c, q, _, n_real = task(seq)
                if msg[0] == "error":
                    err = DripCertError(
                        f"chunk {c} failed in worker process {k}: {msg[2]}; the chunks absorbed "
                        "before are saved in the run directory (with --out / run_dir) and the "
                        "same command resumes after them"
                    )
                    err.add_note(f"worker traceback:\n{msg[3]}")
                    raise err
                outstanding[k].discard(seq)
                done[c][q] = (msg[2], msg[3])
                last_task_cpu_s += msg[4]
                bar.update(n_real * cfg.n_steps)
            while absorbed < len(todo) and len(done[todo[absorbed]]) == parts:
                c0 = todo[absorbed]
                by_part = done.pop(c0)
                outs = [by_part[q] for q in range(parts)]
                recs = np.concatenate([o[0] for o in outs], axis=2)[:, :, :cs]
                codes = np.concatenate([o[1] for o in outs], axis=1)[:, :cs]
                idx64 = np.arange(c0 * cs, (c0 + 1) * cs, dtype=np.int64)
                state = absorb(state, cfg, idx64, recs, codes)
                if run_dir is not None:
                    save_state(run_dir, state)
                absorbed += 1
        graceful = True
        return state, startup_s, time.perf_counter() - t1
    finally:
        pool.close(graceful)
