"""pytest integration: re-check a certificate, and a user's recorded gaps, in the user's CI.

Installed with drip-cert as a pytest plugin (entry point ``pytest11``, name
``drip_cert.testing``; disable with ``-p no:drip_cert.testing``). It gives

* :func:`assert_certified` ``(spec)``: certify a spec; fail the test unless the verdict is
  ``certified`` (``allow_conditional=True`` accepts ``conditional`` too);
* :func:`assert_gaps_within` ``(spec, data)``: compare recorded gaps (``drip-cert validate SPEC
  --data FILE``, layout in ``docs/data_format.md``) with the spec's certificate; fail unless the
  validation ``holds`` (a violated bound or nothing checked fails, as exit status 1 does; so do
  data recorded with another policy or design than the certified ones, or without a fingerprint
  unless ``accept_unfingerprinted=True``, which passes with an :class:`UnfingerprintedData`
  warning);
* the fixture ``drip_cert_baseline``: ``drip_cert_baseline.check(spec_or_certificate)`` compares
  the certificate (or validation report) with a snapshot stored next to the test file, in
  ``drip_cert_baselines/<test file stem>.<test name>.json``, by the rules of ``drip-cert diff``
  (:mod:`drip_cert.diff`), and fails on a regression. ``pytest --drip-cert-update`` (re)writes
  the snapshots instead; a missing snapshot fails until it is recorded that way. Improvements
  pass with a :class:`BaselineChanged` warning (record them with the flag). The tolerance is the
  ini option ``drip_cert_rtol`` (default :data:`~drip_cert.diff.DEFAULT_RTOL`) or ``rtol=``.

Example (``tests/test_certificate.py`` of a user's project)::

    from drip_cert.testing import assert_certified, assert_gaps_within

    def test_plant_is_certified():
        assert_certified("plant.toml")

    def test_recorded_gaps_within_the_bounds():
        assert_gaps_within("plant.toml", "gaps.npz")

    def test_certificate_did_not_regress(drip_cert_baseline):
        drip_cert_baseline.check("plant.toml")
"""

from __future__ import annotations

import re
import warnings
from collections.abc import Iterator, Mapping
from pathlib import Path
from typing import Any

import pytest

from drip_cert.bounds.certificate import certify
from drip_cert.diff import DEFAULT_RTOL, DiffResult, diff_outputs, diff_text
from drip_cert.errors import DripCertError
from drip_cert.numerics.atomic_io import atomic_write_json, jsonable
from drip_cert.provenance import ValidationStatus
from drip_cert.schema import LoadedOutput, check_output, load_output
from drip_cert.spec import load_spec
from drip_cert.workflows import validate_recorded

__all__ = [
    "BASELINE_DIR",
    "Baseline",
    "BaselineChanged",
    "UnfingerprintedData",
    "assert_certified",
    "assert_gaps_within",
]

BASELINE_DIR = "drip_cert_baselines"
"""The folder, next to a test file, that holds its certificate snapshots."""

UPDATE_FLAG = "--drip-cert-update"


class BaselineChanged(UserWarning):
    """A certificate changed against its snapshot without a regression (an improvement, or a
    change that is neither): the test passes; ``pytest --drip-cert-update`` records it."""


class UnfingerprintedData(UserWarning):
    """Recorded data without a fingerprint accepted by ``accept_unfingerprinted=True``: nothing
    shows they were recorded with the certified policy and design."""


# ------------------------------------------------------------------------------ helpers
def _spec_path(spec: Any) -> Path:
    if not isinstance(spec, str | Path):
        raise TypeError(f"expected a spec file path (str or Path), got {type(spec).__name__}")
    return Path(spec)


def _certify(spec: Any) -> Any:
    """The certificate of ``spec``: a spec file path, a loaded ``Spec`` or a ``System``."""
    if isinstance(spec, str | Path):
        spec = load_spec(spec)
    return certify(spec)


def _failing_lines(d: Mapping[str, Any]) -> list[str]:
    out = [f"  {r}" for r in d.get("verdict_reasons", [])]
    for a in d.get("assumptions", []):
        if a.get("status") != "holds":
            out.append(f"  {a['id']}: {a['status']}, margin {a.get('margin')}: {a.get('detail')}")
    return out


