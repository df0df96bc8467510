"""Command line: ``drip-cert {check-spec, certify, design-l1, train, validate, reproduce, diff}``.

Thin by design: parse arguments, call library functions, print. Exit status 0 = certified /
holds / feasible, 1 = not certified / violated / infeasible (with the reason), 2 = bad input or
usage (a message on stderr naming the file and field, never a traceback), 3 = an internal error
(a one-line message asking for a report; the traceback only with ``--debug``).

Every file a command names (``set_defaults(files=...)`` below: specs, data, constants files read;
``--out`` directories and ``--figure`` files written) is checked before any work starts
(:mod:`drip_cert.numerics.user_files`), so that a typo costs no seconds of certification or
minutes of training.
"""

from __future__ import annotations

import argparse
import atexit
import json
import math
import os
import sys
import threading
import traceback
from collections.abc import Callable, Sequence
from pathlib import Path
from typing import Any

# Light imports only (the standard library and modules that import nothing heavy): numpy,
# sympy, scipy, jax and matplotlib are imported inside the commands that need them, so that
# `drip-cert --help` and a mistyped argument cost a fraction of a second (tests/test_layers.py).
from drip_cert.diff import DEFAULT_RTOL, diff_files, diff_text
from drip_cert.errors import AssumptionViolation, DripCertError, FingerprintError, SpecError
from drip_cert.provenance import ValidationStatus
from drip_cert.sim.backend import Backend


def _print_json(obj: Any) -> None:
    from drip_cert.numerics.atomic_io import jsonable  # numpy: off the start-up path

    sys.stdout.write(json.dumps(jsonable(obj), indent=2, allow_nan=False) + "\n")


# ---------------------------------------------------------------------------- subcommands
def cmd_check_spec(args: argparse.Namespace) -> int:
    from drip_cert.spec import load_spec  # sympy: off the start-up path

    spec = load_spec(args.spec)
    s = spec.system
    if args.json:
        _print_json({"ok": True, "system": s.to_dict(), "notes": list(spec.notes)})
    else:
        print(
            f"{args.spec}: OK — system '{s.name}', n = {s.n}, m = {s.m}, d = {s.d}, "
            f"T = {s.horizon:g}, blocks: {', '.join(s.blocks) or 'none'}, learned policy: "
            f"{'yes' if s.learned is not None else 'no'}"
        )
        for note in spec.notes:
            print(f"  {note}")
    return 0


def cmd_certify(args: argparse.Namespace) -> int:
    from drip_cert.bounds.certificate import certify  # sympy: off the start-up path
    from drip_cert.report import certificate_markdown  # numpy: off the start-up path
    from drip_cert.spec import load_spec  # sympy: off the start-up path

    spec = load_spec(args.spec)
    cert = certify(spec, progress=_progress(args))
    accepted = cert.certified or (args.allow_estimates and cert.verdict.value == "conditional")
    if args.figure:
        from drip_cert.figures_certificate import certificate_figure  # numpy: off start-up

        certificate_figure(
            cert.to_dict(),
            args.figure,
            support_x=spec.system.support,
            states_x=[str(x) for x in spec.system.states],
        )
    if args.json:
        out = cert.to_dict()
        out["accepted"] = {
            "exit_status": 0 if accepted else 1,
            "allow_estimates": bool(args.allow_estimates),
            "note": "a conditional verdict accepted by --allow-estimates: it rests on the "
            "estimates and regions listed in verdict_reasons"
            if accepted and not cert.certified
            else "",
        }
        _print_json(out)
    else:
        print(certificate_markdown(cert))
        if accepted and not cert.certified:
            print(
                "\nNOTE: verdict is CONDITIONAL; exit status 0 only because --allow-estimates "
                "was given (the certificate rests on the items listed above)."
            )
    if args.export_l1_constants is not None:
        from drip_cert.numerics.atomic_io import atomic_write_text  # numpy: off the start-up path
        from drip_cert.report import l1_constants_toml  # numpy: off the start-up path

        text = l1_constants_toml(cert.to_dict(), spec.settings.l1drac, source=str(args.spec))
        atomic_write_text(Path(args.export_l1_constants), text)
    return 0 if accepted else 1


