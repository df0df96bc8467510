"""The throughput benchmark: its numpy baseline computes what the engine computes, and it runs."""

from __future__ import annotations

import re

import numpy as np
import pytest

from drip_cert._jax import jax, jnp
from drip_cert.control.l1drac import L1Params
from drip_cert.sim.config import SimConfig
from drip_cert.sim.kernel import build_chunk_fn
from drip_cert.sim.noise import normals
from tests.helpers import ROOT, load_script

bench = load_script(ROOT / "benchmarks" / "mc_throughput.py", "mc_throughput")

# float64 rounding of the same operations in another order, grown over 1000 steps: observed
# 3e-15; 1e-10 leaves room and still fails on any modelling difference (another filter
# bandwidth, omega 40 instead of 50, moves the end states by 7.6e-3, checked below)
SAME_PATH_TOL = 1e-10

# the printed rates have 2 significant digits (each within 5 % of the true rate, so their
# quotient within 11 %), the printed ratio one decimal (within 0.05)
RATE_QUOTIENT_REL = 0.11
RATIO_DECIMAL_ABS = 0.05


def _engine_run(paths: int, n_steps: int, dt: float, seed: int):
    model, h, pol = bench.build_system(0)
    l1 = L1Params(omega=50.0, lambda_s=10.0, Ts=10 * dt, dt=dt)
    cfg = SimConfig(
        T=n_steps * dt,
        dt=dt,
        n_paths=paths,
        seed=seed,
        chunk_size=paths,
        scenarios=("learned_l1_true",),
        l1=l1,
        record_every=n_steps,
        n_sample_paths=0,
    )
    idx = jnp.arange(paths, dtype=jnp.uint32)
    recs, codes = build_chunk_fn(model, cfg, bench.x0_sampler)(idx)
    assert not np.any(np.asarray(codes))
    recs = np.asarray(recs)
    k_bm = jax.random.fold_in(jax.random.PRNGKey(seed), 2)  # the engine's Brownian key
    z = jax.jit(lambda j: normals(k_bm, idx, j, 4))

    def noise(j):
        return np.asarray(z(jnp.uint32(j)))

    return h, pol, l1, recs[0, 0], recs[-1, 0], noise


def test_numpy_baseline_computes_what_the_engine_computes():
    """Fed the engine's initial states and normals, the numpy loop ends in the same states."""
    paths, n_steps, dt = 64, 1000, 1e-3
    h, pol, l1, x0, x_eng, noise = _engine_run(paths, n_steps, dt, seed=3)
    _, x_np = bench.numpy_loop(h, pol, l1, paths, n_steps, seed=0, x0=x0, noise=noise)
    assert np.max(np.abs(x_np - x_eng)) < SAME_PATH_TOL
    # the comparison can fail: another L1 filter bandwidth moves the end states visibly
    other = L1Params(omega=40.0, lambda_s=10.0, Ts=10 * dt, dt=dt)
    _, x_other = bench.numpy_loop(h, pol, other, paths, n_steps, seed=0, x0=x0, noise=noise)
    assert np.max(np.abs(x_other - x_eng)) > 1e3 * SAME_PATH_TOL


# the same operations in float32 (unit roundoff 6e-8) over 1000 steps of an O(1) contracting
# state, with the float32 normals: observed 1.0e-6 against the engine's float32 kernel
SAME_PATH_TOL_F32 = 1e-4


@pytest.mark.parametrize(
    ("dtype", "tol"), [("float64", SAME_PATH_TOL), ("float32", SAME_PATH_TOL_F32)]
)
def test_plain_scan_reference_computes_what_the_engine_computes(dtype, tol):
    """The engine / reference ratio compares equal work: from the engine's initial states, the
    reference ends in the engine's states (float64 and float32 end to end)."""
    paths, n_steps, dt = 64, 1000, 1e-3
    model, h, pol = bench.build_system(0)
    l1 = L1Params(omega=50.0, lambda_s=10.0, Ts=10 * dt, dt=dt)
    cfg = SimConfig(
        T=n_steps * dt,
        dt=dt,
        n_paths=paths,
        seed=3,
        chunk_size=paths,
        scenarios=("learned_l1_true",),
        l1=l1,
        record_every=n_steps,
        n_sample_paths=0,
        dtype=dtype,
    )
    idx = jnp.arange(paths, dtype=jnp.uint32)
    recs, codes = build_chunk_fn(model, cfg, bench.x0_sampler)(idx)
    assert not np.any(np.asarray(codes))
    recs = np.asarray(recs)
    assert recs.dtype == np.dtype(dtype)
    ref = bench.plain_scan_reference(h, pol, l1, n_steps, np.dtype(dtype), seed=3)
    x_ref = np.asarray(ref(jnp.asarray(recs[0, 0]), idx))
    assert np.max(np.abs(x_ref - recs[-1, 0])) < tol
    # and it can fail: the reference without its noise ends elsewhere
    quiet = bench.plain_scan_reference(h, pol, l1, n_steps, np.dtype(dtype), noise=False, seed=3)
    assert np.max(np.abs(np.asarray(quiet(jnp.asarray(recs[0, 0]), idx)) - recs[-1, 0])) > 1e2 * tol


@pytest.mark.slow  # compiles a dozen programs: ~10 s on 2 busy cores
def test_benchmark_prints_engine_over_reference_and_the_component_bound(capsys):
    assert bench.main(["--paths", "256", "--T", "0.02", "--no-profile"]) == 0
    lines = capsys.readouterr().out.strip().splitlines()
    for dt in ("float64", "float32"):  # engine / reference and the component bound, per dtype
        assert any(re.search(rf"{dt}, .* engine / reference \d+\.\d+x$", ln) for ln in lines)
        assert any(
            re.search(rf"{dt} component bound .* engine at \d+ % of it$", ln) for ln in lines
        )
    assert any(re.search(r"float32 / float64 speed: \d+\.\d+x$", ln) for ln in lines)


def test_benchmark_runs_and_prints_its_ratio_line(capsys):
    assert bench.main(["--paths", "256", "--T", "0.02", "--no-profile", "--no-bound"]) == 0
    lines = capsys.readouterr().out.strip().splitlines()
    last = lines[-1]
    m = re.fullmatch(r"engine (\S+) steps/s, numpy (\S+) steps/s, ratio (\S+)x", last)
    assert m is not None, last
    eng, npy, ratio = (float(v) for v in m.groups())
    assert eng > 0 and npy > 0
    q = eng / npy
    assert abs(ratio - q) <= RATIO_DECIMAL_ABS + RATE_QUOTIENT_REL * q


@pytest.mark.slow  # three processes compile the engine: ~20 s on 2 busy cores
def test_workers_benchmark_prints_threads_and_pinned_processes(capsys):
    workers = load_script(ROOT / "benchmarks" / "mc_workers.py", "mc_workers")
    if workers.main(["--paths", "256", "--T", "0.02", "--repeats", "1"]) == 1:
        pytest.skip("needs 2 usable cores")
    lines = capsys.readouterr().out.strip().splitlines()
    assert re.search(r"threads \(the engine\): .* 2 workers / 1 worker \d+\.\d+x", lines[-4])
    assert re.search(r"processes pinned to a core: .* -> \d+\.\d+x", lines[-3])
    assert re.search(r"backend processes: .* 2 workers / 1 worker \d+\.\d+x", lines[-2])
    assert re.search(r"start-up per call \d+\.\d+ s", lines[-2])
    assert re.fullmatch(r"  CPU efficiency .*: threads \d+%, pinned \d+%, backend \d+%", lines[-1])
