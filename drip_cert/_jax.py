"""Import jax with 64-bit numerics enabled (every jax user in drip-cert imports from here)."""

from __future__ import annotations

import jax

jax.config.update("jax_enable_x64", True)

import jax.numpy as jnp  # noqa: E402

__all__ = ["jax", "jnp"]
