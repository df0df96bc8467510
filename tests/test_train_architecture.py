"""``drip-cert train --architecture {mlp,residual}`` (issue 24): parsing, the override of
``[tasil] architecture`` for the policy trained and for every method of ``--compare``, the
written spec, the error message of a bad value, and examples/compare_methods.py's
``--architecture`` (all four methods train the same class). Tiny networks, few steps, no
certificate: the end-to-end tables are docs/baselines.md's, not tests."""

from __future__ import annotations

import importlib.util
import json
from pathlib import Path

import numpy as np
import pytest

from drip_cert.spec import load_spec
from drip_cert.spec.settings import TRAIN_METHODS
from tests.helpers import run_cli, two_state_spec, write_spec

ROOT = Path(__file__).resolve().parent.parent
TINY = "[tasil]\nhidden = [4]\nsamples = 10\nheldout = 3\n"
STRUCTURE = '[policy]\nexpert = ["-x1 - 2*x2"]\nstructure = ["-x1"]\n'
TRAIN = ("--no-certify", "--steps", "4", "--trajectories", "3", "--json")


def _residual_spec(tmp_path: Path) -> Path:
    """The helper's spec with ``[policy] structure = -x1`` and ``architecture = "residual"``."""
    text = two_state_spec().replace('[policy]\nexpert = ["-x1 - 2*x2"]\n', STRUCTURE)
    assert "structure" in text
    return write_spec(tmp_path, text + TINY + 'architecture = "residual"\n', "residual.toml")


def _compare_methods():
    path = ROOT / "examples" / "compare_methods.py"
    spec = importlib.util.spec_from_file_location("compare_methods", path)
    assert spec is not None and spec.loader is not None
    mod = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(mod)
    return mod


def test_parser_reads_architecture_default_none():
    from drip_cert.cli import build_parser

    args = build_parser().parse_args(["train", "s.toml", "--out", "o"])
    assert args.architecture is None  # the spec's [tasil] architecture
    for a in ("mlp", "residual"):
        args = build_parser().parse_args(["train", "s.toml", "--out", "o", "--architecture", a])
        assert args.architecture == a


@pytest.mark.parametrize("value", ["cnn", "MLP", ""])
def test_bad_architecture_exits_2_with_the_choices(tmp_path, capsys, value):
    spec = write_spec(tmp_path, two_state_spec())
    with pytest.raises(SystemExit) as exc:
        run_cli(capsys, "train", str(spec), "--out", str(tmp_path / "o"), "--architecture", value)
    assert exc.value.code == 2
    err = capsys.readouterr().err
    assert "Traceback" not in err
    assert "--architecture" in err and "'mlp', 'residual'" in err


@pytest.mark.slow
def test_residual_overrides_an_mlp_spec_and_needs_no_structure(tmp_path, capsys):
    """``residual`` without ``[policy] structure`` is the class ``K x + N(x)``: a learned ``K``."""
    spec = write_spec(tmp_path, two_state_spec() + TINY)
    assert load_spec(spec).settings.tasil.architecture == "mlp"
    argv = ("train", str(spec), "--out", str(tmp_path / "r"), "--no-compare", *TRAIN)
    code, out, _ = run_cli(capsys, *argv, "--architecture", "residual")
    assert code in (0, 1)  # 1: the held-out gap of 4 steps may exceed its threshold
    summary = json.loads(out)
    assert summary["architecture"] == "residual"
    K = np.asarray(summary["linear"])
    assert K.shape == (1, 2) and np.all(np.isfinite(K))
    code, out, _ = run_cli(capsys, *argv)  # no flag: the spec's plain MLP, no K
    summary = json.loads(out)
    assert summary["architecture"] == "mlp" and summary["linear"] is None


def test_mlp_overrides_a_residual_spec_and_the_written_spec_loads(tmp_path, capsys):
    """``--architecture mlp`` on a spec with a structure trains a plain MLP (no structure, no K);
    the spec written next to it drops the structure the plain class does not use and records
    ``architecture = "mlp"``, so check-spec accepts it."""
    spec = _residual_spec(tmp_path)
    assert load_spec(spec).settings.tasil.architecture == "residual"
    written = tmp_path / "trained.toml"
    code, out, _ = run_cli(
        capsys, "train", str(spec), "--out", str(tmp_path / "m"), "--no-compare", *TRAIN,
        "--architecture", "mlp", "--write-spec", str(written),
    )  # fmt: skip
    assert code in (0, 1)
    summary = json.loads(out)
    assert summary["architecture"] == "mlp" and summary["linear"] is None
    assert all("-x1" not in e for e in summary["use_in_spec"].split("learned = [")[1:])
    back = load_spec(written)
    assert back.settings.tasil.architecture == "mlp"
    assert back.structure is None
    assert back.system.learned is not None
    code, _, _ = run_cli(capsys, "check-spec", str(written))
    assert code == 0


