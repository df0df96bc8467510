"""The Dask backend: the same bits as the local engine, resume files included, and a killed
worker costs only its chunks. A LocalCluster of 2 single-threaded worker processes on loopback."""

from __future__ import annotations

import dataclasses
import json
import os
import re
import signal
import threading
import time

import numpy as np
import pytest

from drip_cert.cli import main
from drip_cert.errors import SpecError
from drip_cert.sim.backend import SCHEDULER_ENV, Backend
from drip_cert.sim.config import SimConfig
from drip_cert.sim.engine import simulate
from tests.helpers import PAPER_4D_SPEC, ROOT

distributed = pytest.importorskip("distributed")

#: a LocalCluster of worker processes per test: end to end, in the slow group (make test-all, CI)
pytestmark = pytest.mark.slow

# the system of tests/test_engine.py (picked up from there, so both compare the same runs)
from tests.test_engine import _CFG, _arrays, _mlp_model, _x0, _x0_bar  # noqa: E402

PLANT = ROOT / "examples" / "regression_ci" / "plant.toml"
"""A small certified plant (validated at its certified parameters in seconds)."""

KILL_WAIT_S = 60.0
"""Longest wait for the killed run to get going / finish (a loaded 2-core machine compiles the
kernel in each worker in a few seconds)."""


def _assert_bitwise(r1, r2):
    a1, a2 = _arrays(r1), _arrays(r2)
    assert len(a1) == len(a2)
    for x, y in zip(a1, a2):
        assert x.shape == y.shape
        assert np.array_equal(x, y, equal_nan=True)


@pytest.fixture(scope="module")
def cluster():
    with distributed.LocalCluster(
        n_workers=2, threads_per_worker=1, processes=True, host="127.0.0.1", dashboard_address=":0"
    ) as c:
        yield c


@pytest.fixture(scope="module")
def model():
    return _mlp_model()


@pytest.fixture(scope="module")
def local_result(model):
    return simulate(model, _CFG, _x0, _x0_bar, progress=False)


def test_dask_equals_local_bit_for_bit_with_progress(cluster, model, local_result, capsys):
    """Three chunks as three tasks on two workers; the bar counts every path-step."""
    res = simulate(
        model,
        _CFG,
        _x0,
        _x0_bar,
        progress=True,
        backend=Backend("dask", cluster.scheduler_address),
    )
    _assert_bitwise(local_result, res)
    assert res.complete and res.n_paths_done == _CFG.n_paths
    assert res.settings_hash == local_result.settings_hash
    err = capsys.readouterr().err
    total = _CFG.n_paths * _CFG.n_steps  # 9000: tqdm writes 9.00k
    assert f"{total / 1000:.2f}k/{total / 1000:.2f}k" in err and "100%" in err, err[-300:]


def test_scheduler_from_the_environment_and_float32(cluster, model, monkeypatch):
    """DASK_SCHEDULER_ADDRESS is used when no address is given; the float32 policy path is the
    same on Dask as locally, bit for bit, and another chunk size changes nothing either."""
    monkeypatch.setenv(SCHEDULER_ENV, cluster.scheduler_address)
    backend = Backend("dask")
    assert backend.address == cluster.scheduler_address
    cfg = dataclasses.replace(_CFG, policy_dtype="float32", chunk_size=20)
    local = simulate(model, cfg, _x0, _x0_bar, progress=False)
    _assert_bitwise(local, simulate(model, cfg, _x0, _x0_bar, progress=False, backend=backend))


def test_resume_files_identical_and_backends_interchangeable(cluster, model, tmp_path):
    """A run directory written by Dask holds the same arrays as one written locally, after a
    partial run and after the rest; a run started locally resumes on Dask and vice versa."""
    dask = Backend("dask", cluster.scheduler_address)
    dirs = {name: tmp_path / name for name in ("local", "dask", "mixed")}
    simulate(model, _CFG, _x0, _x0_bar, run_dir=dirs["local"], stop_after_chunks=1)
    simulate(model, _CFG, _x0, _x0_bar, run_dir=dirs["dask"], stop_after_chunks=1, backend=dask)
    _assert_same_files(dirs["local"], dirs["dask"])
    simulate(model, _CFG, _x0, _x0_bar, run_dir=dirs["mixed"], stop_after_chunks=2)
    r_local = simulate(model, _CFG, _x0, _x0_bar, run_dir=dirs["local"])
    r_dask = simulate(model, _CFG, _x0, _x0_bar, run_dir=dirs["dask"], backend=dask)
    r_mixed = simulate(model, _CFG, _x0, _x0_bar, run_dir=dirs["mixed"], backend=dask)
    _assert_same_files(dirs["local"], dirs["dask"])
    _assert_same_files(dirs["local"], dirs["mixed"])
    _assert_bitwise(r_local, r_dask)
    _assert_bitwise(r_local, r_mixed)


def _assert_same_files(a, b):
    assert (a / "settings.json").read_text() == (b / "settings.json").read_text()
    with np.load(a / "state.npz") as za, np.load(b / "state.npz") as zb:
        assert sorted(za.files) == sorted(zb.files)
        for k in za.files:
            assert np.array_equal(za[k], zb[k], equal_nan=True), k


