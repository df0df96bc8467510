"""TaSIL, BC, DAgger and DART side by side on the gallery systems: held-out gap, verdict, rho.

Usage (from the repository root)::

    .venv/bin/python examples/compare_methods.py                      # every system below
    .venv/bin/python examples/compare_methods.py pendulum van_der_pol  # some of them
    .venv/bin/python examples/compare_methods.py --steps 300          # smaller runs
    .venv/bin/python examples/compare_methods.py --architecture residual  # the residual class

``--architecture`` replaces ``[tasil] architecture`` for all four methods (they train the same
class). With ``residual`` each system's spec is ``docs/baselines/residual/<system>.toml`` when
that file exists (the gallery spec with a ``[policy] structure``, a small network and a
``lipschitz_budget``), and the rows go to ``docs/baselines/residual/`` (``--specs``, ``--out``).

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
#: the table's order (inverted_pendulum: run only when named)
ORDER = (*SYSTEMS, "inverted_pendulum", PAPER)
RESIDUAL_SPECS = ROOT / "docs" / "baselines" / "residual"


def spec_path(name: str, specs: Path | None = None) -> Path:
    """``specs/<name>.toml`` when it exists, else the gallery's (or the paper example's) spec."""
    if specs is not None and (specs / f"{name}.toml").exists():
        return specs / f"{name}.toml"
    if name == PAPER:
        return ROOT / "drip_cert" / "data" / PAPER / f"{PAPER}.toml"
    return ROOT / "examples" / name / f"{name}.toml"


def overrides(
    steps: int | None = None,
    heldout: int | None = None,
    architecture: str | None = None,
    trajectories: int | None = None,
) -> dict:
    """The ``[tasil]`` overrides of one run (only those given)."""
    given = {
        "steps": steps,
        "heldout": heldout,
        "architecture": architecture,
        "trajectories": trajectories,
    }
    return {k: v for k, v in given.items() if v is not None}


def run_one(
    name: str,
    seed: int,
    steps: int | None,
    heldout: int | None,
    architecture: str | None = None,
    specs: Path | None = None,
    trajectories: int | None = None,
    spec=None,
) -> dict:
    """Train the four methods on ``name`` (or on ``spec`` when given) and certify each (one
    pipeline run); every method trains the class ``architecture`` (default: the spec's)."""
    from drip_cert.spec import load_spec
    from drip_cert.spec.settings import TRAIN_METHODS
    from drip_cert.workflows import method_rows, run_pipeline

    path = None
    if spec is None:
        path = spec_path(name, specs)
        spec = load_spec(path)
    over = overrides(steps, heldout, architecture, trajectories)
    run = run_pipeline(spec, seed=seed, train=True, methods=TRAIN_METHODS, tasil=over)
    st = dataclass_dict(spec.settings.tasil, over)
    res = {"system": name, "seed": seed, "settings": st, "rows": method_rows(run)}
    if path is not None:
        res["spec"] = path.relative_to(ROOT).as_posix() if path.is_relative_to(ROOT) else str(path)
    return res


def dataclass_dict(st, over: dict) -> dict:
    keys = (
        "trajectories",
        "samples",
        "heldout",
        "steps",
        "hidden",
        "architecture",
        "lipschitz_budget",
        "delta",
    )
    d = {k: getattr(st, k) for k in keys}
    d.update(over)
    d["hidden"] = list(d["hidden"])
    if d["lipschitz_budget"] == float("inf"):
        d["lipschitz_budget"] = None  # JSON has no inf
    return d


def _num(v) -> str:
    return "-" if v is None else f"{v:.3g}"


def table(results: list[dict]) -> str:
    """Markdown: one row per (system, method), the best gap and best certified rho in bold."""
    lines = [
        "| system | method | held-out gap (mean) | gap (max) | verdict | contraction | TaSIL | "
        "L1-DRAC | rho_TaSIL | rho_L1 | rho |",
        "|---|---|---|---|---|---|---|---|---|---|---|",
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
                f"{r.get('contraction_verdict') or '-'} | {r.get('tasil_verdict', '-')} | "
                f"{r.get('l1drac_verdict') or '-'} | {f'**{rt}**' if m == best_rho else rt} | "
                f"{_num(r.get('rho_l1'))} | {_num(r.get('rho'))} |"
            )
    return "\n".join(lines)


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("systems", nargs="*", default=None)
    ap.add_argument("--out", type=Path, default=None, help="default: docs/baselines[/residual]")
    ap.add_argument(
        "--architecture",
        choices=["mlp", "residual"],
        default=None,
        help="the policy class of all four methods (default: each spec's [tasil] architecture)",
    )
    ap.add_argument(
        "--specs",
        type=Path,
        default=None,
        help="a folder of specs <system>.toml used before the gallery's (default with "
        "--architecture residual: docs/baselines/residual)",
    )
    ap.add_argument("--trajectories", type=int, default=None, help="override [tasil] trajectories")
    ap.add_argument("--seed", type=int, default=0)
    ap.add_argument("--steps", type=int, default=None, help="override [tasil] steps")
    ap.add_argument("--heldout", type=int, default=None, help="override [tasil] heldout")
    ap.add_argument("--force", action="store_true", help="recompute systems already in OUT")
    ap.add_argument("--table-only", action="store_true", help="only rebuild OUT/table.md")
    args = ap.parse_args(argv)
    from drip_cert.numerics.atomic_io import atomic_write_json, atomic_write_text

    residual = args.architecture == "residual"
    if args.specs is None and residual:
        args.specs = RESIDUAL_SPECS
    if args.out is None:
        args.out = RESIDUAL_SPECS if residual else ROOT / "docs" / "baselines"
    if args.systems is None:
        args.systems = (
            sorted(p.stem for p in args.specs.glob("*.toml"))
            if residual and args.specs.is_dir()
            else list(SYSTEMS)
        )

    args.out.mkdir(parents=True, exist_ok=True)
    tfile = args.out / "timings.json"
    for name in [] if args.table_only else args.systems:
        path = args.out / f"{name}.json"
        if path.exists() and not args.force:
            continue
        t0 = time.perf_counter()
        res = run_one(
            name,
            args.seed,
            args.steps,
            args.heldout,
            architecture=args.architecture,
            specs=args.specs,
            trajectories=args.trajectories,
        )
        atomic_write_json(path, res)
        wall = time.perf_counter() - t0
        # read at write time: several systems may run in parallel processes
        timings = json.loads(tfile.read_text()) if tfile.exists() else {}
        atomic_write_json(tfile, {**timings, name: wall})
        print(f"{name}: {wall:.0f} s", flush=True)
    files = sorted(
        (p for p in args.out.glob("*.json") if p.stem in ORDER),
        key=lambda p: ORDER.index(p.stem),
    )
    text = table([json.loads(p.read_text()) for p in files])
    atomic_write_text(args.out / "table.md", text + "\n")
    print(text)
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
