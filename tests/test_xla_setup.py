"""The process-wide jax settings of drip_cert._jax: single-threaded XLA on the CPU and the
persistent compilation cache (its place, its switch, and that a cache hit changes no bit)."""

from __future__ import annotations

import os
import subprocess
import sys

from tests.helpers import ROOT

# a jitted loop whose float64 result depends on every rounding of its 200 steps: a cache hit that
# returned another program would show in the printed bits
_PROGRAM = """
import sys
from drip_cert._jax import jax, jnp, xla_cache_dir
jax.config.update("jax_persistent_cache_min_compile_time_secs", 0.0)
f = jax.jit(lambda x: jax.lax.fori_loop(0, 200, lambda i, y: jnp.tanh(y @ y.T) + 0.1 * y, x))
x = jnp.asarray([[0.3, -1.2], [0.7, 0.4]])
print(xla_cache_dir(), float(f(x).sum()).hex(), sep="|")
import os
print("FLAGS", os.environ["XLA_FLAGS"], file=sys.stderr)
"""


def _run(env_extra: dict[str, str]) -> tuple[str, str, str]:
    env = {k: v for k, v in os.environ.items() if k not in ("XLA_FLAGS", "DRIP_CERT_NO_XLA_CACHE")}
    env.update(env_extra)
    out = subprocess.run(
        [sys.executable, "-c", _PROGRAM],
        cwd=ROOT,
        env=env,
        capture_output=True,
        text=True,
        check=False,
    )
    assert out.returncode == 0, out.stderr
    where, bits = out.stdout.strip().split("|")
    return where, bits, out.stderr


def test_the_cache_lives_in_the_user_cache_directory_and_changes_no_bit(tmp_path):
    env = {"XDG_CACHE_HOME": str(tmp_path)}
    where, cold, err = _run(env)
    assert where == str(tmp_path / "drip-cert" / "xla")
    entries = list((tmp_path / "drip-cert" / "xla").iterdir())
    assert entries, "nothing was written to the cache"
    _, warm, _ = _run(env)  # a cache hit
    _, off, _ = _run({**env, "DRIP_CERT_NO_XLA_CACHE": "1"})
    assert cold == warm == off
    assert "--xla_cpu_multi_thread_eigen=false" in err


def test_the_cache_can_be_turned_off(tmp_path):
    where, _, _ = _run({"XDG_CACHE_HOME": str(tmp_path), "DRIP_CERT_NO_XLA_CACHE": "1"})
    assert where == "None"
    assert not (tmp_path / "drip-cert").exists()


def test_a_users_xla_threading_flag_is_kept(tmp_path):
    flag = "--xla_cpu_multi_thread_eigen=true"
    _, _, err = _run({"XDG_CACHE_HOME": str(tmp_path), "XLA_FLAGS": flag})
    assert f"FLAGS {flag}\n" in err
