"""Code written once where it stood twice (issue 27, ``duplicates``): each merged helper keeps
the behaviour of the copies it replaces. Every message, limit and value is pinned here; these
tests pass on the starting commit too (the merge changes no behaviour)."""

from __future__ import annotations

import argparse
import math

import numpy as np
import pytest

# (converter, text, the value it gives or the message it raises): the argparse number types
# of the command line share one implementation
_NUMBER_TYPES = [
    ("_nonneg_float", "0", 0.0),
    ("_nonneg_float", "x", "expected a number >= 0, got 'x'"),
    ("_nonneg_float", "inf", "expected a finite number >= 0, got 'inf'"),
    ("_nonneg_float", "-1", "expected a finite number >= 0, got '-1'"),
    ("_nonneg_float", "nan", "expected a finite number >= 0, got 'nan'"),
    ("_posfloat", "2.5", 2.5),
    ("_posfloat", "x", "expected a number > 0, got 'x'"),
    ("_posfloat", "0", "expected a finite number > 0, got '0'"),
    ("_posfloat", "inf", "expected a finite number > 0, got 'inf'"),
    ("_positive_or_inf", "inf", math.inf),
    ("_positive_or_inf", "x", "expected a number > 0 (or inf), got 'x'"),
    ("_positive_or_inf", "nan", "expected a number > 0 (or inf), got 'nan'"),
    ("_positive_or_inf", "0", "expected a number > 0 (or inf), got '0'"),
    ("_posint", "1", 1),
    ("_posint", "1.5", "expected a positive integer, got '1.5'"),
    ("_posint", "0", "expected a positive integer, got '0'"),
    ("_nonneg_int", "0", 0),
    ("_nonneg_int", "x", "expected an integer >= 0, got 'x'"),
    ("_nonneg_int", "-1", "expected an integer >= 0, got '-1'"),
]


@pytest.mark.parametrize(("name", "text", "want"), _NUMBER_TYPES)
def test_number_option_types(name, text, want):
    from drip_cert import cli

    convert = getattr(cli, name)
    if isinstance(want, str):
        with pytest.raises(argparse.ArgumentTypeError) as err:
            convert(text)
        assert str(err.value) == want
    else:
        got = convert(text)
        assert got == want and type(got) is type(want)


@pytest.mark.parametrize(
    ("value", "want"),
    [
        (np.float32("nan"), None),
        (np.float64("-inf"), "-inf"),
        (math.inf, "inf"),
        (np.float32(0.5), 0.5),
        (1.25, 1.25),
    ],
)
def test_jsonable_floats_as_json_float(value, want):
    """``jsonable`` writes a float as ``provenance.json_float`` does: NaN -> null, +-inf ->
    strings, finite values as Python floats (also inside containers and arrays)."""
    from drip_cert.numerics.atomic_io import jsonable

    got = jsonable({"a": [value], "b": np.array([value])})
    assert got == {"a": [want], "b": [want]}
    assert all(type(v) is type(want) for v in (*got["a"], *got["b"]))


def test_design_table_keys():
    """A ``design-l1`` file's ``[design]`` keys: ``p``, the design keys a spec's ``[l1drac]``
    shares (read by the same reader, with the same descriptions) and the omega interval."""
    from drip_cert.bounds.l1drac.toml import DESIGN_KEYS
    from drip_cert.spec.settings import L1Settings

    shared = ["p", "lambda_s", "omega", "Ts", "rho_r", "rho_a", "delta", "objective"]
    shared += ["rho_budget", "front"]
    assert list(DESIGN_KEYS) == [*shared, "omega_min", "omega_max"]
    assert all(DESIGN_KEYS[k] == L1Settings.KEYS[k] for k in shared)


@pytest.mark.parametrize(
    ("spec", "smooth", "onnx"),
    [
        ("leaky_relu(0.2)", False, {"alpha": 0.2}),
        ("leaky_relu(1.0)", True, {"alpha": 1.0}),
        ("elu(0.5)", False, {"alpha": 0.5}),
        ("elu", True, {"alpha": 1.0}),
        ("relu", False, {}),
    ],
)
def test_one_slope_activations(spec, smooth, onnx):
    """leaky_relu and elu share their ``alpha`` handling: the spec string parses back to an
    equal activation, ``smooth`` iff ``alpha = 1``, ``alpha`` is the ONNX attribute; and their
    value enclosure comes from the ends (both are increasing)."""
    from drip_cert.model.activations import get_activation

    act = get_activation(spec)
    assert get_activation(act.spec) == act and hash(get_activation(act.spec)) == hash(act)
    assert act.smooth is smooth and act.onnx_attributes() == onnx
    lo, hi = np.array([-2.0, -1.0, 0.5]), np.array([-1.5, 3.0, 0.75])
    elo, ehi = act.enclose(lo, hi)
    assert np.all(elo <= act.value_np(lo)) and np.all(ehi >= act.value_np(hi))
    assert np.array_equal(elo, act._value_point(lo)[0])
    assert np.array_equal(ehi, act._value_point(hi)[1])