def cmd_design_l1(args: argparse.Namespace) -> int:
    from drip_cert.bounds.l1drac.toml import design_l1_report  # sympy: off the start-up path
    from drip_cert.figures_l1 import (  # numpy: off the start-up path
        l1_front_figure,
        l1_terms_figure,
    )
    from drip_cert.report import l1_design_text  # numpy: off the start-up path

    report = design_l1_report(args.constants, Ts=args.Ts, rho_budget=args.rho_budget)
    if args.figure:
        report["figure"] = str(l1_front_figure(report, args.figure))
        fig = Path(args.figure)
        terms = fig.with_name(f"{fig.stem}_terms{fig.suffix}")
        report["figure_terms"] = str(l1_terms_figure(report, terms))
    if args.json:
        _print_json(report)
    else:
        print(l1_design_text(report))
    return 0 if report["feasible"] else 1


def cmd_train(args: argparse.Namespace) -> int:
    from drip_cert.report import train_text  # numpy: off the start-up path
    from drip_cert.workflows import train_from_spec  # sympy: off the start-up path

    summary = train_from_spec(
        args.spec,
        method=args.method,
        architecture=args.architecture,
        trajectories=args.trajectories,
        seed=args.seed,
        out=args.out,
        steps=args.steps,
        progress=_progress(args),
        certify=not args.no_certify,
        compare=not args.no_compare,
        compare_all=args.compare,
        until_certified=args.until_certified,
        max_heldout_gap=args.max_heldout_gap,
        write_spec=args.write_spec,
    )
    if args.json:
        _print_json(summary)
    else:
        print(train_text(summary, args.out))
    for why in summary["failures"]:
        print(f"drip-cert: training failed: {why}", file=sys.stderr)
    return 0 if summary["ok"] else 1


def cmd_export_policy(args: argparse.Namespace) -> int:
    from drip_cert.workflows import export_policy  # flint: off the start-up path (sympy, onnx too)

    summary = export_policy(args.spec, args.out, dtype=args.dtype, block=args.block)
    if args.json:
        _print_json(summary)
    else:
        print(
            f"wrote {summary['out']}: block {summary['block']!r}, sizes {summary['sizes']}, "
            f"activations {', '.join(summary['activations'])}, {summary['dtype']}"
        )
        if not summary["block_is_policy"]:
            print(f"  note: policy.learned = {summary['learned']} wraps the network")
    return 0


def cmd_validate(args: argparse.Namespace) -> int:
    from drip_cert.report import validation_text  # numpy: off the start-up path
    from drip_cert.workflows import validate_recorded, validate_spec  # sympy: off the start-up path

    if args.data is not None:
        report = validate_recorded(
            args.spec,
            args.data,
            out=args.out,
            progress=_progress(args),
            accept_unfingerprinted=args.accept_unfingerprinted,
        )
        if report.unfingerprinted_data:  # accepted by the flag: say so on stderr
            print(
                f"drip-cert: warning: {args.data}: the data carry no fingerprint; accepted "
                "unverified by --accept-unfingerprinted",
                file=sys.stderr,
            )
    else:
        report = validate_spec(
            args.spec,
            trajectories=args.trajectories,
            seed=args.seed,
            out=args.out,
            practical_ts=args.practical_ts,
            quick=args.quick,
            progress=_progress(args),
            backend=_backend(args),
            policy_dtype=args.policy_dtype,
            dtype=args.dtype,
        )
    if args.json:
        _print_json(report.to_dict())
    else:
        print(validation_text(report.to_dict()))
    # exit 0 only when a finite bound was checked and none is violated (not "nothing checked")
    return 0 if report.status == ValidationStatus.HOLDS else 1


def cmd_diff(args: argparse.Namespace) -> int:
    res = diff_files(args.old, args.new, rtol=args.rtol)
    if args.json:
        _print_json(res.to_dict())
    else:
        print(diff_text(res))
    return res.exit_status  # 1 on a regression


