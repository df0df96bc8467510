"""Two workers against one: threads in one process (the engine) and processes pinned to a core.

Issue 26 asks for 2 workers >= 1.5x 1 worker on 2 quiet cores; ``mc_throughput.py`` measured
1.49x. What this script isolates: on the CPU, XLA runs a compiled program's thunks on the
client's intra-op thread pool (``tf_XLAEigen``, one thread per usable core), not on the calling
thread, and a program's consecutive thunks hop between the pool's threads (one call of 2048
paths x 200 steps, profiled: 11,000 thunk executions, 64 % on one thread and 36 % on the other,
overlapping 0.1 ms of 170 ms). Two workers' programs then share both cores' caches. A process
whose affinity is one core when jax starts has a pool of one thread on that core, so its
program stays in that core's L2.

It times, on the benchmark system of ``mc_throughput.py`` (wall time of ``simulate``'s run,
compilation excluded, median of interleaved repeats):

* ``threads``: ``simulate(workers=1)`` and ``simulate(workers=2)`` in this process (what the
  engine does);
* ``processes``: one process pinned to core 0 simulating all paths, and two processes pinned
  to cores 0 and 1 simulating half of them each, started together (the upper bound of a
  process-per-core engine; each process simulates its own paths 0..n/2-1: the same work);
* ``backend processes``: ``simulate(backend=Backend("processes", n_workers=w))`` for w = 1, 2
  (the engine's process-per-core backend, :mod:`drip_cert.sim.process_backend`: the run time
  excludes its start-up, which is printed apart: spawn + ``import jax`` + compile per worker,
  concurrently; its CPU time is the workers' CPU time in their sub-batches).

CPU ns per path-step of 2 workers against 1 worker is the CPU efficiency of the second worker
(100 % = no loss); it is meaningful on a loaded machine too, the wall-time ratios are not.

The numbers need quiet cores (load average printed). Usage: ``python benchmarks/mc_workers.py
[--paths N] [--T T] [--dtype float32] [--sub-batch B] [--repeats R]``.
"""

from __future__ import annotations

import argparse
import json
import os
import statistics
import subprocess
import sys
import time
from pathlib import Path

REPEATS = 3
"""Interleaved repeats of each measurement; the median is printed (the machine is shared)."""


def _config(paths: int, T: float, dtype: str):
    from drip_cert.control.l1drac import L1Params
    from drip_cert.sim.config import SimConfig

    dt = 1e-3
    n_steps = round(T / dt)
    return SimConfig(
        T=T,
        dt=dt,
        n_paths=paths,
        chunk_size=paths,
        scenarios=("learned_l1_true",),
        l1=L1Params(omega=50.0, lambda_s=10.0, Ts=10 * dt, dt=dt),
        record_every=100 if n_steps % 100 == 0 else 1,
        n_sample_paths=0,
        dtype=dtype,
    )


def _setup(sub_batch: int | None):
    sys.path.insert(0, str(Path(__file__).resolve().parent))
    import mc_throughput as mc

    import drip_cert.sim.engine as engine

    if sub_batch:
        engine.SUB_BATCH_PATHS = sub_batch
    return engine, mc


def _child(core: int, paths: int, T: float, dtype: str, sub_batch: int | None) -> None:
    """Pinned to ``core`` before jax starts; simulate once (compile), say ready, wait for a line
    on stdin, simulate again and print its run time."""
    os.sched_setaffinity(0, {core})
    engine, mc = _setup(sub_batch)
    model, _, _ = mc.build_system(0)
    cfg = _config(paths, T, dtype)
    engine.simulate(model, cfg, mc.x0_sampler, progress=False, workers=1)
    print("ready", flush=True)
    sys.stdin.readline()
    c0 = time.process_time()
    r = engine.simulate(model, cfg, mc.x0_sampler, progress=False, workers=1)
    print(json.dumps({"run_s": r.run_s, "cpu_s": time.process_time() - c0}), flush=True)


