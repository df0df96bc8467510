"""TOML specifications: the issue's minimal shape loads; every kind of bad input is a SpecError
that names the file and the field; nothing is executed."""

from __future__ import annotations

import numpy as np
import pytest
import sympy as sp

from drip_cert.errors import SpecError
from drip_cert.model.mlp import init_mlp
from drip_cert.spec import load_spec
from tests.helpers import PAPER_4D_SPEC, two_state_spec, write_spec

MINIMAL = two_state_spec()
"""The issue's minimal spec shape (two states, one input, drift and diffusion)."""

LOWERED_ATOL = 1e-15
"""The lowered (numeric) functions and a numpy formula evaluate the same float64 operations on
O(1) numbers, up to an ulp of reordering."""


def test_minimal_issue_spec_loads(tmp_path):
    spec = load_spec(write_spec(tmp_path, MINIMAL))
    s = spec.system
    assert (s.n, s.m, s.d) == (2, 1, 2)
    x1, x2 = s.states
    assert sp.simplify(s.closed_loop()[1] - (-x1 - x2**3 - x1 - 2 * x2)) == 0
    J = s.closed_loop_jacobian()
    assert J[1, 1] == -3 * x2**2 - 2


def test_numeric_functions_match_symbolic(tmp_path):
    s = load_spec(write_spec(tmp_path, MINIMAL)).system
    x = np.array([0.4, -0.3])
    num = s.numeric
    fx = np.asarray(num.f(0.0, x))
    assert np.allclose(fx, [x[1], -x[0] - x[1] ** 3], rtol=0, atol=LOWERED_ATOL)
    lam_mu = np.asarray(num.lam_mu(0.0, x))
    assert np.allclose(lam_mu, [0.1 * np.sin(0.4), 0.1], rtol=0, atol=LOWERED_ATOL)
    assert np.allclose(np.asarray(num.theta_ad(0.0)), [[0.0, 1.0]], rtol=0, atol=LOWERED_ATOL)


def test_paper_example_loads_and_expert_cancels_h():
    spec = load_spec(PAPER_4D_SPEC)
    J = spec.system.closed_loop_jacobian("expert")
    assert J == -sp.Rational(1, 10) * sp.eye(4)


@pytest.mark.parametrize(
    "old, new, field, fragment",
    [
        ('f = ["x2", "-x1 - x2**3"]', 'f = ["x2", "-x1 - y"]', "dynamics.f[1]", "unknown symbol"),
        ('f = ["x2", "-x1 - x2**3"]', 'f = ["x2"]', "dynamics.f", "2 entries"),
        ('g = [["0"], ["1"]]', 'g = [["0"], ["x1"]]', "dynamics.g", "rank 0"),
        (
            'g = [["0"], ["1"]]\n[policy]\nexpert = ["-x1 - 2*x2"]',
            'g = [["1", "2"], ["2", "4"]]\n[policy]\nexpert = ["-x1", "-x2"]',
            "system.inputs",
            "2 columns",
        ),
        ('g = [["0"], ["1"]]', 'g = [["0"], ["0"]]', "dynamics.g", "rank 0"),
        ("horizon = 10.0", "horizon = -1.0", "system.horizon", "> 0"),
        ("horizon = 10.0", "horizon = 0", "system.horizon", "> 0"),
        ("horizon = 10.0", "horizon = nan", "system.horizon", "> 0"),
        (
            "support = [[-1.0, 1.0], [-1.0, 1.0]]",
            "support = [[1.0, -1.0], [-1.0, 1.0]]",
            "initial.support",
            "empty",
        ),
        (
            "support = [[-1.0, 1.0], [-1.0, 1.0]]",
            "support = [[-1.0, inf], [-1.0, 1.0]]",
            "initial.support",
            "not finite",
        ),
        (
            "support = [[-1.0, 1.0], [-1.0, 1.0]]",
            "support = [[-1.0, 1.0]]",
            "initial.support",
            "2 pairs",
        ),
        (
            'drift = ["0.1*sin(x1)", "0.1"]',
            'drift = ["x1.real", "0.1"]',
            "uncertainty.drift[0]",
            "not allowed",
        ),
        (
            'drift = ["0.1*sin(x1)", "0.1"]',
            'drift = ["0.1*sin(x1)", "0.1"]\nDelta_mu = 0.3',
            "uncertainty.Delta_mu",
            "not both",
        ),
        ("[uncertainty]", "[uncertainty]\nDelta_sigma = -1", "uncertainty.Delta_sigma", ">= 0"),
        (
            'expert = ["-x1 - 2*x2"]',
            'expert = ["-x1 - 2*t"]',
            "policy.expert[0]",
            "the name 't' cannot be used here",
        ),
        ("[initial]", "[initals]", "initals", "unknown section"),
        ('name = "example"', 'name = "example"\ncolour = "red"', "system.colour", "unknown key"),
    ],
)
def test_bad_specs_raise_spec_error_naming_the_field(tmp_path, old, new, field, fragment):
    assert old in MINIMAL
    path = write_spec(tmp_path, MINIMAL.replace(old, new, 1))
    with pytest.raises(SpecError) as info:
        load_spec(path)
    msg = str(info.value)
    assert str(path) in msg
    assert field in msg
    assert fragment in msg