def cmd_reproduce(args: argparse.Namespace) -> int:
    from drip_cert.workflows import reproduce  # sympy: off the start-up path

    report = reproduce(
        args.name,
        out=args.out,
        quick=args.quick,
        seed=args.seed,
        progress=_progress(args),
        backend=_backend(args),
        policy_dtype=args.policy_dtype,
        dtype=args.dtype,
    )
    if args.json:
        _print_json(report)
    else:
        print(report["summary"])
    return 0 if report["holds"] else 1


# ---------------------------------------------------------------------------- parser
def build_parser() -> argparse.ArgumentParser:
    p = argparse.ArgumentParser(
        prog="drip-cert",
        description="Certificates for DRIP (TaSIL + L1-DRAC): constants, bounds, validation.",
    )
    p.add_argument("--debug", action="store_true", help=DEBUG_HELP)
    sub = p.add_subparsers(dest="command", required=True)

    q = sub.add_parser("check-spec", help="parse and validate a TOML specification only")
    q.add_argument("spec", help=SPEC_HELP)
    q.add_argument("--json", action="store_true", help=JSON_HELP)
    q.set_defaults(func=cmd_check_spec, files=[("spec", IN, "specification file")])

    q = sub.add_parser("certify", help="compute the certificate of a system")
    q.add_argument("spec", help=SPEC_HELP)
    q.add_argument("--json", action="store_true", help=JSON_HELP)
    q.add_argument(
        "--allow-estimates",
        action="store_true",
        help="exit 0 for a conditional verdict too (one resting on estimates or unproved regions)",
    )
    q.add_argument(
        "--figure",
        default=None,
        metavar="PATH",
        help="draw the assumption margins and the proved sets (support, proof boxes, invariant "
        "set) in x here (png, svg or pdf)",
    )
    q.add_argument(
        "--export-l1-constants",
        default=None,
        metavar="FILE",
        help="write the L1-DRAC constants and design inputs as a complete `drip-cert design-l1` "
        "file (.toml), to explore T_s and rho without certifying again",
    )
    q.set_defaults(
        func=cmd_certify,
        files=[
            ("spec", IN, "specification file"),
            ("figure", FIGURE, "--figure file"),
            ("export_l1_constants", OUT_FILE, "--export-l1-constants file"),
        ],
    )

    q = sub.add_parser("design-l1", help="L1-DRAC parameter feasibility from a constants file")
    q.add_argument(
        "constants",
        help="a TOML file of the L1-DRAC constants (examples/l1drac_constants; "
        "certify --export-l1-constants writes one)",
    )
    q.add_argument("--json", action="store_true", help=JSON_HELP)
    q.add_argument(
        "--Ts",
        type=float,
        default=None,
        help="the hardware's sampling period [s]: the smallest rho at this T_s (replaces the "
        "file's Ts)",
    )
    q.add_argument(
        "--rho-budget",
        type=float,
        default=None,
        help="the largest acceptable rho: the largest T_s with rho <= this",
    )
    q.add_argument(
        "--figure", default=None, metavar="PATH", help="write the (T_s, rho) Pareto front here"
    )
    q.set_defaults(
        func=cmd_design_l1,
        files=[("constants", IN, "constants file"), ("figure", FIGURE, "--figure file")],
    )

    q = sub.add_parser("train", help="train an imitation policy (TaSIL, BC, DAgger or DART)")
    q.add_argument("spec", help=SPEC_HELP)
    q.add_argument(
        "--method",
        type=_train_method,
        default=None,
        help="tasil (matches the policy's Jacobian too), bc (behaviour cloning), dagger or dart "
        "(docs/baselines.md) (default: [tasil] method of the spec, else tasil)",
    )
    q.add_argument(
        "--architecture",
        choices=["mlp", "residual"],
        default=None,
        help="policy class, overriding [tasil] architecture: mlp (a plain MLP) or residual "
        "([policy] structure, when given, + K x + MLP); --compare trains every method in it "
        "(default: the spec's)",
    )
    q.add_argument(
        "--trajectories",
        type=_posint,
        default=None,
        help="expert demonstrations to draw (default: [tasil] trajectories of the spec, else 20)",
    )
    q.add_argument(
        "--seed",
        type=_nonneg_int,
        default=None,
        help="seed of the demonstrations and the training (default: [tasil] seed of the spec, "
        "else 0)",
    )
    q.add_argument(
        "--steps",
        type=_posint,
        default=None,
        help="optimiser steps (default: [tasil] steps of the spec)",
    )
    q.add_argument(
        "--out",
        required=True,
        metavar="DIR",
        help="directory for the weights, the training curves and the summary (created)",
    )
    q.add_argument("--json", action="store_true", help=JSON_HELP)
    q.add_argument("--no-certify", action="store_true", help="skip the certificate of the policy")
    cmp = q.add_mutually_exclusive_group()
    cmp.add_argument(
        "--no-compare", action="store_true", help="do not train the other method for comparison"
    )
    cmp.add_argument(
        "--compare",
        action="store_true",
        help="train and certify TaSIL, BC, DAgger and DART on the same data and label budget, "
        "side by side",
    )
    q.add_argument(
        "--until-certified",
        type=_posint,
        default=0,
        metavar="ROUNDS",
        help="retrain with twice the steps (at most ROUNDS rounds) until the verdict is certified",
    )
    q.add_argument(
        "--max-heldout-gap",
        type=_positive_or_inf,
        default=None,
        help="exit 1 when the held-out mean gap exceeds this (default: [tasil] max_heldout_gap, "
        "else the size of the held-out expert trajectories)",
    )
    q.add_argument(
        "--write-spec",
        default=None,
        metavar="OUT.toml",
        help="also write the spec with the trained policy in it (blocks, [policy] learned, the "
        "[tasil] demonstrations), ready for check-spec and certify",
    )
    q.set_defaults(
        func=cmd_train,
        files=[
            ("spec", IN, "specification file"),
            ("out", OUT_DIR, "--out directory"),
            ("write_spec", OUT_FILE, "--write-spec file"),
        ],
    )

    q = sub.add_parser(
        "export-policy", help="write the learned policy's network as ONNX (docs/networks.md)"
    )
    q.add_argument("spec", help=SPEC_HELP)
    q.add_argument("--out", default="policy.onnx", help="the .onnx file to write")
    q.add_argument(
        "--dtype",
        choices=["float64", "float32"],
        default="float64",
        help="the floats of the written weights (default: %(default)s)",
    )
    q.add_argument("--block", default=None, help="the MLP block (default: the learned policy's)")
    q.add_argument("--json", action="store_true", help=JSON_HELP)
    q.set_defaults(func=cmd_export_policy, files=[("spec", IN, "specification file")])

    q = sub.add_parser("validate", help="check a certificate against Monte-Carlo simulation")
    q.add_argument("spec", help=SPEC_HELP)
    q.add_argument("--trajectories", type=_posint, default=1000, help="simulated paths")
    q.add_argument(
        "--seed",
        type=_nonneg_int,
        default=None,
        help="one seed for demonstrations, training and simulation (default: [tasil] seed)",
    )
    q.add_argument(
        "--out",
        default=None,
        metavar="DIR",
        help="directory for validation.json and the figures (created; default: none written)",
    )
    q.add_argument(
        "--practical-ts",
        type=_posfloat,
        default=None,
        help="simulate at this T_s when the certified one is impractically small",
    )
    q.add_argument(
        "--quick", action="store_true", help="fewer paths and a shorter horizon: a smoke test"
    )
    q.add_argument(
        "--data",
        default=None,
        metavar="FILE",
        help="check recorded trajectories or gap series (.npz or .csv, docs/data_format.md) "
        "instead of simulating; --trajectories, --seed, --practical-ts, --quick do not apply",
    )
    q.add_argument(
        "--accept-unfingerprinted",
        action="store_true",
        help="with --data: accept data without a fingerprint (with a warning) instead of "
        "refusing them (docs/data_format.md)",
    )
    q.add_argument("--json", action="store_true", help=JSON_HELP)
    _add_simulation_options(q)
    q.set_defaults(
        func=cmd_validate,
        files=[
            ("spec", IN, "specification file"),
            ("data", IN, "--data file"),
            ("out", OUT_DIR, "--out directory"),
        ],
    )

    q = sub.add_parser("reproduce", help="reproduce a paper experiment end to end")
    q.add_argument("name", choices=["paper-4d"], help="the experiment: %(choices)s")
    q.add_argument(
        "--out",
        default="demo_out",
        metavar="DIR",
        help="directory for the certificate, the report and the figures (default: %(default)s)",
    )
    q.add_argument(
        "--quick", action="store_true", help="fewer paths and training steps: a smoke test"
    )
    q.add_argument(
        "--seed",
        type=_nonneg_int,
        default=0,
        help="one seed for demonstrations, training and simulation (default: %(default)s)",
    )
    q.add_argument("--json", action="store_true", help=JSON_HELP)
    _add_simulation_options(q)
    q.set_defaults(func=cmd_reproduce, files=[("out", OUT_DIR, "--out directory")])

    q = sub.add_parser(
        "diff",
        help="compare two certificates (or validation reports); exit 1 on a regression",
        description="Compares claims, not headline numbers: verdicts and their reasons, each "
        "bound as a claim (radius, delta, p, form, coordinates), constants (removed, or moved "
        "beyond --rtol in the loosening direction), soundness, scope_justified, margins that "
        "changed sign, provenance (exact > sound > given > estimate); for validation reports "
        "also statuses. Timings are ignored. Rules: docs/diff.md. Exit 1 on a regression, 0 "
        "otherwise.",
    )
    q.add_argument("old", help="the baseline: certify --json or validation.json output")
    q.add_argument("new", help="the output to compare with it (same kind)")
    q.add_argument(
        "--rtol",
        type=_nonneg_float,
        default=DEFAULT_RTOL,
        help=f"relative tolerance of a bound change (default {DEFAULT_RTOL:g})",
    )
    q.add_argument("--json", action="store_true", help=JSON_HELP)
    q.set_defaults(
        func=cmd_diff, files=[("old", IN, "baseline file"), ("new", IN, "file to compare")]
    )
    for q in sub.choices.values():  # `drip-cert CMD ... --debug` works as well as before CMD
        q.add_argument("--debug", action="store_true", default=argparse.SUPPRESS, help=DEBUG_HELP)
        q.add_argument("--quiet", action="store_true", help=QUIET_HELP)
    return p


