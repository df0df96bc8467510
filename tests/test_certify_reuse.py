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


def test_interval_product_without_stacking_is_the_stacked_one():
    """The batched interval product takes min / max of its four products without stacking them
    (a hot spot of the growth constants' branch and bound); every result, signed zeros, infinities
    and NaNs included, is the stacked form's."""
    from drip_cert.numerics import interval_batch as ib

    rng = np.random.default_rng(1)
    special = np.array([0.0, -0.0, np.inf, -np.inf, np.nan, 1e-310, -1e308, 3.0])
    for _ in range(200):
        a = np.sort(rng.choice(np.concatenate([special, rng.normal(size=8)]), (2, 16)), axis=0)
        b = np.sort(rng.choice(np.concatenate([special, rng.normal(size=8)]), (2, 16)), axis=0)
        fast = ib._mul(a[0], a[1], b[0], b[1])
        slow = ib._mul_stacked(a[0], a[1], b[0], b[1])
        for x, y in zip(fast, slow, strict=True):
            assert np.array_equal(x, y, equal_nan=True)


def test_growth_rewritings_are_computed_once_per_expression():
    """The equivalent forms of an entry (sympy expand / cancel / powsimp / simplify, the costly
    part of the paper example's growth constants: 11 distinct entries asked 176 times) are kept
    per expression; they are the forms a fresh computation gives, and equal-looking but distinct
    expressions (a Float and an Integer of the same value hash alike) are not confused."""
    import sympy as sp

    from drip_cert.analysis.growth import rewrites

    r = sp.Dummy("rho", nonnegative=True)
    e = r / 20 + sp.Rational(1, 10) + sp.sqrt(r**2) / (1 + r)
    first = rewrites._rewrites(e)
    assert rewrites._rewrites(e) is first
    assert list(first) == list(rewrites._rewrites.__wrapped__(e))
    assert rewrites._rewrites(sp.Float(2.0))[0] == sp.Float(2.0)
    assert rewrites._rewrites(sp.Integer(2))[0] == sp.Integer(2)
    assert rewrites._rewrites(sp.Integer(2))[0].is_Integer


def test_the_certificate_imports_no_onnx():
    """onnx (0.07 CPU-s to import) is needed only to read an .onnx network: importing the
    certificate (the path of every `certify`) does not load it."""
    import subprocess
    import sys

    code = "import sys, drip_cert.bounds.certificate; print('onnx' in sys.modules)"
    out = subprocess.run(
        [sys.executable, "-c", code], cwd=ROOT, capture_output=True, text=True, check=False
    )
    assert out.returncode == 0, out.stderr
    assert out.stdout.strip() == "False"
