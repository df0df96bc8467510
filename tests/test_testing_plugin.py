"""The pytest plugin ``drip_cert.testing`` and the README's worked example ("Regression tests
against your own gaps", ``examples/regression_ci``) end to end.

* the baseline fixture fails on a missing snapshot and on a regression, and passes after
  ``--drip-cert-update`` (run in an inner pytest session with ``pytester``);
* ``assert_certified`` and ``assert_gaps_within`` pass and fail as the verdict and the
  validation status say; recorded data within the bounds exit 0, data violating a bound exit 1,
  malformed data exit 2 with a message naming the array and the problem;
* the project's own certificates of bundled examples are held to snapshots with the fixture.
"""

from __future__ import annotations

import json
import shutil

import numpy as np
import pytest

from drip_cert.deploy import learned_policy
from drip_cert.model.fingerprint import Fingerprint
from drip_cert.schema import load_output
from drip_cert.testing import UnfingerprintedData, assert_certified, assert_gaps_within
from tests.helpers import ROOT, example_spec, load_script, run_cli

pytest_plugins = ["pytester"]

EXAMPLE = ROOT / "examples" / "regression_ci"
PLANT_GAIN = "-0.98*x"
"""The certified learned policy of the example's plant.toml; the tests change it."""


def _set_gain(spec, old, new):
    """Change the learned policy ``u = old`` of a copy of plant.toml to ``u = new``."""
    text = spec.read_text()
    assert f'learned = ["{old}"]' in text
    spec.write_text(text.replace(f'learned = ["{old}"]', f'learned = ["{new}"]'))


@pytest.fixture
def example(tmp_path):
    """A copy of examples/regression_ci (the README's steps write into it)."""
    d = tmp_path / "regression_ci"
    shutil.copytree(EXAMPLE, d, ignore=shutil.ignore_patterns("gaps.npz", "out", "*.json"))
    return d


@pytest.fixture
def warm():
    """Certify once in this process before an in-process inner pytest run: pytester restores
    ``sys.modules`` after each run, and a compiled extension (jax, flint) first imported inside
    one would be imported a second time afterwards (a crash); imported here, it stays."""
    assert_certified(EXAMPLE / "plant.toml")


@pytest.fixture(scope="module")
def recorder():
    return load_script(EXAMPLE / "record_gaps.py", "record_gaps")


# ------------------------------------------------------------------------ baseline fixture
BASELINE_TEST = """
from pathlib import Path

def test_cert(drip_cert_baseline):
    drip_cert_baseline.check(Path(__file__).parent / "plant.toml")
"""


@pytest.mark.slow  # an inner pytest run per step, each certifying: end to end
def test_baseline_fails_on_a_regression_and_passes_after_the_update_flag(warm, pytester):
    spec = pytester.path / "plant.toml"
    shutil.copy(EXAMPLE / "plant.toml", spec)
    pytester.makepyfile(test_plant=BASELINE_TEST)
    snap = pytester.path / "drip_cert_baselines" / "test_plant.test_cert.json"
    plugin = ("-p", "drip_cert.testing", "-W", "ignore::pytest.PytestAssertRewriteWarning")

    res = pytester.runpytest(*plugin)  # no snapshot yet: fail, saying how to record one
    res.assert_outcomes(failed=1)
    res.stdout.fnmatch_lines(["*no drip-cert baseline*--drip-cert-update*"])
    assert not snap.exists()

    res = pytester.runpytest(*plugin, "--drip-cert-update")
    res.assert_outcomes(passed=1)
    res.stdout.fnmatch_lines(["*drip-cert: 1 baseline(s) written*"])
    assert load_output(snap).kind == "certificate"  # a valid, versioned certificate
    pytester.runpytest(*plugin).assert_outcomes(passed=1)

    _set_gain(spec, PLANT_GAIN, "-0.90*x")  # change the policy: rho_TaSIL loosens
    res = pytester.runpytest(*plugin)
    res.assert_outcomes(failed=1)
    res.stdout.fnmatch_lines(["*REGRESSION*", "*rho_TaSIL (rho.rho_tasil) loosened*"])

    pytester.runpytest(*plugin, "--drip-cert-update").assert_outcomes(passed=1)
    pytester.runpytest(*plugin).assert_outcomes(passed=1)

    # less noise: every bound and constant tightens, an improvement passes with a warning (the
    # policy back to -0.98 x is not one: the nominal drift bound Delta_f grows, 1.9 -> 1.98)
    text = spec.read_text()
    assert 'diffusion = [["0.05"]]' in text
    spec.write_text(text.replace('diffusion = [["0.05"]]', 'diffusion = [["0.02"]]'))
    res = pytester.runpytest(*plugin)
    res.assert_outcomes(passed=1, warnings=1)
    res.stdout.fnmatch_lines(["*BaselineChanged*tightened*"])


def test_a_corrupt_snapshot_fails_with_the_file_and_the_fix(warm, pytester):
    shutil.copy(EXAMPLE / "plant.toml", pytester.path / "plant.toml")
    pytester.makepyfile(test_plant=BASELINE_TEST)
    snap = pytester.path / "drip_cert_baselines" / "test_plant.test_cert.json"
    snap.parent.mkdir()
    snap.write_text('{"verdict": ')
    res = pytester.runpytest("-p", "drip_cert.testing")
    res.assert_outcomes(failed=1)
    res.stdout.fnmatch_lines(["*test_plant.test_cert.json: not valid JSON*--drip-cert-update*"])


