"""No traceback for any user mistake (issue 22, finding 7).

Every file a command names is checked before any work starts (exit 2, the file named); an
unexpected error while reading user input is exit 2 with the file named, any other error a
one-line "internal error" (exit 3) whose traceback only ``--debug`` shows. The Python API takes a
spec file's path, a ``Spec`` or a ``System`` alike; another type is an ``InputTypeError`` (a
``TypeError`` and a ``DripCertError``). The commands run in-process (``main(argv)``); where a
mistake used to be found only after the work, the work is replaced by a function that fails the
test if it is reached, so each test is fast both before and after the fix.
"""

from __future__ import annotations

import zipfile
from pathlib import Path
from typing import Any

import numpy as np
import pytest

import drip_cert
import drip_cert.bounds.l1drac.toml as toml_mod
import drip_cert.workflows as workflows
from drip_cert.cli import main
from drip_cert.errors import DripCertError, InputTypeError, SpecError
from tests.helpers import (
    DOUBLE_INTEGRATOR_CONSTANTS,
    EXAMPLES,
    ROUNDING_ATOL,
    example_spec,
    run_cli,
)

#: a spec with a learned policy that certifies in about a second (validate --data reads it)
PLANT = EXAMPLES / "regression_ci" / "plant.toml"
#: a spec that certifies in under a second (not certified: Assumption 7 fails)
FAST_SPEC = example_spec("infeasible_2d")


def _no_work(*_: Any, **__: Any) -> Any:
    raise AssertionError("the work started although an argument was already known to be bad")


def _no_traceback(err: str) -> None:
    assert "Traceback" not in err
    assert len(err.strip().splitlines()) == 1, err  # one line


# ------------------------------------------------------------------- files read: validate --data
def _corrupt_npz(tmp_path: Path) -> Path:
    """A real .npz whose central directory is cut off: numpy raises zipfile.BadZipFile."""
    good = tmp_path / "good.npz"
    np.savez(good, t=np.linspace(0.0, 1.0, 5))
    bad = tmp_path / "corrupt.npz"
    bad.write_bytes(good.read_bytes()[:40])
    with pytest.raises(zipfile.BadZipFile):  # the file really is what the test says
        np.load(bad)
    return bad


def test_validate_corrupt_npz_is_exit_2_naming_the_file(tmp_path, capsys):
    bad = _corrupt_npz(tmp_path)
    code, out, err = run_cli(capsys, "validate", str(PLANT), "--data", str(bad))
    assert code == 2  # not 1: a script reads 1 as "the bound is violated"
    assert str(bad) in err and "damaged .npz" in err
    _no_traceback(err)
    assert out == ""


@pytest.mark.parametrize(
    ("content", "says"),
    [
        (b"t,x\n0,1\n", "not an .npz archive"),  # a text file named .npz
        (None, "single .npy array"),  # numpy.save output named .npz
    ],
)
def test_validate_data_that_is_no_npz_says_what_it_is(tmp_path, capsys, content, says):
    path = tmp_path / "data.npz"
    if content is None:
        with path.open("wb") as fh:
            np.save(fh, np.zeros(3))
    else:
        path.write_bytes(content)
    code, _, err = run_cli(capsys, "validate", str(PLANT), "--data", str(path))
    assert code == 2
    assert str(path) in err and says in err
    _no_traceback(err)


def test_validate_data_binary_csv_is_exit_2(tmp_path, capsys):
    path = tmp_path / "gaps.csv"
    path.write_bytes(bytes(range(256)))  # not UTF-8 text
    code, _, err = run_cli(capsys, "validate", str(PLANT), "--data", str(path))
    assert code == 2
    assert str(path) in err and "UnicodeDecodeError" in err
    _no_traceback(err)


def test_validate_data_directory_is_exit_2(tmp_path, capsys):
    code, _, err = run_cli(capsys, "validate", str(PLANT), "--data", str(tmp_path))
    assert code == 2
    assert str(tmp_path) in err and "is a directory" in err


