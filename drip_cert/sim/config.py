"""Settings of one Monte-Carlo run and the names they use: scenarios, gaps, path status codes.

The four processes of the DRIP paper (Definition "Systems", eqs. NominalProcesses and
L1DRACProcess) are the :data:`SCENARIOS`; the imitation gaps of Definition "ImitationGap" are the
:data:`GAPS` (pairs of scenarios); a path's status code says whether and how it diverged.
"""

from __future__ import annotations

import dataclasses
import math
from dataclasses import dataclass

import numpy as np

from drip_cert.control.l1drac import L1Params
from drip_cert.errors import SpecError
from drip_cert.vocabulary import DEFAULT_SCENARIOS, GAPS, SCENARIOS

__all__ = [
    "DEFAULT_SCENARIOS",
    "GAPS",
    "DTYPES",
    "POLICY_DTYPES",
    "SCENARIOS",
    "STATUS_CAP",
    "STATUS_NONFINITE",
    "STATUS_OK",
    "SimConfig",
]


STATUS_OK = 0
"""A path that stayed finite and below ``divergence_cap``."""
STATUS_NONFINITE = 1
"""A path frozen at its last good state after a non-finite state."""
STATUS_CAP = 2
"""A path frozen at its last good state after its norm exceeded ``divergence_cap``."""


POLICY_DTYPES = ("float64", "float32")
"""Dtypes the learned policy can be evaluated in (:attr:`SimConfig.policy_dtype`)."""

DTYPES = ("float64", "float32")
"""Dtypes of a whole simulation (:attr:`SimConfig.dtype`)."""

_STEP_RTOL = 1e-9
"""Relative tolerance on T/dt being an integer (float inputs like T=5, dt=1e-3 are a few ulps
off); anything larger is a horizon that the grid does not hit."""


