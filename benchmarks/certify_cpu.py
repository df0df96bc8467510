"""CPU time of ``drip-cert certify`` now against a baseline commit, measured in one run.

Issue 26's target: ``certify`` of the three natural-coordinate examples (pendulum, Van der Pol,
cart-pole) and of the paper example uses >= 3x less CPU time than at the start of the issue
(commit ``8844af7``). This script checks the baseline out into a temporary git worktree (or
takes ``--base-tree``), then runs ``certify SPEC --json`` of each spec in a fresh process per
run, alternating baseline and this tree (``--repeats`` times each, after one warm-up run of each
tree and spec that writes the bytecode and fills the XLA compilation cache), and prints the
median CPU time (user + sys of the child, ``resource.getrusage``) of each, their ratio, and the
two verdicts.

What is measured is what a user's ``drip-cert certify`` costs: a fresh interpreter, the
imports, the certificate, the exit (through the command's own entry point where the tree has
one: ``cli.console_main`` here, ``cli.main`` at the baseline), with Python's bytecode cache on
(``PYTHONDONTWRITEBYTECODE`` removed from the environment) as an installed package has it.
CPU time, not wall time: the machine may be shared; both trees see the same load because the
runs alternate.

Usage: ``python benchmarks/certify_cpu.py [--base 8844af7] [--repeats 3] [SPEC ...]``.
"""

from __future__ import annotations

import argparse
import json
import os
import resource
import statistics
import subprocess
import sys
import tempfile
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
SPECS = (
    "examples/pendulum/pendulum.toml",
    "examples/van_der_pol/van_der_pol.toml",
    "examples/cart_pole/cart_pole.toml",
    "drip_cert/data/paper_4d/paper_4d.toml",
)
#: the command's entry point of a tree: console_main where it exists (it skips the teardown)
ENTRY = (
    "import sys, drip_cert.cli as c\n"
    "sys.argv = ['drip-cert', *sys.argv[1:]]\n"
    "f = getattr(c, 'console_main', None)\n"
    "sys.exit(f() if f is not None else c.main(sys.argv[1:]))\n"
)


def _run(tree: Path, spec: str, out: Path) -> float:
    """CPU seconds (user + sys) of one ``certify`` of ``spec`` with ``tree`` on the path."""
    env = {k: v for k, v in os.environ.items() if k != "PYTHONDONTWRITEBYTECODE"}
    env["PYTHONPATH"] = str(tree)
    before = resource.getrusage(resource.RUSAGE_CHILDREN)
    with out.open("w") as fh:
        proc = subprocess.run(
            [sys.executable, "-c", ENTRY, "certify", str(tree / spec), "--json"],
            env=env,
            stdout=fh,
            stderr=subprocess.DEVNULL,
            cwd=tempfile.gettempdir(),
            check=False,
        )
    after = resource.getrusage(resource.RUSAGE_CHILDREN)
    if proc.returncode not in (0, 1):  # 1: a certificate that does not certify
        raise SystemExit(f"certify {spec} in {tree} exited {proc.returncode}")
    return (after.ru_utime - before.ru_utime) + (after.ru_stime - before.ru_stime)


def _verdict(p: Path) -> str:
    """The certificate's verdict (the two trees' certificates differ in fields and digits: the
    issues between them changed what a certificate holds)."""
    return str(json.loads(p.read_text()).get("verdict"))


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("specs", nargs="*", default=list(SPECS), help="specs, relative to the tree")
    ap.add_argument("--base", default="8844af7", help="baseline commit (default: 8844af7)")
    ap.add_argument("--base-tree", type=Path, help="a checkout of the baseline (no worktree)")
    ap.add_argument("--repeats", type=int, default=3)
    args = ap.parse_args()
    with tempfile.TemporaryDirectory(prefix="drip-certify-bench-") as tmp:
        tmpd = Path(tmp)
        base = args.base_tree
        if base is None:
            base = tmpd / "base"
            subprocess.run(
                ["git", "-C", str(ROOT), "worktree", "add", "--detach", "-q", str(base), args.base],
                check=True,
            )
        try:
            print(f"load average {os.getloadavg()[0]:.2f}; baseline {args.base}; CPU-s, median")
            ratios = []
            for spec in args.specs:
                ob, oh = tmpd / "base.json", tmpd / "head.json"
                _run(base, spec, ob), _run(ROOT, spec, oh)  # warm-up: bytecode, XLA cache
                tb, th = [], []
                for _ in range(args.repeats):
                    tb.append(_run(base, spec, ob))
                    th.append(_run(ROOT, spec, oh))
                mb, mh = statistics.median(tb), statistics.median(th)
                ratios.append(mb / mh)
                print(
                    f"{spec:42s} base {mb:6.2f}  head {mh:6.2f}  ratio {mb / mh:5.2f}x  "
                    f"(base {' '.join(f'{t:.2f}' for t in tb)}; head "
                    f"{' '.join(f'{t:.2f}' for t in th)}; verdict {_verdict(ob)} / {_verdict(oh)})"
                )
            print(f"smallest ratio {min(ratios):.2f}x (target >= 3x)")
        finally:
            if args.base_tree is None:
                subprocess.run(
                    ["git", "-C", str(ROOT), "worktree", "remove", "--force", str(base)],
                    check=False,
                )


if __name__ == "__main__":
    main()
