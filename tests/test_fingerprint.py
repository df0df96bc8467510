"""Fingerprints of the certified policy and design (:mod:`drip_cert.model.fingerprint`).

A fingerprint is useful only if it is a function of what runs: the same system gives the same
digests in every process (other hash seeds, another load of the spec, another certification,
whose timings differ), and the smallest change of what runs (one ulp of one weight, of one
design parameter, of ``Theta``) gives another. Both directions are checked here; the refusal
of recorded data of another policy or design is in ``tests/test_validate_data.py`` and
``tests/test_testing_plugin.py``.
"""

from __future__ import annotations

import dataclasses
import os
import subprocess
import sys

import numpy as np
import pytest

from drip_cert.model.blocks import mlp_block
from drip_cert.model.fingerprint import (
    HEX_DIGITS,
    Fingerprint,
    design_fingerprint,
    fingerprint_of,
    policy_fingerprint,
)
from drip_cert.model.mlp import MLP
from drip_cert.schema import check_output
from drip_cert.spec import load_spec
from tests.helpers import PAPER_4D_SPEC, ROOT, example_spec

PLANT = ROOT / "examples" / "regression_ci" / "plant.toml"
DESIGN = (50.0, 10.0, 0.02)
"""An ``(omega, lambda_s, T_s)`` to fingerprint (any positive numbers: nothing is certified)."""

SEED = 0
HIDDEN = 8
SUBPROCESS_TIMEOUT_S = 300
"""Two fresh interpreters import sympy and drip_cert (seconds each on the loaded 2-core box)."""


def _ulp_up(a: np.ndarray, index: tuple[int, ...]) -> np.ndarray:
    """``a`` with one entry moved to the next float64 up (one ulp)."""
    out = np.array(a, dtype=np.float64)
    out[index] = np.nextafter(out[index], np.inf)
    assert out[index] != a[index]
    return out


@pytest.fixture(scope="module")
def mlp_policy_system():
    """The pendulum with a seeded tanh MLP plus a linear term as its learned policy."""
    from drip_cert.learn.imitation import learned_system

    s = load_spec(example_spec("pendulum")).system
    rng = np.random.default_rng(SEED)
    mlp = MLP(
        (rng.normal(size=(HIDDEN, s.n)), rng.normal(size=(s.m, HIDDEN))),
        (rng.normal(size=HIDDEN), rng.normal(size=s.m)),
        activation="tanh",
    )
    K = rng.normal(size=(s.m, s.n))
    return learned_system(s, mlp, linear=K), mlp, K


# ------------------------------------------------------------------------------ stable
def test_same_spec_loaded_twice_gives_the_same_hex():
    for spec in (PLANT, PAPER_4D_SPEC, example_spec("pendulum")):
        a, b = load_spec(spec).system, load_spec(spec).system
        fa, fb = fingerprint_of(a, DESIGN), fingerprint_of(b, DESIGN)
        assert fa == fb, spec
        assert len(fa.policy) == len(fa.design) == HEX_DIGITS


_IN_A_FRESH_PROCESS = """
import sys
from drip_cert.model.fingerprint import fingerprint_of
from drip_cert.spec import load_spec
print(fingerprint_of(load_spec(sys.argv[1]).system, (50.0, 10.0, 0.02)))
"""


def test_two_processes_with_other_hash_seeds_give_the_same_hex():
    """No dict or set order enters: ``PYTHONHASHSEED`` 1 and 2 (and this process) agree, on
    the paper's spec whose expert and dynamics apply an MLP block."""
    outs = []
    for seed in ("1", "2"):
        env = dict(os.environ, PYTHONHASHSEED=seed, PYTHONPATH=str(ROOT))
        res = subprocess.run(
            [sys.executable, "-c", _IN_A_FRESH_PROCESS, str(PAPER_4D_SPEC)],
            capture_output=True,
            text=True,
            env=env,
            timeout=SUBPROCESS_TIMEOUT_S,
            check=True,
        )
        outs.append(res.stdout.strip())
    here = str(fingerprint_of(load_spec(PAPER_4D_SPEC).system, DESIGN))
    assert outs == [here, here]


