"""Recorded data against a certificate: ``drip-cert validate SPEC --data FILE``.

The user brings trajectories of the four processes of the DRIP paper (recorded in their own
simulator, on hardware, in a log) or precomputed gap series; :func:`load_recorded` reads and
checks them (layout: ``docs/data_format.md``) and :func:`validate_data` compares them with the
certificate through the SAME code as the Monte-Carlo validation: the gaps
``r_t = ||a_t - b_t||`` are accumulated with :func:`drip_cert.numerics.stats.accumulate` and
finalised with :func:`~drip_cert.numerics.stats.finalize` exactly as the engine's chunks are, and
the checks are :func:`drip_cert.validate.checks.checks_from_result`'s (means and ``L_2p`` norms
with one-sided Student-t bounds at a Bonferroni level per recorded time, the ``(1 - delta)``
radius and the tails with Clopper-Pearson bounds, the total tail by the triangle inequality and a
union bound; see :mod:`drip_cert.validate.checks`). W2 between the laws at the last recorded
time is reported beside its same-law baselines, as in the simulated validation (not checked).

Data recorded with another policy or L1-DRAC design than the certified ones are refused
(:func:`check_fingerprint`, :class:`~drip_cert.errors.FingerprintError`, exit status 1): the
file's ``fingerprint`` (``str(controller.fingerprint)``, :mod:`drip_cert.model.fingerprint`)
must be the certificate's, part by part; a file without one is refused unless
``accept_unfingerprinted`` accepts it, with a warning in the report.

What data cannot decide is said: a check whose processes are not in the file is ``not_checked``
("not in the data"); L1-DRAC checks of data recorded at other parameters than the certified ones
(``l1_design``) are ``not_checked`` ("not at certified parameters"); times beyond the certified
horizon, non-finite values outside paths marked ``diverged``, unsorted or mismatched time grids,
wrong shapes or dimensions, unpaired initial states and too few paths for the confidence asked
are errors (:class:`~drip_cert.errors.SpecError`, exit status 2) naming the file, the array and
the fix.
"""

from __future__ import annotations

import csv
import math
from collections.abc import Mapping
from dataclasses import dataclass, replace
from pathlib import Path
from types import MappingProxyType
from typing import Any

import numpy as np

from drip_cert.errors import FingerprintError, SpecError
from drip_cert.model.fingerprint import Fingerprint
from drip_cert.numerics import stats as _stats
from drip_cert.numerics.user_files import input_file, read_npz, reading
from drip_cert.validate.checks import (
    NOT_CHECKED,
    NOTHING_CHECKED,
    EmpiricalCheck,
    checks_from_result,
    claim_arguments,
    overall_status,
    total_tail_claim,
)
from drip_cert.validate.run import ValidationReport, _thresholds
from drip_cert.vocabulary import GAPS, SCENARIOS

__all__ = [
    "DEFAULT_LEVEL",
    "DataResult",
    "RecordedData",
    "check_fingerprint",
    "check_fits",
    "load_recorded",
    "minimum_paths",
    "validate_data",
]


L1_GAPS = ("total_l1", "uncertainty_l1")
"""The gaps that read the L1-DRAC process ``learned_l1_true``."""

GAP_PREFIX = "gap_"
"""Precomputed gap series are the arrays ``gap_<name>`` (``gap_policy``, ``gap_uncertainty_l1``)."""

DEFAULT_LEVEL = 0.95
"""Confidence level of the checks: the Monte-Carlo validation's (``SimConfig.ci_level``)."""

INITIAL_MATCH_RTOL = 1e-9
"""Paired paths start from one initial state (the engine's identity coupling): their ``t = 0``
states may differ by this relative amount (a float32 round trip keeps 6e-8; 1e-9 allows text
formats with 10+ digits and rejects a shuffled or mismatched row)."""

TIME_MATCH_RTOL = 1e-9
"""Relative tolerance of two series' times being the same grid point (CSV), and of the last time
against the certified horizon: a few ulps of ``j dt`` computed two ways."""

MIN_PATHS = 2
"""A one-sided t bound needs two paths (a sample variance)."""

# the checks of checks_from_result and the gap each one reads
_CHECK_GAP = {
    "policy_radius": "policy",
    "policy_gap": "policy",
    "uncertainty_gap": "uncertainty_l1",
    "uncertainty_gap_rho_mean": "uncertainty_l1",
    "tail_frequency": "uncertainty_l1",
    "total_tail": "total_l1",
    "total_gap": "total_l1",
}


def _gap_of_check(name: str) -> str:
    """The gap a check of :func:`checks_from_result` reads (``uncertainty_L{2p}_norm`` too)."""
    if name.startswith("uncertainty_L") and name.endswith("_norm"):
        return "uncertainty_l1"
    return _CHECK_GAP[name]