def test_not_toml(tmp_path):
    with pytest.raises(SpecError, match="not valid TOML"):
        load_spec(write_spec(tmp_path, "[system\nname="))


def test_missing_file(tmp_path):
    with pytest.raises(SpecError, match="does not exist"):
        load_spec(tmp_path / "nope.toml")


BLOCK_SPEC = """
[system]
name = "blk"
states = ["x1", "x2"]
horizon = 1.0
[blocks.h]
kind = "mlp"
weights = "{weights}"
inputs = 2
outputs = 2
activation = "tanh"
[dynamics]
f = ["-x1 + h(x)[0]", "-x2 + h(x)[1]"]
g = [["1", "0"], ["0", "1"]]
[policy]
expert = ["-h(x)[0]", "-h(x)[1]"]
[initial]
support = [[-1.0, 1.0], [-1.0, 1.0]]
"""


def test_block_spec_loads_and_cancels(tmp_path):
    init_mlp([2, 5, 2], np.random.default_rng(1)).save(tmp_path / "h.npz")
    s = load_spec(write_spec(tmp_path, BLOCK_SPEC.format(weights="h.npz"))).system
    assert s.closed_loop_jacobian() == -sp.eye(2)
    x = np.array([0.2, 0.1])
    h = s.blocks["h"].evaluate_np(x)
    assert np.allclose(np.asarray(s.numeric.f(0.0, x)), -x + h, rtol=0, atol=LOWERED_ATOL)


def test_missing_weights_file(tmp_path):
    with pytest.raises(SpecError, match="does not exist") as info:
        load_spec(write_spec(tmp_path, BLOCK_SPEC.format(weights="absent.npz")))
    assert "blocks.h.weights" in str(info.value)


def test_weights_of_wrong_shape(tmp_path):
    init_mlp([3, 5, 2], np.random.default_rng(1)).save(tmp_path / "h.npz")
    with pytest.raises(SpecError, match="takes 3 inputs but the block declares 2"):
        load_spec(write_spec(tmp_path, BLOCK_SPEC.format(weights="h.npz")))


def test_weights_file_with_pickles_is_refused(tmp_path):
    np.savez(tmp_path / "h.npz", W0=np.array([object()], dtype=object), b0=np.zeros(2))
    with pytest.raises(SpecError, match="without pickles"):
        load_spec(write_spec(tmp_path, BLOCK_SPEC.format(weights="h.npz")))


def test_rank_deficient_g_says_the_rank(tmp_path):
    text = (
        MINIMAL.replace('inputs = ["u1"]\n', "")
        .replace('g = [["0"], ["1"]]', 'g = [["1", "2"], ["2", "4"]]')
        .replace('expert = ["-x1 - 2*x2"]', 'expert = ["-x1", "-x2"]')
    )
    with pytest.raises(SpecError, match=r"rank 1 < m = 2") as info:
        load_spec(write_spec(tmp_path, text))
    assert "dynamics.g" in str(info.value)