# ------------------------------------------------------------------------------ asserts
def test_assert_certified_passes_and_fails_on_the_verdict():
    cert = assert_certified(EXAMPLE / "plant.toml")
    assert cert.verdict.value == "certified"
    with pytest.raises(pytest.fail.Exception, match="verdict NOT_CERTIFIED") as exc:
        assert_certified(example_spec("infeasible_2d"))
    assert "L1DRAC-A7: fails" in str(exc.value)
    with pytest.raises(pytest.fail.Exception, match="NOT_CERTIFIED"):
        assert_certified(example_spec("infeasible_2d"), allow_conditional=True)


# ------------------------------------------------------------------- the worked example
@pytest.mark.slow  # the README's four steps, each a certify or a validation: end to end
def test_worked_example_end_to_end(example, recorder, capsys):
    """The README's steps: record gaps with the controller object in a plain numpy loop,
    validate them (exit 0), snapshot the certificate, change the policy, diff exits 1; data of
    another policy violate the certified bound (exit 1); malformed data exit 2."""
    spec, gaps = example / "plant.toml", example / "gaps.npz"
    recorded = recorder.record(spec, paths=100, seed=0)
    np.savez(gaps, **recorded)
    code, _, _ = run_cli(capsys, "validate", str(spec), "--data", str(gaps), "--out", "out")
    assert code == 0
    rep = assert_gaps_within(spec, gaps, out=example / "out")
    assert rep.status == "holds" and rep.at_certified_parameters
    assert rep.result.data.fingerprint is not None  # record_gaps.py writes it
    # without it: refused, unless accepted (with a warning)
    bare = example / "bare.npz"
    np.savez(bare, **{k: v for k, v in recorded.items() if k != "fingerprint"})
    with pytest.raises(pytest.fail.Exception, match="no fingerprint.*--accept-unfingerprinted"):
        assert_gaps_within(spec, bare)
    with pytest.warns(UnfingerprintedData, match="no fingerprint"):
        rep = assert_gaps_within(spec, bare, accept_unfingerprinted=True)
    assert rep.status == "holds" and any("no fingerprint" in n for n in rep.notes)
    assert {p.name for p in (example / "out").iterdir()} >= {
        "validation.json",
        "validation.md",
        "validation.png",
    }

    code, out, _ = run_cli(capsys, "certify", str(spec), "--json", "--quiet")
    assert code == 0
    (example / "baseline.json").write_text(out)
    _set_gain(spec, PLANT_GAIN, "-0.90*x")
    code, out, _ = run_cli(capsys, "certify", str(spec), "--json", "--quiet")
    (example / "new.json").write_text(out)
    code, out, _ = run_cli(
        capsys, "diff", str(example / "baseline.json"), str(example / "new.json")
    )
    assert code == 1 and "rho_TaSIL (rho.rho_tasil) loosened" in out

    # data recorded with another policy than the certified one: refused by their fingerprint
    _set_gain(spec, "-0.90*x", "-0.8*x")
    other = example / "other.npz"
    recorded = recorder.record(spec, paths=100, seed=1)
    np.savez(other, **recorded)
    _set_gain(spec, "-0.8*x", PLANT_GAIN)  # checked against the certified policy's certificate
    certified = learned_policy(spec).fingerprint.policy
    old = Fingerprint.parse(recorded["fingerprint"].item()).policy
    assert old != certified
    code, out, err = run_cli(capsys, "validate", str(spec), "--data", str(other), "--json")
    assert code == 1 and out == "" and "Traceback" not in err
    assert "recorded with another policy" in err
    assert f"policy={old} in the data" in err and f"policy={certified} certified" in err
    with pytest.raises(pytest.fail.Exception, match="recorded with another policy"):
        assert_gaps_within(spec, other)
    # the same data without their fingerprint, accepted unverified: they violate rho_TaSIL
    np.savez(bare, **{k: v for k, v in recorded.items() if k != "fingerprint"})
    code, out, _ = run_cli(capsys, "validate", str(spec), "--data", str(bare), "--json")
    assert code == 1 and out == ""  # refused: no fingerprint
    code, out, err = run_cli(
        capsys, "validate", str(spec), "--data", str(bare), "--json", "--accept-unfingerprinted"
    )
    v = json.loads(out)
    assert code == 1 and v["status"] == "violated" and "no fingerprint" in err
    assert {c["name"]: c["status"] for c in v["checks"]}["policy_radius"] == "violated"
    with (
        pytest.warns(UnfingerprintedData),
        pytest.raises(pytest.fail.Exception, match="policy_radius: empirical"),
    ):
        assert_gaps_within(spec, bare, accept_unfingerprinted=True)


def test_malformed_data_exits_2_naming_the_array_and_the_problem(example, capsys):
    spec, bad = example / "plant.toml", example / "bad.npz"
    t = np.linspace(0.0, 1.0, 11)
    np.savez(bad, t=t, expert_nominal=np.zeros((5, 10, 1)), learned_nominal=np.zeros((5, 11, 1)))
    code, out, err = run_cli(capsys, "validate", str(spec), "--data", str(bad))
    assert code == 2 and out == "" and "Traceback" not in err
    assert f"{bad}: expert_nominal: has 10 times" in err and "but t has 11" in err
    with pytest.raises(pytest.fail.Exception, match="expert_nominal"):
        assert_gaps_within(spec, bad)


# ---------------------------------------------------- the project's own certificate baselines
@pytest.mark.parametrize(
    "spec",
    [EXAMPLE / "plant.toml", example_spec("infeasible_2d")],
    ids=["regression_ci", "infeasible_2d"],
)
def test_bundled_example_certificate_does_not_regress(spec, drip_cert_baseline):
    """Snapshots in tests/drip_cert_baselines/ (exact or sound numbers: deterministic); a change
    that loosens a bound, weakens a provenance or flips a verdict fails here first. Re-record an
    intended change with ``pytest tests/test_testing_plugin.py --drip-cert-update``."""
    drip_cert_baseline.check(spec)