# ------------------------------------------------------------------------------ the data
@dataclass(frozen=True)
class RecordedData:
    """Recorded trajectories or gap series, read and checked by :func:`load_recorded`.

    Attributes
    ----------
    path, format
        The file and its format (``npz`` or ``csv``).
    kind
        ``trajectories`` (states of the processes) or ``gaps`` (precomputed ``r_t``).
    times
        ``(T,)`` recorded times, strictly increasing, ``>= 0``.
    scenarios
        ``name -> (N, T, n)`` states (``kind == "trajectories"``); row ``i`` of every array is
        one path tuple (the same initial state, the same noise for the two true processes).
    gaps
        ``name -> (N, T)`` gap norms (``kind == "gaps"``).
    diverged
        ``(N,)`` bool: path tuples that diverged; unknown in every check (as in the engine).
    l1_design
        ``(omega, lambda_s, T_s)`` the L1-DRAC data were recorded with, or ``None`` (not said).
    fingerprint
        The :class:`~drip_cert.model.fingerprint.Fingerprint` the data were recorded with, or
        ``None`` (not said).
    """

    path: str
    format: str
    kind: str
    times: np.ndarray
    scenarios: Mapping[str, np.ndarray]
    gaps: Mapping[str, np.ndarray]
    diverged: np.ndarray
    l1_design: tuple[float, float, float] | None
    fingerprint: Fingerprint | None = None

    @property
    def n_paths(self) -> int:
        """Number of path tuples ``N`` (diverged ones included)."""
        return int(self.diverged.size)

    @property
    def n_state(self) -> int | None:
        """State dimension ``n`` of the trajectories (``None`` for gap series)."""
        for a in self.scenarios.values():
            return int(a.shape[2])
        return None

    def available_gaps(self) -> tuple[str, ...]:
        """The gaps the data give (both processes recorded, or the series itself)."""
        if self.kind == "gaps":
            return tuple(g for g, _, _ in GAPS if g in self.gaps)
        return tuple(g for g, a, b in GAPS if a in self.scenarios and b in self.scenarios)

    def gap_norms(self, name: str) -> np.ndarray:
        """``(N, T)``: ``||a_t - b_t||`` per path (the engine's :func:`norms_sequential`)."""
        if self.kind == "gaps":
            return self.gaps[name]
        _, a, b = next(g for g in GAPS if g[0] == name)
        return _stats.norms_sequential(self.scenarios[a] - self.scenarios[b])

    def summary(self) -> dict[str, Any]:
        """Sizes, the time grid and what the file holds (JSON-ready)."""
        t = self.times
        steps = np.diff(t)
        return {
            "file": self.path,
            "format": self.format,
            "kind": self.kind,
            "n_paths": self.n_paths,
            "n_diverged": int(np.sum(self.diverged)),
            "n_state": self.n_state,
            "times": {
                "n": int(t.size),
                "first": float(t[0]),
                "last": float(t[-1]),
                "min_step": float(steps.min()) if steps.size else None,
                "max_step": float(steps.max()) if steps.size else None,
            },
            "arrays": sorted(self.scenarios) if self.kind == "trajectories" else sorted(self.gaps),
            "gaps": list(self.available_gaps()),
            "l1_design": None if self.l1_design is None else list(self.l1_design),
            "fingerprint": None if self.fingerprint is None else self.fingerprint.to_dict(),
        }

    @property
    def has_l1(self) -> bool:
        """Whether the data hold a process of the L1-DRAC controller (``learned_l1_true`` or
        the gap series computed from it)."""
        return "learned_l1_true" in self.scenarios or any(g in self.gaps for g in L1_GAPS)


def load_recorded(path: str | Path) -> RecordedData:
    """Read and check recorded data (``.npz`` or ``.csv``; ``docs/data_format.md``).

    Raises
    ------
    SpecError
        Naming the file, the array (or CSV line) and the problem: a missing or unknown array,
        a wrong shape, a non-finite value outside the paths marked ``diverged``, negative gap
        norms, unsorted or unequal time grids, unequal path counts or state dimensions,
        initial states that are not paired, fewer than :data:`MIN_PATHS` paths.
    """
    p = input_file(path, "data file")
    where = str(p)
    suffix = p.suffix.lower()
    if suffix == ".npz":
        arrays, diverged_ids = _read_npz(p), None
        fmt = "npz"
    elif suffix == ".csv":
        with reading(p, "CSV data file"):  # not UTF-8 text, a NUL byte (csv.Error), ...
            arrays, diverged_ids = _read_csv(p)
        fmt = "csv"
    else:
        raise SpecError(
            f"unknown data format {suffix!r}: give a .npz (numpy.savez) or a .csv file "
            "(docs/data_format.md)",
            path=where,
        )
    return _checked(arrays, where, fmt, diverged_ids)


def _read_npz(p: Path) -> dict[str, np.ndarray]:
    return read_npz(p, "data file")  # a text file, a .npy, a damaged archive: SpecError


def _fail(where: str, array: str, msg: str) -> SpecError:
    return SpecError(msg, path=where, field=array)


