"""The spec reference: every section and key of a spec with its default and meaning, as Markdown.

Generated from the one declaration of each key (:data:`drip_cert.spec.load.SECTIONS`,
:data:`~drip_cert.spec.load.BLOCK_KEYS` and the ``setting(...)`` fields of
:mod:`drip_cert.spec.settings`), so that the documentation cannot list a key the loader rejects
or miss one it accepts. ``docs/reference/spec.md`` is this function's output; a test regenerates
it and fails when the committed file is stale (``python -m drip_cert.spec.reference > docs/...``).
"""

from __future__ import annotations

import dataclasses
from typing import Any

from drip_cert.spec.load import BLOCK_KEYS, REQUIRED, SECTIONS
from drip_cert.spec.settings import (
    CONSTANT_NAMES,
    HELDOUT_FROM_DELTA,
    POSITIVE_CONSTANTS,
    Settings,
    declared,
    toml_text,
)

__all__ = ["spec_reference_markdown"]


def _cell(text: str) -> str:
    return text.replace("|", "\\|").replace("\n", " ")


def _default_text(table: str, f: dataclasses.Field[Any]) -> str:
    default = f.default if f.default is not dataclasses.MISSING else f.default_factory()  # type: ignore[operator]
    if table == "tasil" and f.name == "heldout" and default == HELDOUT_FROM_DELTA:
        return "derived from `delta` (59 at 0.1)"
    if default is None:
        return "none"
    return f"`{toml_text(list(default) if isinstance(default, tuple) else default)}`"


def spec_reference_markdown() -> str:
    """The spec reference page (Markdown)."""
    out = [
        "# Spec reference",
        "",
        "Every section and key of a TOML specification, generated from the declarations the loader",
        "itself uses (`drip_cert/spec/load.py` `SECTIONS`, `drip_cert/spec/settings.py`",
        "`setting(...)`): `python -m drip_cert.spec.reference` prints this page. A key not listed",
        'here is rejected by `drip-cert check-spec` (exit status 2, with a "did you mean").',
        "How to write a whole spec: [Describing a system](../getting_started.md).",
        "",
    ]
    classes = Settings.table_classes()
    for section, keys in SECTIONS.items():
        required = sorted(REQUIRED.get(section, ()))
        out += [f"## `[{section}]`", ""]
        if required:
            out += ["Required keys: " + ", ".join(f"`{k}`" for k in required) + ".", ""]
        if section == "blocks":
            out += [
                "`[blocks.NAME]`: one table per network block, used in expressions as "
                "`NAME(x)[j]`.",
                "",
                "| key | meaning |",
                "|---|---|",
            ]
            out += [f"| `{k}` | {_cell(v)} |" for k, v in BLOCK_KEYS.items()]
        elif section == "constants":
            out += [
                "Any constant of the papers that you know better than the computed one; it is "
                "labelled `given` in the certificate. Every value is a finite number >= 0 "
                "(> 0 for " + ", ".join(f"`{c}`" for c in sorted(POSITIVE_CONSTANTS)) + "). "
                "Keys: " + ", ".join(f"`{c}`" for c in CONSTANT_NAMES) + ".",
            ]
        elif keys is not None:
            out += ["| key | meaning |", "|---|---|"]
            out += [f"| `{k}` | {_cell(v)} |" for k, v in keys.items()]
        else:
            cls = classes[section]
            out += [_cell((cls.__doc__ or "").strip().split("\n\n")[0]), ""]
            out += ["| key | default | meaning |", "|---|---|---|"]
            for f in declared(cls):
                key = f.metadata["key"] or f.name
                meaning = _cell(f.metadata["description"])
                out.append(f"| `{key}` | {_default_text(section, f)} | {meaning} |")
        out.append("")
    return "\n".join(out)


if __name__ == "__main__":  # pragma: no cover - the documentation's generator
    print(spec_reference_markdown(), end="")
