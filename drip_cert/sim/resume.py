"""Resumable runs: the settings hash, the run directory and the file format of a run's state.

With ``run_dir`` the settings are hashed (configuration, model name, a numerical fingerprint of the
model and the samplers) and the accumulators are written atomically after each chunk; a rerun with
the same settings continues after the last finished chunk, and its result is bit-for-bit that of
an uninterrupted run. A directory written with other settings is refused, never overwritten.
"""

from __future__ import annotations

import dataclasses
import hashlib
import json
from pathlib import Path

import numpy as np

from drip_cert._jax import jax, jnp
from drip_cert.errors import SpecError
from drip_cert.model.numeric import SimModel
from drip_cert.numerics.atomic_io import atomic_savez, atomic_write_text
from drip_cert.sim.accumulate import RunState
from drip_cert.sim.config import SimConfig

__all__ = ["open_run", "save_state", "settings_hash"]

_STATE_FILE = "state.npz"
_SETTINGS_FILE = "settings.json"


def open_run(run_dir: str | Path, h: str, model_name: str, cfg: SimConfig, empty: RunState):
    """Open (or create) the run directory of the settings with hash ``h``; return its state.

    Parameters
    ----------
    run_dir
        The directory (created if missing).
    h
        :func:`settings_hash` of this run.
    model_name, cfg
        Written with ``h`` into ``settings.json`` of a new directory.
    empty
        The state of a run with nothing done (the template of the saved arrays).

    Returns
    -------
    tuple of Path and RunState
        The directory and the saved state (``empty`` when nothing was saved yet).

    Raises
    ------
    SpecError
        When the directory belongs to a run with other settings.
    """
    rdir = Path(run_dir)
    rdir.mkdir(parents=True, exist_ok=True)
    sfile = rdir / _SETTINGS_FILE
    if not sfile.exists():
        atomic_write_text(
            sfile,
            json.dumps(
                {"settings_hash": h, "model": model_name, "config": cfg.to_dict()}, indent=2
            ),
        )
        return rdir, empty
    old = json.loads(sfile.read_text())
    if old.get("settings_hash") != h:
        raise SpecError(
            f"run directory {str(rdir)!r} belongs to a run with other settings "
            f"(hash {str(old.get('settings_hash'))[:12]} != {h[:12]}); use a new "
            "run_dir or delete it to start over",
            field="run_dir",
        )
    if not (rdir / _STATE_FILE).exists():
        return rdir, empty
    with np.load(rdir / _STATE_FILE, allow_pickle=False) as data:
        return rdir, _state_from_arrays(dict(data.items()), empty)


def save_state(run_dir: Path, state: RunState) -> None:
    """Write ``state`` into ``run_dir`` atomically (the previous state survives a crash)."""
    atomic_savez(run_dir / _STATE_FILE, _state_arrays(state))


_SUM_ARRAYS = ("count", "power_sums", "tail_counts", "max", "path_max")
"""The fields of a :class:`~drip_cert.numerics.stats.GapSums` that change as paths are added (the
others, the exponents and thresholds, follow from the config)."""


def _state_arrays(state: RunState) -> dict[str, np.ndarray]:
    """The ``.npz`` arrays of ``state``: its fields, and ``sums{i}.{field}`` per gap."""
    out = {
        f.name: np.asarray(getattr(state, f.name))
        for f in dataclasses.fields(state)
        if f.name != "sums"
    }
    for i, gs in enumerate(state.sums):
        out.update({f"sums{i}.{k}": np.asarray(getattr(gs, k)) for k in _SUM_ARRAYS})
    return out


def _state_from_arrays(a: dict[str, np.ndarray], template: RunState) -> RunState:
    """Inverse of :func:`_state_arrays`; ``template`` (the empty state) gives the types."""

    def value(name: str, like):
        return int(a[name]) if isinstance(like, int) else a[name]

    sums = tuple(
        dataclasses.replace(gs, **{k: value(f"sums{i}.{k}", getattr(gs, k)) for k in _SUM_ARRAYS})
        for i, gs in enumerate(template.sums)
    )
    fields = {
        f.name: value(f.name, getattr(template, f.name))
        for f in dataclasses.fields(template)
        if f.name != "sums"
    }
    return dataclasses.replace(template, sums=sums, **fields)


def _fingerprint(model: SimModel, x0_sampler, x0_bar_sampler) -> str:
    """Hash of the model's and samplers' values at fixed probe points (detects edited code)."""
    rng = np.random.default_rng(12345)
    xs = jnp.asarray(rng.normal(size=(3, model.n)))
    ts = (0.0, 0.37, 1.9)
    vals = []
    for t, x in zip(ts, xs):
        t = jnp.float64(t)
        vals += [model.f(t, x), model.g(t, x), model.p(t, x), model.lam_mu(t, x)]
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


def settings_hash(model: SimModel, cfg: SimConfig, x0_sampler, x0_bar_sampler) -> str:
    """SHA-256 of everything that determines a run's numbers (config, model, samplers)."""
    payload = {
        "config": cfg.to_dict(),
        "model": model.name,
        "sizes": [model.n, model.m, model.d],
        "fingerprint": _fingerprint(model, x0_sampler, x0_bar_sampler),
        "has_x0_bar": x0_bar_sampler is not None,
        "format": 2,  # 2: per-path maxima in the state file
    }
    return hashlib.sha256(json.dumps(payload, sort_keys=True).encode()).hexdigest()