# ------------------------------------------------------------------------------ asserts
def assert_certified(spec: Any, *, allow_conditional: bool = False) -> Any:
    """Certify ``spec`` and fail the test unless its verdict is ``certified``.

    Parameters
    ----------
    spec
        A spec file path, a loaded :class:`~drip_cert.spec.load.Spec` or a
        :class:`~drip_cert.model.system.System`.
    allow_conditional
        Accept a ``conditional`` verdict (one resting on sampled estimates or unproved regions),
        as ``drip-cert certify --allow-estimates`` does.

    Returns
    -------
    Certificate
        The certificate, for further assertions.
    """
    try:
        cert = _certify(spec)
    except DripCertError as exc:
        pytest.fail(f"drip-cert could not certify {spec}: {exc}", pytrace=False)
    verdict = cert.verdict.value
    if verdict == "certified" or (allow_conditional and verdict == "conditional"):
        return cert
    lines = [f"{spec}: verdict {verdict.upper()} (expected certified)"]
    lines += _failing_lines(cert.to_dict())
    pytest.fail("\n".join(lines), pytrace=False)


def assert_gaps_within(
    spec: str | Path,
    data: str | Path,
    *,
    out: str | Path | None = None,
    accept_unfingerprinted: bool = False,
) -> Any:
    """Compare recorded data with the certificate of ``spec``; fail unless the validation holds.

    Runs what ``drip-cert validate SPEC --data FILE`` runs
    (:func:`~drip_cert.workflows.validate_recorded`): the data file is read and checked, the
    spec's system (with its learned policy, the one that produced the data) is certified, and
    every certified bound is compared with the data's statistic at its confidence level.

    Parameters
    ----------
    spec
        The spec file.
    data
        The recorded trajectories or gap series (``.npz`` or ``.csv``, ``docs/data_format.md``).
    out
        Optional folder for ``validation.json``, ``validation.md`` and ``validation.png``.
    accept_unfingerprinted
        Accept data without a ``fingerprint`` (``docs/data_format.md``), with an
        :class:`UnfingerprintedData` warning; by default they fail the test.

    Returns
    -------
    ValidationReport
        The report, when it holds. A violated bound, or a run that checked nothing, fails the
        test with every violated check (bound, empirical value, confidence bound); malformed
        data fails it with the data error (file, array, problem); data whose fingerprint is
        not the certificate's fail it naming the part (``policy``, ``design``) that differs.
    """
    try:
        rep = validate_recorded(
            _spec_path(spec), data, out=out, accept_unfingerprinted=accept_unfingerprinted
        )
    except DripCertError as exc:
        pytest.fail(f"drip-cert could not validate {data} against {spec}: {exc}", pytrace=False)
    if rep.unfingerprinted_data:  # accepted unverified (else refused above)
        warnings.warn(
            UnfingerprintedData(
                f"{data}: the data carry no fingerprint; accepted unverified by "
                "accept_unfingerprinted=True"
            ),
            stacklevel=2,
        )
    if rep.status == ValidationStatus.HOLDS:
        return rep
    lines = [f"{data} against {spec}: validation {rep.status.upper()}"]
    for c in rep.all_checks:
        if c.status == ValidationStatus.VIOLATED:
            lines.append(
                f"  {c.name}: empirical {c.empirical:.6g} (one-sided confidence bound "
                f"{c.confidence_low:.6g} at level {c.level}) exceeds the certified bound "
                f"{c.bound:.6g}: {c.what}"
            )
    lines += [f"  note: {n}" for n in rep.notes[:3]]
    pytest.fail("\n".join(lines), pytrace=False)


