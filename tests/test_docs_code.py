"""Every code block of the README and of docs/ is exercised, so the documentation cannot rot.

* ``python`` blocks are executed (from the repository root, each in a fresh namespace); a block
  that needs minutes is preceded by the comment ``<!-- test: slow -->`` and runs in the slow group.
* ``toml`` blocks are parsed, and every table and key they show must be one the spec reader knows
  (a documented key that the loader would reject is a bug of the documentation or the loader).
* ``bash`` blocks: every ``drip-cert`` command line is parsed by the command line's own parser,
  and every file it reads must exist (or be written by an earlier line of the same block);
  ``make`` targets must exist in the Makefile; ``python -m MOD`` / ``python FILE`` must name a
  module or file.
* ``>>>`` examples in the docstrings of the main entry points run as doctests.

Blocks in other languages (``text``, unlabelled output) are output shown to the reader.
"""

from __future__ import annotations

import doctest
import importlib
import re
import shlex
import tomllib
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[1]
DOC_FILES = sorted([ROOT / "README.md", *(ROOT / "docs").rglob("*.md")])
FENCE = re.compile(r"^```(\w*)[^\n]*\n(.*?)^```", re.M | re.S)
SLOW_MARK = "<!-- test: slow -->"
EXCERPT_MARK = re.compile(r"<!-- test: excerpt of (\S+) -->")


def _blocks(lang: str) -> list[tuple[str, str, str]]:
    """``(where, code, mark)`` of every block in ``lang``; ``mark`` is the HTML comment on the
    line before the block ("" when none)."""
    out = []
    for path in DOC_FILES:
        text = path.read_text()
        for m in FENCE.finditer(text):
            if m.group(1) != lang:
                continue
            before = text[: m.start()].rstrip().splitlines()[-1:] or [""]
            mark = before[0] if before[0].startswith("<!-- test:") else ""
            line = text[: m.start()].count("\n") + 1
            out.append((f"{path.relative_to(ROOT)}:{line}", m.group(2), mark))
    return out


def _params(lang: str) -> list[object]:
    return [
        pytest.param(code, mark, id=where, marks=[pytest.mark.slow] if mark == SLOW_MARK else [])
        for where, code, mark in _blocks(lang)
    ]


def test_the_docs_have_code_blocks_of_each_kind() -> None:
    """The collector itself works: the README's own blocks are found (a broken regex would make
    every test below vacuous)."""
    assert len(_blocks("python")) >= 3
    assert len(_blocks("toml")) >= 3
    assert len(_blocks("bash")) >= 1


@pytest.mark.parametrize(("code", "mark"), _params("python"))
def test_python_block_runs(code: str, mark: str, monkeypatch: pytest.MonkeyPatch) -> None:
    """A Python block runs; an excerpt of a file (marked ``<!-- test: excerpt of FILE -->``)
    must consist of that file's lines, and the file itself is run by its own test
    (``tests/test_testing_plugin.py`` runs examples/regression_ci)."""
    excerpt = EXCERPT_MARK.fullmatch(mark)
    if excerpt:
        lines = {ln.strip() for ln in (ROOT / excerpt.group(1)).read_text().splitlines()}
        foreign = [ln for ln in code.splitlines() if ln.strip() and ln.strip() not in lines]
        assert not foreign, f"not lines of {excerpt.group(1)}: {foreign}"
        return
    assert mark in ("", SLOW_MARK), f"unknown test mark {mark!r}"
    monkeypatch.chdir(ROOT)
    exec(compile(code, "<doc block>", "exec"), {"__name__": "__doc_block__"})


def _known_keys() -> dict[str, set[str] | None]:
    from drip_cert.spec.load import BLOCK_KEYS, SECTIONS
    from drip_cert.spec.settings import Settings

    known: dict[str, set[str] | None] = {k: (set(v) if v else None) for k, v in SECTIONS.items()}
    for name, cls in Settings.table_classes().items():
        known[name] = set(cls.KEYS)
    known["blocks"] = set(BLOCK_KEYS)
    return known


@pytest.mark.parametrize(("code", "mark"), _params("toml"))
def test_toml_block_uses_only_known_keys(code: str, mark: str) -> None:
    doc = tomllib.loads(code)
    known = _known_keys()
    for table, body in doc.items():
        assert table in known, f"unknown table [{table}]"
        if table == "blocks":
            for block in body.values():
                assert set(block) <= known["blocks"], set(block) - known["blocks"]  # type: ignore[operator]
            continue
        allowed = known[table]
        if allowed is None or not isinstance(body, dict):
            continue
        nested = {k for k, v in body.items() if isinstance(v, dict) and k not in allowed}
        assert set(body) - nested <= allowed, f"[{table}]: {sorted(set(body) - nested - allowed)}"


def _shell_lines(code: str) -> list[list[str]]:
    lines = []
    for raw in code.splitlines():
        line = raw.split(" #", 1)[0].strip()
        if not line or line.startswith("#"):
            continue
        lines.append(shlex.split(line))
    return lines


@pytest.mark.parametrize(("code", "mark"), _params("bash"))
def test_shell_block_commands_exist(code: str, mark: str) -> None:
    from drip_cert.cli import build_parser

    parser = build_parser()
    targets = set(re.findall(r"^([\w-]+):", (ROOT / "Makefile").read_text(), re.M))
    written: set[str] = set()
    for words in _shell_lines(code):
        if ">" in words:  # a redirect writes the file a later line may read
            written.add(words[words.index(">") + 1])
            words = words[: words.index(">")]
        prog = Path(words[0]).name
        if prog == "make":
            assert set(words[1:]) <= targets, f"no make target {words[1:]}"
        elif prog == "drip-cert":
            args = parser.parse_args(words[1:])
            for attr in ("spec", "constants", "old", "new", "data"):
                value = getattr(args, attr, None)
                if isinstance(value, str) and value != "paper-4d":
                    assert (ROOT / value).exists() or value in written, f"{value} does not exist"
        elif prog == "python":
            if words[1] == "-m":
                assert importlib.util.find_spec(words[2]) is not None, words[2]
            else:
                assert (ROOT / words[1]).exists(), words[1]
        else:
            raise AssertionError(f"unexpected command {words[0]!r} in a documented shell block")


DOCTEST_MODULES = (
    "drip_cert.provenance",
    "drip_cert.numerics.stats",
    "drip_cert.model.literals",
)


@pytest.mark.parametrize("module", DOCTEST_MODULES)
def test_docstring_examples(module: str) -> None:
    mod = importlib.import_module(module)
    result = doctest.testmod(mod, optionflags=doctest.ELLIPSIS | doctest.NORMALIZE_WHITESPACE)
    assert result.attempted > 0, f"{module} has no >>> example"
    assert result.failed == 0


def test_spec_reference_page_is_generated_from_the_declarations() -> None:
    """docs/reference/spec.md is exactly what the declarations give (regenerate it with
    ``python -m drip_cert.spec.reference > docs/reference/spec.md``)."""
    from drip_cert.spec.reference import spec_reference_markdown

    committed = (ROOT / "docs" / "reference" / "spec.md").read_text()
    assert committed == spec_reference_markdown(), "regenerate docs/reference/spec.md"


def test_spec_reference_lists_every_key_the_loader_accepts() -> None:
    """Each settings key is in the page, and a new declaration shows up there without further
    edits (the page is built from the same field list the reader iterates)."""
    from drip_cert.spec.reference import spec_reference_markdown
    from drip_cert.spec.settings import Settings

    page = spec_reference_markdown()
    for cls in Settings.table_classes().values():
        for key in cls.KEYS:
            assert f"`{key}`" in page, key
