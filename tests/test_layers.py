"""The layer order of ``docs/ARCHITECTURE`` (README) is enforced on the source text.

Every ``import`` of every module of ``drip_cert`` is parsed (function-local ones included) and
checked against the layer table below: a module may import only from a strictly lower layer or
from its own package; two packages of one layer (``analysis`` | ``learn`` | ``control``, ``bounds``
| ``sim``) may not import each other. No cycle between modules or between packages.
"""

from __future__ import annotations

import ast
from collections import defaultdict
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[1]
PKG = ROOT / "drip_cert"

#: layer of each top-level unit of drip_cert (a module or a sub-package), lowest first
LAYERS: dict[str, int] = {
    "errors": 1,
    "provenance": 1,
    "progress": 1,
    "_jax": 2,
    "numerics": 2,
    "model": 3,
    "spec": 4,
    "analysis": 5,
    "learn": 5,
    "control": 5,
    "bounds": 6,
    "sim": 6,
    "validate": 7,
    "workflows": 8,
    "report": 8,
    "cli": 9,
    "__main__": 10,
    "": 10,  # drip_cert/__init__.py: the lazy public re-exports
}

#: units of one layer that may import each other (same concept split over two modules)
SAME_LAYER_ALLOWED: set[tuple[str, str]] = {
    ("errors", "provenance"),
    ("provenance", "errors"),
    ("numerics", "_jax"),
    ("workflows", "report"),
}


def _module_name(path: Path) -> str:
    rel = path.relative_to(ROOT).with_suffix("")
    parts = list(rel.parts)
    if parts[-1] == "__init__":
        parts = parts[:-1]
    return ".".join(parts)


def _modules() -> dict[str, Path]:
    return {_module_name(p): p for p in PKG.rglob("*.py")}


def _imports(name: str, path: Path, known: set[str]) -> set[str]:
    """Every drip_cert module ``name`` imports, at any depth of the file (function-local too)."""
    tree = ast.parse(path.read_text(), filename=str(path))
    package = name if path.name == "__init__.py" else name.rpartition(".")[0]
    found: set[str] = set()
    for node in ast.walk(tree):
        targets: list[str] = []
        if isinstance(node, ast.Import):
            targets = [a.name for a in node.names]
        elif isinstance(node, ast.ImportFrom):
            base = node.module or ""
            if node.level:
                parts = package.split(".")[: len(package.split(".")) - node.level + 1]
                base = ".".join([*parts, base] if base else parts)
            # ``from pkg import module`` imports pkg.module; ``from mod import name`` imports mod
            targets = [
                f"{base}.{a.name}" if f"{base}.{a.name}" in known else base for a in node.names
            ]
        for t in targets:
            # the longest known module that t names (from pkg import module -> pkg.module)
            while t and t not in known:
                t = t.rpartition(".")[0]
            if t and t != name and t.startswith("drip_cert"):
                found.add(t)
    return found


def _unit(module: str) -> str:
    parts = module.split(".")
    return parts[1] if len(parts) > 1 else ""


def _graph() -> dict[str, set[str]]:
    mods = _modules()
    known = set(mods)
    return {m: _imports(m, p, known) for m, p in mods.items()}


def _cycles(graph: dict[str, set[str]]) -> list[list[str]]:
    """Strongly connected components with more than one node (Tarjan), i.e. the import cycles."""
    index: dict[str, int] = {}
    low: dict[str, int] = {}
    stack: list[str] = []
    on: set[str] = set()
    out: list[list[str]] = []
    counter = [0]

    def visit(v: str) -> None:
        index[v] = low[v] = counter[0]
        counter[0] += 1
        stack.append(v)
        on.add(v)
        for w in graph.get(v, ()):
            if w not in index:
                visit(w)
                low[v] = min(low[v], low[w])
            elif w in on:
                low[v] = min(low[v], index[w])
        if low[v] == index[v]:
            comp = []
            while True:
                w = stack.pop()
                on.discard(w)
                comp.append(w)
                if w == v:
                    break
            if len(comp) > 1:
                out.append(sorted(comp))

    for v in sorted(graph):
        if v not in index:
            visit(v)
    return out


def test_every_unit_has_a_layer():
    missing = sorted({_unit(m) for m in _modules()} - set(LAYERS))
    assert not missing, f"add these to LAYERS (and to the README's ARCHITECTURE table): {missing}"


def _violations(graph: dict[str, set[str]]) -> list[str]:
    bad = []
    for mod, targets in sorted(graph.items()):
        u = _unit(mod)
        for t in sorted(targets):
            v = _unit(t)
            if u == v or LAYERS[v] < LAYERS[u] or (u, v) in SAME_LAYER_ALLOWED:
                continue
            bad.append(f"{mod} (layer {LAYERS[u]}) imports {t} (layer {LAYERS[v]})")
    return bad


def _package_graph(graph: dict[str, set[str]]) -> dict[str, set[str]]:
    pk: dict[str, set[str]] = defaultdict(set)
    for mod, targets in graph.items():
        src = _unit(mod)
        pk[src]
        for t in targets:
            if _unit(t) != src:
                pk[src].add(_unit(t))
    return dict(pk)


def test_no_upward_or_sideways_import():
    bad = _violations(_graph())
    assert not bad, "\n".join(bad)


def test_no_module_cycle():
    assert _cycles(_graph()) == []


def test_no_package_cycle():
    assert _cycles(_package_graph(_graph())) == []


@pytest.mark.parametrize(
    "source, expected",
    [
        ("from drip_cert.numerics import rounding\n", {"drip_cert.numerics.rounding"}),
        (
            "def f():\n    from drip_cert.bounds.tasil import h_continuous\n",
            {"drip_cert.bounds.tasil"},
        ),
        ("import drip_cert.model.system as s\n", {"drip_cert.model.system"}),
        ("from ..bounds import tasil\n", {"drip_cert.bounds.tasil"}),
    ],
)
def test_the_parser_sees_every_form_of_import(tmp_path, source, expected):
    """The checker itself: top-level, function-local, aliased and relative imports are all found."""
    path = tmp_path / "mod.py"
    path.write_text(source)
    known = set(_modules())
    assert _imports("drip_cert.analysis.mod", path, known) == expected


def test_the_checker_fails_on_an_upward_import_a_sideways_import_and_a_cycle():
    """Made-up graphs: the checks above would fail on each of these."""
    up = {"drip_cert.model.system": {"drip_cert.analysis.constants"}}
    assert _violations(up) == [
        "drip_cert.model.system (layer 3) imports drip_cert.analysis.constants (layer 5)"
    ]
    side = {
        "drip_cert.analysis.x": {"drip_cert.learn.y"},
        "drip_cert.bounds.z": {"drip_cert.sim.w"},
    }
    assert len(_violations(side)) == 2
    down = {"drip_cert.bounds.z": {"drip_cert.analysis.x", "drip_cert.bounds.q"}}
    assert _violations(down) == []
    assert _cycles({"a": {"b"}, "b": {"a"}, "c": set()}) == [["a", "b"]]
    assert _cycles({"a": {"b"}, "b": set()}) == []
    pk = _package_graph(
        {"drip_cert.bounds.a": {"drip_cert.sim.b"}, "drip_cert.sim.c": {"drip_cert.bounds.d"}}
    )
    assert _cycles(pk) == [["bounds", "sim"]]
