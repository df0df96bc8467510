"""The versioned JSON layouts of drip-cert's outputs, and a loader that checks a file against them.

Two layouts ship as package data (JSON Schema, draft 2020-12):

* ``certificate.schema.json``: :meth:`Certificate.to_dict
  <drip_cert.bounds.certificate.Certificate.to_dict>`, i.e. ``drip-cert certify --json`` and
  ``certificate.json`` (``schema_version`` 4);
* ``validation.schema.json``: :meth:`ValidationReport.to_dict
  <drip_cert.validate.run.ValidationReport.to_dict>`, i.e. ``drip-cert validate --json`` and
  ``validation.json`` (``schema_version`` 1); its ``certificate`` key holds a certificate in the
  certificate layout.

Versioning rule: a key may be *added* to an output without a version bump (every object of the
schemas accepts further keys); removing, renaming or retyping a key the schema lists changes the
layout and needs a new ``schema_version`` (and a new schema file). The schema files are the
contract; ``tests/test_schema.py`` validates real ``certify`` and ``validate`` outputs against
them with the reference validator (``jsonschema``) and checks that the version each file states is
the version the code writes.

:func:`load_output` reads a JSON file, decides which layout it is in (:func:`output_kind`) and
checks it with :func:`problems`, a small validator for the subset of JSON Schema these files use
(``type``, ``required``, ``properties``, ``additionalProperties``, ``items``, ``enum``,
``const``, ``oneOf``, ``minimum``, ``$ref``), so that reading an output needs no third-party
package. Every failure is a :class:`~drip_cert.errors.SpecError` that names the file, the key and
the fix (exit status 2 on the command line).
"""

from __future__ import annotations

import json
import math
from collections.abc import Mapping
from dataclasses import dataclass
from functools import cache
from importlib import resources
from pathlib import Path
from typing import Any

from drip_cert.errors import SpecError

__all__ = [
    "KINDS",
    "LoadedOutput",
    "check_output",
    "load_output",
    "output_kind",
    "problems",
    "schema",
    "schema_version",
]

KINDS: tuple[str, ...] = ("certificate", "validation")
"""The output layouts, each with its schema file ``<kind>.schema.json``."""

_REGENERATE = {
    "certificate": "drip-cert certify SPEC --json > FILE",
    "validation": "drip-cert validate SPEC --json > FILE (or --out DIR: DIR/validation.json)",
}

MAX_PROBLEMS = 5
"""How many schema problems a message lists (the first ones, in document order)."""


@cache
def schema(kind: str) -> dict[str, Any]:
    """The JSON Schema of output layout ``kind`` (``"certificate"`` or ``"validation"``)."""
    if kind not in KINDS:
        raise ValueError(f"unknown output kind {kind!r}; have {KINDS}")
    text = resources.files(__package__).joinpath(f"{kind}.schema.json").read_text("utf-8")
    out: dict[str, Any] = json.loads(text)
    return out


def schema_version(kind: str) -> int:
    """The ``schema_version`` that layout ``kind``'s schema file describes."""
    return int(schema(kind)["properties"]["schema_version"]["const"])


def output_kind(obj: Any) -> str | None:
    """``"validation"`` or ``"certificate"`` for an object in one of those layouts (judged by its
    keys: a validation report has ``checks`` and a nested ``certificate``, a certificate has
    ``verdict`` and ``assumptions``), ``None`` for anything else."""
    if not isinstance(obj, Mapping):
        return None
    if "checks" in obj and "certificate" in obj:
        return "validation"
    if "verdict" in obj and "assumptions" in obj:
        return "certificate"
    return None


# ------------------------------------------------------------------------- the validator
def _by_id() -> dict[str, dict[str, Any]]:
    """Every schema by the last segment of its ``$id`` (``certificate-3.json``), for ``$ref``."""
    return {schema(k)["$id"].rsplit("/", 1)[-1]: schema(k) for k in KINDS}


