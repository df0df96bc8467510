"""A typed public surface (issue 27): a type checker sees every public name's real type.

``drip_cert/__init__.py`` imports its names lazily at run time (``__getattr__``, typed ``Any``);
the same names are re-exported under ``TYPE_CHECKING``. The fast tests check that the two lists
agree and that the result fields are typed; the slow one runs mypy on a file that misuses the
API (it must fail) and on a correct one (it must pass).
"""

from __future__ import annotations

import ast
import dataclasses
import os
import subprocess
import sys
import typing
from pathlib import Path

import pytest

import drip_cert

ROOT = Path(drip_cert.__file__).resolve().parent.parent


def _type_checking_imports() -> dict[str, str]:
    """``name -> module`` of the ``from module import name as name`` under ``TYPE_CHECKING``."""
    tree = ast.parse((ROOT / "drip_cert" / "__init__.py").read_text())
    out: dict[str, str] = {}
    for node in tree.body:
        if (
            isinstance(node, ast.If)
            and isinstance(node.test, ast.Name)
            and node.test.id == "TYPE_CHECKING"
        ):
            for imp in node.body:
                assert isinstance(imp, ast.ImportFrom) and imp.module is not None
                for alias in imp.names:
                    assert alias.asname == alias.name, f"{alias.name}: not an explicit re-export"
                    out[alias.name] = imp.module
    return out


def test_every_public_name_is_re_exported_for_the_type_checker():
    exports = drip_cert._EXPORTS
    assert len(exports) > 40  # the surface really is read (not an empty dict)
    assert _type_checking_imports() == exports


def test_the_lazy_imports_still_resolve():
    for name, module in drip_cert._EXPORTS.items():
        assert getattr(drip_cert, name).__module__.startswith(module.split(".")[0])


@pytest.mark.parametrize(
    "cls, fields",
    [
        ("drip_cert.bounds.certificate.Certificate", ("delta_iss", "l1", "tasil")),
        ("drip_cert.bounds.certificate.ContractionAnalysis", ("metric",)),
        ("drip_cert.validate.run.ValidationReport", ("certificate", "result")),
    ],
)
def test_result_fields_are_typed_not_any(cls, fields):
    """The fields the issue names carry their real type (resolved: the annotation is no
    ``Any``, and names the class a reader would look for)."""
    import importlib

    module, name = cls.rsplit(".", 1)
    mod = importlib.import_module(module)
    hints = typing.get_type_hints(getattr(mod, name), vars(mod) | _type_namespace())
    for f in fields:
        hint = hints[f]
        assert hint is not typing.Any, f"{cls}.{f} is Any"
        assert typing.Any not in typing.get_args(hint), f"{cls}.{f} is Any | ..."


def _type_namespace() -> dict[str, object]:
    from drip_cert.analysis.contraction.lmi import MetricResult
    from drip_cert.analysis.contraction.slope_lmi import TraceObstruction
    from drip_cert.analysis.iss import DeltaISSResult
    from drip_cert.bounds.certificate import Certificate
    from drip_cert.bounds.l1drac.system import L1Section
    from drip_cert.bounds.tasil.certificate import TasilCertificate
    from drip_cert.validate.checks import GapEvidence

    return {
        c.__name__: c
        for c in (
            DeltaISSResult,
            MetricResult,
            TraceObstruction,
            Certificate,
            L1Section,
            TasilCertificate,
            GapEvidence,
        )
    }


def test_deploy_without_an_l1_design_is_a_spec_error():
    """Found by typing ``Certificate.l1``: a certificate whose L1-DRAC part has no design at all
    (``design is None``, e.g. L1-DRAC Assumption 2 fails) crashed ``l1drac_controller`` with an
    ``AttributeError`` (``None.reason``) instead of saying why there is nothing to deploy."""
    from drip_cert import certify
    from drip_cert.bounds.l1drac.system import L1Section
    from drip_cert.deploy import l1drac_controller
    from drip_cert.errors import SpecError
    from drip_cert.spec import load_spec
    from tests.helpers import EXAMPLES

    cert = certify(load_spec(EXAMPLES / "regression_ci" / "plant.toml"))
    why = "L1-DRAC Assumption 2 fails, no design"
    no_design = dataclasses.replace(cert, l1=L1Section(constants={}, design=None, error=why))
    with pytest.raises(SpecError, match="Assumption 2 fails"):
        l1drac_controller(no_design)


MISUSE = """\
from drip_cert import certify, load_spec

x: int = certify("nope")
spec = load_spec(123.0)
"""
CORRECT = """\
from drip_cert import Certificate, ValidationReport, certify, validate

cert: Certificate = certify("spec.toml")
ok: bool = cert.certified
rho = cert.tasil.rho if cert.tasil is not None else None
report: ValidationReport = validate("spec.toml", paths=100, seed=0)
same: Certificate = report.certificate
"""


def _mypy(tmp_path: Path, name: str, text: str) -> subprocess.CompletedProcess[str]:
    path = tmp_path / name
    path.write_text(text)
    env = dict(os.environ, MYPYPATH=str(ROOT))  # this checkout, not an installed copy
    return subprocess.run(
        [
            sys.executable,
            "-m",
            "mypy",
            "--config-file",
            str(ROOT / "pyproject.toml"),
            "--follow-imports=silent",  # errors of drip_cert itself are the mypy CI step's
            "--cache-dir",
            str(tmp_path / "cache"),
            str(path),
        ],
        capture_output=True,
        text=True,
        env=env,
        cwd=tmp_path,
        timeout=900,
    )


@pytest.mark.slow  # mypy analyses the whole package: about 15 s of CPU, a minute on a busy machine
def test_mypy_rejects_a_misuse_and_accepts_a_correct_use(tmp_path):
    bad = _mypy(tmp_path, "misuse.py", MISUSE)
    assert bad.returncode == 1, bad.stdout + bad.stderr
    assert 'has type "Certificate", variable has type "int"' in bad.stdout, bad.stdout
    assert "load_spec" in bad.stdout and '"float"' in bad.stdout, bad.stdout
    good = _mypy(tmp_path, "correct.py", CORRECT)
    assert good.returncode == 0, good.stdout + good.stderr


def test_one_status_vocabulary_with_unchanged_json():
    """``Check.status`` and the validation statuses are enums of :mod:`drip_cert.provenance`,
    str-valued, so the JSON keeps the words it had."""
    import json
    import math

    from drip_cert.provenance import Check, CheckStatus, ValidationStatus
    from drip_cert.validate.checks import HOLDS, NOTHING_CHECKED, overall_status

    ok = Check.compare("a", 1.0, 2.0, "1 <= 2")
    bad = Check.compare("b", 3.0, 2.0, "3 <= 2")
    nan = Check.compare("c", math.nan, 2.0, "nan <= 2")
    assert [c.status for c in (ok, bad, nan)] == [
        CheckStatus.HOLDS,
        CheckStatus.FAILS,
        CheckStatus.UNKNOWN,
    ]
    assert all(isinstance(c.status, CheckStatus) for c in (ok, bad, nan))
    assert json.loads(json.dumps(bad.to_dict()))["status"] == "fails"
    assert HOLDS is ValidationStatus.HOLDS and json.dumps(HOLDS) == '"holds"'
    assert overall_status([]) is NOTHING_CHECKED
    assert {s.value for s in ValidationStatus} == {
        "holds",
        "violated",
        "not_checked",
        "nothing_checked",
    }