# ---------------------------------------------------------------- files written: checked first
def test_design_l1_figure_in_missing_directory_is_exit_2_before_the_design(
    tmp_path, capsys, monkeypatch
):
    monkeypatch.setattr(toml_mod, "design_l1_report", _no_work)
    target = tmp_path / "no_such_dir" / "x.png"
    code, out, err = run_cli(
        capsys, "design-l1", str(DOUBLE_INTEGRATOR_CONSTANTS), "--figure", str(target)
    )
    assert code == 2
    assert str(target.parent) in err and "does not exist" in err
    _no_traceback(err)
    assert out == "" and not target.parent.exists()


@pytest.mark.parametrize(("name", "says"), [("", "is a directory"), ("x.foo", ".foo")])
def test_design_l1_figure_directory_or_unknown_format_is_exit_2(
    tmp_path, capsys, monkeypatch, name, says
):
    monkeypatch.setattr(toml_mod, "design_l1_report", _no_work)
    target = tmp_path / name if name else tmp_path
    code, _, err = run_cli(
        capsys, "design-l1", str(DOUBLE_INTEGRATOR_CONSTANTS), "--figure", str(target)
    )
    assert code == 2 and says in err
    _no_traceback(err)


def test_train_out_existing_file_is_exit_2_before_training(tmp_path, capsys, monkeypatch):
    import drip_cert.workflows as wf

    monkeypatch.setattr(wf, "run_pipeline", _no_work)  # the training must not start
    existing = tmp_path / "results"
    existing.write_text("not a directory\n")
    code, _, err = run_cli(capsys, "train", str(PLANT), "--out", str(existing))
    assert code == 2
    assert str(existing) in err and "existing file" in err
    _no_traceback(err)
    # the library function checks it first too (no CLI in between)
    with pytest.raises(SpecError, match="existing file"):
        wf.train_from_spec(PLANT, method="tasil", trajectories=2, seed=0, out=existing)


@pytest.mark.parametrize("command", ["validate", "reproduce"])
def test_out_existing_file_is_exit_2_before_the_work(tmp_path, capsys, monkeypatch, command):
    import drip_cert.workflows as wf

    monkeypatch.setattr(wf, "run_pipeline", _no_work)
    existing = tmp_path / "out"
    existing.write_text("x\n")
    head = [command, str(PLANT)] if command == "validate" else [command, "paper-4d"]
    code, _, err = run_cli(capsys, *head, "--out", str(existing))
    assert code == 2
    assert str(existing) in err
    _no_traceback(err)


def test_out_below_an_existing_file_is_exit_2(tmp_path, capsys, monkeypatch):
    import drip_cert.workflows as wf

    monkeypatch.setattr(wf, "run_pipeline", _no_work)
    (tmp_path / "f").write_text("x\n")
    code, _, err = run_cli(capsys, "train", str(PLANT), "--out", str(tmp_path / "f" / "sub"))
    assert code == 2 and "is a file" in err


# ------------------------------------------------------------------ numbers that make no sense
@pytest.mark.parametrize(
    "argv",
    [
        ["validate", str(PLANT), "--practical-ts", "0"],
        ["validate", str(PLANT), "--practical-ts", "-0.001"],
        ["validate", str(PLANT), "--practical-ts", "nan"],
        ["validate", str(PLANT), "--seed", "-5"],
        ["train", str(PLANT), "--out", "o", "--seed", "-1"],
        ["train", str(PLANT), "--out", "o", "--max-heldout-gap", "nan"],
        ["train", str(PLANT), "--out", "o", "--max-heldout-gap", "0"],
        ["reproduce", "paper-4d", "--seed", "-1"],
    ],
)
def test_nonsense_numbers_are_usage_errors(argv, capsys, monkeypatch):
    for name in ("validate_spec", "train_from_spec", "reproduce"):
        monkeypatch.setattr(workflows, name, _no_work)  # the CLI imports it when it runs
    with pytest.raises(SystemExit) as info:
        main(argv)
    assert info.value.code == 2
    assert argv[-2] in capsys.readouterr().err  # the option is named