def _checked(
    arrays: dict[str, np.ndarray], where: str, fmt: str, diverged_ids: list[int] | None
) -> RecordedData:
    names = set(arrays)
    gap_names = {GAP_PREFIX + g for g, _, _ in GAPS}
    allowed = {"t", "diverged", "l1_design", "fingerprint"} | set(SCENARIOS) | gap_names
    unknown = sorted(names - allowed)
    if unknown:
        raise _fail(
            where,
            unknown[0],
            f"unknown array(s) {unknown}: the allowed names are t, {', '.join(SCENARIOS)}, "
            f"{', '.join(sorted(gap_names))}, diverged, l1_design, fingerprint "
            "(docs/data_format.md)",
        )
    if "t" not in arrays:
        raise _fail(where, "t", "missing: give the recorded times as a 1-D array 't'")
    t = _numeric(arrays["t"], where, "t")
    if t.ndim != 1 or t.size < 1:
        raise _fail(where, "t", f"must be a non-empty 1-D array of times, got shape {t.shape}")
    if not np.all(np.isfinite(t)):
        i = int(np.argmin(np.isfinite(t)))
        raise _fail(where, "t", f"t[{i}] = {t[i]!r} is not finite")
    if t[0] < 0:
        raise _fail(where, "t", f"t[0] = {t[0]!r} < 0: times start at 0 (the initial state)")
    bad = np.nonzero(np.diff(t) <= 0)[0]
    if bad.size:
        i = int(bad[0])
        raise _fail(
            where,
            "t",
            f"times must be strictly increasing: t[{i}] = {t[i]!r} >= t[{i + 1}] = {t[i + 1]!r} "
            "(sort the records by time and drop repeated ones)",
        )
    scen = {k: arrays[k] for k in SCENARIOS if k in arrays}
    gaps = {k[len(GAP_PREFIX) :]: arrays[k] for k in sorted(gap_names) if k in arrays}
    if scen and gaps:
        raise _fail(
            where,
            sorted(gaps)[0],
            "a file holds either trajectories or gap series, not both: split it in two",
        )
    if not scen and not gaps:
        raise _fail(
            where,
            "t",
            f"no data: give trajectories ({', '.join(SCENARIOS)}) or gap series "
            f"({', '.join(sorted(gap_names))})",
        )
    kind = "trajectories" if scen else "gaps"
    data = scen or gaps
    ndim = 3 if scen else 2
    label = (lambda k: k) if scen else (lambda k: GAP_PREFIX + k)
    first: str | None = None
    n_paths = n_state = 0
    out: dict[str, np.ndarray] = {}
    for k, raw in data.items():
        a = _numeric(raw, where, label(k))
        shape_txt = "(paths, times, n)" if scen else "(paths, times)"
        if a.ndim != ndim:
            raise _fail(
                where, label(k), f"must have shape {shape_txt}, got {a.ndim}-D shape {a.shape}"
            )
        if a.shape[1] != t.size:
            raise _fail(
                where,
                label(k),
                f"has {a.shape[1]} times (axis 1 of shape {a.shape}) but t has {t.size}: every "
                "array is recorded on the one grid t",
            )
        if first is None:
            first, n_paths = label(k), a.shape[0]
            n_state = a.shape[2] if scen else 0
        elif a.shape[0] != n_paths:
            raise _fail(
                where,
                label(k),
                f"has {a.shape[0]} paths but {first} has {n_paths}: rows are paired path by path "
                "across arrays (row i of every array is one path tuple)",
            )
        elif scen and a.shape[2] != n_state:
            raise _fail(
                where,
                label(k),
                f"has state dimension {a.shape[2]} but {first} has {n_state}",
            )
        out[k] = a
    if n_paths < MIN_PATHS:
        raise _fail(
            where,
            first or "t",
            f"{n_paths} path(s): at least {MIN_PATHS} are needed for any confidence bound",
        )
    diverged = np.zeros(n_paths, dtype=bool)
    if "diverged" in arrays:
        dv = np.asarray(arrays["diverged"])
        if dv.shape != (n_paths,) or not (
            dv.dtype == bool or (np.issubdtype(dv.dtype, np.number) and np.all(np.isin(dv, (0, 1))))
        ):
            raise _fail(
                where,
                "diverged",
                f"must be {n_paths} booleans (one per path), got shape {dv.shape} dtype {dv.dtype}",
            )
        diverged = dv.astype(bool)
    if diverged_ids is not None:
        diverged = np.isin(np.arange(n_paths), diverged_ids)
    for k, a in out.items():
        ok = np.isfinite(a).reshape(n_paths, -1).all(axis=1)
        bad_rows = np.nonzero(~ok & ~diverged)[0]
        if bad_rows.size:
            i = int(bad_rows[0])
            idx = tuple(int(v) for v in np.argwhere(~np.isfinite(a[i]))[0])
            raise _fail(
                where,
                label(k),
                f"path {i} has a non-finite value at index {(i, *idx)} (time t = "
                f"{t[idx[0]]:g}): {int(bad_rows.size)} path(s) affected; mark diverged paths in "
                "'diverged' (they count as unknown) or drop them everywhere",
            )
        if not scen:
            neg = np.nonzero((a < 0).any(axis=1) & ~diverged)[0]
            if neg.size:
                i = int(neg[0])
                raise _fail(
                    where,
                    label(k),
                    f"path {i} has a negative value ({float(a[i].min())!r}): a gap is a norm "
                    "||a_t - b_t|| >= 0",
                )
    if scen:
        if t[0] != 0.0:
            raise _fail(
                where,
                "t",
                f"trajectories must start at t = 0 (the initial state), got t[0] = {t[0]!r}",
            )
        ref_name = first
        assert ref_name is not None
        x0 = out[ref_name][:, 0]
        for k, a in out.items():
            diff = np.abs(a[:, 0] - x0)
            scale = np.maximum(1.0, np.maximum(np.abs(a[:, 0]), np.abs(x0)))
            bad_rows = np.nonzero((diff > INITIAL_MATCH_RTOL * scale).any(axis=1) & ~diverged)[0]
            if bad_rows.size:
                i = int(bad_rows[0])
                raise _fail(
                    where,
                    k,
                    f"path {i} starts at {a[i, 0].tolist()} but {ref_name} path {i} at "
                    f"{x0[i].tolist()}: paired paths start from one initial state (the "
                    f"certificate's coupling X_0 = x'_0 = x*_0); {int(bad_rows.size)} path(s) "
                    "differ. Reorder the rows, or compute the gaps yourself and give gap_* arrays",
                )
    l1 = None
    if "l1_design" in arrays:
        d = _numeric(arrays["l1_design"], where, "l1_design").reshape(-1)
        if d.shape != (3,) or not (np.all(np.isfinite(d)) and np.all(d > 0)):
            raise _fail(
                where,
                "l1_design",
                f"must be the three positive numbers [omega, lambda_s, Ts], got {d.tolist()}",
            )
        l1 = (float(d[0]), float(d[1]), float(d[2]))
    fp = _fingerprint(arrays["fingerprint"], where) if "fingerprint" in arrays else None
    return RecordedData(
        path=where,
        format=fmt,
        kind=kind,
        times=t,
        scenarios=MappingProxyType(out if scen else {}),
        gaps=MappingProxyType(out if not scen else {}),
        diverged=diverged,
        l1_design=l1,
        fingerprint=fp,
    )


