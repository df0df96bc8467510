"""Throughput of the Monte-Carlo engine against a plain numpy loop (trajectory-steps per second).

System: the DRIP paper's 4-D example with seeded stand-ins for the learned parts,
``f(x) = -0.05 x - 0.25 h(x)``, ``g = 0.25 I_4``, expert ``-0.2 x + h(x)``, ``h`` a tanh MLP 4-32-4,
learned policy a tanh MLP 4-64-64-4, ``Lambda_mu = (0.1 + 0.05||x||) 1_4``,
``Lambda_sigma = (0.1 + 0.05||x||^{1/2}) I_4``, ``p = 0``; L1-DRAC with ``lambda_s = 10``,
``omega = 50``, ``T_s = 10 dt``. Scenario: learned policy + L1-DRAC on the true SDE (the same in
both implementations). The engine's rate excludes JIT compilation (reported separately) and
includes its per-chunk statistics. The numpy loop steps all paths together in a Python loop.

Component bound and plain-scan reference (issue 26). In the same run, in CPU time of one
single-threaded XLA program (``time.process_time``, median of interleaved repeats, at the
engine's sub-batch of :data:`~drip_cert.sim.engine.SUB_BATCH_PATHS` paths), the benchmark times

* the engine's kernel on that sub-batch (:func:`drip_cert.sim.kernel.build_chunk_fn`);
* :func:`plain_scan_reference`, the same Euler-Maruyama + L1-DRAC step as ~40 lines of plain
  ``jax.lax.scan`` (what a user would write; no records, codes or divergence guard), and prints
  ``engine / reference`` (>= 1 means the engine is as fast);
* each ingredient alone at the engine's shapes: the five dense products of the two MLPs, the
  160 ``tanh`` per path-step, the 4 normals, and the rest of the step (the reference with the
  MLPs and the noise removed). Their sum is the component bound of a path-step; the benchmark
  prints it and the engine's fraction of it (bound / engine time).

All of it in float64 and float32 (``SimConfig(dtype="float32")``: states, noise, L1-DRAC and
policy). The machine is shared and noisy: CPU time, medians of interleaved repeats; the wall-time
rates of ``simulate`` (all workers, 2 workers / 1 worker) depend on the load printed with them.
The 2 workers / 1 worker line times the local backend (worker threads) and the ``processes``
backend (one process pinned to each core; its start-up, printed apart, is not in the run time).

``--float32`` also runs ``simulate`` in float32 end to end and with the policy alone in float32 and
prints their rates, the ratio to float64 and the largest change of the gap means; ``--dask`` times
the Dask backend on a LocalCluster of ``default_workers()`` processes against the local backend with
the same chunks, checks that the results are identical, and prints the per-chunk cost and the wall
time it implies for 10^8 and 10^9 paths on N workers.

Usage: ``python benchmarks/mc_throughput.py [--quick] [--paths N] [--T T] [--dt DT] [--float32]
[--dask] [--no-bound]``. The last line printed is ``engine X steps/s, numpy Y steps/s, ratio
Zx``.
"""

from __future__ import annotations

import argparse
import dataclasses
import math
import os
import resource
import time
from collections.abc import Callable
from functools import partial
from typing import Any

import numpy as np

from drip_cert._jax import jax, jnp
from drip_cert.control.l1drac import L1Params
from drip_cert.model.mlp import MLP, init_mlp
from drip_cert.model.numeric import SimModel, make_model
from drip_cert.sim.backend import Backend
from drip_cert.sim.config import SCENARIOS, SimConfig
from drip_cert.sim.dtype_effect import EFFECT_PATHS, dtype_effect
from drip_cert.sim.engine import SUB_BATCH_PATHS, default_workers, simulate
from drip_cert.sim.kernel import build_chunk_fn
from drip_cert.sim.noise import normal_columns, normals, normals_via_jax

N = 4

BOUND_STEPS = 200
"""Steps per timed call of the component bound and the engine/reference comparison (with
:data:`~drip_cert.sim.engine.SUB_BATCH_PATHS` paths: ~0.1-0.3 s per call)."""

BOUND_REPEATS = 5
"""Interleaved repeats of each timed call; the median is printed (the machine is shared)."""

TANH_PER_PATH_STEP = 64 + 64 + 32
"""Hidden activations of one path-step: the policy's two 64-wide layers and h's 32-wide one."""


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
    _tanh_alternatives(min(n_paths, SUB_BATCH_PATHS), n_steps)


