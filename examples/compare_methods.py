"""TaSIL, BC, DAgger and DART side by side on the gallery systems: held-out gap, verdict, rho.

Usage (from the repository root)::

    .venv/bin/python examples/compare_methods.py                      # every system below
    .venv/bin/python examples/compare_methods.py pendulum van_der_pol  # some of them
    .venv/bin/python examples/compare_methods.py --steps 300 --quick   # smaller runs

For each system the four methods are trained on the same expert demonstrations and label budget
(``[tasil] trajectories`` trajectories of ``samples`` expert-labelled states; DAgger and DART spend
that budget over 4 iterations, drip_cert/learn/baselines.py) and each policy is certified on the
same expert training and held-out sets (``drip_cert.workflows.method_rows``): the held-out gap is
the mean over the held-out initial states of ``max_t ||x'_t - x*_t||`` on the nominal model.
Each system's rows go to ``OUT/<system>.json`` as soon as it is done (a run can be resumed; a
system whose file exists is not recomputed unless ``--force``); the Markdown table of every file
in ``OUT`` is printed and written to ``OUT/table.md``. Same seed, same numbers (no wall-clock
field in the rows; the timings go to ``OUT/timings.json``).
"""

from __future__ import annotations

import argparse
import json
import time
from pathlib import Path

ROOT = Path(__file__).resolve().parent.parent
SYSTEMS = ("pendulum", "van_der_pol", "nonlinear_2d", "cart_pole", "unmatched_2d")
PAPER = "paper_4d"  #: the paper example: run only when named (slow)


def spec_path(name: str) -> Path:
    if name == PAPER:
        return ROOT / "drip_cert" / "data" / PAPER / f"{PAPER}.toml"
    return ROOT / "examples" / name / f"{name}.toml"


def run_one(name: str, seed: int, steps: int | None, heldout: int | None) -> dict:
    """Train the four methods on ``name`` and certify each (one pipeline run)."""
    from drip_cert.spec import load_spec
    from drip_cert.spec.settings import TRAIN_METHODS
    from drip_cert.workflows import method_rows, run_pipeline

    spec = load_spec(spec_path(name))
    over: dict = {}
    if steps is not None:
        over["steps"] = steps
    if heldout is not None:
        over["heldout"] = heldout
    run = run_pipeline(spec, seed=seed, train=True, methods=TRAIN_METHODS, tasil=over)
    st = dataclass_dict(spec.settings.tasil, over)
    return {"system": name, "seed": seed, "settings": st, "rows": method_rows(run)}


def dataclass_dict(st, over: dict) -> dict:
    keys = ("trajectories", "samples", "heldout", "steps", "hidden", "architecture", "delta")
    d = {k: getattr(st, k) for k in keys}
    d.update(over)
    d["hidden"] = list(d["hidden"])
    return d


def _num(v) -> str:
    return "-" if v is None else f"{v:.3g}"


def table(results: list[dict]) -> str:
    """Markdown: one row per (system, method), the best gap and best certified rho in bold."""
    lines = [
        "| system | method | held-out gap (mean) | gap (max) | verdict | TaSIL part | "
        "rho_TaSIL | rho |",
        "|---|---|---|---|---|---|---|---|",
    ]
    for res in results:
        rows = res["rows"]
        gaps = {m: r["heldout_gap_mean"] for m, r in rows.items() if r["heldout_gap_mean"]}
        best_gap = min(gaps, key=lambda m: gaps[m]) if gaps else None
        cert = {
            m: r["rho_tasil"]
            for m, r in rows.items()
            if r.get("tasil_verdict") == "certified" and r.get("rho_tasil") is not None
        }
        best_rho = min(cert, key=lambda m: cert[m]) if cert else None
        for m, r in rows.items():
            g = _num(r["heldout_gap_mean"])
            rt = _num(r.get("rho_tasil"))
            lines.append(
                f"| {res['system']} | {m} | {f'**{g}**' if m == best_gap else g} | "
                f"{_num(r['heldout_gap_max'])} | {r.get('verdict', '-')} | "
                f"{r.get('tasil_verdict', '-')} | {f'**{rt}**' if m == best_rho else rt} | "
                f"{_num(r.get('rho'))} |"
            )
    return "\n".join(lines)


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("systems", nargs="*", default=list(SYSTEMS))
    ap.add_argument("--out", type=Path, default=ROOT / "docs" / "baselines")
    ap.add_argument("--seed", type=int, default=0)
    ap.add_argument("--steps", type=int, default=None, help="override [tasil] steps")
    ap.add_argument("--heldout", type=int, default=None, help="override [tasil] heldout")
    ap.add_argument("--force", action="store_true", help="recompute systems already in OUT")
    ap.add_argument("--table-only", action="store_true", help="only rebuild OUT/table.md")
    args = ap.parse_args(argv)
    from drip_cert.numerics.atomic_io import atomic_write_json, atomic_write_text

    args.out.mkdir(parents=True, exist_ok=True)
    tfile = args.out / "timings.json"
    for name in [] if args.table_only else args.systems:
        path = args.out / f"{name}.json"
        if path.exists() and not args.force:
            continue
        t0 = time.perf_counter()
        atomic_write_json(path, run_one(name, args.seed, args.steps, args.heldout))
        wall = time.perf_counter() - t0
        # read at write time: several systems may run in parallel processes
        timings = json.loads(tfile.read_text()) if tfile.exists() else {}
        atomic_write_json(tfile, {**timings, name: wall})
        print(f"{name}: {wall:.0f} s", flush=True)
    order = [*SYSTEMS, PAPER]
    files = sorted(
        (p for p in args.out.glob("*.json") if p.stem in order),
        key=lambda p: order.index(p.stem),
    )
    text = table([json.loads(p.read_text()) for p in files])
    atomic_write_text(args.out / "table.md", text + "\n")
    print(text)
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