def test_compare_trains_every_method_in_the_requested_class(tmp_path, monkeypatch):
    """``train --compare --architecture residual``: run_pipeline gets every method and the
    override (the one place where the four methods' class is set)."""
    import drip_cert.workflows as wf

    seen = {}

    class Seen(Exception):
        pass

    def spy(spec, **kw):
        seen.update(kw)
        raise Seen  # the wiring is what is tested; training is the next test's

    monkeypatch.setattr(wf, "run_pipeline", spy)
    spec = write_spec(tmp_path, two_state_spec() + TINY)
    with pytest.raises(Seen):
        wf.train_from_spec(
            spec, method="bc", trajectories=3, seed=0, out=tmp_path / "c", steps=4,
            progress=False, certify=False, compare_all=True, architecture="residual",
        )  # fmt: skip
    assert seen["methods"] == ("bc", "tasil", "dagger", "dart")
    assert seen["tasil"]["architecture"] == "residual"
    seen.clear()
    with pytest.raises(Seen):
        wf.train_from_spec(
            spec, method="tasil", trajectories=3, seed=0, out=tmp_path / "d", steps=4,
            progress=False, certify=False, compare_all=True,
        )  # fmt: skip
    assert "architecture" not in seen["tasil"]  # no flag: the spec's own class
    seen.clear()
    with pytest.raises(Seen):
        wf.train_from_spec(
            spec, method="tasil", trajectories=3, seed=0, out=tmp_path / "e", steps=4,
            progress=False, certify=False, compare_all=True, architecture="residual",
        )  # fmt: skip
    assert seen["methods"] == TRAIN_METHODS
    assert seen["tasil"]["architecture"] == "residual"


def test_compare_methods_example_trains_all_four_in_one_class(tmp_path):
    """examples/compare_methods.py's overrides reach every method: with ``residual`` each of
    TaSIL/BC/DAgger/DART has a learned ``K`` and the structure in its policy; with ``mlp`` (one
    method: the same code path) neither."""
    from drip_cert.workflows import run_pipeline

    cm = _compare_methods()
    spec = load_spec(_residual_spec(tmp_path))
    for arch, has_k, methods in (("residual", True, TRAIN_METHODS), ("mlp", False, ("bc",))):
        over = cm.overrides(steps=4, architecture=arch, trajectories=3)
        assert over == {"steps": 4, "architecture": arch, "trajectories": 3}
        run = run_pipeline(spec, seed=0, train=True, methods=methods, tasil=over,
                           certify=False)  # fmt: skip
        assert list(run.trained) == list(methods)
        for m, tp in run.trained.items():
            assert tp.settings.architecture == arch, m
            assert (tp.result.linear is not None) == has_k, m
            # the whole policy at x = (1, 0): the structure -x1 is in it only for residual
            x = np.array([1.0, 0.0])
            net = tp.result.policy()(x)
            whole = np.asarray(tp.system.numeric.learned(x))
            shift = -1.0 if has_k else 0.0
            np.testing.assert_allclose(whole - np.asarray(net), shift, atol=STRUCT_ATOL)


def test_compare_methods_spec_path_prefers_the_specs_folder(tmp_path):
    cm = _compare_methods()
    (tmp_path / "pendulum.toml").write_text("")
    assert cm.spec_path("pendulum", tmp_path) == tmp_path / "pendulum.toml"
    assert cm.spec_path("van_der_pol", tmp_path) == (
        ROOT / "examples" / "van_der_pol" / "van_der_pol.toml"
    )
    assert cm.spec_path("paper_4d", None).name == "paper_4d.toml"
    assert (cm.RESIDUAL_SPECS / "pendulum.toml").exists()


STRUCT_ATOL = 1e-12  # structure(x) = -x1 evaluated in float64: one negation, no rounding


def test_train_options_left_out_are_the_spec_s_keys(tmp_path, monkeypatch, capsys):
    """``--method``, ``--trajectories`` and ``--seed`` default to the spec's ``[tasil]`` keys: a
    parser default (20 trajectories, seed 0, tasil) silently replaced a spec's
    ``trajectories = 100`` before."""
    import drip_cert.workflows as wf

    seen: dict = {}

    class Seen(Exception):
        pass

    def spy(spec, **kw):
        seen.update(kw)
        raise Seen

    monkeypatch.setattr(wf, "run_pipeline", spy)
    text = two_state_spec() + TINY + 'trajectories = 7\nseed = 5\nmethod = "bc"\n'
    spec = write_spec(tmp_path, text)
    run_cli(capsys, "train", str(spec), "--out", str(tmp_path / "o"), "--no-certify")  # Seen
    assert seen["seed"] == 5
    assert seen["tasil"]["trajectories"] == 7 and seen["tasil"]["method"] == "bc"
    seen.clear()
    run_cli(
        capsys, "train", str(spec), "--out", str(tmp_path / "o"), "--no-certify",
        "--trajectories", "3", "--seed", "1", "--method", "dagger",
    )  # fmt: skip
    assert seen["seed"] == 1
    assert seen["tasil"]["trajectories"] == 3 and seen["tasil"]["method"] == "dagger"
