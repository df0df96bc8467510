"""The layer order of ``docs/ARCHITECTURE`` (README) is enforced on the source text.

Every ``import`` of every module of ``drip_cert`` is parsed (function-local ones included) and
checked against the layer table below: a module may import only from a strictly lower layer or
from its own package; two packages of one layer (``analysis`` | ``learn`` | ``control``, ``bounds``
| ``sim``) may not import each other. No cycle between modules or between packages.
"""

from __future__ import annotations

import ast
import io
import re
import subprocess
import sys
import tokenize
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
    "vocabulary": 1,  # names shared across layers: processes and gaps, contraction routes
    "_jax": 2,
    "numerics": 2,
    "schema": 2,  # the output layouts (JSON Schema files) and their loader
    "model": 3,
    "spec": 4,
    "analysis": 5,
    "learn": 5,
    "control": 5,
    "bounds": 6,
    "sim": 6,
    "validate": 7,
    "workflows": 8,
    "deploy": 8,
    "report": 8,
    "figures_l1": 8,
    "figures_training": 8,
    "figures_certificate": 8,
    "diff": 8,
    "cli": 9,
    "testing": 9,  # the pytest plugin, beside the command line
    "__main__": 10,
    "": 10,  # drip_cert/__init__.py: the lazy public re-exports
}

#: units of one layer that may import each other (same concept split over two modules)
SAME_LAYER_ALLOWED: set[tuple[str, str]] = {
    ("errors", "provenance"),
    ("provenance", "errors"),
    ("numerics", "_jax"),
    ("workflows", "report"),
    ("workflows", "figures_l1"),
    ("workflows", "figures_training"),
}


def _module_name(path: Path) -> str:
    rel = path.relative_to(ROOT).with_suffix("")
    parts = list(rel.parts)
    if parts[-1] == "__init__":
        parts = parts[:-1]
    return ".".join(parts)


def _modules() -> dict[str, Path]:
    return {_module_name(p): p for p in PKG.rglob("*.py")}


ImportNode = ast.Import | ast.ImportFrom


def _package(name: str, path: Path) -> str:
    return name if path.name == "__init__.py" else name.rpartition(".")[0]


def _targets(node: ImportNode, package: str, known: set[str]) -> list[str]:
    """The modules one import statement imports: a drip_cert one as the longest known module it
    names, any other as written (``from scipy.optimize import root`` -> ``scipy.optimize``)."""
    if isinstance(node, ast.Import):
        targets = [a.name for a in node.names]
    else:
        base = node.module or ""
        if node.level:
            parts = package.split(".")[: len(package.split(".")) - node.level + 1]
            base = ".".join([*parts, base] if base else parts)
        # ``from pkg import module`` imports pkg.module; ``from mod import name`` imports mod
        targets = [f"{base}.{a.name}" if f"{base}.{a.name}" in known else base for a in node.names]
    out = []
    for t in targets:
        if t.startswith("drip_cert"):
            # the longest known module that t names (from pkg import module -> pkg.module)
            while t and t not in known:
                t = t.rpartition(".")[0]
        if t:
            out.append(t)
    return out