def _add_simulation_options(q: argparse.ArgumentParser) -> None:
    """``--backend``, ``--scheduler``, ``--policy-dtype`` and ``--dtype`` of the commands that
    simulate."""
    q.add_argument(
        "--backend",
        choices=["local", "processes", "dask"],
        default="local",
        help="where the Monte Carlo runs: threads in this process, one worker process pinned to "
        "each core (a few seconds to start; pays off for long runs), or one task per chunk on "
        "Dask (a LocalCluster unless --scheduler or DASK_SCHEDULER_ADDRESS names one); same "
        "numbers",
    )
    q.add_argument(
        "--scheduler",
        default=None,
        metavar="ADDRESS",
        help="Dask scheduler address (tcp://host:8786) for --backend dask",
    )
    q.add_argument(
        "--policy-dtype",
        choices=["float64", "float32"],
        default="float64",
        help="arithmetic of the learned policy in the simulation (float32: faster, its effect "
        "on the gaps is measured and reported; the certificate stays float64)",
    )
    q.add_argument(
        "--dtype",
        choices=["float64", "float32"],
        default="float64",
        help="arithmetic of the whole simulation: states, noise, vector fields, policy and "
        "L1-DRAC (float32: about 2x faster; its effect on the gaps is measured against float64 "
        "and reported; the certificate stays float64)",
    )