def _fingerprint(raw: Any, where: str) -> Fingerprint:
    """The ``fingerprint`` entry: one string ``"policy=<hex>, design=<hex>"``."""
    a = np.asarray(raw)
    if a.dtype.kind not in "US" or a.size != 1:
        raise _fail(
            where,
            "fingerprint",
            f"must be one string (str(controller.fingerprint)), got shape {a.shape} dtype "
            f"{a.dtype}",
        )
    item = a.reshape(-1)[0]
    text = item.decode("ascii", "replace") if isinstance(item, bytes) else str(item)
    try:
        return Fingerprint.parse(text)
    except ValueError as exc:
        raise _fail(where, "fingerprint", str(exc)) from None


def _numeric(a: Any, where: str, name: str) -> np.ndarray:
    arr = np.asarray(a)
    if arr.dtype == bool or not np.issubdtype(arr.dtype, np.number) or np.iscomplexobj(arr):
        raise _fail(where, name, f"must hold real numbers, got dtype {arr.dtype}")
    return arr.astype(np.float64)


def _read_csv(p: Path) -> tuple[dict[str, np.ndarray], list[int] | None]:
    """The long CSV layout of docs/data_format.md -> the arrays of the .npz layout."""
    where = str(p)
    meta: dict[str, str] = {}
    series: dict[str, dict[int, tuple[list[float], list[list[float]]]]] = {}
    header: list[str] | None = None
    with p.open(newline="") as fh:
        for lineno, row in enumerate(csv.reader(fh), start=1):
            if not row or not "".join(row).strip():
                continue
            if row[0].lstrip().startswith("#"):
                text = ",".join(row).lstrip()[1:]
                key, sep, val = text.partition(":")
                if sep:
                    meta[key.strip()] = val.strip()
                continue
            cells = [c.strip() for c in row]
            if header is None:
                header = cells
                if header[:3] not in (["scenario", "path", "t"], ["gap", "path", "t"]) or (
                    len(header) < 4
                ):
                    raise SpecError(
                        f"line {lineno}: the header must be 'scenario,path,t,x0,...' or "
                        f"'gap,path,t,value', got {','.join(cells)!r}",
                        path=where,
                    )
                if header[0] == "gap" and header[3:] != ["value"]:
                    raise SpecError(
                        f"line {lineno}: a gap file has the columns gap,path,t,value",
                        path=where,
                    )
                continue
            if len(cells) != len(header):
                raise SpecError(
                    f"line {lineno}: {len(cells)} columns, the header has {len(header)}",
                    path=where,
                )
            name = cells[0] if header[0] == "scenario" else GAP_PREFIX + cells[0]
            try:
                pid = int(cells[1])
                tv = float(cells[2])
                vals = [float(c) for c in cells[3:]]
            except ValueError:
                raise SpecError(
                    f"line {lineno}: path must be an integer and t, {','.join(header[3:])} "
                    f"numbers, got {','.join(cells[1:])!r}",
                    path=where,
                ) from None
            ts, xs = series.setdefault(name, {}).setdefault(pid, ([], []))
            if ts and not tv > ts[-1]:
                raise SpecError(
                    f"line {lineno}: {cells[0]} path {pid}: t = {tv!r} after t = {ts[-1]!r}; "
                    "the rows of each path must be in strictly increasing time",
                    path=where,
                    field=name,
                )
            ts.append(tv)
            xs.append(vals)
    if header is None:
        raise SpecError("no header and no data", path=where)
    arrays: dict[str, np.ndarray] = {}
    ids: list[int] | None = None
    t_ref: np.ndarray | None = None
    ref_label = ""
    for name, paths in series.items():
        pids = sorted(paths)
        if ids is None:
            ids = pids
        elif pids != ids:
            raise SpecError(
                f"its path ids {_ids_text(pids)} differ from those of the first series "
                f"{_ids_text(ids)}: rows are paired path by path across processes",
                path=where,
                field=name,
            )
        for pid in pids:
            tp = np.asarray(paths[pid][0])
            if t_ref is None:
                t_ref, ref_label = tp, f"{name} path {pid}"
            elif tp.shape != t_ref.shape or not np.all(
                np.abs(tp - t_ref) <= TIME_MATCH_RTOL * np.maximum(1.0, np.abs(t_ref))
            ):
                raise SpecError(
                    f"path {pid} has {tp.size} times {_times_text(tp)}, {ref_label} has "
                    f"{t_ref.size} {_times_text(t_ref)}: every series is recorded on one grid",
                    path=where,
                    field=name,
                )
        arr = np.array([paths[pid][1] for pid in pids], dtype=np.float64)
        arrays[name] = arr[:, :, 0] if name.startswith(GAP_PREFIX) else arr
    if t_ref is None or ids is None:
        raise SpecError("the file has a header but no data rows", path=where)
    arrays["t"] = t_ref
    diverged_ids = None
    for key, val in meta.items():
        nums = [v for v in (s.strip() for s in val.split(",")) if v]
        try:
            if key == "l1_design":
                arrays["l1_design"] = np.array([float(v) for v in nums])
            elif key == "fingerprint":
                arrays["fingerprint"] = np.array(val)
            elif key == "diverged":
                want = {int(v) for v in nums}
                missing = sorted(want - set(ids))
                if missing:
                    raise SpecError(
                        f"'# diverged:' names path ids {missing} that have no rows",
                        path=where,
                        field="diverged",
                    )
                diverged_ids = [i for i, pid in enumerate(ids) if pid in want]
        except ValueError:
            raise SpecError(
                f"'# {key}:' must be a comma-separated list of numbers, got {val!r}",
                path=where,
                field=key,
            ) from None
    return arrays, diverged_ids


