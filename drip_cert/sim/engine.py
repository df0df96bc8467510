"""Monte-Carlo engine: the four processes of the DRIP paper, simulated pathwise in one pass.

Scenarios (DRIP Definition "Systems", eqs. NominalProcesses and L1DRACProcess):

``expert_nominal``   ``dx*  = (f(t,x*) + g(t) pi*(x*)) dt``,           ``x*_0 = xi ~ D``
``learned_nominal``  ``dx'  = (f(t,x') + g(t) pi_IL(x')) dt``,         ``x'_0 = xi``
``learned_true``     ``dX   = (f + g pi_IL + Lambda_mu)(t,X) dt + (p + Lambda_sigma)(t,X) dW``
``learned_l1_true``  as ``learned_true`` with ``pi_ad = pi_IL + U_L1`` (L1-DRAC (15)).

Discretisation: Euler-Maruyama with step ``dt`` for the SDEs and explicit Euler with the SAME
``dt`` for the nominal ODEs. Using one scheme for all four makes the gaps measure the difference
of the processes, not of integrators: with ``pi_IL = pi*`` and no uncertainty every gap is
exactly zero. Euler is first order for the ODEs; choose ``dt`` accordingly.

Couplings. Identity coupling of the initial laws by default: ``X_0 = x'_0 = x*_0 = xi`` (the
DRIP paper's ``D = D_bar``). With ``x0_bar_sampler`` the true processes start from
``xi_bar ~ D_bar`` drawn INDEPENDENTLY of ``xi`` (the product coupling, one admissible coupling
in Definition "ImitationGap"). ``learned_true`` and ``learned_l1_true`` are driven by the SAME
Brownian path (common random numbers); each process has the law the paper defines, and the
comparison with/without L1 has less Monte-Carlo noise.

Randomness. Path ``i`` draws its initial states from ``fold_in(k_x0, i)`` (and
``fold_in(k_x0bar, i)``), with ``k_* = fold_in(PRNGKey(seed), const)``. Component ``c`` of its
standard normal increment at step ``j`` is ``sqrt(2) erfinv(u)``, ``u`` in (-1, 1) built from the
64 bits of ``threefry2x32(k_bm; (i, j d + c))`` -- the counter-based hash behind ``jax.random``,
unrolled so that XLA fuses it into the step (:mod:`drip_cert.sim.noise`); a vmapped
``fold_in`` + ``normal`` per path and step costs more (the benchmark prints both). The numbers
of a path depend only on the seed, its global index and the step, so neither the chunk size nor
the number of concurrent workers changes them; the statistics are summed path by path in global
order (:mod:`drip_cert.numerics.stats`), so they do not change either, bit for bit.

Divergence. After every step a path whose state is non-finite or whose norm exceeds
``divergence_cap`` is frozen at its last good state and gets a status code (``STATUS_NONFINITE``
or ``STATUS_CAP``); it is excluded from every gap that involves its scenario, and the fraction is
reported per scenario. The run never stops because of a path.

Resume. With ``run_dir`` the settings are hashed (configuration, model name, a numerical
fingerprint of the model and the samplers) and the accumulators are written atomically after
each chunk; a rerun with the same settings continues after the last finished chunk, and its result
is bit-for-bit that of an uninterrupted run.
"""

from __future__ import annotations

import dataclasses
import functools
import hashlib
import json
import math
import os
import sys
import time
from collections import deque
from collections.abc import Callable
from concurrent.futures import ThreadPoolExecutor
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from drip_cert._jax import jax, jnp
from drip_cert.control.l1drac import L1Params, L1State, l1_init, l1_step
from drip_cert.errors import SpecError
from drip_cert.model.numeric import SimModel
from drip_cert.numerics import stats as _stats
from drip_cert.numerics.atomic_io import atomic_savez, atomic_write_text
from drip_cert.sim.noise import normals

__all__ = [
    "GAPS",
    "SCENARIOS",
    "STATUS_CAP",
    "STATUS_NONFINITE",
    "STATUS_OK",
    "ScenarioStatus",
    "SimConfig",
    "SimResult",
    "build_chunk_fn",
    "simulate",
]

SCENARIOS = ("expert_nominal", "learned_nominal", "learned_true", "learned_l1_true")
STATUS_OK = 0
STATUS_NONFINITE = 1
STATUS_CAP = 2