def test_certifying_twice_gives_the_same_fingerprint_and_the_deploy_objects_carry_it():
    """Two certifications (their timings differ) give one fingerprint; the controller carries
    it whole, the policy its policy part, and the certificate JSON (schema-valid) holds it."""
    from drip_cert.bounds.certificate import certify
    from drip_cert.deploy import l1drac_controller, learned_policy

    spec = load_spec(PLANT)
    first, second = certify(spec), certify(load_spec(PLANT))
    assert first.fingerprint is not None and first.fingerprint == second.fingerprint
    d = first.l1.design
    assert first.fingerprint == fingerprint_of(spec.system, (d.omega, d.lambda_s, d.Ts))
    assert l1drac_controller(first).fingerprint == first.fingerprint
    assert learned_policy(PLANT).fingerprint == Fingerprint(policy=first.fingerprint.policy)
    out = first.to_dict()
    check_output(out, where="certify --json")
    assert out["fingerprint"]["policy"] == first.fingerprint.policy
    assert out["fingerprint"]["design"] == first.fingerprint.design


# --------------------------------------------------------------------------- sensitive
def test_one_ulp_of_one_mlp_weight_changes_the_policy_part_only(mlp_policy_system):
    s, mlp, _ = mlp_policy_system
    base = fingerprint_of(s, DESIGN)
    name = next(iter(s.blocks))
    for layer, index in ((0, (3, 1)), (1, (0, HIDDEN - 1))):
        ws = list(mlp.weights)
        ws[layer] = _ulp_up(ws[layer], index)
        bumped = mlp_block(name, MLP(tuple(ws), mlp.biases, mlp.activation))
        s2 = dataclasses.replace(s, blocks={**s.blocks, name: bumped})
        fp = fingerprint_of(s2, DESIGN)
        assert fp.policy != base.policy and fp.design == base.design, (layer, index)
    bs = (mlp.biases[0], _ulp_up(mlp.biases[1], (0,)))
    s3 = dataclasses.replace(s, blocks={**s.blocks, name: mlp_block(name, MLP(mlp.weights, bs))})
    assert policy_fingerprint(s3) != base.policy


def test_one_ulp_of_a_linear_coefficient_of_the_policy_changes_it(mlp_policy_system):
    from drip_cert.learn.imitation import learned_system

    s, mlp, K = mlp_policy_system
    base = load_spec(example_spec("pendulum")).system
    again = learned_system(base, mlp, linear=K)
    assert policy_fingerprint(again) == policy_fingerprint(s)
    assert policy_fingerprint(learned_system(base, mlp, linear=_ulp_up(K, (0, 1)))) != (
        policy_fingerprint(s)
    )


def test_the_expert_enters_the_policy_part():
    s = load_spec(PLANT).system
    s2 = dataclasses.replace(s, expert=[s.expert[0] * 1.0000001])
    assert policy_fingerprint(s2) != policy_fingerprint(s)


@pytest.mark.parametrize("k", range(3))
def test_one_ulp_of_one_design_parameter_changes_the_design_part_only(k):
    s = load_spec(PLANT).system
    base = fingerprint_of(s, DESIGN)
    moved = tuple(float(v) for v in _ulp_up(np.array(DESIGN), (k,)))
    fp = fingerprint_of(s, moved)
    assert fp.design != base.design and fp.policy == base.policy


def test_coordinates_and_the_nominal_model_enter_the_design_part():
    s = load_spec(example_spec("pendulum")).system
    theta = np.array([[1.0, 0.25], [0.0, 2.0]])
    in_x = design_fingerprint(s, DESIGN)
    in_z = design_fingerprint(s, DESIGN, theta)
    assert in_z != in_x
    assert design_fingerprint(s, DESIGN, _ulp_up(theta, (0, 1))) != in_z
    assert design_fingerprint(s, None) != in_x  # no feasible design is a design of its own
    f2 = dataclasses.replace(s, f=[s.f[0], s.f[1] * 1.0000001])
    assert design_fingerprint(f2, DESIGN) != in_x and policy_fingerprint(f2) == (
        policy_fingerprint(s)
    )


# -------------------------------------------------------------------------- the text
def test_text_round_trips_and_malformed_text_is_refused():
    fp = Fingerprint(policy="0123456789abcdef", design="fedcba9876543210")
    assert str(fp) == "policy=0123456789abcdef, design=fedcba9876543210"
    assert Fingerprint.parse(str(fp)) == fp
    assert Fingerprint.parse("design=fedcba9876543210,policy=0123456789abcdef") == fp
    only = Fingerprint(policy="0123456789abcdef")
    assert Fingerprint.parse(str(only)) == only and only.design is None
    assert np.asarray(fp).item() == str(fp)  # numpy.savez(..., fingerprint=fp) stores the text
    for bad in ("", "policy=0123", "design=fedcba9876543210", "policy=0123456789ABCDEF", "x=1"):
        with pytest.raises(ValueError):
            Fingerprint.parse(bad)