TANH_FORMS: dict[str, Callable] = {
    "XLA tanh": jnp.tanh,
    "1 - 2/(1 + exp(2x))": lambda x: 1.0 - 2.0 / (1.0 + jnp.exp(2.0 * x)),
    "sign(x) (1 - e)/(1 + e), e = exp(-2|x|)": lambda x: jnp.copysign(
        (1.0 - jnp.exp(-2.0 * jnp.abs(x))) / (1.0 + jnp.exp(-2.0 * jnp.abs(x))), x
    ),
    "-sign(x) m/(2 + m), m = expm1(-2|x|)": lambda x: (
        -jnp.sign(x) * jnp.expm1(-2.0 * jnp.abs(x)) / (2.0 + jnp.expm1(-2.0 * jnp.abs(x)))
    ),
}
"""Ways to write ``tanh`` timed against XLA's own (issue 26): the engine keeps the fastest that
is as accurate as the arithmetic (XLA's, in both dtypes, on this machine)."""


def _scan_call(f: Callable, z0, half, js) -> Callable[[], Any]:
    """A call of one jitted scan of ``z -> f(z) + half`` over ``js`` from ``z0``."""
    run = jax.jit(lambda z: jax.lax.scan(lambda c, j: (f(c) + half, None), z, js)[0])
    return lambda: run(z0)


def _tanh_alternatives(batch: int, steps: int) -> None:
    """CPU ns of :data:`TANH_PER_PATH_STEP` tanh per path-step in each of :data:`TANH_FORMS`,
    and each form's largest relative error on [-20, 20] against numpy's float64 tanh."""
    x = np.linspace(-20.0, 20.0, 200_001)
    ref = np.tanh(x)
    for dt in (np.float64, np.float32):
        half = np.asarray(0.5, dt)
        z0 = jnp.linspace(-3.0, 3.0, batch * TANH_PER_PATH_STEP, dtype=dt).reshape(batch, -1)
        js = jnp.arange(steps)
        calls = {name: _scan_call(f, z0, half, js) for name, f in TANH_FORMS.items()}
        ns = cpu_ns_per_path_step(calls, batch * steps)
        for name, f in TANH_FORMS.items():
            err = np.max(
                np.abs(np.asarray(f(jnp.asarray(x, dt)), np.float64) - ref)
                / np.abs(ref).clip(1e-300)
            )
            print(
                f"  tanh {np.dtype(dt).name}: {name:40s} {ns[name]:6.1f} CPU ns per path-step, "
                f"max relative error {err:.2g}"
            )


def _float32(model, cfg: SimConfig, r64) -> None:
    """``simulate`` in float32 end to end and with the policy alone in float32: rates, ratios
    to float64, and the effect on the gaps (all four scenarios, the first paths)."""
    steps = cfg.n_paths * cfg.n_steps
    e64 = steps / r64.run_s
    for what, kw in (
        ("end to end", {"dtype": "float32"}),
        ("policy only", {"policy_dtype": "float32"}),
    ):
        r32 = simulate(model, dataclasses.replace(cfg, **kw), x0_sampler, progress=False)
        e32 = steps / r32.run_s
        print(
            f"  simulate, float32 {what}: run {r32.run_s:.2f} s -> {e32:.3g} steps/s, "
            f"{e32 / e64:.2f}x float64 (wall time)"
        )
        eff = dtype_effect(
            model,
            dataclasses.replace(cfg, scenarios=SCENARIOS, **kw),
            x0_sampler,
            n_paths=min(EFFECT_PATHS, cfg.n_paths),
        )
        worst = max(eff.gaps, key=lambda g: g.max_abs_mean)
        print(
            f"  float32 {what}, effect on {eff.n_paths} paths: gap means moved by <= "
            f"{eff.max_abs_gap_mean:.2g} ({worst.name}: max mean {worst.max_mean_64:.4g} -> "
            f"{worst.max_mean_32:.4g}), {eff.max_relative_to_ci:.2g}x the CI half-width; "
            f"states by <= {eff.max_abs_state:.2g}"
        )