def _progress(args: argparse.Namespace) -> bool:
    """Stage lines (and, on a terminal, progress bars) on stderr: not with ``--json`` or
    ``--quiet``."""
    return not (args.json or args.quiet)


def _backend(args: argparse.Namespace) -> Backend:
    """The :class:`~drip_cert.sim.backend.Backend` of ``--backend`` / ``--scheduler``."""
    return Backend(args.backend, args.scheduler)


def _number_type(
    parse: Callable[[str], Any], ok: Callable[[Any], bool], what: str, bad: str | None = None
) -> Callable[[str], Any]:
    """An argparse ``type``: ``parse(text)``, then ``ok(value)`` or the message "expected
    ``what`` (``bad`` when the value parsed but is out of range), got 'text'"."""

    def convert(text: str) -> Any:
        try:
            v = parse(text)
        except ValueError:
            raise argparse.ArgumentTypeError(f"expected {what}, got {text!r}") from None
        if not ok(v):  # NaN fails every comparison
            raise argparse.ArgumentTypeError(f"expected {bad or what}, got {text!r}")
        return v

    return convert


def _train_method(text: str) -> str:
    from drip_cert.spec.settings import TRAIN_METHODS  # flint: keep off the CLI start-up path

    if text not in TRAIN_METHODS:
        raise argparse.ArgumentTypeError(
            f"unknown method {text!r}; use one of {', '.join(TRAIN_METHODS)}"
        )
    return text