GAPS = (
    # name, process a, process b: r_t = ||a_t - b_t||
    ("policy", "learned_nominal", "expert_nominal"),
    ("total_true", "learned_true", "expert_nominal"),
    ("uncertainty_true", "learned_true", "learned_nominal"),
    ("total_l1", "learned_l1_true", "expert_nominal"),
    ("uncertainty_l1", "learned_l1_true", "learned_nominal"),
)

_STEP_RTOL = 1e-9
"""Relative tolerance on T/dt being an integer (float inputs like T=5, dt=1e-3 are a few ulps
off); anything larger is a horizon that the grid does not hit."""

_MAX_CHUNK_BYTES = 1 << 30
"""Largest recorded-state block one chunk may return (1 GiB): beyond it the run would swap on
small machines; the error says to reduce chunk_size or record fewer times."""

_STATE_FILE = "state.npz"
_SETTINGS_FILE = "settings.json"


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
        Subset of :data:`SCENARIOS` to simulate.
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
    """

    T: float
    dt: float
    n_paths: int
    seed: int = 0
    chunk_size: int = 4096
    scenarios: tuple[str, ...] = SCENARIOS
    l1: L1Params | None = None
    record_every: int = 10
    n_sample_paths: int = 8
    p_max: int = 4
    kappas: tuple[float, ...] = ()
    w2_times: tuple[float, ...] = ()
    w2_points: int = 2000
    ci_level: float = 0.95
    divergence_cap: float = 1e6

    def __post_init__(self) -> None:
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
        return out


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
        """JSON-ready dictionary."""
        return {
            "name": self.name,
            "n_paths": self.n_paths,
            "n_nonfinite": self.n_nonfinite,
            "n_capped": self.n_capped,
            "diverged_fraction": self.diverged_fraction,
        }


@dataclass(frozen=True)
class SimResult:
    """Result of :func:`simulate`.

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
        :class:`~drip_cert.numerics.stats.GapStats` per gap of :data:`GAPS` that was simulated.
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
        for g in self.gaps:
            if g.name == name:
                return g
        raise KeyError(f"gap {name!r} was not simulated; have {[g.name for g in self.gaps]}")

    def scenario_status(self, name: str) -> ScenarioStatus:
        """The :class:`ScenarioStatus` of scenario ``name``."""
        for s in self.status:
            if s.name == name:
                return s
        raise KeyError(f"scenario {name!r} was not simulated")

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


# ----------------------------------------------------------------------------------------------
# the jitted chunk simulator


def build_chunk_fn(
    model: SimModel,
    config: SimConfig,
    x0_sampler: Callable,
    x0_bar_sampler: Callable | None = None,
) -> Callable:
    """The jitted chunk simulator ``idx (B,) uint32 -> (records, codes)``.

    ``records`` has shape ``(n_records, n_scenarios, B, n)`` (states on the recorded grid, frozen
    after divergence) and ``codes`` ``(n_scenarios, B)`` (status codes). Time-major: one
    ``lax.scan`` over steps with the whole chunk in the carry, nested in a scan over records.
    The seed is a traced argument and the settings that do not shape the simulation are
    normalised away, so runs that differ only in them reuse one compiled program.
    """
    if model.learned is None and any(s != "expert_nominal" for s in config.scenarios):
        raise SpecError(
            "the model has no learned policy; simulate only 'expert_nominal' or give one",
            field="SimModel.learned",
        )
    if config.n_steps * model.d >= 2**32:
        raise SpecError(
            f"n_steps * d = {config.n_steps * model.d} exceeds the 32-bit noise counter; "
            "shorten T or enlarge dt",
            field="SimConfig.dt",
        )
    static = dataclasses.replace(
        config,
        seed=0,
        n_paths=1,
        chunk_size=1,
        n_sample_paths=0,
        p_max=1,
        kappas=(),
        w2_times=(),
        w2_points=1,
        ci_level=0.95,
    )
    return functools.partial(
        _chunk_jit,
        jax.random.PRNGKey(config.seed),
        model=_ByIdentity(model),
        config=static,
        x0_sampler=_ByIdentity(x0_sampler),
        x0_bar_sampler=_ByIdentity(x0_bar_sampler),
    )


class _ByIdentity:
    """Static-argument wrapper hashed and compared by the identity of what it holds.

    jit caches compiled programs by static arguments; user callables need not be hashable,
    and the same model object must hit the cache.
    """

    __slots__ = ("obj",)

    def __init__(self, obj) -> None:
        self.obj = obj

    def __hash__(self) -> int:
        return id(self.obj)

    def __eq__(self, other) -> bool:
        return isinstance(other, _ByIdentity) and other.obj is self.obj