def _ids_text(ids: list[int]) -> str:
    return str(ids) if len(ids) <= 6 else f"[{ids[0]}, {ids[1]}, ..., {ids[-1]}] ({len(ids)})"


def _times_text(ts: np.ndarray) -> str:
    return f"[{ts[0]:g} .. {ts[-1]:g}]" if ts.size else "[]"


# ----------------------------------------------------------------------- the statistics
@dataclass(frozen=True)
class _Level:
    """The one field of a run's config the checks read."""

    ci_level: float


@dataclass(frozen=True)
class DataResult:
    """The gap statistics of recorded data, in the shape of a
    :class:`~drip_cert.sim.result.SimResult` as far as the checks read it (``gap(name)``,
    ``n_paths_done``, ``config.ci_level``, ``times``, ``w2``).

    ``gaps`` are :class:`~drip_cert.numerics.stats.GapStats` from
    :func:`~drip_cert.numerics.stats.finalize`; a gap the data lack is an empty one (no path)
    and listed in ``missing``.
    """

    data: RecordedData
    config: _Level
    times: np.ndarray
    gaps: tuple[_stats.GapStats, ...]
    missing: tuple[str, ...]
    w2: tuple[_stats.W2Estimate, ...]

    @property
    def n_paths_done(self) -> int:
        """Path tuples in the data (diverged ones included: they are unknown, as simulated)."""
        return self.data.n_paths

    def gap(self, name: str) -> _stats.GapStats:
        """The :class:`GapStats` called ``name``."""
        for g in self.gaps:
            if g.name == name:
                return g
        raise KeyError(f"gap {name!r}; have {[g.name for g in self.gaps]}")

    def to_dict(self) -> dict[str, Any]:
        """JSON summary: the data (sizes, grid, arrays), the gaps it gave, the W2 estimates."""
        return {
            "source": "recorded data",
            **self.data.summary(),
            "level": self.config.ci_level,
            "gap_statistics": [g.to_dict() for g in self.gaps if g.name not in self.missing],
            "not_in_data": list(self.missing),
            "w2": [w.to_dict() for w in self.w2],
        }


