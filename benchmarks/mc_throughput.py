"""Throughput of the Monte-Carlo engine against a plain numpy loop (trajectory-steps per second).

System: the DRIP paper's 4-D example with seeded stand-ins for the learned parts,
``f(x) = -0.05 x - 0.25 h(x)``, ``g = 0.25 I_4``, expert ``-0.2 x + h(x)``, ``h`` a tanh MLP 4-32-4,
learned policy a tanh MLP 4-64-64-4, ``Lambda_mu = (0.1 + 0.05||x||) 1_4``,
``Lambda_sigma = (0.1 + 0.05||x||^{1/2}) I_4``, ``p = 0``; L1-DRAC with ``lambda_s = 10``,
``omega = 50``, ``T_s = 10 dt``. Scenario: learned policy + L1-DRAC on the true SDE (the same in
both implementations). The engine's rate excludes JIT compilation (reported separately) and
includes its per-chunk statistics. The numpy loop steps all paths together in a Python loop.

Roofline. In the same run the benchmark measures the machine's dense matrix throughput (a
1024 x 1024 product, float64 and float32, the better of numpy's BLAS and XLA) and prints the
engine's fraction of it for :data:`FLOPS_PER_PATH_STEP`, the dense FLOPs of one path-step (the
policy 4-64-64-4 and ``h`` 4-32-4: ``2 * sum(fan_in * fan_out)``; elementwise work, ``tanh``,
the noise and L1-DRAC are not counted, so the fraction is a lower bound of the useful work).

``--float32`` also times the engine with the policy in float32 (``policy_dtype="float32"``) and
prints the ratio to float64 and the largest change of the gap mean; ``--dask`` times the Dask
backend on a LocalCluster of ``default_workers()`` processes against the local backend with the
same chunks, checks that the results are identical, and prints the per-chunk cost and the wall
time it implies for 10^8 and 10^9 paths on N workers.

Usage: ``python benchmarks/mc_throughput.py [--quick] [--paths N] [--T T] [--dt DT] [--float32]
[--dask] [--no-roofline]``. The last line printed is ``engine X steps/s, numpy Y steps/s, ratio
Zx``.
"""

from __future__ import annotations

import argparse
import dataclasses
import math
import resource
import time
from collections.abc import Callable

import numpy as np

from drip_cert._jax import jax, jnp
from drip_cert.control.l1drac import L1Params
from drip_cert.model.mlp import MLP, init_mlp
from drip_cert.model.numeric import SimModel, make_model
from drip_cert.sim.backend import Backend
from drip_cert.sim.config import SCENARIOS, SimConfig
from drip_cert.sim.dtype_effect import EFFECT_PATHS, policy_dtype_effect
from drip_cert.sim.engine import default_workers, simulate
from drip_cert.sim.noise import normals, normals_via_jax

N = 4

FLOPS_PER_PATH_STEP = 2 * (4 * 64 + 64 * 64 + 64 * 4) + 2 * (4 * 32 + 32 * 4)
"""Dense FLOPs of one path-step of the benchmark scenario: the learned policy 4-64-64-4 and
``h`` 4-32-4 in ``f`` (9728; a multiply-add is two)."""

ROOFLINE_SIZE = 1024
"""Side of the square products timed for the machine's matrix throughput (large enough for
BLAS/XLA to reach their peak, small enough to take well under a second)."""


def build_system(
    seed: int = 0, *, with_h: bool = True, with_policy: bool = True, with_uncertainty: bool = True
) -> tuple[SimModel, MLP, MLP]:
    """The benchmark system and its two seeded MLPs (h and the learned policy).

    The ``with_*`` switches remove one ingredient for the ablation profile: ``h`` becomes 0,
    the policy becomes the linear ``-0.2 x``, the uncertainty becomes ``Lambda_mu = 0``,
    ``Lambda_sigma = 0.1 I`` (the noise is still drawn).
    """
    rng = np.random.default_rng(seed)
    h = init_mlp([N, 32, N], rng)
    pol = init_mlp([N, 64, 64, N], rng)

    def f(t, x):
        return -0.05 * x - 0.25 * h.apply_jax(x) if with_h else -0.05 * x

    def expert(x):
        return -0.2 * x + h.apply_jax(x)

    def learned(x):
        return pol.apply_jax(x) if with_policy else -0.2 * x

    def lam_mu(t, x):
        return (0.1 + 0.05 * jnp.sqrt(jnp.sum(x * x))) * jnp.ones(N)

    def lam_sigma(t, x):
        if not with_uncertainty:
            return 0.1 * jnp.eye(N)
        return (0.1 + 0.05 * jnp.sqrt(jnp.sqrt(jnp.sum(x * x)))) * jnp.eye(N)

    model = make_model(
        N,
        N,
        N,
        f,
        0.25 * np.eye(N),
        expert,
        learned,
        lam_mu=lam_mu if with_uncertainty else None,
        lam_sigma=lam_sigma,
        name="paper-4d-benchmark",
    )
    return model, h, pol