def _chunk_impl(key, idx, *, model, config, x0_sampler, x0_bar_sampler):
    """Body of :func:`build_chunk_fn` (``model``, ``config`` and the samplers are static)."""
    model = model.obj
    x0_sampler = x0_sampler.obj
    x0_bar_sampler = x0_bar_sampler.obj
    scen = config.scenarios
    dt = config.dt
    sqrt_dt = math.sqrt(dt)
    inv_cap = 1.0 / config.divergence_cap
    stride = config.record_every
    n_out = config.n_records - 1
    l1p = config.l1
    true_scen = [s for s in scen if s in ("learned_true", "learned_l1_true")]
    d = model.d

    k_x0 = jax.random.fold_in(key, 0)
    k_x0bar = jax.random.fold_in(key, 1)
    k_bm = jax.random.fold_in(key, 2)

    f_b = jax.vmap(model.f, in_axes=(None, 0))
    lam_mu_b = jax.vmap(model.lam_mu, in_axes=(None, 0))
    diff_b = jax.vmap(lambda t, x: model.p(t, x) + model.lam_sigma(t, x), in_axes=(None, 0))
    expert_b = jax.vmap(model.expert)
    learned_b = jax.vmap(model.learned) if model.learned is not None else None
    # Theta_ad and the step counter depend on time only: one copy for the whole chunk
    shared = L1State(x_hat=0, eta=0, lam_hat=0, theta=None, step=None)
    l1_b = (
        jax.vmap(
            lambda st, x, fk, g_t, th: l1_step(l1p, st, x, fk, g_t, th),
            in_axes=(shared, 0, 0, None, None),
            out_axes=(0, shared),
        )
        if l1p is not None
        else None
    )

    def known_drift(t, x, g_t, policy_b):
        # f(t,x) + g(t) pi(x), batched: (B, n)
        return f_b(t, x) + policy_b(x) @ g_t.T

    def guard(x_old, x_new, code):
        nonfinite = ~jnp.all(jnp.isfinite(x_new), axis=-1)
        scaled = x_new * inv_cap  # ||x|| > cap without overflowing the square
        capped = jnp.sum(scaled * scaled, axis=-1) > 1.0
        new_code = jnp.where(
            code != STATUS_OK,
            code,
            jnp.where(nonfinite, STATUS_NONFINITE, jnp.where(capped, STATUS_CAP, STATUS_OK)),
        )
        frozen = new_code != STATUS_OK
        return jnp.where(frozen[:, None], x_old, x_new), new_code.astype(code.dtype)

    def step(carry, j):
        xs, codes, l1s, idx = carry
        t = j.astype(jnp.float64) * dt
        g_t = model.g(t)
        new_xs, new_codes = [], []
        dw = None
        if true_scen:
            dw = sqrt_dt * normals(k_bm, idx, j, d)
        for i, s in enumerate(scen):
            x = xs[i]
            if s == "expert_nominal":
                x_new = x + dt * known_drift(t, x, g_t, expert_b)
            elif s == "learned_nominal":
                x_new = x + dt * known_drift(t, x, g_t, learned_b)
            elif s == "learned_true":
                drift = known_drift(t, x, g_t, learned_b) + lam_mu_b(t, x)
                noise = jnp.einsum("bnd,bd->bn", diff_b(t, x), dw)
                x_new = x + dt * drift + noise
            else:  # learned_l1_true
                fk = known_drift(t, x, g_t, learned_b)
                u, l1s = l1_b(l1s, x, fk, g_t, model.theta_ad(t))
                drift = fk + u @ g_t.T + lam_mu_b(t, x)
                noise = jnp.einsum("bnd,bd->bn", diff_b(t, x), dw)
                x_new = x + dt * drift + noise
            x_new, c_new = guard(x, x_new, codes[i])
            new_xs.append(x_new)
            new_codes.append(c_new)
        return (tuple(new_xs), tuple(new_codes), l1s, idx), None

    def record_block(carry, r):
        js = (r * stride + jnp.arange(stride)).astype(jnp.uint32)
        carry, _ = jax.lax.scan(step, carry, js)
        return carry, jnp.stack(carry[0])

    def chunk(idx):
        x0 = jax.vmap(lambda i: x0_sampler(jax.random.fold_in(k_x0, i)))(idx)
        if x0_bar_sampler is not None:
            x0b = jax.vmap(lambda i: x0_bar_sampler(jax.random.fold_in(k_x0bar, i)))(idx)
        else:
            x0b = x0
        x0 = x0.astype(jnp.float64)
        x0b = x0b.astype(jnp.float64)
        xs = tuple(x0b if s in true_scen else x0 for s in scen)
        zero = jnp.zeros(idx.shape, dtype=jnp.int8)
        codes = []
        for x in xs:  # a non-finite or too large initial state is a divergence at t = 0
            _, c = guard(x, x, zero)
            codes.append(c)
        l1s = None
        if "learned_l1_true" in scen:
            l1s = jax.vmap(l1_init, in_axes=(0, None), out_axes=shared)(
                x0b, model.theta_ad(jnp.float64(0.0))
            )
        carry = (xs, tuple(codes), l1s, idx)
        carry, recs = jax.lax.scan(record_block, carry, jnp.arange(n_out, dtype=jnp.uint32))
        recs = jnp.concatenate([jnp.stack(xs)[None], recs], axis=0)
        return recs, jnp.stack(carry[1])

    return chunk(idx)