def minimum_paths(delta: float, level: float) -> int:
    """The fewest paths with which a frequency test ``P <= delta`` at ``level`` can fail.

    The smallest ``N`` with :func:`~drip_cert.numerics.stats.clopper_pearson_lower`
    ``(N, N, level) > delta``, the rule of :func:`~drip_cert.validate.checks.check_radius` and
    :func:`~drip_cert.validate.checks.check_tail` (below it even ``N`` of ``N`` paths beyond the
    threshold would not show a violation). The closed form of the lower bound at ``k = N`` is
    ``(1 - level)^{1/N}``, so ``N = floor(log(1 - level) / log(delta)) + 1`` (the search starts
    below it and confirms with the function the checks use).
    """
    guess = math.floor(math.log1p(-level) / math.log(delta)) + 1
    n = max(1, guess - 2)
    while float(_stats.clopper_pearson_lower(n, n, level)) <= delta:
        n += 1
    return n


def _require_paths(
    data: RecordedData, need: list[tuple[str, float | None, float, str]], level: float
) -> None:
    """:class:`SpecError` when the data are too few for a frequency check they feed."""
    n = data.n_paths
    for gap, delta, lvl, claim in need:
        if delta is None or not 0.0 < delta < 1.0:
            continue
        n_min = minimum_paths(delta, lvl)
        if n < n_min:
            arrays = _arrays_of_gap(data, gap)
            raise SpecError(
                f"{n} paths are too few to test {claim} at confidence {level:g}"
                + (f" (per recorded time {lvl:.6g}, Bonferroni)" if lvl != level else "")
                + f": even all {n} beyond the threshold would not show a violation; record at "
                f"least {n_min} paths" + (" (or fewer times)" if lvl != level else ""),
                path=data.path,
                field=arrays,
            )


def _arrays_of_gap(data: RecordedData, gap: str) -> str:
    if data.kind == "gaps":
        return GAP_PREFIX + gap
    _, a, b = next(g for g in GAPS if g[0] == gap)
    return f"{a}, {b}"


