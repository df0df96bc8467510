"""Import jax with 64-bit numerics enabled (every jax user in drip-cert imports from here).

Two process-wide settings are made here, before jax starts its backend:

* **Single-threaded XLA programs on the CPU** (``--xla_cpu_multi_thread_eigen=false`` appended
  to ``XLA_FLAGS`` unless it already names that flag). The Monte-Carlo engine runs one compiled
  call per core from a thread pool (:func:`drip_cert.sim.engine.simulate`); XLA's own intra-op
  threads would make the calls compete for the same cores (issue 26 measured a second worker
  adding nothing, 0.96x, with them). The numbers do not depend on it: every operation is the same,
  only the threads that run it change.
* **A persistent compilation cache** in ``$XDG_CACHE_HOME/drip-cert/xla`` (``~/.cache/drip-cert/
  xla`` without it), so that a second ``certify`` or ``validate`` of the same system skips XLA's
  compilations. A cache hit is the executable an identical program compiled to (jax keys it by the
  program, the jax and XLA versions, the flags and the device), so it never changes a result. Off
  with ``DRIP_CERT_NO_XLA_CACHE=1``.
"""

from __future__ import annotations

import os
from pathlib import Path

NO_CACHE_ENV = "DRIP_CERT_NO_XLA_CACHE"
"""Environment variable: ``1`` turns the persistent XLA compilation cache off."""

CACHE_MIN_COMPILE_S = 0.1
"""Compilations shorter than this are not written to the cache (reading an entry costs a few
milliseconds; the engine's and the certificate's programs take 0.1-2 s to compile)."""

_SINGLE_THREAD_FLAG = "--xla_cpu_multi_thread_eigen=false"

if "xla_cpu_multi_thread_eigen" not in os.environ.get("XLA_FLAGS", ""):
    os.environ["XLA_FLAGS"] = f"{os.environ.get('XLA_FLAGS', '')} {_SINGLE_THREAD_FLAG}".strip()

import jax  # noqa: E402

jax.config.update("jax_enable_x64", True)

import jax.numpy as jnp  # noqa: E402


def xla_cache_dir() -> Path | None:
    """The persistent compilation cache's directory, or ``None`` when it is turned off."""
    if os.environ.get(NO_CACHE_ENV, "").strip() not in ("", "0"):
        return None
    base = os.environ.get("XDG_CACHE_HOME") or os.path.join(os.path.expanduser("~"), ".cache")
    return Path(base) / "drip-cert" / "xla"


def _enable_cache() -> None:
    where = xla_cache_dir()
    if where is None:
        return
    try:
        where.mkdir(parents=True, exist_ok=True)
    except OSError:  # a read-only home: run without the cache rather than fail
        return
    jax.config.update("jax_compilation_cache_dir", str(where))
    jax.config.update("jax_persistent_cache_min_compile_time_secs", CACHE_MIN_COMPILE_S)


_enable_cache()

__all__ = ["NO_CACHE_ENV", "jax", "jnp", "xla_cache_dir"]