_chunk_jit = jax.jit(
    _chunk_impl, static_argnames=("model", "config", "x0_sampler", "x0_bar_sampler")
)


# ----------------------------------------------------------------------------------------------
# accumulators of a run (pure updates), their file format, the resume hash


@dataclass(frozen=True)
class _RunState:
    chunks_done: int
    sums: tuple[_stats.GapSums, ...]
    samples: np.ndarray  # (S, n_sample, n_rec, n)
    sample_status: np.ndarray  # (S, n_sample) int8
    clouds: np.ndarray  # (n_w2, S, 2N, n)
    cloud_status: np.ndarray  # (S, 2N) int8
    n_nonfinite: np.ndarray  # (S,) int64
    n_capped: np.ndarray  # (S,) int64
    n_done: int


def _new_state(model: SimModel, cfg: SimConfig) -> _RunState:
    s = len(cfg.scenarios)
    n_keep = min(cfg.n_sample_paths, cfg.n_paths)
    return _RunState(
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


def _absorb(state: _RunState, cfg: SimConfig, idx: np.ndarray, recs, codes) -> _RunState:
    """Add one chunk's recorded states and codes to the run state (pure)."""
    recs = np.asarray(recs)
    codes = np.asarray(codes)
    real = idx < cfg.n_paths
    ok = (codes == STATUS_OK) & real[None, :]
    sums = []
    for (_, a, b), gs in zip(cfg.gaps, state.sums):
        ia, ib = cfg.scenarios.index(a), cfg.scenarios.index(b)
        r = _stats.norms_sequential(recs[:, ia] - recs[:, ib]).T  # (B, n_rec)
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
    return _RunState(
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


def _state_arrays(state: _RunState) -> dict[str, np.ndarray]:
    out = {
        "chunks_done": np.int64(state.chunks_done),
        "n_done": np.int64(state.n_done),
        "samples": state.samples,
        "sample_status": state.sample_status,
        "clouds": state.clouds,
        "cloud_status": state.cloud_status,
        "n_nonfinite": state.n_nonfinite,
        "n_capped": state.n_capped,
    }
    for i, gs in enumerate(state.sums):
        out[f"sums{i}.count"] = np.int64(gs.count)
        out[f"sums{i}.power_sums"] = gs.power_sums
        out[f"sums{i}.tail_counts"] = gs.tail_counts
        out[f"sums{i}.max"] = gs.max
        out[f"sums{i}.path_max"] = gs.path_max
    return out


def _state_from_arrays(a: dict[str, np.ndarray], template: _RunState) -> _RunState:
    sums = []
    for i, gs in enumerate(template.sums):
        sums.append(
            dataclasses.replace(
                gs,
                count=int(a[f"sums{i}.count"]),
                power_sums=a[f"sums{i}.power_sums"],
                tail_counts=a[f"sums{i}.tail_counts"],
                max=a[f"sums{i}.max"],
                path_max=a[f"sums{i}.path_max"],
            )
        )
    return _RunState(
        chunks_done=int(a["chunks_done"]),
        sums=tuple(sums),
        samples=a["samples"],
        sample_status=a["sample_status"],
        clouds=a["clouds"],
        cloud_status=a["cloud_status"],
        n_nonfinite=a["n_nonfinite"],
        n_capped=a["n_capped"],
        n_done=int(a["n_done"]),
    )


def _fingerprint(model: SimModel, x0_sampler, x0_bar_sampler) -> str:
    """Hash of the model's and samplers' values at fixed probe points (detects edited code)."""
    rng = np.random.default_rng(12345)
    xs = jnp.asarray(rng.normal(size=(3, model.n)))
    ts = (0.0, 0.37, 1.9)
    vals = []
    for t, x in zip(ts, xs):
        t = jnp.float64(t)
        vals += [model.f(t, x), model.g(t), model.p(t, x), model.lam_mu(t, x)]
        vals += [model.lam_sigma(t, x), model.expert(x), model.theta_ad(t)]
        if model.learned is not None:
            vals.append(model.learned(x))
    key = jax.random.PRNGKey(7)
    vals.append(x0_sampler(key))
    if x0_bar_sampler is not None:
        vals.append(x0_bar_sampler(key))
    h = hashlib.sha256()
    for v in vals:
        h.update(np.ascontiguousarray(np.asarray(v, dtype=np.float64)).tobytes())
    return h.hexdigest()


def _settings_hash(model, cfg, x0_sampler, x0_bar_sampler) -> str:
    payload = {
        "config": cfg.to_dict(),
        "model": model.name,
        "sizes": [model.n, model.m, model.d],
        "fingerprint": _fingerprint(model, x0_sampler, x0_bar_sampler),
        "has_x0_bar": x0_bar_sampler is not None,
        "format": 2,  # 2: per-path maxima in the state file
    }
    return hashlib.sha256(json.dumps(payload, sort_keys=True).encode()).hexdigest()


# ----------------------------------------------------------------------------------------------
# the driver


def simulate(
    model: SimModel,
    config: SimConfig,
    x0_sampler: Callable,
    x0_bar_sampler: Callable | None = None,
    run_dir: str | Path | None = None,
    progress: bool | None = None,
    stop_after_chunks: int | None = None,
    workers: int | None = None,
) -> SimResult:
    """Simulate the scenarios of ``config`` on ``model`` and return their statistics.

    Parameters
    ----------
    model
        The :class:`~drip_cert.model.numeric.SimModel`.
    config
        :class:`SimConfig`.
    x0_sampler
        ``key -> (n,)``: one draw of ``xi ~ D`` (jax-traceable).
    x0_bar_sampler
        Optional ``key -> (n,)`` for ``xi_bar ~ D_bar``, drawn independently of ``xi``; when
        ``None``, ``xi_bar = xi`` (identity coupling).
    run_dir
        Directory for resumable runs (created if missing).
    progress
        Show a tqdm bar; ``None`` shows it only when stderr is a terminal.
    stop_after_chunks
        Simulate at most this many NEW chunks in this call (the result is then marked
        incomplete unless all chunks are done).
    workers
        Compiled calls run at once from a thread pool (``None``: the usable CPU cores on the CPU
        backend, 1 on an accelerator). One call keeps two cores only partly busy; concurrent
        calls fill them (``benchmarks/mc_throughput.py``: 3.6e6 path-steps/s with 1 worker,
        4.4e6 with 2, on the 4-D paper system). Fewer chunks than workers are split into equal
        sub-batches. Results do not depend on ``workers``, bit for bit: the noise of
        a path is a function of its global index, and chunks are absorbed in order.

    Returns
    -------
    SimResult
    """
    if not isinstance(model, SimModel):
        raise SpecError("model must be a SimModel (see drip_cert.model.numeric.make_model)")
    if not isinstance(config, SimConfig):
        raise SpecError("config must be a SimConfig")
    cfg = config
    rec_bytes = cfg.n_records * len(cfg.scenarios) * cfg.chunk_size * model.n * 8
    if rec_bytes > _MAX_CHUNK_BYTES:
        raise SpecError(
            f"one chunk would record {rec_bytes / 2**20:.0f} MiB of states "
            f"({cfg.n_records} times x {len(cfg.scenarios)} scenarios x {cfg.chunk_size} paths); "
            "reduce chunk_size or increase record_every",
            field="SimConfig.chunk_size",
        )
    h = _settings_hash(model, cfg, x0_sampler, x0_bar_sampler)
    state = _new_state(model, cfg)
    rdir = None
    if run_dir is not None:
        rdir = Path(run_dir)
        rdir.mkdir(parents=True, exist_ok=True)
        sfile = rdir / _SETTINGS_FILE
        if sfile.exists():
            old = json.loads(sfile.read_text())
            if old.get("settings_hash") != h:
                raise SpecError(
                    f"run directory {str(rdir)!r} belongs to a run with other settings "
                    f"(hash {str(old.get('settings_hash'))[:12]} != {h[:12]}); use a new "
                    "run_dir or delete it to start over",
                    field="run_dir",
                )
            if (rdir / _STATE_FILE).exists():
                with np.load(rdir / _STATE_FILE, allow_pickle=False) as data:
                    state = _state_from_arrays(dict(data.items()), state)
        else:
            atomic_write_text(
                sfile,
                json.dumps(
                    {"settings_hash": h, "model": model.name, "config": cfg.to_dict()}, indent=2
                ),
            )

    todo = list(range(state.chunks_done, cfg.n_chunks))
    if stop_after_chunks is not None:
        todo = todo[: max(0, int(stop_after_chunks))]
    compile_s = 0.0
    t_run = 0.0
    if todo:
        n_workers = _default_workers() if workers is None else int(workers)
        if n_workers < 1:
            raise SpecError(f"workers must be >= 1, got {workers!r}", field="workers")
        # memory: at most _MAX_CHUNK_BYTES of records in flight
        n_workers = max(1, min(n_workers, _MAX_CHUNK_BYTES // max(rec_bytes, 1)))
        parts = max(1, min(n_workers // len(todo), cfg.chunk_size))
        sub = -(-cfg.chunk_size // parts)  # paths per call; the last part is padded
        fn = build_chunk_fn(model, cfg, x0_sampler, x0_bar_sampler)
        t0 = time.perf_counter()
        compiled = fn.func.lower(
            *fn.args, jax.ShapeDtypeStruct((sub,), jnp.uint32), **fn.keywords
        ).compile()
        compile_s = time.perf_counter() - t0
        show = progress if progress is not None else sys.stderr.isatty()
        from tqdm.auto import tqdm

        def run_part(idx):
            # blocks in the worker thread, so concurrent calls really execute concurrently
            return jax.block_until_ready(compiled(*fn.args, idx))

        def submit(c: int):
            idx = np.arange(c * cfg.chunk_size, (c + 1) * cfg.chunk_size, dtype=np.uint32)
            padded = np.concatenate([idx, np.full(parts * sub - idx.size, idx[-1], np.uint32)])
            futs = [
                pool.submit(run_part, jnp.asarray(padded[q * sub : (q + 1) * sub]))
                for q in range(parts)
            ]
            return idx, futs

        def finish(st: _RunState, job) -> _RunState:
            idx, futs = job
            outs = [jax.device_get(f.result()) for f in futs]
            recs = np.concatenate([o[0] for o in outs], axis=2)[:, :, : idx.size]
            codes = np.concatenate([o[1] for o in outs], axis=1)[:, : idx.size]
            st = _absorb(st, cfg, idx.astype(np.int64), recs, codes)
            if rdir is not None:
                atomic_savez(rdir / _STATE_FILE, _state_arrays(st))
            bar.update(1)
            return st

        bar = tqdm(total=cfg.n_chunks, initial=state.chunks_done, disable=not show, unit="chunk")
        t1 = time.perf_counter()
        in_flight = max(1, n_workers // parts)  # chunks computing while the oldest is absorbed
        with ThreadPoolExecutor(max_workers=n_workers) as pool:
            pending: deque = deque()
            for c in todo:
                pending.append(submit(c))
                if len(pending) >= in_flight:
                    state = finish(state, pending.popleft())
            while pending:
                state = finish(state, pending.popleft())
        bar.close()
        t_run = time.perf_counter() - t1
    return _result(model, cfg, h, state, compile_s, t_run)


def _default_workers() -> int:
    """Usable CPU cores on the CPU backend, else 1."""
    if jax.default_backend() != "cpu":
        return 1
    try:
        return max(1, len(os.sched_getaffinity(0)))
    except AttributeError:  # not on Linux
        return max(1, os.cpu_count() or 1)


def _result(model, cfg: SimConfig, h: str, state: _RunState, compile_s, run_s) -> SimResult:
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
        model_name=model.name,
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