def test_a_system_from_a_spec_runs_remotely(cluster):
    """A spec's system (sympy expressions lowered to jax: not picklable) runs on Dask: the
    workers receive the exported kernel, not the model's code."""
    from drip_cert.control.l1drac import L1Params
    from drip_cert.spec import load_spec
    from drip_cert.validate.scenarios import x0_sampler

    s = load_spec(PAPER_4D_SPEC).system
    if s.learned is None:
        s = s.with_learned(list(s.expert))
    cfg = SimConfig(
        T=0.05,
        dt=0.005,
        n_paths=24,
        chunk_size=10,
        l1=L1Params(50.0, 10.0, 0.01, 0.005),
        record_every=2,
        seed=3,
    )
    samp = x0_sampler(s.support)
    local = simulate(s.numeric, cfg, samp, progress=False)
    remote = simulate(
        s.numeric, cfg, samp, progress=False, backend=Backend("dask", cluster.scheduler_address)
    )
    _assert_bitwise(local, remote)


def test_backend_errors_say_what_to_do(monkeypatch):
    monkeypatch.delenv(SCHEDULER_ENV, raising=False)
    with pytest.raises(SpecError, match="backend must be one of"):
        Backend("ray")
    with pytest.raises(SpecError, match="needs backend 'dask'"):
        Backend("local", "tcp://127.0.0.1:8786")
    with pytest.raises(SpecError, match="n_workers"):
        Backend("dask", n_workers=0)
    assert Backend("dask").address is None  # no address anywhere: a LocalCluster
    assert Backend("dask").describe() == "dask (LocalCluster)"
    # an address where no scheduler listens: a SpecError naming it, after the timeout
    dead = Backend("dask", "tcp://127.0.0.1:9", connect_timeout=1.0)
    with pytest.raises(SpecError, match="cannot reach the Dask scheduler"):
        simulate(_mlp_model(), _CFG, _x0, _x0_bar, progress=False, backend=dead)


def test_cli_scheduler_without_dask_is_a_usage_error(capsys):
    rc = main(["validate", str(PAPER_4D_SPEC), "--scheduler", "tcp://127.0.0.1:8786", "--json"])
    assert rc == 2
    assert "needs backend 'dask'" in capsys.readouterr().err


def _cancel_chunk_submissions(monkeypatch, chunk: int, times: int) -> list[str]:
    """Make the cluster cancel the first ``times`` submissions of chunk ``chunk`` (as the
    scheduler does for a key it has forgotten); returns the keys cancelled."""
    cancelled: list[str] = []
    submit = distributed.Client.submit

    def cancelling_submit(self, func, *args, key=None, **kwargs):
        fut = submit(self, func, *args, key=key, **kwargs)
        if re.fullmatch(rf"drip-chunk-[0-9a-f]+-{chunk}(-retry\d+)?", str(key)):
            if len(cancelled) < times:
                cancelled.append(str(key))
                self.cancel([fut])
        return fut

    monkeypatch.setattr(distributed.Client, "submit", cancelling_submit)
    return cancelled


def test_a_chunk_cancelled_by_the_cluster_is_submitted_again(
    cluster, model, local_result, monkeypatch
):
    """A chunk future cancelled by the cluster (CI saw ``already forgotten`` for a chunk lost
    with a killed worker) is submitted again under its key: the same bits as the local run."""
    cancelled = _cancel_chunk_submissions(monkeypatch, chunk=1, times=2)
    backend = Backend("dask", cluster.scheduler_address)
    res = simulate(model, _CFG, _x0, _x0_bar, progress=False, backend=backend)
    assert len(cancelled) == 2
    _assert_bitwise(local_result, res)


def test_a_chunk_cancelled_again_and_again_ends_the_run_with_a_clear_error(
    cluster, model, monkeypatch
):
    from drip_cert.errors import DripCertError
    from drip_cert.sim.dask_backend import MAX_RESUBMIT

    _cancel_chunk_submissions(monkeypatch, chunk=1, times=MAX_RESUBMIT + 1)
    backend = Backend("dask", cluster.scheduler_address)
    with pytest.raises(DripCertError, match="cancelled chunk 1 4 times"):
        simulate(model, _CFG, _x0, _x0_bar, progress=False, backend=backend)