def x0_sampler(key):
    """xi ~ uniform on [-1, 1]^4."""
    return jax.random.uniform(key, (N,), minval=-1.0, maxval=1.0)


def numpy_loop(
    h: MLP,
    pol: MLP,
    l1: L1Params,
    n_paths: int,
    n_steps: int,
    seed: int,
    x0: np.ndarray | None = None,
    noise: Callable[[int], np.ndarray] | None = None,
) -> tuple[float, np.ndarray]:
    """Seconds for the learned + L1-DRAC true SDE, all paths stepped together in numpy, and
    the final states ``(n_paths, 4)``.

    ``x0`` and ``noise(j) -> (n_paths, 4)`` (standard normals) replace numpy's own draws; the
    tests pass the engine's, and the two implementations must then end in the same states up to
    rounding.
    """
    rng = np.random.default_rng(seed)
    dt = l1.dt
    g = 0.25 * np.eye(N)
    theta = np.linalg.solve(g.T @ g, g.T)
    x = rng.uniform(-1.0, 1.0, size=(n_paths, N)) if x0 is None else np.array(x0, dtype=float)
    x_hat = x.copy()
    eta = np.zeros((n_paths, N))
    lam_hat = np.zeros((n_paths, N))
    gain, decay, fgain = l1.adaptation_gain, l1.filter_decay, l1.filter_input_gain
    sq = math.sqrt(dt)
    t0 = time.perf_counter()
    for j in range(n_steps):
        if j > 0 and j % l1.k == 0:
            lam_hat = gain * (x_hat - x)
        u = -eta
        fk = -0.05 * x - 0.25 * h.apply_np(x) + pol.apply_np(x) @ g.T
        eta = decay * eta + fgain * (lam_hat @ theta.T)
        x_hat = x_hat + dt * (-l1.lambda_s * (x_hat - x) + fk + u @ g.T + lam_hat)
        nrm = np.sqrt(np.sum(x * x, axis=1, keepdims=True))
        drift = fk + u @ g.T + (0.1 + 0.05 * nrm)
        sig = 0.1 + 0.05 * np.sqrt(nrm)
        z = rng.standard_normal((n_paths, N)) if noise is None else noise(j)
        x = x + dt * drift + sig * (sq * z)
    elapsed = time.perf_counter() - t0
    assert np.all(np.isfinite(x))
    return elapsed, x


def _ablation(cfg: SimConfig) -> None:
    """ns per path-step of the engine (all workers) with one ingredient removed at a time."""
    variants = {
        "whole step": {},
        "without h (f = -0.05 x)": {"with_h": False},
        "policy MLP -> linear": {"with_policy": False},
        "without uncertainty terms": {"with_uncertainty": False},
        "all three removed (noise, L1, Euler)": {
            "with_h": False,
            "with_policy": False,
            "with_uncertainty": False,
        },
    }
    for name, kw in variants.items():
        m, _, _ = build_system(0, **kw)
        r = simulate(m, cfg, x0_sampler, progress=False)
        ns = r.run_s / (cfg.n_paths * cfg.n_steps) * 1e9
        print(f"  ablation: {name:38s} {ns:7.1f} ns/path-step")


def _micro(pol: MLP, n_paths: int, n_steps: int) -> None:
    """ns per path-step of single ingredients, each alone in one jitted time-major scan."""
    key = jax.random.PRNGKey(0)
    idx = jnp.arange(n_paths, dtype=jnp.uint32)
    keys = jax.vmap(lambda i: jax.random.fold_in(key, i))(idx)
    x0 = jax.random.uniform(key, (n_paths, N))
    rng = np.random.default_rng(1)
    w64 = jnp.asarray(rng.normal(size=(64, 64)) / 8.0)
    linear_pol = dataclasses.replace(pol, activation="identity")

    def loop(body):
        def run(x):
            def step(x, j):
                return body(x, j), None

            return jax.lax.scan(step, x, jnp.arange(n_steps, dtype=jnp.uint32))[0]

        f = jax.jit(run)
        f(x0).block_until_ready()
        t0 = time.perf_counter()
        f(x0).block_until_ready()
        return (time.perf_counter() - t0) / (n_paths * n_steps) * 1e9

    parts = {
        "rng: engine (unrolled threefry + erfinv)": lambda x, j: x + 1e-3 * normals(key, idx, j, N),
        "rng: jax threefry_2x32 primitive + erfinv": lambda x, j: (
            x + 1e-3 * normals_via_jax(key, idx, j, N)
        ),
        "rng: vmapped fold_in + normal per path": lambda x, j: (
            x + 1e-3 * jax.vmap(lambda k: jax.random.normal(jax.random.fold_in(k, j), (N,)))(keys)
        ),
        "dense 64x64 product alone (float64)": lambda x, j: (
            x + 1e-3 * (jnp.tile(x, (1, 16)) @ w64)[:, :N]
        ),
        "policy MLP 4-64-64-4 alone": lambda x, j: x + 1e-3 * pol.apply_jax(x),
        "policy MLP, tanh -> identity": lambda x, j: x + 1e-3 * linear_pol.apply_jax(x),
    }
    for name, body in parts.items():
        print(f"  micro: {name:43s} {loop(body):7.1f} ns/path-step")


