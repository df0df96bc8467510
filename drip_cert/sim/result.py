"""The result of a Monte-Carlo run: gap statistics, W2 estimates and divergence bookkeeping."""

from __future__ import annotations

import dataclasses
import json
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from drip_cert.numerics import stats as _stats
from drip_cert.numerics.atomic_io import atomic_savez, atomic_write_text
from drip_cert.sim.accumulate import RunState
from drip_cert.sim.config import STATUS_OK, SimConfig

__all__ = ["ScenarioStatus", "SimResult", "build_result"]


@dataclass(frozen=True)
class ScenarioStatus:
    """Divergence bookkeeping of one scenario."""

    name: str
    n_paths: int
    n_nonfinite: int
    n_capped: int

    @property
    def diverged_fraction(self) -> float:
        """Fraction of paths frozen for divergence (either code)."""
        return (self.n_nonfinite + self.n_capped) / self.n_paths if self.n_paths else 0.0

    def to_dict(self) -> dict:
        """JSON-ready dictionary: the fields and ``diverged_fraction``."""
        return {**dataclasses.asdict(self), "diverged_fraction": self.diverged_fraction}


@dataclass(frozen=True)
class SimResult:
    """Result of :func:`~drip_cert.sim.engine.simulate`.

    Attributes
    ----------
    model_name, config, settings_hash
        What was run.
    complete
        False when the run stopped early (``stop_after_chunks``); statistics cover
        ``n_paths_done`` paths.
    n_paths_done
        Paths simulated (real ones, padding excluded).
    times
        Recorded times.
    gaps
        :class:`~drip_cert.numerics.stats.GapStats` per simulated gap of
        :data:`~drip_cert.sim.config.GAPS`.
    w2
        :class:`~drip_cert.numerics.stats.W2Estimate` per (time, pair).
    status
        :class:`ScenarioStatus` per scenario.
    sample_paths
        ``(n_scenarios, n_sample_paths, n_records, n)``: the first paths (frozen after divergence).
    sample_status
        ``(n_scenarios, n_sample_paths)`` status codes of the kept paths.
    compile_s, run_s
        JIT compile time and simulation wall time of this call (compile excluded).
    """

    model_name: str
    config: SimConfig
    settings_hash: str
    complete: bool
    n_paths_done: int
    times: np.ndarray
    gaps: tuple[_stats.GapStats, ...]
    w2: tuple[_stats.W2Estimate, ...]
    status: tuple[ScenarioStatus, ...]
    sample_paths: np.ndarray
    sample_status: np.ndarray
    compile_s: float
    run_s: float

    def gap(self, name: str) -> _stats.GapStats:
        """The :class:`GapStats` called ``name`` (``"policy"``, ``"uncertainty_l1"``, ...)."""
        return _named(self.gaps, name, "gap")

    def scenario_status(self, name: str) -> ScenarioStatus:
        """The :class:`ScenarioStatus` of scenario ``name``."""
        return _named(self.status, name, "scenario")

    def to_dict(self) -> dict:
        """JSON summary (no per-time arrays; those go to the .npz of :meth:`save`)."""
        return {
            "model": self.model_name,
            "settings_hash": self.settings_hash,
            "complete": self.complete,
            "n_paths_done": self.n_paths_done,
            "config": self.config.to_dict(),
            "gaps": [g.to_dict() for g in self.gaps],
            "w2": [w.to_dict() for w in self.w2],
            "status": [s.to_dict() for s in self.status],
            "compile_s": self.compile_s,
            "run_s": self.run_s,
        }

    def save(self, directory: str | Path) -> Path:
        """Write ``summary.json`` and ``arrays.npz`` into ``directory`` atomically; return it."""
        directory = Path(directory)
        directory.mkdir(parents=True, exist_ok=True)
        arrays: dict[str, np.ndarray] = {
            "times": self.times,
            "sample_paths": self.sample_paths,
            "sample_status": self.sample_status,
        }
        for g in self.gaps:
            for fld in (
                "mean",
                "ci_low",
                "ci_high",
                "moments",
                "lp_norms",
                "tail_freq",
                "tail_upper",
                "sample_max",
                "path_max",
            ):
                arrays[f"{g.name}.{fld}"] = getattr(g, fld)
        atomic_savez(directory / "arrays.npz", arrays)
        atomic_write_text(
            directory / "summary.json", json.dumps(self.to_dict(), indent=2, allow_nan=False)
        )
        return directory


def _named(items, name: str, what: str):
    """The item of ``items`` whose ``.name`` is ``name``; KeyError naming those there are."""
    for item in items:
        if item.name == name:
            return item
    raise KeyError(f"{what} {name!r} was not simulated; have {[i.name for i in items]}")


def build_result(
    model_name: str, cfg: SimConfig, h: str, state: RunState, compile_s: float, run_s: float
) -> SimResult:
    """The :class:`SimResult` of the paths in ``state``: gap statistics, W2 estimates, status.

    The W2 estimates need ``2 N`` absorbed paths (``N = cfg.w2_n``); a pair is skipped when
    either cloud half has no path of status OK.
    """
    times = cfg.record_times
    gaps = tuple(
        _stats.finalize(name, gs, times, cfg.ci_level)
        for (name, _, _), gs in zip(cfg.gaps, state.sums)
    )
    w2 = []
    n = cfg.w2_n
    if n >= 1 and state.n_done >= 2 * n:
        pairs = [(a, b) for _, a, b in cfg.gaps]
        for w, ri in enumerate(cfg.w2_record_indices):
            for a, b in pairs:
                ia, ib = cfg.scenarios.index(a), cfg.scenarios.index(b)
                ca, cb = state.clouds[w, ia], state.clouds[w, ib]
                oka = state.cloud_status[ia] == STATUS_OK
                okb = state.cloud_status[ib] == STATUS_OK
                a1, a2 = ca[:n][oka[:n]], ca[n:][oka[n:]]
                b1, b2 = cb[:n][okb[:n]], cb[n:][okb[n:]]
                if min(len(a1), len(a2), len(b1), len(b2)) == 0:
                    continue
                w2.append(
                    _stats.W2Estimate(
                        pair=(a, b),
                        time=float(times[ri]),
                        n_points=n,
                        w2=_stats.w2_empirical(a1, b2),
                        baseline_a=_stats.w2_empirical(a1, a2),
                        baseline_b=_stats.w2_empirical(b1, b2),
                    )
                )
    status = tuple(
        ScenarioStatus(s, state.n_done, int(state.n_nonfinite[i]), int(state.n_capped[i]))
        for i, s in enumerate(cfg.scenarios)
    )
    return SimResult(
        model_name=model_name,
        config=cfg,
        settings_hash=h,
        complete=state.chunks_done >= cfg.n_chunks,
        n_paths_done=state.n_done,
        times=times,
        gaps=gaps,
        w2=tuple(w2),
        status=status,
        sample_paths=state.samples,
        sample_status=state.sample_status,
        compile_s=float(compile_s),
        run_s=float(run_s),
    )