def test_a_killed_worker_reruns_only_its_chunks(model, local_result):
    """SIGKILL one worker while it runs a chunk: the nanny restarts it, the scheduler re-runs
    that chunk elsewhere, the chunks already absorbed are not recomputed, and the result is the
    local one, bit for bit."""
    cfg = dataclasses.replace(_CFG, T=2.0, n_paths=12_000, chunk_size=1500, w2_times=(1.0,))
    local = simulate(model, cfg, _x0, _x0_bar, progress=False)
    with (
        distributed.LocalCluster(
            n_workers=2,
            threads_per_worker=1,
            processes=True,
            host="127.0.0.1",
            dashboard_address=":0",
        ) as cl,
        distributed.Client(cl) as client,
    ):
        pids = client.run(os.getpid)
        out: dict = {}

        def run():
            try:
                out["res"] = simulate(
                    model,
                    cfg,
                    _x0,
                    _x0_bar,
                    progress=False,
                    backend=Backend("dask", cl.scheduler_address),
                )
            except BaseException as exc:  # re-raised in the test's thread below
                out["err"] = exc

        with distributed.get_task_stream(client) as ts:
            th = threading.Thread(target=run)
            th.start()
            victim, key = _wait_for_running_chunk(client, min_chunk=2)
            os.kill(pids[victim], signal.SIGKILL)
            th.join(KILL_WAIT_S)
            assert not th.is_alive()
        if "err" in out:
            raise out["err"]
        res = out["res"]
    _assert_bitwise(local, res)
    runs: dict[str, list[str]] = {}
    for t in ts.data:
        if str(t["key"]).startswith("drip-chunk-"):  # a chunk cancelled by the cluster: -retryN
            runs.setdefault(str(t["key"]).split("-retry")[0], []).append(t["worker"])
    assert len(runs) == cfg.n_chunks  # every chunk completed
    assert victim not in runs[key]  # the chunk killed with its worker finished elsewhere
    # chunks done before the kill were absorbed and released: at most the in-flight window
    # (2 per worker thread) ran twice
    assert sum(len(w) for w in runs.values()) <= cfg.n_chunks + 4


def test_the_job_lost_with_every_worker_holding_it_is_recomputed(model):
    """CI saw every chunk cancelled for "lost dependencies": the kernel's bytes were scattered
    data, Dask's active memory manager kept one replica, and its worker was killed. Kill every
    worker that holds the job while a chunk runs: the job is recomputed from its spec, and the
    result is the local one, bit for bit (with a scattered job this run ends in the error)."""
    cfg = dataclasses.replace(_CFG, T=2.0, n_paths=12_000, chunk_size=1500, w2_times=(1.0,))
    local = simulate(model, cfg, _x0, _x0_bar, progress=False)
    with (
        distributed.LocalCluster(
            n_workers=2,
            threads_per_worker=1,
            processes=True,
            host="127.0.0.1",
            dashboard_address=":0",
        ) as cl,
        distributed.Client(cl) as client,
    ):
        pids = client.run(os.getpid)
        out: dict = {}

        def run():
            try:
                out["res"] = simulate(
                    model,
                    cfg,
                    _x0,
                    _x0_bar,
                    progress=False,
                    backend=Backend("dask", cl.scheduler_address),
                )
            except BaseException as exc:  # re-raised in the test's thread below
                out["err"] = exc

        th = threading.Thread(target=run)
        th.start()
        _wait_for_running_chunk(client, min_chunk=1)
        # the job: all data but chunk results (named drip-job-..., a scattered _ChunkJob-... before)
        holders = {
            w
            for k, ws in client.who_has().items()
            if not str(k).startswith("drip-chunk-")
            for w in ws
        }
        assert holders  # the job is held somewhere while a chunk runs
        for w in holders:
            os.kill(pids[w], signal.SIGKILL)
        th.join(KILL_WAIT_S)
        assert not th.is_alive()
        if "err" in out:
            raise out["err"]
    _assert_bitwise(local, out["res"])


def _wait_for_running_chunk(client, min_chunk: int) -> tuple[str, str]:
    """(worker address, task key) of a chunk task with index >= ``min_chunk`` now running (keys
    ``drip-chunk-<hash>-<c>`` or, for a chunk submitted again, ``...-<c>-retry<n>``)."""
    t_end = time.monotonic() + KILL_WAIT_S
    while time.monotonic() < t_end:
        for worker, keys in client.processing().items():
            for key in keys:
                m = re.fullmatch(r"drip-chunk-[0-9a-f]+-(\d+)(-retry\d+)?", str(key))
                if m and int(m.group(1)) >= min_chunk:
                    return worker, str(key)
        time.sleep(0.02)
    raise AssertionError("no chunk task started in time")


def test_cli_validate_on_dask_with_the_float32_policy(cluster, capsys):
    """`drip-cert validate --backend dask --scheduler ADDR --policy-dtype float32`: the report
    says the policy ran in float32 and how much that moved the gaps; the checks are those of
    the local float32 run."""
    common = ["validate", str(PLANT), "--trajectories", "100", "--seed", "0", "--json"]
    common += ["--policy-dtype", "float32"]
    rc = main([*common, "--backend", "dask", "--scheduler", cluster.scheduler_address])
    remote = json.loads(capsys.readouterr().out)
    assert rc == 0 and remote["status"] == "holds"
    assert remote["simulation"]["config"]["policy_dtype"] == "float32"
    eff = remote["empirical"]["policy_dtype_effect"]
    assert eff["n_paths"] == 100 and eff["max_abs_gap_mean"] >= 0
    assert any(n.startswith("policy evaluated in float32") for n in remote["notes"])
    assert main(common) == 0
    local = json.loads(capsys.readouterr().out)
    assert local["checks"] == remote["checks"]
