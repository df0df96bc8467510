"""The four processes of the DRIP paper simulated for one system: the scenario runner of
:func:`drip_cert.validate.validate` and its limits.
"""

from __future__ import annotations

from pathlib import Path
from typing import Any

import numpy as np

from drip_cert.model.system import System
from drip_cert.progress import bars_enabled

MAX_STEPS = 200_000  #: largest number of Euler steps per path accepted for a certified-T_s run
SHORT_STEPS = 2_000  #: steps of the short-horizon run at the certified T_s (dt = T_s)
SHORT_PATHS = 200  #: paths of the short-horizon run
MIN_SIMULABLE_TS = 1e-9
#: below this T_s an Euler step changes an O(1) state by less than ~1e-9 relative: with float64
#: (eps 2.2e-16) the drift of one step keeps fewer than 7 digits, and below ~1e-15 it is lost
#: entirely, so a run at such T_s says nothing about the certificate


def x0_sampler(box, theta: np.ndarray | None = None) -> Any:
    """Uniform initial law on the box ``D`` (jax key -> state); with ``theta``, its push-forward
    by ``z = theta x`` (the initial law of a system in metric coordinates)."""
    from drip_cert._jax import jax, jnp  # jax: keep off the API's import path

    b = np.array(box, dtype=float)
    lo, hi = jnp.asarray(b[:, 0]), jnp.asarray(b[:, 1])
    th = None if theta is None else jnp.asarray(theta, dtype=jnp.float64)

    def sample(key):
        x = jax.random.uniform(key, (b.shape[0],), minval=lo, maxval=hi, dtype=jnp.float64)
        return x if th is None else th @ x

    return sample


# ----------------------------------------------------------------------------------------------
# the checks: one statistic against one certified number, with a status


def has_known_diffusion(s: System) -> bool:
    """Whether the known diffusion ``p`` of ``s`` is not identically zero."""
    return s.diffusion is not None and any(e != 0 for e in s.diffusion)


def scenarios_for(s: System, base: tuple[str, ...]) -> tuple[str, ...]:
    """``base`` plus L1-DRAC's nominal SDE (4b) (``nominal_sde``) when ``s`` has a known
    diffusion: the uncertainty gaps are then measured against it, like with like. Without the
    L1-DRAC process when ``g`` depends on the state (L1-DRAC needs ``g(t)``)."""
    if s.g_depends_on_x:
        base = tuple(b for b in base if b != "learned_l1_true")
    return (*base, "nominal_sde") if has_known_diffusion(s) else tuple(base)


def run_scenarios(
    s: System,
    *,
    paths: int,
    seed: int,
    dt: float,
    T: float,
    l1_params: Any,
    chunk_size: int,
    record_every: int,
    kappas: tuple[float, ...] = (),
    p_max: int = 4,
    w2_times: tuple[float, ...] = (),
    run_dir: Path | None = None,
    progress: bool = False,
    x0_box: Any = None,
    theta: np.ndarray | None = None,
    backend: Any = None,
    policy_dtype: str = "float64",
    dtype: str = "float64",
):
    """Simulate the four scenarios of the DRIP paper for ``s`` (with its learned policy), and
    L1-DRAC's nominal SDE (4b) when ``s`` has a known diffusion (:func:`scenarios_for`).

    Initial states are uniform on ``x0_box`` (default ``s.support``), mapped by ``theta`` when
    ``s`` is a system in coordinates ``z = theta x``; the gap statistics are then those of the
    user's ``x = theta^{-1} z`` (:attr:`~drip_cert.sim.config.SimConfig.gap_readout`).
    ``backend`` (:class:`~drip_cert.sim.backend.Backend`), ``policy_dtype`` and ``dtype`` go to
    the engine."""
    from drip_cert.sim.config import (  # jax: keep off the API's import path
        DEFAULT_SCENARIOS,
        SimConfig,
    )
    from drip_cert.sim.engine import simulate  # jax: keep off the API's import path

    cfg = SimConfig(
        T=T,
        dt=dt,
        n_paths=paths,
        seed=seed,
        chunk_size=min(chunk_size, paths),
        l1=None if s.g_depends_on_x else l1_params,
        record_every=record_every,
        kappas=kappas,
        p_max=p_max,
        w2_times=w2_times,
        w2_points=min(2000, max(2, paths // 2)),
        gap_readout=None if theta is None else tuple(map(tuple, np.linalg.inv(theta))),
        policy_dtype=policy_dtype,
        dtype=dtype,
        scenarios=scenarios_for(s, DEFAULT_SCENARIOS),
    )
    box = s.support if x0_box is None else x0_box
    return simulate(
        s.numeric,
        cfg,
        x0_sampler(box, theta),
        run_dir=run_dir,
        progress=bars_enabled(progress),  # a bar redrawn in place: on a terminal only
        backend=backend,
    )


def dtype_effect(
    s: System, result: Any, *, x0_box: Any = None, theta: np.ndarray | None = None, backend=None
):
    """The float32 path's effect (the policy alone, or end to end) on the gaps of the run
    ``result`` of :func:`run_scenarios`, measured on its first paths against float64
    (:func:`~drip_cert.sim.dtype_effect.dtype_effect`)."""
    from drip_cert.sim.dtype_effect import dtype_effect as effect  # jax: keep off the import path

    box = s.support if x0_box is None else x0_box
    return effect(s.numeric, result.config, x0_sampler(box, theta), backend=backend)