def _resolve(ref: str, root: dict[str, Any]) -> tuple[dict[str, Any], dict[str, Any]]:
    """The schema ``ref`` points to and the root document it lives in."""
    doc, _, pointer = ref.partition("#")
    if doc:
        root = _by_id()[doc]
    node: Any = root
    for part in [p for p in pointer.split("/") if p]:
        node = node[part]
    return node, root


def _type_ok(value: Any, t: str) -> bool:
    if t == "null":
        return value is None
    if t == "boolean":
        return isinstance(value, bool)
    if t == "integer":
        return (isinstance(value, int) and not isinstance(value, bool)) or (
            isinstance(value, float) and math.isfinite(value) and value.is_integer()
        )
    if t == "number":
        return isinstance(value, int | float) and not isinstance(value, bool)
    if t == "string":
        return isinstance(value, str)
    if t == "array":
        return isinstance(value, list)
    if t == "object":
        return isinstance(value, dict)
    raise ValueError(f"schema type {t!r} is not supported by this validator")


def _where(path: str) -> str:
    return path or "(top level)"


def _walk(value: Any, sch: dict[str, Any], root: dict[str, Any], path: str, out: list[str]) -> None:
    if "$ref" in sch:
        target, troot = _resolve(sch["$ref"], root)
        _walk(value, target, troot, path, out)
    if "const" in sch and value != sch["const"]:
        out.append(f"{_where(path)}: {value!r} is not {sch['const']!r}")
        return
    if "enum" in sch and value not in sch["enum"]:
        out.append(f"{_where(path)}: {value!r} is not one of {sch['enum']}")
        return
    if "type" in sch:
        types = sch["type"] if isinstance(sch["type"], list) else [sch["type"]]
        if not any(_type_ok(value, t) for t in types):
            out.append(f"{_where(path)}: expected {' or '.join(types)}, got {_json_type(value)}")
            return
    if "oneOf" in sch:
        subs = []
        for alt in sch["oneOf"]:
            sub: list[str] = []
            _walk(value, alt, root, path, sub)
            subs.append(sub)
        matching = sum(not sub for sub in subs)
        # the form whose type fits but whose inside does not: report its problems
        deeper = [
            sub for alt, sub in zip(sch["oneOf"], subs) if sub and _shape_fits(value, alt, root)
        ]
        if matching == 0 and deeper:
            out.extend(deeper[0])
            return
        if matching != 1:
            want = sch.get("description") or f"exactly one of {len(sch['oneOf'])} forms"
            out.append(f"{_where(path)}: expected {want}, got {_short(value)}")
            return
    if "minimum" in sch and _type_ok(value, "number") and value < sch["minimum"]:
        out.append(f"{_where(path)}: {value!r} is below the minimum {sch['minimum']!r}")
    if isinstance(value, dict):
        for key in sch.get("required", ()):
            if key not in value:
                out.append(f"{_where(path)}: required key {key!r} is missing")
        props = sch.get("properties", {})
        extra = sch.get("additionalProperties", True)
        for key, v in value.items():
            sub_path = f"{path}.{key}" if path else key
            if key in props:
                _walk(v, props[key], root, sub_path, out)
            elif isinstance(extra, dict):
                _walk(v, extra, root, sub_path, out)
            elif extra is False:
                out.append(f"{_where(path)}: key {key!r} is not allowed")
    if isinstance(value, list) and "items" in sch:
        for i, v in enumerate(value):
            _walk(v, sch["items"], root, f"{path}[{i}]", out)


def _shape_fits(value: Any, sch: dict[str, Any], root: dict[str, Any]) -> bool:
    """Whether ``value`` has the outer shape (type, constant) of ``sch``, inside aside."""
    while "$ref" in sch:
        sch, root = _resolve(sch["$ref"], root)
    if "oneOf" in sch:
        return any(_shape_fits(value, alt, root) for alt in sch["oneOf"])
    if "type" in sch:
        types = sch["type"] if isinstance(sch["type"], list) else [sch["type"]]
        return any(_type_ok(value, t) for t in types)
    if "enum" in sch:
        return value in sch["enum"]
    return "const" not in sch or value == sch["const"]


def _json_type(value: Any) -> str:
    for t in ("null", "boolean", "integer", "number", "string", "array", "object"):
        if _type_ok(value, t):
            return t
    return type(value).__name__