@dataclass(frozen=True)
class SimConfig:
    """Settings of one Monte-Carlo run.

    Parameters
    ----------
    T, dt
        Horizon and step; ``T / dt`` must be an integer.
    n_paths
        Number of paths.
    seed
        Seed of ``jax.random.PRNGKey``.
    chunk_size
        Paths simulated together (memory bound; does not change the result).
    scenarios
        Subset of :data:`SCENARIOS` to simulate (default :data:`DEFAULT_SCENARIOS`).
    l1
        :class:`~drip_cert.control.l1drac.L1Params` (required for ``learned_l1_true``;
        its ``dt`` must equal ``dt``).
    record_every
        Steps between recorded times (must divide ``T / dt``); statistics live on that grid.
    n_sample_paths
        Number of full trajectories kept (the first paths) for plots.
    p_max
        Moments ``E||.||^{2p}`` are accumulated for ``p = 1..p_max``.
    kappas
        Tail thresholds for ``P(||.|| >= kappa)``.
    w2_times
        Times (snapped to the recorded grid) where the empirical W2 is computed.
    w2_points
        Cloud size for W2 (two disjoint sets of this size are kept per law).
    ci_level
        Confidence level of the t intervals and of the Clopper-Pearson bounds.
    divergence_cap
        A path whose state norm exceeds this is frozen and excluded.
    gap_readout
        ``None``, or an invertible ``n x n`` matrix ``M`` (nested tuples): the gap statistics
        are then of ``||M (a - b)||`` instead of ``||a - b||`` (a system simulated in
        ``z = Theta x`` with ``M = Theta^{-1}`` gives the gaps in the user's ``x``); recorded
        trajectories and W2 clouds stay in the simulated coordinates.
    policy_dtype
        ``"float32"``: the learned policy alone in float32 (:mod:`drip_cert.sim.precision`).
    dtype
        ``"float32"``: the whole simulation in float32 (states, noise, every vector field, the
        policy and L1-DRAC; :mod:`drip_cert.sim.kernel`); the statistics are accumulated in
        float64 either way. Opt-in; its effect on the gaps is measured against float64
        (:mod:`drip_cert.sim.dtype_effect`).
    """

    T: float
    dt: float
    n_paths: int
    seed: int = 0
    chunk_size: int = 4096
    scenarios: tuple[str, ...] = DEFAULT_SCENARIOS
    l1: L1Params | None = None
    record_every: int = 10
    n_sample_paths: int = 8
    p_max: int = 4
    kappas: tuple[float, ...] = ()
    w2_times: tuple[float, ...] = ()
    w2_points: int = 2000
    ci_level: float = 0.95
    divergence_cap: float = 1e6
    gap_readout: tuple[tuple[float, ...], ...] | None = None
    policy_dtype: str = "float64"
    dtype: str = "float64"

    def __post_init__(self) -> None:
        if self.policy_dtype not in POLICY_DTYPES:
            raise SpecError(
                f"policy_dtype must be one of {POLICY_DTYPES}, got {self.policy_dtype!r}",
                field="SimConfig.policy_dtype",
            )
        if self.dtype not in DTYPES:
            raise SpecError(
                f"dtype must be one of {DTYPES}, got {self.dtype!r}", field="SimConfig.dtype"
            )
        if self.gap_readout is not None:
            M = np.array(self.gap_readout, dtype=np.float64)
            if (
                M.ndim != 2
                or M.shape[0] != M.shape[1]
                or not np.all(np.isfinite(M))
                or np.linalg.matrix_rank(M) < M.shape[0]
            ):
                raise SpecError(
                    f"gap_readout must be a finite invertible square matrix, got {M.tolist()}",
                    field="SimConfig.gap_readout",
                )
            object.__setattr__(self, "gap_readout", tuple(tuple(map(float, r)) for r in M))
        for fld in ("T", "dt", "divergence_cap"):
            v = float(getattr(self, fld))
            if not (math.isfinite(v) and v > 0):
                raise SpecError(f"must be finite and > 0, got {v!r}", field=f"SimConfig.{fld}")
            object.__setattr__(self, fld, v)
        for fld, lo in (
            ("n_paths", 1),
            ("chunk_size", 1),
            ("record_every", 1),
            ("p_max", 1),
            ("n_sample_paths", 0),
            ("w2_points", 1),
            ("seed", 0),
        ):
            v = getattr(self, fld)
            if isinstance(v, bool) or not isinstance(v, int | np.integer) or int(v) < lo:
                raise SpecError(f"must be an integer >= {lo}, got {v!r}", field=f"SimConfig.{fld}")
            object.__setattr__(self, fld, int(v))
        ratio = self.T / self.dt
        if abs(ratio - round(ratio)) > _STEP_RTOL * ratio or round(ratio) < 1:
            raise SpecError(
                f"T={self.T!r} is not an integer multiple of dt={self.dt!r} (T/dt={ratio!r}); "
                "choose dt = T/N",
                field="SimConfig.dt",
            )
        if self.n_steps % self.record_every:
            raise SpecError(
                f"record_every={self.record_every} does not divide the {self.n_steps} steps; "
                "choose a divisor of T/dt",
                field="SimConfig.record_every",
            )
        scen = tuple(self.scenarios)
        bad = [s for s in scen if s not in SCENARIOS]
        if bad or not scen or len(set(scen)) != len(scen):
            raise SpecError(
                f"scenarios must be distinct names from {SCENARIOS}, got {scen}",
                field="SimConfig.scenarios",
            )
        object.__setattr__(self, "scenarios", tuple(s for s in SCENARIOS if s in scen))
        if self.n_paths >= 2**32:
            raise SpecError(
                f"at most 2**32 - 1 paths per run (path indices are 32-bit counters), got "
                f"{self.n_paths}; split the run over several seeds",
                field="SimConfig.n_paths",
            )
        if "learned_l1_true" in scen:
            if not isinstance(self.l1, L1Params):
                raise SpecError(
                    "scenario 'learned_l1_true' needs L1 parameters: pass l1=L1Params(...)",
                    field="SimConfig.l1",
                )
            if abs(self.l1.dt - self.dt) > _STEP_RTOL * self.dt:
                raise SpecError(
                    f"L1Params.dt={self.l1.dt!r} differs from the simulation dt={self.dt!r}; "
                    "build L1Params with the same dt",
                    field="SimConfig.l1",
                )
        if not 0.0 < float(self.ci_level) < 1.0:
            raise SpecError(f"must be in (0, 1), got {self.ci_level!r}", field="SimConfig.ci_level")
        object.__setattr__(self, "ci_level", float(self.ci_level))
        object.__setattr__(self, "kappas", tuple(float(k) for k in self.kappas))
        if any(not (math.isfinite(k) and k > 0) for k in self.kappas):
            raise SpecError(
                f"tail thresholds must be finite and > 0, got {self.kappas}",
                field="SimConfig.kappas",
            )
        wt = tuple(float(t) for t in self.w2_times)
        if any(not (0.0 <= t <= self.T) for t in wt):
            raise SpecError(
                f"W2 times must lie in [0, T={self.T}], got {wt}", field="SimConfig.w2_times"
            )
        object.__setattr__(self, "w2_times", wt)

    @property
    def n_steps(self) -> int:
        """Number of Euler steps ``T / dt``."""
        return int(round(self.T / self.dt))

    @property
    def n_records(self) -> int:
        """Number of recorded times, including ``t = 0``."""
        return self.n_steps // self.record_every + 1

    @property
    def record_times(self) -> np.ndarray:
        """The recorded times ``r * record_every * dt``."""
        return np.arange(self.n_records) * (self.record_every * self.dt)

    @property
    def n_chunks(self) -> int:
        """Number of chunks, the last one padded."""
        return -(-self.n_paths // self.chunk_size)

    @property
    def gaps(self) -> tuple[tuple[str, str, str], ...]:
        """The gaps whose two processes are both simulated."""
        return tuple(g for g in GAPS if g[1] in self.scenarios and g[2] in self.scenarios)

    @property
    def w2_record_indices(self) -> tuple[int, ...]:
        """Recorded-grid indices nearest to ``w2_times``."""
        step = self.record_every * self.dt
        return tuple(int(round(t / step)) for t in self.w2_times)

    @property
    def w2_n(self) -> int:
        """Cloud size actually used: ``min(w2_points, n_paths // 2)``."""
        return min(self.w2_points, self.n_paths // 2)

    def to_dict(self) -> dict:
        """JSON-ready dictionary (also the input of the resume hash)."""
        out = dataclasses.asdict(self)
        out["l1"] = dataclasses.asdict(self.l1) if self.l1 is not None else None
        out["scenarios"] = list(self.scenarios)
        out["kappas"] = list(self.kappas)
        out["w2_times"] = list(self.w2_times)
        if self.gap_readout is None:
            del out["gap_readout"]  # the resume hash of runs without one is unchanged
        else:
            out["gap_readout"] = [list(r) for r in self.gap_readout]
        if self.policy_dtype == "float64":
            del out["policy_dtype"]  # the resume hash of float64 runs is unchanged
        if self.dtype == "float64":
            del out["dtype"]
        return out