def matmul_throughput(dtype, repeats: int = 5) -> tuple[float, float]:
    """FLOP/s of a ``ROOFLINE_SIZE`` square product: ``(numpy BLAS, XLA)``, best of
    ``repeats``, all cores."""
    k = ROOFLINE_SIZE
    rng = np.random.default_rng(0)
    a = rng.normal(size=(k, k)).astype(dtype)
    b = rng.normal(size=(k, k)).astype(dtype)
    flops = 2.0 * k**3

    def best(f) -> float:
        f()
        ts = []
        for _ in range(repeats):
            t0 = time.perf_counter()
            f()
            ts.append(time.perf_counter() - t0)
        return flops / min(ts)

    ja, jb = jnp.asarray(a), jnp.asarray(b)
    mm = jax.jit(jnp.matmul)
    return best(lambda: a @ b), best(lambda: mm(ja, jb).block_until_ready())


def _roofline() -> dict[str, float]:
    """The machine's matrix throughput per dtype (the better of numpy and XLA), printed."""
    out = {}
    for dt in ("float64", "float32"):
        blas, xla = matmul_throughput(np.dtype(dt))
        out[dt] = max(blas, xla)
        print(
            f"  roofline {dt}: {ROOFLINE_SIZE}^2 product, numpy {blas / 1e9:.1f} GFLOP/s, "
            f"XLA {xla / 1e9:.1f} GFLOP/s"
        )
    return out


def _fraction(rate: float, roof: dict[str, float] | None, dt: str) -> str:
    """``, X GFLOP/s = Y % of the dt roofline`` for ``rate`` path-steps/s (empty without)."""
    if not roof:
        return ""
    gf = rate * FLOPS_PER_PATH_STEP
    return f", {gf / 1e9:.1f} GFLOP/s = {100 * gf / roof[dt]:.0f} % of the {dt} roofline"


def _float32(model, cfg: SimConfig, r64, roof) -> None:
    """The engine with the policy in float32: rate, ratio to float64, the gap change."""
    cfg32 = dataclasses.replace(cfg, policy_dtype="float32")
    r32 = simulate(model, cfg32, x0_sampler, progress=False)
    steps = cfg.n_paths * cfg.n_steps
    e64, e32 = steps / r64.run_s, steps / r32.run_s
    print(
        f"  engine, policy in float32: run {r32.run_s:.2f} s -> {e32:.3g} steps/s, "
        f"{e32 / e64:.2f}x float64{_fraction(e32, roof, 'float32')}"
    )
    # the effect on the gaps: all four scenarios, the first paths in both dtypes
    eff = policy_dtype_effect(
        model,
        dataclasses.replace(cfg, scenarios=SCENARIOS),
        x0_sampler,
        n_paths=min(EFFECT_PATHS, cfg.n_paths),
    )
    worst = max(eff.gaps, key=lambda g: g.max_abs_mean)
    print(
        f"  float32 policy, effect on {eff.n_paths} paths: gap means moved by <= "
        f"{eff.max_abs_gap_mean:.2g} ({worst.name}: max mean {worst.max_mean_64:.4g} -> "
        f"{worst.max_mean_32:.4g}), {eff.max_relative_to_ci:.2g}x the CI half-width; "
        f"states by <= {eff.max_abs_state:.2g}"
    )