def test_validate_api_refuses_a_nonpositive_practical_ts():
    from drip_cert.validate import validate

    spec = drip_cert.load_spec(PLANT)
    with pytest.raises(SpecError, match="practical_ts"):
        validate(spec.system, object(), spec.settings.simulation, paths=2, seed=0, practical_ts=0.0)


# ------------------------------------------------------------------------------ spec files read
@pytest.mark.parametrize("command", ["check-spec", "certify"])
def test_spec_that_is_a_directory_says_so(tmp_path, capsys, command):
    code, _, err = run_cli(capsys, command, str(tmp_path))
    assert code == 2 and "is a directory" in err  # not "does not exist"
    _no_traceback(err)


def test_missing_spec_in_missing_directory_says_both(tmp_path, capsys):
    target = tmp_path / "nodir" / "spec.toml"
    code, _, err = run_cli(capsys, "certify", str(target))
    assert code == 2
    assert "does not exist" in err and f"{str(target.parent)!r} does not exist either" in err


def test_corrupt_weights_file_named_in_the_spec_is_exit_2(tmp_path, capsys):
    (tmp_path / "h.npz").write_bytes(b"PK\x03\x04 cut short")
    spec = tmp_path / "spec.toml"
    spec.write_text(
        '[system]\nname = "blk"\nstates = ["x1"]\nhorizon = 1.0\n'
        '[blocks.h]\nkind = "mlp"\nweights = "h.npz"\ninputs = 1\noutputs = 1\n'
        'activation = "tanh"\n[dynamics]\nf = ["-x1"]\ng = [["1"]]\n'
        '[policy]\nexpert = ["-x1"]\nlearned = ["-x1 + h(x)[0]"]\n'
        "[initial]\nsupport = [[-1.0, 1.0]]\n"
    )
    code, _, err = run_cli(capsys, "check-spec", str(spec))
    assert code == 2
    assert "h.npz" in err and "damaged .npz" in err and "blocks.h.weights" in err
    _no_traceback(err)


def test_binary_constants_file_is_exit_2(tmp_path, capsys):
    path = tmp_path / "c.toml"
    path.write_bytes(bytes(range(256)))
    code, _, err = run_cli(capsys, "design-l1", str(path))
    assert code == 2 and str(path) in err
    _no_traceback(err)


def test_diff_of_a_directory_is_exit_2(tmp_path, capsys):
    (tmp_path / "new.json").write_text("{}\n")
    code, _, err = run_cli(capsys, "diff", str(tmp_path), str(tmp_path / "new.json"))
    assert code == 2 and "is a directory" in err


# ------------------------------------------------------------------------- the top-level guard
def test_unexpected_error_reading_a_spec_is_exit_2_naming_the_file(capsys, monkeypatch):
    import drip_cert.spec.load as load

    def broken(*_: Any, **__: Any) -> Any:
        raise KeyError("some key the reader did not expect")

    monkeypatch.setattr(load, "spec_from_dict", broken)
    code, _, err = run_cli(capsys, "check-spec", str(PLANT))
    assert code == 2
    assert str(PLANT) in err and "KeyError" in err
    _no_traceback(err)


def _internal_bug(*_: Any, **__: Any) -> Any:
    return 1 / 0  # stands for any bug of drip-cert after the input was read


def test_internal_error_is_one_line_exit_3(capsys, monkeypatch):
    monkeypatch.setattr(toml_mod, "design_l1_report", _internal_bug)
    code, out, err = run_cli(capsys, "design-l1", str(DOUBLE_INTEGRATOR_CONSTANTS))
    assert code == 3
    _no_traceback(err)
    assert err.startswith("drip-cert: internal error: ZeroDivisionError")
    assert "please report it" in err and "--debug" in err and "design-l1" in err
    assert out == ""