# ----------------------------------------------------------------------------- baseline
class Baseline:
    """A certificate snapshot next to a test; see the module docstring.

    Parameters
    ----------
    path
        The snapshot file (the fixture makes it ``<test dir>/drip_cert_baselines/<file
        stem>.<test name>.json``).
    update
        Write the snapshot instead of comparing (``--drip-cert-update``).
    rtol
        Relative tolerance of a bound change (:func:`drip_cert.diff.diff_outputs`).
    """

    def __init__(self, path: Path, *, update: bool = False, rtol: float = DEFAULT_RTOL) -> None:
        self.path = Path(path)
        self.update = update
        self.rtol = rtol
        self.written: list[Path] = []

    def path_for(self, name: str | None) -> Path:
        """The snapshot file of ``check(..., name=name)``."""
        if not name:
            return self.path
        return self.path.with_name(f"{self.path.stem}.{_safe(name)}{self.path.suffix}")

    def check(self, result: Any, *, name: str | None = None, rtol: float | None = None) -> Any:
        """Compare ``result`` with its snapshot; fail the test on a regression.

        Parameters
        ----------
        result
            A spec file path, ``Spec`` or ``System`` (certified here), a ``Certificate``, a
            ``ValidationReport``, or the ``to_dict()`` of either.
        name
            Tells several snapshots of one test apart.
        rtol
            Overrides the baseline's tolerance for this check.

        Returns
        -------
        DiffResult or None
            The comparison (``None`` when the snapshot was written).
        """
        data = _as_output_dict(result)
        new = check_output(data, where="this run's output")
        path = self.path_for(name)
        if self.update:
            atomic_write_json(path, data)
            self.written.append(path)
            return None
        if not path.is_file():
            pytest.fail(
                f"no drip-cert baseline {path}: record it with `pytest {UPDATE_FLAG}` and commit "
                "it",
                pytrace=False,
            )
        try:
            old = load_output(path)
        except DripCertError as exc:
            pytest.fail(f"{exc} (or re-record it with `pytest {UPDATE_FLAG}`)", pytrace=False)
        res: DiffResult = diff_outputs(
            old,
            LoadedOutput(Path("(this run)"), new.kind, new.version, new.data),
            rtol=self.rtol if rtol is None else rtol,
        )
        if res.regression:
            pytest.fail(
                diff_text(res) + f"\n\nif the change is intended: pytest {UPDATE_FLAG}",
                pytrace=False,
            )
        if res.changes:
            warnings.warn(
                BaselineChanged(
                    f"{path}: {len(res.changes)} change(s) without a regression "
                    f"({'; '.join(c.text for c in res.changes[:3])}); record with "
                    f"`pytest {UPDATE_FLAG}`"
                ),
                stacklevel=2,
            )
        return res


def _safe(text: str) -> str:
    """A file-name-safe form of a test or snapshot name (``test_a[x-1]`` -> ``test_a_x-1_``)."""
    return re.sub(r"[^A-Za-z0-9_.-]", "_", text)


def _as_output_dict(result: Any) -> dict[str, Any]:
    if isinstance(result, str | Path) or type(result).__name__ in ("Spec", "System"):
        result = _certify(result)
    if hasattr(result, "to_dict"):
        result = result.to_dict()
    if not isinstance(result, Mapping):
        raise TypeError(
            "drip_cert_baseline.check takes a spec path, Spec, System, Certificate, "
            f"ValidationReport or its to_dict(), got {type(result).__name__}"
        )
    out: dict[str, Any] = jsonable(dict(result))
    return out


# ------------------------------------------------------------------------- pytest hooks
def pytest_addoption(parser: pytest.Parser) -> None:
    group = parser.getgroup("drip-cert", "drip-cert certificate baselines")
    group.addoption(
        UPDATE_FLAG,
        action="store_true",
        default=False,
        help="write the drip_cert_baseline snapshots instead of comparing with them",
    )
    parser.addini(
        "drip_cert_rtol",
        f"relative tolerance of drip_cert_baseline (default {DEFAULT_RTOL:g})",
        default=str(DEFAULT_RTOL),
    )


@pytest.fixture
def drip_cert_baseline(request: pytest.FixtureRequest) -> Iterator[Baseline]:
    """A :class:`Baseline` whose snapshot is
    ``<test dir>/drip_cert_baselines/<test file stem>.<test name>.json``."""
    test_file = Path(str(request.node.path))
    path = test_file.parent / BASELINE_DIR / f"{test_file.stem}.{_safe(request.node.name)}.json"
    rtol_text = str(request.config.getini("drip_cert_rtol"))
    try:
        rtol = float(rtol_text)
    except ValueError:
        raise pytest.UsageError(
            f"ini option drip_cert_rtol = {rtol_text!r} is not a number"
        ) from None
    update = bool(request.config.getoption(UPDATE_FLAG))
    base = Baseline(path, update=update, rtol=rtol)
    yield base
    if base.written:
        request.config.stash.setdefault(_WRITTEN, []).extend(base.written)


_WRITTEN = pytest.StashKey[list[Path]]()


def pytest_terminal_summary(terminalreporter: Any, config: pytest.Config) -> None:
    written = config.stash.get(_WRITTEN, [])
    if written:
        terminalreporter.write_sep("-", f"drip-cert: {len(written)} baseline(s) written")
        for p in written:
            terminalreporter.write_line(str(p))
