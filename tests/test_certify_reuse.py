"""certify computes each thing once: work that two parts (or two demonstration sets) of one
certificate share is built once, with the same numbers as building it again."""

from __future__ import annotations

from pathlib import Path

import numpy as np

from drip_cert.bounds.tasil import section
from drip_cert.spec import load_spec

ROOT = Path(__file__).resolve().parents[1]


def test_tasil_difference_functions_are_built_once_per_system():
    """The training and the held-out demonstrations share one jitted Delta, Jacobian and speed
    (one trace and one XLA compilation each, not one per set); the values are those of a fresh
    build."""
    s = load_spec(ROOT / "examples" / "pendulum" / "pendulum.toml").system
    first = section._difference_fns(s)
    assert section._difference_fns(s) is first
    X = np.random.default_rng(0).uniform(-0.5, 0.5, (7, s.n))
    section._FNS.clear()
    fresh = section._difference_fns(s)
    assert fresh is not first
    for a, b in zip(first, fresh, strict=True):
        assert np.array_equal(np.asarray(a(X)), np.asarray(b(X)))