@pytest.mark.parametrize("where", ["before", "after"])
def test_debug_shows_the_traceback(capsys, monkeypatch, where):
    monkeypatch.setattr(toml_mod, "design_l1_report", _internal_bug)
    argv = ["design-l1", str(DOUBLE_INTEGRATOR_CONSTANTS)]
    argv = ["--debug", *argv] if where == "before" else [*argv, "--debug"]
    code, _, err = run_cli(capsys, *argv)
    assert code == 3
    assert "Traceback" in err and "_internal_bug" in err
    assert err.strip().splitlines()[-1].startswith("drip-cert: internal error:")


def test_debug_shows_the_traceback_of_a_user_error_too(tmp_path, capsys):
    code, _, err = run_cli(capsys, "--debug", "certify", str(tmp_path / "nope.toml"))
    assert code == 2 and "Traceback" in err and "SpecError" in err


# ------------------------------------------------------- the API: a path, a Spec or a System
def _without_timings(obj: Any) -> Any:
    if isinstance(obj, dict):
        return {k: _without_timings(v) for k, v in obj.items() if "time" not in k}
    if isinstance(obj, list):
        return [_without_timings(v) for v in obj]
    return obj


@pytest.mark.parametrize("form", [str, Path])
def test_certify_takes_a_path(form):
    by_path = drip_cert.certify(form(FAST_SPEC))
    by_spec = drip_cert.certify(drip_cert.load_spec(FAST_SPEC))
    assert by_path.verdict == by_spec.verdict
    assert _without_timings(by_path.to_dict()) == _without_timings(by_spec.to_dict())


def test_load_spec_takes_a_spec_or_a_system():
    spec = drip_cert.load_spec(FAST_SPEC)
    assert drip_cert.load_spec(spec) is spec
    wrapped = drip_cert.load_spec(spec.system)
    assert wrapped.system is spec.system and wrapped.path is None
    assert wrapped.settings.tasil.seed == drip_cert.Spec(None, spec.system).settings.tasil.seed


@pytest.mark.parametrize(
    ("call", "argument"),
    [
        (lambda v: drip_cert.load_spec(v), "path"),
        (lambda v: drip_cert.certify(v), "spec"),
        (lambda v: drip_cert.validate(v, paths=2, seed=0), "s"),
        (lambda v: drip_cert.l1drac_controller(v), "source"),
        (lambda v: drip_cert.learned_policy(v), "source"),
    ],
)
@pytest.mark.parametrize("value", [123, None, b"spec.toml"])
def test_wrong_type_is_a_typeerror_and_a_dripcerterror(call, argument, value):
    with pytest.raises(InputTypeError) as info:
        call(value)
    assert isinstance(info.value, TypeError) and isinstance(info.value, DripCertError)
    msg = str(info.value)
    assert msg.startswith(f"{argument}: expected") and "drip_cert.Spec" in msg
    assert type(value).__name__ in msg


def test_drip_cert_validate_stays_callable_after_its_package_is_imported():
    import drip_cert.validate as package  # binds drip_cert.validate to the package

    assert drip_cert.validate is package
    with pytest.raises(InputTypeError):  # reached the function: not "module is not callable"
        drip_cert.validate(123, paths=2, seed=0)


def test_validate_takes_a_path(tmp_path):
    with pytest.raises(SpecError, match="does not exist"):
        drip_cert.validate(str(tmp_path / "nope.toml"), paths=2, seed=0)
    # a spec without a learned policy: the message says what is missing (no AttributeError)
    with pytest.raises(SpecError, match="learned policy"):
        drip_cert.validate(FAST_SPEC, paths=2, seed=0)


def test_learned_policy_takes_a_path_and_a_system():
    spec = drip_cert.load_spec(PLANT)
    x = np.array([0.3])
    by_path = np.asarray(drip_cert.learned_policy(str(PLANT))(x))
    by_system = np.asarray(drip_cert.learned_policy(spec.system)(x))
    assert by_path.tolist() == by_system.tolist()  # one policy: the same floats
    assert abs(by_path[0] - (-0.98 * 0.3)) < ROUNDING_ATOL