def plain_scan_reference(
    h: MLP,
    pol: MLP,
    l1: L1Params,
    n_steps: int,
    dtype=np.float64,
    *,
    mlps: bool = True,
    noise: bool = True,
    seed: int = 0,
) -> Callable:
    """The benchmark's step as a plain ``lax.scan``: ``run(x0 (B, 4), idx (B,)) -> x_T``.

    What a user would write for the learned + L1-DRAC true SDE of :func:`build_system`: the
    MLPs as ``x @ W.T + b`` and ``tanh``, the L1-DRAC filter (15a)-(15c), Euler-Maruyama with
    the engine's counter-based normals (:func:`drip_cert.sim.noise.normals`, so that it ends
    in the engine's states); no records, status codes or divergence guard. ``mlps=False`` and
    ``noise=False`` remove the MLPs (``h = 0``, policy ``-0.2 x``) and the normals: the "rest"
    of the component bound.
    """
    f = np.dtype(dtype).type
    hw = [(np.asarray(w, dtype), np.asarray(b, dtype)) for w, b in h.params()]
    pw = [(np.asarray(w, dtype), np.asarray(b, dtype)) for w, b in pol.params()]
    gT = np.asarray(0.25 * np.eye(N), dtype)  # g is symmetric
    thT = np.asarray(np.linalg.solve(gT.T @ gT, gT.T).T, dtype)
    k_bm = jax.random.fold_in(jax.random.PRNGKey(seed), 2)
    dt, sq = f(l1.dt), f(math.sqrt(l1.dt))
    gain, decay, fgain, lam_s = (
        f(v) for v in (l1.adaptation_gain, l1.filter_decay, l1.filter_input_gain, l1.lambda_s)
    )

    def mlp(params, x):
        for w, b in params[:-1]:
            x = jnp.tanh(x @ w.T + b)
        return x @ params[-1][0].T + params[-1][1]

    def step(carry, j, idx):
        x, xh, eta, lam = carry
        if mlps:
            fk = -0.05 * x - 0.25 * mlp(hw, x) + mlp(pw, x) @ gT
        else:
            fk = -0.05 * x + (-0.2 * x) @ gT
        sample = (j > 0) & (j % l1.k == 0)
        tilde = xh - x
        lam = jnp.where(sample, gain * tilde, lam)
        u = -eta
        eta = decay * eta + fgain * (lam @ thT)
        xh = xh + dt * (-lam_s * tilde + fk + u @ gT + lam)
        nrm = jnp.sqrt(jnp.sum(x * x, axis=1, keepdims=True))
        drift = fk + u @ gT + (0.1 + 0.05 * nrm)
        sig = 0.1 + 0.05 * jnp.sqrt(nrm)
        z = normals(k_bm, idx, j, N, dtype) if noise else jnp.full_like(x, 0.5)
        x = x + dt * drift + sig * (sq * z)
        return (x, xh, eta, lam), None

    @jax.jit
    def run(x0, idx):
        x0 = x0.astype(dtype)
        zero = jnp.zeros_like(x0)
        body = partial(step, idx=idx)
        return jax.lax.scan(body, (x0, x0, zero, zero), jnp.arange(n_steps, dtype=jnp.uint32))[0][0]

    return run


def cpu_ns_per_path_step(
    calls: dict[str, Callable[[], Any]], path_steps: int, repeats: int = BOUND_REPEATS
) -> dict[str, float]:
    """Median CPU nanoseconds per path-step of each call, the calls interleaved (a change of the
    machine's load hits all of them alike). Each is called once first (compilation)."""
    for c in calls.values():
        jax.block_until_ready(c())
    times: dict[str, list[float]] = {k: [] for k in calls}
    for _ in range(repeats):
        for k, c in calls.items():
            t0 = time.process_time()
            jax.block_until_ready(c())
            times[k].append((time.process_time() - t0) / path_steps * 1e9)
    return {k: float(np.median(v)) for k, v in times.items()}


def _ingredients(
    h: MLP, pol: MLP, l1: L1Params, batch: int, steps: int, dtype
) -> dict[str, Callable]:
    """One jitted scan per ingredient of a path-step at the engine's shapes (``batch`` paths,
    ``steps`` steps), each a closure timing one call: the five dense products, the
    :data:`TANH_PER_PATH_STEP` tanh, the normals, and the rest of the step."""
    key = jax.random.PRNGKey(0)
    idx = jnp.arange(batch, dtype=jnp.uint32)
    x0 = jax.random.uniform(key, (batch, N)).astype(dtype)
    js = jnp.arange(steps, dtype=jnp.uint32)
    ws = [np.asarray(w, dtype) for m in (pol, h) for w, _ in m.params()]
    half = np.asarray(0.5, dtype)

    def scan(body, init):
        run = jax.jit(lambda c: jax.lax.scan(lambda c, j: (body(c, j), None), c, js)[0])
        return lambda: run(init)

    def products(x, j):  # 4-64-64-4 and 4-32-4 without activations (the biases fuse in)
        p = ((x @ ws[0].T) @ ws[1].T) @ ws[2].T
        q = (x @ ws[3].T) @ ws[4].T
        return half * x + 1e-3 * (p + q)

    def tanhs(z, j):  # the fixed point of z = tanh(z) + 1/2 keeps z normal (no denormals)
        return jnp.tanh(z) + half

    def noise(x, j):  # in the engine's form: float32 column by column (normal_columns)
        if np.dtype(dtype) == np.float32:
            return half * x + jnp.stack(normal_columns(key, idx, j, N, dtype), axis=1)
        return half * x + normals(key, idx, j, N, dtype)

    rest = plain_scan_reference(h, pol, l1, steps, dtype, mlps=False, noise=False)
    return {
        "products": scan(products, x0),
        "tanh": scan(tanhs, jnp.zeros((batch, TANH_PER_PATH_STEP), dtype)),
        "normals": scan(noise, x0),
        "rest": lambda: rest(x0, idx),
    }