def _short(value: Any) -> str:
    text = json.dumps(value) if not isinstance(value, dict | list) else _json_type(value)
    return text if len(text) <= 40 else text[:37] + "..."


def problems(obj: Any, kind: str) -> list[str]:
    """Every place where ``obj`` departs from layout ``kind`` (``[]`` when it conforms).

    Each entry is ``"<key path>: <what is wrong>"``, e.g.
    ``"rho.rho_total: expected number, got array"``.
    """
    out: list[str] = []
    root = schema(kind)
    _walk(obj, root, root, "", out)
    return out


# ---------------------------------------------------------------------------- the loader
@dataclass(frozen=True)
class LoadedOutput:
    """A drip-cert output file, read and checked against its layout.

    Attributes
    ----------
    path
        The file it was read from.
    kind
        ``"certificate"`` or ``"validation"``.
    version
        Its ``schema_version``.
    data
        The parsed JSON (a dictionary in the layout of ``kind``).
    """

    path: Path
    kind: str
    version: int
    data: dict[str, Any]

    @property
    def certificate(self) -> dict[str, Any]:
        """The certificate: the file itself, or a validation report's ``certificate``."""
        return self.data if self.kind == "certificate" else self.data["certificate"]


def check_output(obj: Any, *, where: str = "the output") -> LoadedOutput:
    """Check an already parsed output ``obj`` (see :func:`load_output`); ``where`` names it in
    messages."""
    kind = output_kind(obj)
    if kind is None:
        keys = sorted(obj)[:8] if isinstance(obj, Mapping) else None
        raise SpecError(
            "not a drip-cert certificate or validation report (a certificate has the keys "
            "'verdict' and 'assumptions', a validation report 'checks' and 'certificate'"
            + (f"; this has {keys}" if keys is not None else f"; this is a JSON {_json_type(obj)}")
            + f"); write one with `{_REGENERATE['certificate']}`",
            path=where,
        )
    want = schema_version(kind)
    got = obj.get("schema_version")
    fix = f"regenerate it with this drip-cert: `{_REGENERATE[kind]}`"
    if got is None:
        raise SpecError(
            f"a drip-cert {kind} without 'schema_version' (written before the layout was "
            f"versioned; this drip-cert reads version {want}): {fix}",
            field="schema_version",
            path=where,
        )
    if got != want:
        raise SpecError(
            f"{kind} layout version {got!r} is not the one this drip-cert reads ({want}): {fix}",
            field="schema_version",
            path=where,
        )
    found = problems(obj, kind)
    if found:
        more = f" (and {len(found) - MAX_PROBLEMS} more)" if len(found) > MAX_PROBLEMS else ""
        raise SpecError(
            f"does not follow the drip-cert {kind} layout version {want}: "
            + "; ".join(found[:MAX_PROBLEMS])
            + more
            + f"; {fix}",
            field=found[0].split(":", 1)[0],
            path=where,
        )
    return LoadedOutput(Path(where), kind, want, dict(obj))


def load_output(path: str | Path) -> LoadedOutput:
    """Read a drip-cert certificate or validation report and check it against its layout.

    Raises
    ------
    SpecError
        The file is missing or unreadable, is not JSON, is not a drip-cert output, has another
        ``schema_version`` than the one this drip-cert reads, or departs from the layout; the
        message names the file, the key and how to fix it.
    """
    path = Path(path)
    try:
        text = path.read_text("utf-8")
    except FileNotFoundError:
        raise SpecError("no such file", path=str(path)) from None
    except (OSError, UnicodeDecodeError) as exc:
        raise SpecError(f"cannot read the file ({exc})", path=str(path)) from None
    try:
        obj = json.loads(text)
    except json.JSONDecodeError as exc:
        raise SpecError(
            f"not valid JSON (line {exc.lineno}, column {exc.colno}: {exc.msg}); write it with "
            f"`{_REGENERATE['certificate']}`",
            path=str(path),
        ) from None
    out = check_output(obj, where=str(path))
    return LoadedOutput(path, out.kind, out.version, out.data)
