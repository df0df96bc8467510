"""Writing a specification back as TOML, with a trained policy in it (``train --write-spec``).

:func:`spec_with_policy` takes the parsed TOML document of a spec (floats as
:class:`~drip_cert.model.literals.DecimalFloat`, so every literal keeps the digits it was written
with and means the same exact rational), puts a network block and the learned policy into it, and
re-bases every relative path (the blocks' weights) on the directory of the file written, so that
the result loads from where it is written. :func:`toml_document` renders such a document.
"""

from __future__ import annotations

import os
import tomllib
from collections.abc import Mapping, Sequence
from pathlib import Path
from typing import Any

from drip_cert.errors import SpecError
from drip_cert.model.literals import DecimalFloat
from drip_cert.spec.settings import toml_key, toml_text

__all__ = ["read_document", "spec_with_policy", "toml_document"]


def read_document(path: str | os.PathLike[str]) -> dict[str, Any]:
    """The TOML document of a spec file, floats kept as :class:`DecimalFloat` (their text)."""
    with open(path, "rb") as fh:
        return tomllib.load(fh, parse_float=DecimalFloat)


def spec_with_policy(
    doc: Mapping[str, Any],
    *,
    source: str | os.PathLike[str],
    target: str | os.PathLike[str],
    block: str,
    block_table: Mapping[str, Any],
    learned: Sequence[str],
    tasil: Mapping[str, Any],
) -> dict[str, Any]:
    """``doc`` (read from ``source``) with ``[blocks.<block>]``, ``[policy] learned`` and the
    ``[tasil]`` keys replaced, every relative ``weights`` path re-based for ``target``.

    Parameters
    ----------
    doc
        The spec's TOML document (:func:`read_document`).
    source, target
        The spec file read, and the file the result will be written to.
    block, block_table
        The network block's name and table (``weights`` absolute or relative to the cwd).
    learned
        The ``[policy] learned`` expressions, one per input.
    tasil
        ``[tasil]`` keys to set (the demonstrations the policy was trained on).
    """
    src_dir = Path(source).resolve().parent
    out_dir = Path(target).resolve().parent
    new = {k: (dict(v) if isinstance(v, Mapping) else v) for k, v in doc.items()}
    blocks = {name: dict(t) for name, t in (new.get("blocks") or {}).items()}
    for table in blocks.values():  # the user's own blocks: weights relative to the spec's dir
        if isinstance(table.get("weights"), str) and not Path(table["weights"]).is_absolute():
            table["weights"] = _relative(src_dir / table["weights"], out_dir)
    table = dict(block_table)
    table["weights"] = _relative(Path(table["weights"]).resolve(), out_dir)
    blocks[block] = table
    new["blocks"] = blocks
    policy = dict(new.get("policy") or {})
    policy["learned"] = list(learned)
    new["policy"] = policy
    if tasil or "tasil" in new:  # an empty [tasil] would ask certify for TaSIL by itself
        new["tasil"] = {**dict(new.get("tasil") or {}), **dict(tasil)}
    return _ordered(new)


def _relative(path: Path, base: Path) -> str:
    """``path`` relative to ``base`` when both are on one drive, else absolute (POSIX slashes)."""
    try:
        return Path(os.path.relpath(path, base)).as_posix()
    except ValueError:  # pragma: no cover - another drive on Windows
        return path.as_posix()


_ORDER = ("system", "blocks", "dynamics", "policy", "uncertainty", "initial")


def _ordered(doc: Mapping[str, Any]) -> dict[str, Any]:
    """The sections in the order a reader expects (blocks before the expressions using them)."""
    first = [k for k in _ORDER if k in doc]
    return {k: doc[k] for k in [*first, *(k for k in doc if k not in _ORDER)]}


def toml_document(doc: Mapping[str, Any], header: str = "") -> str:
    """``doc`` as TOML text: each table with its scalar and array keys, sub-tables as
    ``[a.b]``; floats that came from a TOML file keep their text.

    Raises
    ------
    SpecError
        A value TOML cannot hold here (a date, an array of tables): the spec format has none.
    """
    lines = [f"# {line}" if line else "#" for line in header.splitlines()]
    if lines:
        lines.append("")
    for name, table in doc.items():
        if not isinstance(table, Mapping):
            raise SpecError(f"top-level key {name!r} is not a table", field=str(name))
        _emit_table(lines, _key(name), table)
    return "\n".join(lines).rstrip("\n") + "\n"


def _emit_table(lines: list[str], prefix: str, table: Mapping[str, Any]) -> None:
    plain = {k: v for k, v in table.items() if not isinstance(v, Mapping)}
    subs = {k: v for k, v in table.items() if isinstance(v, Mapping)}
    if plain or not subs:
        lines.append(f"[{prefix}]")
        lines += [f"{_key(k)} = {_value(v, f'{prefix}.{k}')}" for k, v in plain.items()]
        lines.append("")
    for k, v in subs.items():
        _emit_table(lines, f"{prefix}.{_key(k)}", v)


def _key(k: Any) -> str:
    return toml_key(k)


def _value(v: Any, where: str) -> str:
    return toml_text(v, strict=True, where=where)