def _engine_vs_bound(model, h: MLP, pol: MLP, cfg: SimConfig, steps: int) -> dict[str, float]:
    """The engine's kernel against the plain-scan reference and the component bound, per dtype,
    in CPU time of one single-threaded call on one sub-batch; prints them, returns the kernel's
    CPU-ns per path-step per dtype."""
    batch = min(SUB_BATCH_PATHS, cfg.n_paths)
    rec = next(r for r in (100, 50, 20, 10, 5, 2, 1) if steps % r == 0)
    kcfg = dataclasses.replace(
        cfg, T=steps * cfg.dt, n_paths=batch, chunk_size=batch, record_every=rec
    )
    idx = jnp.arange(batch, dtype=jnp.uint32)
    x0 = jax.random.uniform(jax.random.PRNGKey(1), (batch, N), minval=-1.0, maxval=1.0)
    out = {}
    for dt in ("float64", "float32"):
        kern = build_chunk_fn(model, dataclasses.replace(kcfg, dtype=dt), x0_sampler).compile(batch)
        ref = plain_scan_reference(h, pol, cfg.l1, steps, np.dtype(dt))
        calls = {"engine": lambda k=kern: k(idx), "reference": lambda r=ref: r(x0, idx)}
        calls.update(_ingredients(h, pol, cfg.l1, batch, steps, np.dtype(dt)))
        ns = cpu_ns_per_path_step(calls, batch * steps)
        bound = ns["products"] + ns["tanh"] + ns["normals"] + ns["rest"]
        parts = ", ".join(f"{k} {ns[k]:.0f}" for k in ("products", "tanh", "normals", "rest"))
        print(
            f"  {dt}, {batch} paths x {steps} steps, CPU ns per path-step (one core, median of "
            f"{BOUND_REPEATS}): engine {ns['engine']:.0f}, plain-scan reference "
            f"{ns['reference']:.0f} -> engine / reference {ns['reference'] / ns['engine']:.2f}x"
        )
        print(
            f"  {dt} component bound {bound:.0f} ns ({parts}) = "
            f"{1e9 / bound:.3g} path-steps/s per core; engine at "
            f"{100 * bound / ns['engine']:.0f} % of it"
        )
        out[dt] = ns["engine"]
    print(f"  engine kernel, float32 / float64 speed: {out['float64'] / out['float32']:.2f}x")
    return out


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
    ap.add_argument("--no-bound", action="store_true", help="skip the component bound")
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
    print(
        f"  engine ({workers} workers): compile {res.compile_s:.2f} s, run {res.run_s:.2f} s "
        f"-> {eng:.3g} steps/s (wall time; load average {os.getloadavg()[0]:.1f} on "
        f"{os.cpu_count()} CPUs)"
    )
    if not args.no_bound:
        _engine_vs_bound(model, h, pol, cfg, min(n_steps, BOUND_STEPS))
    if args.float32:
        _float32(model, cfg, res)
    if args.dask:
        _dask(model, cfg, workers)
    rss = resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 1024  # Linux: KiB
    print(f"  peak resident memory after the engine: {rss:.0f} MiB (chunks of {cfg.chunk_size})")
    if not args.no_profile:
        r1 = simulate(model, cfg, x0_sampler, progress=False, workers=1)
        r2 = simulate(model, cfg, x0_sampler, progress=False, workers=2)
        p1, p2 = (
            simulate(
                model, cfg, x0_sampler, progress=False, backend=Backend("processes", n_workers=n)
            )
            for n in (1, 2)
        )
        print(
            f"  engine, 1 worker: run {r1.run_s:.2f} s, 2 workers: {r2.run_s:.2f} s -> 2 workers "
            f"/ 1 worker {r1.run_s / r2.run_s:.2f}x as threads; as processes pinned to a core "
            f"(--backend processes) 1 worker {p1.run_s:.2f} s, 2 workers {p2.run_s:.2f} s -> "
            f"{p1.run_s / p2.run_s:.2f}x, start-up {p2.compile_s:.1f} s per call not included "
            f"(wall time; load average {os.getloadavg()[0]:.1f})"
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