def _processes(n: int, paths: int, args) -> tuple[float, float]:
    """Wall time (the slowest) and CPU time (all) of ``n`` pinned processes simulating
    ``paths / n`` paths each, started together."""
    cmd = [sys.executable, __file__, "--T", str(args.T), "--dtype", args.dtype]
    if args.sub_batch:
        cmd += ["--sub-batch", str(args.sub_batch)]
    procs = [
        subprocess.Popen(
            [*cmd, "--child", str(k), "--paths", str(paths // n)],
            stdin=subprocess.PIPE,
            stdout=subprocess.PIPE,
            text=True,
        )
        for k in range(n)
    ]
    for p in procs:
        assert p.stdout is not None and p.stdout.readline().strip() == "ready"
    for p in procs:
        assert p.stdin is not None
        p.stdin.write("go\n")
        p.stdin.flush()
    outs = [json.loads(p.communicate()[0].strip().splitlines()[-1]) for p in procs]
    return max(o["run_s"] for o in outs), sum(o["cpu_s"] for o in outs)


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--paths", type=int, default=8192)
    ap.add_argument("--T", type=float, default=0.5)
    ap.add_argument("--dtype", default="float64", choices=("float64", "float32"))
    ap.add_argument("--sub-batch", type=int, default=None, help="engine.SUB_BATCH_PATHS")
    ap.add_argument("--repeats", type=int, default=REPEATS)
    ap.add_argument("--child", type=int, default=None, help=argparse.SUPPRESS)
    args = ap.parse_args(argv)
    if args.child is not None:
        _child(args.child, args.paths, args.T, args.dtype, args.sub_batch)
        return 0
    if len(os.sched_getaffinity(0)) < 2:
        print("needs 2 usable cores")
        return 1
    engine, mc = _setup(args.sub_batch)
    model, _, _ = mc.build_system(0)
    cfg = _config(args.paths, args.T, args.dtype)
    for w in (1, 2):  # compile
        engine.simulate(model, cfg, mc.x0_sampler, progress=False, workers=w)
    from drip_cert.sim import process_backend
    from drip_cert.sim.backend import Backend

    keys = ("threads 1", "threads 2", "procs 1", "procs 2", "backend 1", "backend 2")
    startup: list[float] = []
    t: dict[str, list[float]] = {k: [] for k in keys}
    c: dict[str, list[float]] = {k: [] for k in keys}
    for _ in range(args.repeats):
        for w in (1, 2):
            c0 = time.process_time()
            r = engine.simulate(model, cfg, mc.x0_sampler, progress=False, workers=w)
            c[f"threads {w}"].append(time.process_time() - c0)
            t[f"threads {w}"].append(r.run_s)
        for n in (1, 2):
            wall, cpu = _processes(n, args.paths, args)
            t[f"procs {n}"].append(wall)
            c[f"procs {n}"].append(cpu)
        for n in (1, 2):
            r = engine.simulate(
                model, cfg, mc.x0_sampler, progress=False, backend=Backend("processes", n_workers=n)
            )
            t[f"backend {n}"].append(r.run_s)
            c[f"backend {n}"].append(process_backend.last_task_cpu_s)
            startup.append(r.compile_s)
    st = process_backend.last_startup
    assert st is not None
    m = {k: statistics.median(v) for k, v in t.items()}
    ns = {k: statistics.median(v) / (args.paths * cfg.n_steps) * 1e9 for k, v in c.items()}
    sub = engine.SUB_BATCH_PATHS
    print(
        f"{args.paths} paths, T={args.T}, {args.dtype}, sub-batches of <= {sub} paths, median of "
        f"{args.repeats}, load average {os.getloadavg()[0]:.1f}:"
    )
    print(
        f"  threads (the engine): 1 worker {m['threads 1']:.3f} s, 2 workers "
        f"{m['threads 2']:.3f} s -> 2 workers / 1 worker {m['threads 1'] / m['threads 2']:.2f}x "
        f"(CPU ns per path-step {ns['threads 1']:.0f} and {ns['threads 2']:.0f})"
    )
    print(
        f"  processes pinned to a core: 1 process {m['procs 1']:.3f} s, 2 processes "
        f"{m['procs 2']:.3f} s -> {m['procs 1'] / m['procs 2']:.2f}x; 1 pinned process / 1 "
        f"worker thread {m['threads 1'] / m['procs 1']:.2f}x (CPU ns per path-step "
        f"{ns['procs 1']:.0f} and {ns['procs 2']:.0f})"
    )
    print(
        f"  backend processes: 1 worker {m['backend 1']:.3f} s, 2 workers {m['backend 2']:.3f} s "
        f"-> 2 workers / 1 worker {m['backend 1'] / m['backend 2']:.2f}x (CPU ns per path-step "
        f"{ns['backend 1']:.0f} and {ns['backend 2']:.0f}); start-up per call "
        f"{statistics.median(startup):.2f} s (last, per worker: spawn + import "
        + ", ".join(f"{x:.2f}" for x in st.import_s)
        + " s, compile "
        + ", ".join(f"{x:.2f}" for x in st.compile_s)
        + f" s; cores {list(st.cores)})"
    )
    print(
        "  CPU efficiency of the second worker (CPU ns per path-step, 1 worker / 2 workers): "
        + ", ".join(
            f"{name} {ns[f'{key} 1'] / ns[f'{key} 2']:.0%}"
            for name, key in (("threads", "threads"), ("pinned", "procs"), ("backend", "backend"))
        )
    )
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
