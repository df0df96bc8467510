"""The ``processes`` backend: one worker process per core, pinned before it imports jax, the same
bits as the local engine, and no worker outlives a run that fails or is interrupted."""

from __future__ import annotations

import dataclasses
import os

import numpy as np
import pytest

from drip_cert.cli import build_parser
from drip_cert.errors import DripCertError, SpecError
from drip_cert.sim import engine, kernel, process_backend
from drip_cert.sim.backend import BACKENDS, Backend
from drip_cert.sim.engine import simulate
from tests.test_engine import _CFG, _arrays, _assert_bitwise, _mlp_model, _x0, _x0_bar

PROCS = Backend("processes", n_workers=2)
"""Two workers: with three chunks of 32 paths, each worker computes whole chunks, and the chunks
finish out of order whenever the second worker is faster."""


@pytest.fixture(scope="module")
def model():
    return _mlp_model()


@pytest.fixture(scope="module")
def local_result(model):
    return simulate(model, _CFG, _x0, _x0_bar, progress=False)


@pytest.fixture
def pools(monkeypatch):
    """Every worker pool started in the test (to check that its processes are gone)."""
    made: list[process_backend._Pool] = []

    class Recorded(process_backend._Pool):
        def __init__(self, n_workers: int) -> None:
            super().__init__(n_workers)
            made.append(self)

    monkeypatch.setattr(process_backend, "_Pool", Recorded)
    return made


def _all_gone(pools) -> None:
    assert pools, "no worker pool was started"
    for pool in pools:
        for p in pool.procs:
            assert p.returncode is not None, f"worker {p.pid} still running"
            with pytest.raises(ProcessLookupError):  # exited and reaped: no orphan, no zombie
                os.kill(p.pid, 0)


def test_processes_equal_local_bit_for_bit(model, local_result, pools, capsys):
    """Records (sample paths), gap means and every other statistic: the same bits, 3 chunks
    on 2 pinned workers; each worker reports its own core; the bar counts every path-step."""
    res = simulate(model, _CFG, _x0, _x0_bar, progress=True, backend=PROCS)
    err = capsys.readouterr().err
    total = _CFG.n_paths * _CFG.n_steps  # 9000: tqdm writes 9.00k
    assert f"{total / 1000:.2f}k/{total / 1000:.2f}k" in err and "100%" in err, err[-300:]
    assert res.complete and res.n_paths_done == _CFG.n_paths and _CFG.n_chunks == 3
    assert np.array_equal(res.sample_paths, local_result.sample_paths, equal_nan=True)
    for g, g0 in zip(res.gaps, local_result.gaps, strict=True):
        assert np.array_equal(g.mean, g0.mean)
    _assert_bitwise(local_result, res)
    assert res.settings_hash == local_result.settings_hash
    start = process_backend.last_startup
    assert start is not None and len(start.cores) == 2
    if process_backend.can_pin():
        usable = sorted(os.sched_getaffinity(0))
        assert [c for c in start.cores] == [(usable[k % len(usable)],) for k in range(2)]
    _all_gone(pools)


def test_an_exception_in_a_chunk_propagates_and_ends_the_workers(model, monkeypatch, pools):
    """The kernel exported for one path more than the workers are sent: every chunk call raises
    in its worker; the run raises that message, naming the chunk, and no worker survives."""
    export = kernel.ChunkKernel.export
    monkeypatch.setattr(kernel.ChunkKernel, "export", lambda self, b: export(self, b + 1))
    with pytest.raises(DripCertError, match=r"chunk \d failed in worker process \d: TypeError"):
        simulate(model, _CFG, _x0, _x0_bar, progress=False, backend=PROCS)
    _all_gone(pools)


def test_keyboard_interrupt_ends_the_workers(model, monkeypatch, pools):
    """Ctrl-C in the caller while chunks are computed (raised at the first progress update):
    KeyboardInterrupt propagates and every worker is terminated and reaped."""

    class Interrupting:
        def __enter__(self):
            return self

        def __exit__(self, *exc):
            return False

        def update(self, n):
            raise KeyboardInterrupt

    monkeypatch.setattr(engine, "_bar", lambda *a: Interrupting())
    with pytest.raises(KeyboardInterrupt):
        simulate(model, _CFG, _x0, _x0_bar, progress=False, backend=PROCS)
    _all_gone(pools)


def test_without_flatbuffers_the_error_says_what_to_install(model, monkeypatch, pools):
    monkeypatch.setattr(process_backend, "_can_serialize", lambda: False)
    with pytest.raises(SpecError, match="pip install flatbuffers"):
        simulate(model, _CFG, _x0, _x0_bar, progress=False, backend=PROCS)
    assert not pools  # refused before any worker starts


def test_backend_and_cli_accept_processes():
    assert "processes" in BACKENDS and Backend("processes").describe() == "processes"
    args = build_parser().parse_args(["validate", "x.toml", "--backend", "processes"])
    assert args.backend == "processes"


@pytest.mark.slow
@pytest.mark.parametrize(
    ("chunk_size", "n_workers"),
    [
        (90, 3),  # one chunk split into three sub-batches of 30 on 3 workers (round robin)
        (45, 5),  # two chunks, each in two sub-batches of 23 (the last one padded)
    ],
)
def test_processes_sub_batches_bit_for_bit(model, local_result, chunk_size, n_workers):
    cfg = dataclasses.replace(_CFG, chunk_size=chunk_size)
    res = simulate(
        model, cfg, _x0, _x0_bar, progress=False, backend=Backend("processes", n_workers=n_workers)
    )
    _assert_bitwise(local_result, res)


@pytest.mark.slow
def test_resume_across_local_and_processes(model, local_result, tmp_path):
    """One chunk on processes, the rest locally (and the reverse): the result and the resume
    file are those of an uninterrupted local run."""
    a, b = tmp_path / "a", tmp_path / "b"
    simulate(model, _CFG, _x0, _x0_bar, run_dir=a, stop_after_chunks=1, backend=PROCS)
    simulate(model, _CFG, _x0, _x0_bar, run_dir=b, stop_after_chunks=1)
    ra = simulate(model, _CFG, _x0, _x0_bar, run_dir=a)
    rb = simulate(model, _CFG, _x0, _x0_bar, run_dir=b, backend=PROCS)
    _assert_bitwise(local_result, ra)
    _assert_bitwise(local_result, rb)
    assert np.array_equal(_arrays(ra)[0], _arrays(rb)[0])