def _w2_at_last_time(data: RecordedData) -> tuple[_stats.W2Estimate, ...]:
    """W2 of each recorded pair at the last time, on disjoint halves, with same-law baselines
    (the engine's construction in :func:`drip_cert.sim.result.build_result`)."""
    if data.kind != "trajectories":
        return ()
    ok = ~data.diverged
    n = min(2000, data.n_paths // 2)
    if n < 1:
        return ()
    out = []
    for _, a, b in GAPS:
        if a not in data.scenarios or b not in data.scenarios:
            continue
        ca, cb = data.scenarios[a][:, -1], data.scenarios[b][:, -1]
        a1, a2 = ca[:n][ok[:n]], ca[n : 2 * n][ok[n : 2 * n]]
        b1, b2 = cb[:n][ok[:n]], cb[n : 2 * n][ok[n : 2 * n]]
        if min(len(a1), len(a2), len(b1), len(b2)) == 0:
            continue
        out.append(
            _stats.W2Estimate(
                pair=(a, b),
                time=float(data.times[-1]),
                n_points=n,
                w2=_stats.w2_empirical(a1, b2),
                baseline_a=_stats.w2_empirical(a1, a2),
                baseline_b=_stats.w2_empirical(b1, b2),
            )
        )
    return tuple(out)


# ------------------------------------------------------------------------- the validation
def check_fits(data: RecordedData, *, n_state: int, certified_horizon: float) -> None:
    """:class:`SpecError` unless the data's state dimension is ``n_state`` and its times lie in
    the certified ``[0, T]`` (checked before the certificate is computed, to fail fast)."""
    n = data.n_state
    if n is not None and n != n_state:
        raise SpecError(
            f"the trajectories have state dimension {n}, the system has n = {n_state}",
            path=data.path,
            field=", ".join(sorted(data.scenarios)),
        )
    T_end = float(data.times[-1])
    if T_end > certified_horizon * (1.0 + TIME_MATCH_RTOL):
        raise SpecError(
            f"the last recorded time t = {T_end:g} is beyond the certified horizon "
            f"T = {certified_horizon:g}: the certificate says nothing there; cut the data at T",
            path=data.path,
            field="t",
        )


ACCEPT_FLAG = "--accept-unfingerprinted"
"""The command-line flag that accepts data without a fingerprint (``accept_unfingerprinted``)."""


def check_fingerprint(cert: Any, data: RecordedData, *, accept_unfingerprinted: bool) -> str | None:
    """Refuse data not recorded with the certified policy and design; the warning, if any.

    Every part the data's fingerprint states must be the certificate's
    (``Certificate.fingerprint``); the ``design`` part must be stated when the data hold a
    process of the L1-DRAC controller (:attr:`RecordedData.has_l1`). Data without a fingerprint
    are refused unless ``accept_unfingerprinted``.

    Returns
    -------
    str or None
        The warning for accepted data without a fingerprint, else ``None``.

    Raises
    ------
    FingerprintError
        Naming the part that differs (``policy``, ``design``) with the recorded and the
        certified digests, or saying the data carry none and how to accept them.
    """
    cert_fp: Fingerprint | None = getattr(cert, "fingerprint", None)
    certified = "none" if cert_fp is None else str(cert_fp)
    got = data.fingerprint
    if got is None:
        if accept_unfingerprinted:
            return (
                "the data carry no fingerprint: accepted unverified (accept_unfingerprinted, "
                f"{ACCEPT_FLAG}): nothing shows they were recorded with the certified policy and "
                f"design ({certified})"
            )
        raise FingerprintError(
            f"{data.path}: refused: the data carry no fingerprint, so nothing shows they were "
            f"recorded with the certified policy and design ({certified}). Record them with "
            "str(controller.fingerprint) in a 'fingerprint' entry (docs/data_format.md), or "
            f"accept them unverified with {ACCEPT_FLAG} (accept_unfingerprinted=True in Python)"
        )
    if cert_fp is None:
        raise FingerprintError(
            f"{data.path}: refused: the certificate has no fingerprint to compare the data's "
            f"({got}) with"
        )
    differ = [
        f"{part}={getattr(got, part)} in the data, {part}={getattr(cert_fp, part)} certified"
        for part in ("policy", "design")
        if getattr(got, part) is not None and getattr(got, part) != getattr(cert_fp, part)
    ]
    if differ:
        parts = " and ".join(d.partition("=")[0] for d in differ)
        raise FingerprintError(
            f"{data.path}: refused: the data were recorded with another {parts} than the "
            f"certificate's ({'; '.join(differ)}). Record them again with this spec's "
            "drip_cert.deploy.l1drac_controller / learned_policy and their .fingerprint, or "
            "validate them against the spec they were recorded with"
        )
    if got.design is None and data.has_l1:
        raise FingerprintError(
            f"{data.path}: refused: the data hold the L1-DRAC process but their fingerprint "
            f"({got}) has no design part (learned_policy's): record them with "
            f"str(controller.fingerprint) (certified: {cert_fp})"
        )
    return None


def validate_data(
    cert: Any,
    data: RecordedData,
    *,
    n_state: int,
    certified_horizon: float,
    level: float = DEFAULT_LEVEL,
    accept_unfingerprinted: bool = False,
) -> ValidationReport:
    """Check recorded data against certificate ``cert`` (the statistics of the simulated run).

    Parameters
    ----------
    cert
        The :class:`~drip_cert.bounds.certificate.Certificate` of the system that produced the
        data (its bounds are read in the user's ``x``, mapped back when it is in ``z``).
    data
        From :func:`load_recorded`, in the user's coordinates ``x``.
    n_state, certified_horizon
        The system's state dimension and horizon ``T`` (the certificate's claims are on
        ``[0, T]``).
    level
        Confidence level (familywise over the recorded times for per-time checks).
    accept_unfingerprinted
        Accept data without a fingerprint (with a warning among the report's notes).

    Returns
    -------
    ValidationReport
        ``result`` is a :class:`DataResult`; ``short_horizon`` is ``None``.

    Raises
    ------
    SpecError
        State dimension or horizon mismatch, or too few paths for a frequency check the data
        feed (:func:`minimum_paths`).
    FingerprintError
        Data recorded with another policy or design, or without a fingerprint
        (:func:`check_fingerprint`).
    """
    check_fits(data, n_state=n_state, certified_horizon=certified_horizon)
    warning = check_fingerprint(cert, data, accept_unfingerprinted=accept_unfingerprinted)
    T_end = float(data.times[-1])
    # the certified numbers in the user's x (Certificate.claims: validate reads the same)
    c = cert.claims()
    rho_tasil, delta_tasil = c.rho_tasil, c.delta_tasil
    p, kappa, delta_l1 = c.p, c.kappa, c.delta_l1
    notes: list[str] = [] if warning is None else ["WARNING: " + warning]
    at_cert = c.design is not None
    why = "no feasible L1-DRAC design"
    if c.design is not None:
        cert_design = c.design
        if data.l1_design is None:
            notes.append(
                "the data do not say which L1-DRAC parameters produced them (no l1_design): "
                f"taken at the user's word to be the certified omega = {cert_design[0]:g}, "
                f"lambda_s = {cert_design[1]:g}, T_s = {cert_design[2]:.6g}"
            )
        elif not all(
            math.isclose(a, b, rel_tol=TIME_MATCH_RTOL) for a, b in zip(data.l1_design, cert_design)
        ):
            at_cert = False
            why = (
                f"recorded with (omega, lambda_s, T_s) = {data.l1_design}, certified {cert_design}"
            )
    kappas = _thresholds(c)
    p_max = max(4, 2 * p)
    have = data.available_gaps()
    m = int(data.times.size)
    per_time = _stats.bonferroni_level(level, m)
    need: list[tuple[str, float | None, float, str]] = []
    if "policy" in have and rho_tasil is not None and math.isfinite(rho_tasil):
        need.append(
            ("policy", delta_tasil, level, "P(max_t ||x'_t - x*_t|| > rho_TaSIL) <= delta_TaSIL")
        )
    if at_cert and kappa is not None and math.isfinite(kappa):
        if "uncertainty_l1" in have:
            need.append(
                ("uncertainty_l1", delta_l1, per_time, "P(||X_t - x'_t|| >= kappa) <= delta_L1")
            )
        thr, dsum, _ = total_tail_claim(rho_tasil, kappa, delta_tasil, delta_l1, c.rho_sde, p)
        if "total_l1" in have and dsum is not None:
            need.append(
                (
                    "total_l1",
                    dsum,
                    per_time,
                    f"P(||X_t - x*_t|| >= {thr:.6g}) <= {dsum:.6g} (the total tail)",
                )
            )
    _require_paths(data, need, level)
    valid = ~data.diverged
    stats = []
    for g, _, _ in GAPS:
        sums = _stats.new_sums(m, p_max, kappas)
        if g in have:
            sums = _stats.accumulate(sums, data.gap_norms(g), valid)
        stats.append(_stats.finalize(g, sums, data.times, level))
    missing = tuple(g for g, _, _ in GAPS if g not in have)
    res = DataResult(
        data=data,
        config=_Level(level),
        times=data.times,
        gaps=tuple(stats),
        missing=missing,
        w2=_w2_at_last_time(data),
    )
    checks = checks_from_result(
        res,
        **claim_arguments(c),
        at_certified_l1=at_cert,
        not_certified_why=why,
    )
    checks = [_not_in_data(c, data) if _gap_of_check(c.name) in missing else c for c in checks]
    notes.append(
        f"{data.kind} from {data.path}: {data.n_paths} paths ({int(data.diverged.sum())} marked "
        f"diverged, unknown in every check) on {m} recorded times in "
        f"[{float(data.times[0]):g}, {T_end:g}] s; the checks cover these times only"
        + (
            f" (the certified horizon is T = {certified_horizon:g} s)"
            if T_end < certified_horizon * (1.0 - TIME_MATCH_RTOL)
            else ""
        )
    )
    if missing:
        notes.append(
            "not in the data: "
            + "; ".join(f"{g} ({_arrays_of_gap(data, g)})" for g in missing)
            + ": the checks that read them are not checked"
        )
    emp: dict[str, Any] = {}
    for key, gap in (
        ("tig_max", "total_l1"),
        ("policy_ig_max", "policy"),
        ("uncertainty_ig_max", "uncertainty_l1"),
        ("tig_max_without_l1", "total_true"),
    ):
        if gap in missing:
            emp[key] = None
            continue
        gs = res.gap(gap)
        emp[key] = {
            "value": gs.max_mean,
            "ci_low": gs.max_ci_low,
            "ci_high": gs.max_ci_high,
            "argmax_time": gs.argmax_time,
        }
    emp["w2"] = [w.to_dict() for w in res.w2]
    if res.w2:
        notes.append(
            "W2 estimates from samples are biased upward (see the same-law baselines "
            "beside each); they are reported, not checked against a bound"
        )
    if overall_status(checks) == NOTHING_CHECKED:
        notes.insert(
            0,
            "nothing was checked: no finite certified bound could be compared with these data "
            "(see each check's reason)",
        )
    frac = float(np.mean(data.diverged)) if data.n_paths else 0.0
    return ValidationReport(
        checks=tuple(checks),
        short_horizon=None,
        certificate=cert,
        empirical=emp,
        at_certified_parameters=at_cert,
        horizon=T_end,
        certified_horizon=float(certified_horizon),
        l1_parameters=(
            {}
            if c.design is None
            else dict(zip(("omega", "lambda_s", "Ts"), c.design, strict=True))
        ),
        diverged_fraction={
            s: frac for s in (data.scenarios if data.kind == "trajectories" else ("all paths",))
        },
        notes=tuple(notes),
        result=res,
    )


def _not_in_data(check: EmpiricalCheck, data: RecordedData) -> EmpiricalCheck:
    """A check whose gap the file does not give: ``not_checked``, saying which arrays to add."""
    gap = _gap_of_check(check.name)
    return replace(
        check,
        status=NOT_CHECKED,
        empirical=None,
        confidence_low=None,
        confidence_high=None,
        reason=f"not in the data: give {_arrays_of_gap(data, gap)}",
        note="",
        extra=MappingProxyType(
            {k: v for k, v in check.extra.items() if k in ("delta", "threshold", "quantile")}
        ),
    )