def _dask(model, cfg: SimConfig, workers: int) -> None:
    """Dask backend (LocalCluster of ``workers``) against the local backend, same chunks."""
    chunk = cfg.chunk_size if cfg.n_chunks > 1 else -(-cfg.n_paths // (4 * workers))
    c = dataclasses.replace(cfg, chunk_size=chunk)
    loc = simulate(model, c, x0_sampler, progress=False)
    dsk = simulate(model, c, x0_sampler, progress=False, backend=Backend("dask", n_workers=workers))
    same = all(
        np.array_equal(a, b, equal_nan=True)
        for ga, gb in zip(loc.gaps, dsk.gaps)
        for a, b in ((ga.mean, gb.mean), (ga.power_sums, gb.power_sums), (ga.path_max, gb.path_max))
    )
    steps = c.n_paths * c.n_steps
    el, ed = steps / loc.run_s, steps / dsk.run_s
    per_chunk = dsk.run_s * workers / c.n_chunks  # seconds of one worker per chunk
    print(
        f"  dask ({workers} workers, {c.n_chunks} chunks of {chunk}): "
        f"compile {dsk.compile_s:.1f} s (on the workers), run {dsk.run_s:.2f} s -> "
        f"{ed:.3g} steps/s; local, same chunks {el:.3g} steps/s; dask/local {ed / el:.2f}x; "
        f"identical results: {same}"
    )
    per_path = per_chunk / chunk  # worker-seconds per path at this T
    for n_paths in (10**8, 10**9):
        est = ", ".join(
            f"{nw} workers {per_path * n_paths / nw / 3600:.2g} h" for nw in (2, 16, 64, 256)
        )
        print(f"  dask estimate, {n_paths:.0e} paths at T={c.T:g}: {est}")


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--quick", action="store_true", help="1000 paths, T = 0.5")
    ap.add_argument("--paths", type=int, default=None)
    ap.add_argument("--T", type=float, default=None)
    ap.add_argument("--dt", type=float, default=1e-3)
    ap.add_argument("--chunk", type=int, default=None, help="engine chunk size (default: paths)")
    ap.add_argument("--all-scenarios", action="store_true", help="also time the 4-scenario pass")
    ap.add_argument("--no-profile", action="store_true")
    ap.add_argument("--no-roofline", action="store_true", help="skip the matrix throughput")
    ap.add_argument("--float32", action="store_true", help="also time the float32 policy path")
    ap.add_argument("--dask", action="store_true", help="also time the Dask backend")
    args = ap.parse_args(argv)
    n_paths = args.paths or (1000 if args.quick else 10_000)
    T = args.T or (0.5 if args.quick else 5.0)
    dt = args.dt
    model, h, pol = build_system(0)
    l1 = L1Params(omega=50.0, lambda_s=10.0, Ts=10 * dt, dt=dt)
    n_steps = int(round(T / dt))
    rec = 100 if n_steps % 100 == 0 else 1
    cfg = SimConfig(
        T=T,
        dt=dt,
        n_paths=n_paths,
        chunk_size=args.chunk or n_paths,
        scenarios=("learned_l1_true",),
        l1=l1,
        record_every=rec,
        n_sample_paths=0,
    )
    print(f"system {model.name}: {n_paths} paths, T={T}, dt={dt}, {n_steps} steps")
    res = simulate(model, cfg, x0_sampler, progress=False)
    eng = n_paths * n_steps / res.run_s
    workers = default_workers()
    roof = None if args.no_roofline else _roofline()
    print(
        f"  engine ({workers} workers): compile {res.compile_s:.2f} s, run {res.run_s:.2f} s "
        f"-> {eng:.3g} steps/s{_fraction(eng, roof, 'float64')} "
        f"({FLOPS_PER_PATH_STEP} dense FLOPs per path-step)"
    )
    if args.float32:
        _float32(model, cfg, res, roof)
    if args.dask:
        _dask(model, cfg, workers)
    rss = resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 1024  # Linux: KiB
    print(f"  peak resident memory after the engine: {rss:.0f} MiB (chunks of {cfg.chunk_size})")
    if not args.no_profile:
        r1 = simulate(model, cfg, x0_sampler, progress=False, workers=1)
        print(
            f"  engine (1 worker, XLA's intra-op threads only): run {r1.run_s:.2f} s "
            f"-> {n_paths * n_steps / r1.run_s:.3g} steps/s"
        )
    if args.all_scenarios:
        cfg4 = dataclasses.replace(cfg, scenarios=SCENARIOS)
        r4 = simulate(model, cfg4, x0_sampler, progress=False)
        print(
            f"  engine, all 4 scenarios in one pass: compile {r4.compile_s:.2f} s, run "
            f"{r4.run_s:.2f} s -> {n_paths * n_steps / r4.run_s:.3g} path-steps/s "
            f"({4 * n_paths * n_steps / r4.run_s:.3g} trajectory-steps/s)"
        )
    if not args.no_profile:
        _ablation(cfg)
        _micro(pol, n_paths, min(n_steps, 500))
    t_np, _ = numpy_loop(h, pol, l1, n_paths, n_steps, seed=0)
    npr = n_paths * n_steps / t_np
    print(f"  numpy loop: {t_np:.2f} s")
    print(f"engine {eng:.1e} steps/s, numpy {npr:.1e} steps/s, ratio {eng / npr:.1f}x")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