_nonneg_float = _number_type(
    float, lambda v: v >= 0 and v != math.inf, "a number >= 0", "a finite number >= 0"
)
_posfloat = _number_type(
    float, lambda v: v > 0 and math.isfinite(v), "a number > 0", "a finite number > 0"
)
_positive_or_inf = _number_type(float, lambda v: v > 0, "a number > 0 (or inf)")
_posint = _number_type(int, lambda v: v >= 1, "a positive integer")
_nonneg_int = _number_type(int, lambda v: v >= 0, "an integer >= 0")


# ---------------------------------------------------------------------------- files and errors
#: roles of the files a command names (``set_defaults(files=[(dest, role, what), ...])``)
IN, OUT_DIR, FIGURE, OUT_FILE = "input file", "output directory", "figure file", "output file"

DEBUG_HELP = "on an error, also print the traceback (attach it to a bug report)"
QUIET_HELP = (
    "nothing on stderr but warnings and errors: no stage lines, no progress bars (bars are "
    "drawn only when stderr is a terminal anyway)"
)
JSON_HELP = "print JSON on stdout (and no progress on stderr)"
SPEC_HELP = "the TOML specification of the system (docs: the spec reference)"


def check_files(args: argparse.Namespace) -> None:
    """Check every file the command names before any work starts.

    Inputs must be readable regular files; an output directory must be (or be creatable as) a
    writable directory, not an existing file; a figure's directory must exist and be writable
    and its suffix a format matplotlib writes.

    Raises
    ------
    SpecError
        Naming the argument's file and what to give instead (exit status 2).
    """
    from drip_cert.numerics.user_files import (
        input_file,
        output_dir,
        output_file,
    )  # numpy: off the start-up path

    for dest, role, what in getattr(args, "files", ()):
        value = getattr(args, dest, None)
        if value is None:
            continue
        if role == IN:
            input_file(value, what)
        elif role == OUT_DIR:
            output_dir(value, what)
        elif role == OUT_FILE:
            output_file(value, what)
        else:
            _check_figure(output_file(value, what), what)


def _check_figure(path: Path, what: str) -> None:
    suffix = path.suffix.lower().lstrip(".")
    if not suffix:
        raise SpecError(
            f"the {what} {str(path)!r} has no suffix: end it with .png, .pdf or .svg (the "
            "suffix picks the format)"
        )
    from matplotlib.figure import Figure  # matplotlib: only when a figure is asked for

    formats = Figure().canvas.get_supported_filetypes()
    if suffix not in formats:
        raise SpecError(
            f"the {what} {str(path)!r} ends in .{suffix}, which is no image format matplotlib "
            f"writes: use one of {', '.join('.' + f for f in sorted(formats))}"
        )


