"""``python -m proofs_check [--json] [--only SUBSTRING] [--quick] [--seed N]``.

Prints one line per check (name, the paper's label, verdict, residual) or, with ``--json``, a
list of objects ``{name, label, verdict, residual, detail, erratum}``. Exit status 0 when no
check FAILs (ERRATUM verdicts are documented findings), 1 otherwise, 2 for bad usage.
"""

from __future__ import annotations

import argparse
import json
import sys

from proofs_check._core import Verdict, run_checks


def main(argv: list[str] | None = None) -> int:
    """Run the checks and report; returns the exit status."""
    ap = argparse.ArgumentParser(prog="python -m proofs_check", description=__doc__)
    ap.add_argument("--json", action="store_true", help="machine-readable list on stdout")
    ap.add_argument("--only", metavar="SUBSTRING", help="run the checks whose name contains it")
    ap.add_argument("--quick", action="store_true", help="reduced random-instance counts")
    ap.add_argument("--seed", type=int, default=0, help="seed of every random search (default 0)")
    ap.add_argument("--verbose", "-v", action="store_true", help="also print each detail line")
    args = ap.parse_args(argv)
    results = run_checks(quick=args.quick, seed=args.seed, only=args.only)
    if not results:
        print(f"no check name contains {args.only!r}", file=sys.stderr)
        return 2
    if args.json:
        json.dump([r.to_dict() for r in results], sys.stdout, indent=2)
        sys.stdout.write("\n")
    else:
        w = max(len(r.name) for r in results)
        for r in results:
            print(
                f"{r.name:<{w}}  {r.verdict.value:<7}  residual {r.residual: .2e}  {r.label}"
                + (f"  [{r.erratum}]" if r.erratum else "")
            )
            if args.verbose or r.verdict is Verdict.FAIL:
                print(f"{'':<{w}}    {r.detail}")
        counts = {v: sum(r.verdict is v for r in results) for v in Verdict}
        print(
            f"{len(results)} checks: {counts[Verdict.PASS]} PASS, {counts[Verdict.ERRATUM]} "
            f"ERRATUM (see proofs_check/ERRATA.md), {counts[Verdict.FAIL]} FAIL"
            + (f", {counts[Verdict.SKIP]} SKIP" if counts[Verdict.SKIP] else "")
        )
    return 1 if any(r.verdict is Verdict.FAIL for r in results) else 0


if __name__ == "__main__":
    raise SystemExit(main())
