"""The accumulators of a Monte-Carlo run and their update by one chunk of paths (pure).

A :class:`RunState` holds, for the paths absorbed so far, the power sums of every gap
(:mod:`drip_cert.numerics.stats`, summed path by path in global order), the first paths' full
trajectories, the W2 point clouds and the divergence counts. :func:`absorb` returns the state after
one more chunk; absorbing the chunks in order gives the same bits however the paths were computed.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from drip_cert.model.numeric import SimModel
from drip_cert.numerics import stats as _stats
from drip_cert.sim.config import STATUS_CAP, STATUS_NONFINITE, STATUS_OK, SimConfig

__all__ = ["RunState", "absorb", "new_state"]


@dataclass(frozen=True)
class RunState:
    """What a run has accumulated after ``chunks_done`` chunks (``S`` scenarios).

    Attributes
    ----------
    chunks_done, n_done
        Chunks absorbed and the real paths in them (padding excluded).
    sums
        :class:`~drip_cert.numerics.stats.GapSums` per simulated gap of the config.
    samples, sample_status
        ``(S, n_sample, n_records, n)`` trajectories of the first paths and ``(S, n_sample)``
        their int8 status codes.
    clouds, cloud_status
        ``(n_w2, S, 2 N, n)`` states of the first ``2 N`` paths at the W2 times and their
        ``(S, 2 N)`` codes.
    n_nonfinite, n_capped
        ``(S,)`` int64 counts of paths frozen for each kind of divergence.
    """

    chunks_done: int
    sums: tuple[_stats.GapSums, ...]
    samples: np.ndarray
    sample_status: np.ndarray
    clouds: np.ndarray
    cloud_status: np.ndarray
    n_nonfinite: np.ndarray
    n_capped: np.ndarray
    n_done: int


def new_state(model: SimModel, cfg: SimConfig) -> RunState:
    """The empty state of a run of ``cfg`` on ``model`` (nothing absorbed; NaN placeholders)."""
    s = len(cfg.scenarios)
    n_keep = min(cfg.n_sample_paths, cfg.n_paths)
    return RunState(
        chunks_done=0,
        sums=tuple(_stats.new_sums(cfg.n_records, cfg.p_max, cfg.kappas) for _ in cfg.gaps),
        samples=np.full((s, n_keep, cfg.n_records, model.n), np.nan),
        sample_status=np.zeros((s, n_keep), dtype=np.int8),
        clouds=np.full((len(cfg.w2_times), s, 2 * cfg.w2_n, model.n), np.nan),
        cloud_status=np.zeros((s, 2 * cfg.w2_n), dtype=np.int8),
        n_nonfinite=np.zeros(s, dtype=np.int64),
        n_capped=np.zeros(s, dtype=np.int64),
        n_done=0,
    )


def absorb(state: RunState, cfg: SimConfig, idx: np.ndarray, recs, codes) -> RunState:
    """Add one chunk's recorded states and codes to the run state (pure)."""
    recs = np.asarray(recs, dtype=np.float64)  # float32 runs: the statistics stay float64
    codes = np.asarray(codes)
    real = idx < cfg.n_paths
    ok = (codes == STATUS_OK) & real[None, :]
    sums = []
    M = None if cfg.gap_readout is None else np.array(cfg.gap_readout)
    for (_, a, b), gs in zip(cfg.gaps, state.sums):
        ia, ib = cfg.scenarios.index(a), cfg.scenarios.index(b)
        diff = recs[:, ia] - recs[:, ib]  # (n_rec, B, n)
        if M is not None:
            diff = _stats.map_sequential(diff, M)  # the gap in the readout's coordinates
        r = _stats.norms_sequential(diff).T  # (B, n_rec)
        sums.append(_stats.accumulate(gs, r, ok[ia] & ok[ib]))
    samples = state.samples.copy()
    sample_status = state.sample_status.copy()
    keep = np.nonzero(idx < samples.shape[1])[0]
    for k in keep:
        samples[:, idx[k]] = np.moveaxis(recs[:, :, k], 0, 1)
        sample_status[:, idx[k]] = codes[:, k]
    clouds = state.clouds.copy()
    cloud_status = state.cloud_status.copy()
    inc = np.nonzero(idx < clouds.shape[2])[0]
    for w, ri in enumerate(cfg.w2_record_indices):
        clouds[w][:, idx[inc]] = recs[ri][:, inc]
    cloud_status[:, idx[inc]] = codes[:, inc]
    return RunState(
        chunks_done=state.chunks_done + 1,
        sums=tuple(sums),
        samples=samples,
        sample_status=sample_status,
        clouds=clouds,
        cloud_status=cloud_status,
        n_nonfinite=state.n_nonfinite + np.sum((codes == STATUS_NONFINITE) & real, axis=1),
        n_capped=state.n_capped + np.sum((codes == STATUS_CAP) & real, axis=1),
        n_done=state.n_done + int(np.sum(real)),
    )