def _report(kind: str, text: str, exc: BaseException, debug: bool) -> None:
    """The traceback of ``exc`` with ``--debug``, then one line on stderr."""
    if debug:
        traceback.print_exception(exc, file=sys.stderr)
    print(f"drip-cert: {kind}: {' '.join(text.split())}", file=sys.stderr)


def main(argv: Sequence[str] | None = None) -> int:
    """Entry point; returns the exit status (0, 1, 2 or 3: the module docstring)."""
    parser = build_parser()
    args = parser.parse_args(argv)
    debug = bool(getattr(args, "debug", False))
    func: Callable[[argparse.Namespace], int] = args.func
    try:
        check_files(args)
        return func(args)
    except AssumptionViolation as exc:
        _report("not certified", str(exc), exc, debug)
        return 1
    except FingerprintError as exc:  # recorded data of another policy or design: not evidence
        _report("refused", str(exc), exc, debug)
        return 1
    except DripCertError as exc:  # SpecError, InputTypeError, ...: the user's input
        _report("error", str(exc), exc, debug)
        return 2
    except KeyboardInterrupt:
        print("drip-cert: interrupted", file=sys.stderr)
        return 130
    except BrokenPipeError:  # the reader closed stdout (e.g. `| head`): the shell convention
        try:
            sys.stdout = open(os.devnull, "w")  # noqa: SIM115 - silence the flush at exit
        except OSError:
            pass
        return 141
    except OSError as exc:  # the environment: a file that vanished, a full disk, a network
        where = f"{exc.filename}: " if exc.filename else ""
        _report("error", f"{where}{exc.strerror or exc}", exc, debug)
        return 2
    except Exception as exc:  # a bug of drip-cert: one line, the traceback with --debug
        command = " ".join(["drip-cert", *(sys.argv[1:] if argv is None else argv)])
        _report(
            "internal error",
            f"{type(exc).__name__}: {exc}; please report it with the command ({command}) and "
            "its `--debug` output",
            exc,
            debug,
        )
        return 3


def console_main() -> int:
    """The ``drip-cert`` command (``[project.scripts]``; ``python -m drip_cert.cli``):
    :func:`main`, then the process exits without tearing the interpreter down.

    Freeing every module's objects at exit cost a ``certify`` 0.2-0.25 CPU-s (issue 26) and
    changes nothing a user sees. Once :func:`main` has returned, what a normal exit runs that
    matters is run here: the ``atexit`` handlers (``logging.shutdown``, ``weakref.finalize``
    hooks such as a ``TemporaryDirectory``'s cleanup, multiprocessing's), then stdout and
    stderr are flushed, then ``os._exit``. While another non-daemon thread still runs, under a
    tracer or profiler (``python -m cProfile -m drip_cert.cli``), or when :func:`main` raises
    (``SystemExit`` of ``--help`` or of a usage error), the interpreter exits the normal way.
    Tests call :func:`main`, which returns.
    """
    code = main()
    if sys.gettrace() is not None or sys.getprofile() is not None:
        return code  # a debugger, tracer or profiler (cProfile) writes its results at the exit
    if any(
        t.is_alive() and not t.daemon
        for t in threading.enumerate()
        if t is not threading.main_thread()
    ):
        return code  # the interpreter joins the thread first
    atexit._run_exitfuncs()
    try:
        sys.stdout.flush()
    except BrokenPipeError:  # the reader closed stdout (`| head`): the shell convention
        code = 141
    except (OSError, ValueError) as exc:  # a full disk, a closed stream: not a success
        print(f"drip-cert: error: writing the output failed ({exc})", file=sys.stderr)
        code = code or 2
    try:
        sys.stderr.flush()
    except (OSError, ValueError):
        pass
    os._exit(code)


if __name__ == "__main__":  # pragma: no cover
    sys.exit(console_main())