def _imports(name: str, path: Path, known: set[str]) -> set[str]:
    """Every drip_cert module ``name`` imports, at any depth of the file (function-local too)."""
    tree = ast.parse(path.read_text(), filename=str(path))
    found: set[str] = set()
    for node in ast.walk(tree):
        if isinstance(node, ast.Import | ast.ImportFrom):
            found.update(
                t
                for t in _targets(node, _package(name, path), known)
                if t != name and t.startswith("drip_cert")
            )
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
    up = {"drip_cert.model.system": {"drip_cert.analysis.growth.constants"}}
    assert _violations(up) == [
        "drip_cert.model.system (layer 3) imports drip_cert.analysis.growth.constants (layer 5)"
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


# ---------------------------------------------------------------------------- local imports
#: Third-party packages slow enough to import that a function-local import may keep them off an
#: import path (the design allows one "only to keep jax off the CLI's start-up path"; the others
#: are as slow: seconds each adds to ``import drip_cert.cli`` were jax 0.3, optax 0.4, cvxpy 1.0,
#: ot 0.9, matplotlib.pyplot 0.3, scipy.optimize 0.2, scipy.stats 0.5, onnx 0.07 (every
#: `certify` paid it, for .onnx networks only); clarabel is cvxpy's solver; numpy 0.1, sympy
#: 0.3, scipy.special 0.2 and flint together made `drip-cert --help` cost 0.6 CPU-s, so the CLI
#: imports them only in the commands that need them). Every drip_cert module is not on this
#: list: import it at the top of the module unless it brings one of these.
HEAVY: tuple[str, ...] = (
    "numpy",
    "sympy",
    "scipy",
    "flint",
    "jax",
    "jaxlib",
    "optax",
    "cvxpy",
    "clarabel",
    "ot",
    "onnx",
    "matplotlib",
    "scipy.optimize",
    "scipy.stats",
    "dask",
    "distributed",
)

#: the justification a function-local import carries on its line: ``# jax: <why>``
_JUSTIFICATION = re.compile(r"#\s*([\w.]+)\s*:")


def _heavy(target: str) -> set[str]:
    return {h for h in HEAVY if target == h or target.startswith(h + ".")}


def _parents(module: str) -> list[str]:
    """The packages whose ``__init__`` importing ``module`` runs first (``drip_cert`` included)."""
    parts = module.split(".")
    return [".".join(parts[:i]) for i in range(1, len(parts))]


def _split_imports(path: Path) -> tuple[list[ImportNode], list[ImportNode]]:
    """(module-level, function-local) import statements of a file; an ``if TYPE_CHECKING:`` block
    imports nothing at run time and is skipped. A class body runs at import: module level."""
    top: list[ImportNode] = []
    local: list[ImportNode] = []

    def visit(node: ast.AST, in_function: bool) -> None:
        for child in ast.iter_child_nodes(node):
            if isinstance(child, ast.If) and "TYPE_CHECKING" in ast.unparse(child.test):
                for stmt in child.orelse:
                    visit_one(stmt, in_function)
                continue
            visit_one(child, in_function)

    def visit_one(node: ast.AST, in_function: bool) -> None:
        if isinstance(node, ast.Import | ast.ImportFrom):
            (local if in_function else top).append(node)
        visit(node, in_function or isinstance(node, ast.FunctionDef | ast.AsyncFunctionDef))

    visit(ast.parse(path.read_text(), filename=str(path)), False)
    return top, local


def _heavy_reach(mods: dict[str, Path]) -> dict[str, frozenset[str]]:
    """The :data:`HEAVY` packages that importing each drip_cert module imports: through its
    module-level imports and its parent packages', transitively."""
    known = set(mods)
    top = {
        m: [t for node in _split_imports(p)[0] for t in _targets(node, _package(m, p), known)]
        for m, p in mods.items()
    }
    reach = {}
    for m in mods:
        seen: set[str] = set()
        stack = [m]
        found: set[str] = set()
        while stack:
            x = stack.pop()
            if x in seen:
                continue
            seen.add(x)
            if x in top:
                stack.extend(top[x] + _parents(x))
            else:
                found |= _heavy(x)
        reach[m] = frozenset(found)
    return reach


def _local_import_problems(
    name: str, path: Path, known: set[str], reach: dict[str, frozenset[str]]
) -> list[str]:
    """Each function-local import of module ``name`` that does not carry ``# <package>: <why>``
    naming a :data:`HEAVY` package which the imported module brings and ``name`` itself, at module
    level, does not (otherwise the import belongs at the top of the module)."""

    def brings(target: str) -> frozenset[str]:
        return reach.get(target, frozenset(_heavy(target)))

    source = path.read_text()
    comments: dict[int, list[str]] = defaultdict(list)
    for tok in tokenize.generate_tokens(io.StringIO(source).readline):
        if tok.type == tokenize.COMMENT:
            comments[tok.start[0]].append(tok.string)
    top, local = _split_imports(path)
    package = _package(name, path)
    own: set[str] = set()
    for t in [t for node in top for t in _targets(node, package, known)] + _parents(name):
        own |= brings(t)
    problems = []
    for node in local:
        assert node.end_lineno is not None
        extra: set[str] = set()
        for t in _targets(node, package, known):
            extra |= brings(t) - own
        named = [
            m.group(1)
            for line in range(node.lineno, node.end_lineno + 1)
            for c in comments[line]
            if (m := _JUSTIFICATION.match(c))
        ]
        where = f"{name}:{node.lineno}: {ast.unparse(node)}"
        if not extra:
            problems.append(
                f"{where}: imports no heavy package the module lacks (move it to the top)"
            )
        elif not any(n in extra for n in named):
            problems.append(f"{where}: justify it on its line, e.g. `# {min(extra)}: <why>`")
    return problems


def test_every_function_local_import_keeps_a_heavy_package_off_an_import_path():
    mods = _modules()
    reach = _heavy_reach(mods)
    bad = [
        problem
        for m, p in sorted(mods.items())
        for problem in _local_import_problems(m, p, set(mods), reach)
    ]
    assert not bad, "\n".join(bad)


@pytest.mark.parametrize(
    "source, problem",
    [
        ("def f():\n    import numpy as np\n", "justify it"),
        ("import numpy as np\n\n\ndef f():\n    import numpy.linalg  # numpy: again\n", "move it"),
        (
            "def f():\n    import math  # jax: keep off the CLI start-up path\n",
            "move it to the top",
        ),
        ("def f():\n    from drip_cert._jax import jnp\n", "justify it"),
        ("def f():\n    from drip_cert._jax import jnp  # numpy: fast\n", "justify it"),
        ("def f():\n    from drip_cert._jax import jnp  # cvxpy: wrong package\n", "justify it"),
        (
            "from drip_cert._jax import jax\n\n\ndef f():\n"
            "    from drip_cert._jax import jnp  # jax: the module imports it anyway\n",
            "move it to the top",
        ),
        (
            "from drip_cert.numerics.interval import enclose_expr\n\n\ndef f():\n"
            "    from drip_cert.numerics.interval import interval_add  # jax: not imported\n",
            "move it to the top",
        ),
        (
            "def f():\n    from drip_cert._jax import jnp  # jax: keep off the CLI start-up path\n",
            "",
        ),
        ("def f():\n    import matplotlib.pyplot as plt  # matplotlib: only for figures\n", ""),
        (
            "def f():\n"
            "    from drip_cert.analysis.contraction.lmi import (  # flint: one function\n"
            "        contraction_metric,\n    )\n",
            "",
        ),
        (
            "from typing import TYPE_CHECKING\n\nif TYPE_CHECKING:\n"
            "    from drip_cert._jax import jnp\n\n\nclass A:\n    import json\n",
            "",
        ),
    ],
)
def test_the_local_import_checker(tmp_path, source, problem):
    """The checker itself, on made-up modules: an unjustified or needless local import fails."""
    path = tmp_path / "mod.py"
    path.write_text(source)
    mods = _modules()
    problems = _local_import_problems("drip_cert.analysis.mod", path, set(mods), _heavy_reach(mods))
    if problem:
        assert len(problems) == 1 and problem in problems[0], problems
    else:
        assert problems == []


def test_the_cli_starts_without_jax_or_any_heavy_package():
    code = (
        "import drip_cert.cli, sys; assert 'jax' not in sys.modules; "
        f"print(','.join(h for h in {HEAVY!r} if h in sys.modules))"
    )
    out = subprocess.run(
        [sys.executable, "-c", code], cwd=ROOT, capture_output=True, text=True, check=False
    )
    assert out.returncode == 0, out.stderr
    assert out.stdout.strip() == "", f"imported by `import drip_cert.cli`: {out.stdout}"


HELP_CPU_S = 0.2
"""Most CPU seconds `drip-cert --help` may take (user + system of the child; issue 26: it took
0.6-0.9 s while the CLI imported sympy, numpy and scipy at module level; ~0.05 s without)."""


def test_drip_cert_help_imports_no_heavy_package_and_is_fast():
    """`drip-cert --help` runs the parser only: none of :data:`HEAVY` (numpy and sympy included)
    is imported, and the child process costs at most :data:`HELP_CPU_S` CPU seconds."""
    import resource

    code = (
        "import sys\n"
        "from drip_cert.cli import main\n"
        "sys.argv = ['drip-cert', '--help']\n"
        "try:\n    main()\nexcept SystemExit:\n    pass\n"
        f"print('MODULES', ','.join(h for h in {HEAVY!r} if h in sys.modules), file=sys.stderr)"
    )
    before = resource.getrusage(resource.RUSAGE_CHILDREN)
    out = subprocess.run(
        [sys.executable, "-c", code], cwd=ROOT, capture_output=True, text=True, check=False
    )
    after = resource.getrusage(resource.RUSAGE_CHILDREN)
    assert out.returncode == 0, out.stderr
    assert "usage: drip-cert" in out.stdout
    line = [ln for ln in out.stderr.splitlines() if ln.startswith("MODULES")]
    assert line == ["MODULES "], f"imported by `drip-cert --help`: {out.stderr}"
    cpu = (after.ru_utime - before.ru_utime) + (after.ru_stime - before.ru_stime)
    assert cpu <= HELP_CPU_S, f"`drip-cert --help` took {cpu:.2f} CPU-s"
