"""TOML specifications: :func:`load_spec` reads a file into a :class:`Spec` (a System + settings).

The format (documented in the README) has the sections ``[system]``, ``[dynamics]``
(expressions ``f``, ``g`` or a linear model ``A``, ``B``), ``[policy]`` (an expert as
expressions, as a gain ``{ K = [[...]] }`` or ``"lqr"`` with ``[policy.lqr]``: see
:mod:`drip_cert.spec.linear`), ``[blocks.NAME]``, ``[uncertainty]``, ``[initial]``, and the
optional settings tables ``[constants]`` (user-given values of paper constants),
``[contraction]``, ``[l1drac]``, ``[tasil]`` and ``[simulation]``, each read into its typed
settings object of :mod:`drip_cert.spec.settings` when the spec is loaded (``spec.settings``),
so that a bad value or an unknown key is found before anything is computed. Every problem is a
:class:`~drip_cert.errors.SpecError` naming the file, the field and the fix.
"""

from __future__ import annotations

import difflib
import math
import os
import tomllib
from collections.abc import Mapping
from dataclasses import InitVar, dataclass, replace
from pathlib import Path
from types import MappingProxyType
from typing import Any

import numpy as np
import sympy as sp

from drip_cert.errors import InputTypeError, SpecError
from drip_cert.model.blocks import Block, load_mlp_block
from drip_cert.model.expr import CONSTANTS, FUNCTIONS, parse_expression
from drip_cert.model.literals import DecimalFloat
from drip_cert.model.system import System, box_image
from drip_cert.numerics.user_files import input_file, reading
from drip_cert.spec.linear import ExpertGain, gain_expert, linear_dynamics, linearise, lqr_expert
from drip_cert.spec.settings import TABLES, Settings, toml_text

#: Every section of a spec with its keys and their meanings (``None``: a table of tables, or a
#: settings table whose keys are declared in :mod:`drip_cert.spec.settings`). The one
#: declaration of these keys: the loader's checks and the spec reference read it.
SECTIONS: Mapping[str, Mapping[str, str] | None] = MappingProxyType(
    {
        "system": {
            "name": "name of the system (reports, file names)",
            "states": "names of the state variables, in order",
            "inputs": "names of the inputs (default u1..um)",
            "horizon": "horizon T of the guarantee (seconds)",
            "time": 'name of time in expressions (default "t")',
            "brownian_dim": "dimension d of the Brownian motion (default: columns of the "
            "diffusion, else n)",
        },
        "dynamics": {
            "f": "known drift f(t, x), without the policy: one expression per state",
            "g": "input matrix g(t, x), n x m expressions",
            "A": "linear model f = A x (numbers, n x n), instead of f",
            "B": "linear model g = B (numbers, n x m), instead of g",
            "diffusion": "known diffusion p(t, x), n x d expressions (optional)",
        },
        "policy": {
            "expert": 'the expert pi*: expressions (m), a gain { K = [[...]] } or "lqr"',
            "learned": "the learned policy pi_IL: expressions (m), usually of a block",
            "lqr": "[policy.lqr]: Q and R of the LQR expert",
            "structure": "known part of the residual policy class (m expressions)",
        },
        "blocks": None,  # table of tables, checked per block (BLOCK_KEYS)
        "uncertainty": {
            "drift": "uncertain drift Lambda_mu(t, x): n expressions",
            "diffusion": "uncertain diffusion Lambda_sigma(t, x): n x d expressions",
            "Delta_mu": "a growth bound of the uncertain drift instead of expressions",
            "Delta_sigma": "a growth bound of the uncertain diffusion instead of expressions",
        },
        "initial": {
            "support": "box supporting the initial law D: [[lo, hi], ...] per state",
            "true_support": "box supporting the true initial law D_bar (default D)",
        },
        # the settings tables: checked key by key by drip_cert.spec.settings
        "constants": None,
        "contraction": None,
        "l1drac": None,
        "tasil": None,
        "simulation": None,
    }
)
BLOCK_KEYS: Mapping[str, str] = MappingProxyType(
    {
        "kind": 'the kind of block: "mlp" (the default and only kind)',
        "weights": "the network file: .onnx, .safetensors or .npz, relative to the spec",
        "inputs": "input dimension (read from an .onnx graph; checked when given)",
        "outputs": "output dimension (read from an .onnx graph; checked when given)",
        "activation": 'activation of the hidden layers ("relu", "tanh", ...) or a list with '
        "one entry per layer, the output layer included",
    }
)
REQUIRED = {
    "system": {"name", "states", "horizon"},
    "dynamics": set(),  # f and g, or A and B: checked by _dynamics_form
    "policy": {"expert"},
    "initial": {"support"},
}


@dataclass(frozen=True, eq=False)
class Spec:
    """A loaded specification: the :class:`System` and its typed, validated ``settings`` (the one
    source of truth of every settings table), and ``expert_gain``: how a linear expert
    ``u = -K x`` was given (``{ K = ... }`` or ``"lqr"``, with ``Q``, ``R`` and the closed-loop
    eigenvalues; ``None`` for an expert written as expressions).

    ``tables`` (construction only, not stored): raw settings tables as TOML gives them, read into
    ``settings`` when ``settings`` is not given; ``Spec(None, system)`` has the defaults. A
    variant of a spec is made from its settings (``dataclasses.replace(spec.settings, ...)`` and
    :meth:`with_settings`), never by editing tables and reading them again.
    """

    path: Path | None
    system: System
    tables: InitVar[Mapping[str, Mapping[str, Any]] | None] = None
    settings: Settings = None  # type: ignore[assignment]  # built in __post_init__
    expert_gain: ExpertGain | None = None
    structure: tuple[sp.Expr, ...] | None = None  #: [policy] structure (residual policy class)
    structure_text: tuple[str, ...] | None = None  #: the same, as written in the spec

    def __post_init__(self, tables: Mapping[str, Mapping[str, Any]] | None) -> None:
        if self.settings is None:
            settings = Settings.from_tables(
                tables or {},
                self.system.n,
                path=None if self.path is None else str(self.path),
                support=self.system.support,
            )
            object.__setattr__(self, "settings", settings)
        elif tables is not None:
            raise SpecError("give a Spec either settings or tables, not both")

    @property
    def notes(self) -> tuple[str, ...]:
        """Lines a report should carry about how the spec defined the system (the origin of a
        gain expert: given K, or LQR with its Q, R and closed-loop eigenvalues)."""
        return () if self.expert_gain is None else (self.expert_gain.note,)

    def with_settings(self, settings: Settings) -> Spec:
        """The same spec with other (already validated) settings."""
        return replace(self, settings=settings)

    def in_coordinates(self, theta: Any) -> Spec:
        """The equivalent spec in ``z = Theta x`` (a constant invertible ``Theta``, numbers taken
        as the exact rationals they store): the system transformed exactly
        (:meth:`System.transformed`), the contraction region mapped to the box enclosing its
        image, and the analysis asked for in those coordinates as they are (``metric =
        "euclidean"``: ``z`` already is the metric's coordinates). ``expert_gain`` keeps its note
        about ``x``."""
        Th = sp.Matrix(np.asarray(theta).tolist()).applyfunc(sp.Rational)
        zsys = self.system.transformed(theta)
        c = self.settings.contraction
        region = None if c.region is None else box_image(Th, c.region)
        contraction = replace(c, region=region, metric=False, coordinates="euclidean", P=None)
        return replace(self, system=zsys, settings=replace(self.settings, contraction=contraction))

    def with_system(self, system: System) -> Spec:
        """The same spec (file, tables, settings) with another system (e.g. with a learned
        policy); the state dimension and the support must not change."""
        if system.n != self.system.n or tuple(system.support) != tuple(self.system.support):
            raise SpecError(
                "with_system keeps the settings of the spec: the new system must have the same "
                "states and support"
            )
        return replace(self, system=system)

    @property
    def base_dir(self) -> Path:
        return self.path.parent if self.path is not None else Path.cwd()


SpecSource = str | os.PathLike[str] | Spec | System
"""What :func:`as_spec` (and every API function built on it) accepts: a spec file's path, a
:class:`Spec`, or a bare :class:`~drip_cert.model.system.System` (default settings)."""


def as_spec(source: SpecSource, *, argument: str = "spec", also: str | None = None) -> Spec:
    """The :class:`Spec` of a spec file's path, a :class:`Spec` or a :class:`System`.

    The one conversion behind :func:`load_spec`, :func:`~drip_cert.bounds.certificate.certify`,
    :func:`~drip_cert.validate.validate`, the deploy functions and the workflows: each accepts
    the three forms alike.

    Parameters
    ----------
    source
        A path (``str`` or :class:`os.PathLike`) of a TOML spec (loaded and validated), a
        :class:`Spec` (returned as is) or a :class:`System` (wrapped with default settings:
        ``Spec(None, system)``).
    argument
        The parameter's name, for the message of a wrong type.
    also
        Another type the caller accepts (handled before calling this), for that message.

    Raises
    ------
    InputTypeError
        ``source`` is none of these (a :class:`TypeError` too).
    SpecError
        The file is missing, unreadable or invalid (naming the file, the field and the fix).
    """
    if isinstance(source, Spec):
        return source
    if isinstance(source, System):
        return Spec(None, source)
    if isinstance(source, str | os.PathLike):
        return _load_file(Path(source))
    shown = repr(source)
    if len(shown) > 60:
        shown = shown[:57] + "..."
    accepted = [
        "a spec file's path (str or pathlib.Path)",
        "a drip_cert.Spec",
        "a drip_cert.System",
    ]
    if also:
        accepted.append(also)
    raise InputTypeError(
        f"{argument}: expected {', '.join(accepted[:-1])} or {accepted[-1]}, got "
        f"{type(source).__name__} {shown}"
    )


def load_spec(path: SpecSource) -> Spec:
    """Load and validate a TOML specification.

    Parameters
    ----------
    path
        The ``.toml`` file (``str`` or :class:`os.PathLike`). Relative paths inside it (weights
        files) are relative to its folder. A :class:`Spec` or a :class:`System` is accepted
        too (:func:`as_spec`).

    Raises
    ------
    SpecError
        Naming the file, the field, the offending value and what is allowed.
    InputTypeError
        ``path`` is not a path, a Spec or a System.
    """
    return as_spec(path, argument="path")


def _load_file(path: Path) -> Spec:
    spath = str(path)
    input_file(path, "specification file")
    try:
        with path.open("rb") as fh:
            doc = tomllib.load(fh, parse_float=DecimalFloat)  # floats keep their text
    except tomllib.TOMLDecodeError as exc:
        raise SpecError(f"not valid TOML: {exc}", path=spath) from None
    except (OSError, UnicodeDecodeError) as exc:
        raise SpecError(f"cannot read the file: {exc}", path=spath) from None
    with reading(path, "specification file"):
        return spec_from_dict(doc, path=path)


def spec_from_dict(doc: Mapping[str, Any], path: Path | None = None) -> Spec:
    """Build a :class:`Spec` from an already parsed TOML document."""
    spath = None if path is None else str(path)
    base = path.parent if path is not None else Path.cwd()

    def err(msg: str, fld: str) -> SpecError:
        return SpecError(msg, field=fld, path=spath)

    for sec, val in doc.items():
        if sec not in SECTIONS:
            raise err(
                f"unknown section [{sec}]{_did_you_mean(sec, SECTIONS)}; allowed: "
                + ", ".join(f"[{s}]" for s in SECTIONS),
                sec,
            )
        if not isinstance(val, dict):
            raise err(f"[{sec}] must be a table", sec)
        keys = SECTIONS[sec]
        if keys is not None:
            extra = set(val) - set(keys)
            if extra:
                first = sorted(extra)[0]
                raise err(
                    f"unknown key(s) {sorted(extra)} in [{sec}]{_did_you_mean(first, keys)}; "
                    "allowed: " + ", ".join(keys),
                    f"{sec}.{first}",
                )
    for sec, req in REQUIRED.items():
        if sec not in doc:
            raise err(f"missing section [{sec}] (it needs {sorted(req)})", sec)
        missing = req - set(doc[sec])
        if missing:
            raise err(f"missing key(s) {sorted(missing)} in [{sec}]", f"{sec}.{sorted(missing)[0]}")

    sysd = doc["system"]
    name = sysd["name"]
    if not isinstance(name, str) or not name.strip():
        raise err("must be a non-empty string", "system.name")
    state_names = _names(sysd["states"], "system.states", err)
    tname = sysd.get("time", "t")
    if not isinstance(tname, str) or not tname.isidentifier():
        raise err(f"must be an identifier, got {tname!r}", "system.time")
    reserved = set(FUNCTIONS) | set(CONSTANTS) | {"norm", tname}
    for s in state_names:
        if s in reserved:
            raise err(_reserved_clash("state", s, tname), "system.states")
    t = sp.Symbol(tname, real=True)
    states = tuple(sp.Symbol(s, real=True) for s in state_names)
    n = len(states)

    blocks: dict[str, Block] = {}
    for bname, bdef in doc.get("blocks", {}).items():
        fld = f"blocks.{bname}"
        if not isinstance(bdef, dict):
            raise err("must be a table with kind, weights, inputs, outputs", fld)
        extra = set(bdef) - set(BLOCK_KEYS)
        if extra:
            first = sorted(extra)[0]
            raise err(
                f"unknown key(s) {sorted(extra)}{_did_you_mean(first, BLOCK_KEYS)}; allowed: "
                f"{sorted(BLOCK_KEYS)}",
                f"{fld}.{first}",
            )
        if bname in state_names:
            raise err(f"block name {bname!r} is also a state name: rename the block", fld)
        if bname in reserved:
            raise err(_reserved_clash("block", bname, tname), fld)
        kind = bdef.get("kind", "mlp")
        if kind != "mlp":
            raise err(f'kind {kind!r} is not supported; use kind = "mlp"', f"{fld}.kind")
        if "weights" not in bdef:
            raise err(
                "missing key 'weights' (a .onnx, .safetensors or .npz file)", f"{fld}.weights"
            )
        weights = bdef["weights"]
        if not isinstance(weights, str):
            raise err("must be a path string", f"{fld}.weights")
        wpath = Path(weights)
        if not wpath.is_absolute():
            wpath = base / wpath
            if not wpath.exists() and Path(weights).is_file():  # relative to the cwd, not the spec
                raise err(
                    f"weights file {str(wpath)!r} does not exist: a path in a spec is relative "
                    f"to the spec's directory {str(base)!r}, and {weights!r} is relative to the "
                    f"current directory: write weights = {str(Path(weights).absolute())!r} or "
                    "the path from the spec's directory",
                    f"{fld}.weights",
                )
        # optional: read from the network (checked against it when given)
        ins = _posint(bdef["inputs"], f"{fld}.inputs", err) if "inputs" in bdef else None
        outs = _posint(bdef["outputs"], f"{fld}.outputs", err) if "outputs" in bdef else None
        act = bdef.get("activation")
        if act is not None and not (
            isinstance(act, str) or (isinstance(act, list) and all(isinstance(a, str) for a in act))
        ):
            raise err(
                "must be a name (hidden layers, affine output) or a list of names, one per "
                'layer with the output layer included, e.g. ["relu", "relu", "identity"]',
                f"{fld}.activation",
            )
        try:
            blocks[bname] = load_mlp_block(bname, wpath, ins, outs, act, field=f"{fld}.weights")
        except SpecError as exc:
            raise SpecError(str(exc), path=spath) from None

    scalars = {str(s): s for s in states}
    scalars[tname] = t
    vec_name = "x" if "x" not in state_names else None

    raw_inputs = sysd.get("inputs")
    input_names = (
        [u for u in raw_inputs if isinstance(u, str)] if isinstance(raw_inputs, list) else []
    )
    input_hint = (
        "it names an input; the dynamics are f + g u: write the input's coefficients into its "
        "column of g, not into an expression"
    )
    time_hint = (
        f"a policy is a function of the state only, u = pi(x); move a feed-forward term c({tname}) "
        f"into [dynamics] f (add g * c({tname}) to f), where {tname!r} is allowed"
    )

    def parse(text: Any, fld: str, allow_t: bool = True) -> sp.Expr:
        sc = scalars if allow_t else {k: v for k, v in scalars.items() if k != tname}
        hints = {u: input_hint for u in input_names if u not in sc}
        if not allow_t:
            hints[tname] = time_hint
        return parse_expression(
            text,
            field=fld,
            scalars=sc,
            vector_name=vec_name,
            vector=states,
            blocks=blocks,
            path=spath,
            hints=hints,
        )

    def vector(val: Any, fld: str, length: int | None, allow_t: bool = True) -> list[sp.Expr]:
        if not isinstance(val, list) or not val:
            raise err("must be a non-empty list of expressions", fld)
        if length is not None and len(val) != length:
            raise err(f"must have {length} entries (one per state/input), got {len(val)}", fld)
        return [parse(v, f"{fld}[{i}]", allow_t) for i, v in enumerate(val)]

    def matrix(val: Any, fld: str, rows: int) -> list[list[sp.Expr]]:
        if not isinstance(val, list) or len(val) != rows:
            raise err(f"must be a list of {rows} rows", fld)
        out = []
        width = None
        for i, row in enumerate(val):
            if not isinstance(row, list) or not row:
                raise err(f"row {i} must be a non-empty list", f"{fld}[{i}]")
            if width is None:
                width = len(row)
            elif len(row) != width:
                raise err(f"row {i} has {len(row)} entries, row 0 has {width}", f"{fld}[{i}]")
            prow = []
            for j, v in enumerate(row):
                prow.append(parse(v, f"{fld}[{i}][{j}]"))
            out.append(prow)
        return out

    dyn = doc["dynamics"]
    linear_model = None
    if _dynamics_form(dyn, err) == "linear":
        f, g, A_lin, B_lin = linear_dynamics(dyn, n, states, spath)
        linear_model = (A_lin, B_lin)
    else:
        f = vector(dyn["f"], "dynamics.f", n)
        g = matrix(dyn["g"], "dynamics.g", n)
    m = len(g[0])
    diffusion = matrix(dyn["diffusion"], "dynamics.diffusion", n) if "diffusion" in dyn else None
    pol = doc["policy"]
    expert_val = pol["expert"]
    expert_gain = None
    if "lqr" in pol and expert_val != "lqr":
        raise err(
            f"the table [policy.lqr] is given but expert = {toml_text(expert_val)}; write "
            'expert = "lqr" to use it, or remove [policy.lqr]',
            "policy.lqr",
        )

    def design() -> tuple[Any, Any, bool]:
        """The linear model the gain is designed on / checked against: (A, B, linearised)."""
        if linear_model is not None:
            return (*linear_model, False)
        return (*linearise(f, g, states, t, spath), True)

    if isinstance(expert_val, list):
        expert = vector(expert_val, "policy.expert", m, allow_t=False)
    elif isinstance(expert_val, dict):
        try:
            model = design()
        except SpecError:
            model = None  # a given K needs no linearisation: no closed-loop poles to record
        expert, expert_gain = gain_expert(expert_val, m, states, model, spath)
    elif expert_val == "lqr":
        expert, expert_gain = lqr_expert(pol.get("lqr"), states, design(), spath)
    else:
        raise err(
            f"expert = {toml_text(expert_val)} is not allowed: the expert must be a list of {m} "
            f"expression(s) (one per input), a gain expert = {{ K = [[...]] }} ({m} x {n}, "
            'u = -K x) or expert = "lqr" with a table [policy.lqr] holding Q and R',
            "policy.expert",
        )
    learned = (
        vector(pol["learned"], "policy.learned", m, allow_t=False) if "learned" in pol else None
    )
    structure = (
        tuple(vector(pol["structure"], "policy.structure", m, allow_t=False))
        if "structure" in pol
        else None
    )
    inputs = sysd.get("inputs")
    if inputs is not None:
        inputs = _names(inputs, "system.inputs", err)
        if len(inputs) != m:
            raise err(f"{len(inputs)} input names but g has {m} columns", "system.inputs")

    unc = doc.get("uncertainty", {})
    lam_mu = vector(unc["drift"], "uncertainty.drift", n) if "drift" in unc else None
    lam_sigma = matrix(unc["diffusion"], "uncertainty.diffusion", n) if "diffusion" in unc else None
    deltas = {}
    for key in ("Delta_mu", "Delta_sigma"):
        if key in unc:
            deltas[key] = _nonneg(unc[key], f"uncertainty.{key}", err)
    if lam_mu is not None and "Delta_mu" in deltas:
        raise err("give either the drift expressions or Delta_mu, not both", "uncertainty.Delta_mu")
    if lam_sigma is not None and "Delta_sigma" in deltas:
        raise err(
            "give either the diffusion expressions or Delta_sigma, not both",
            "uncertainty.Delta_sigma",
        )
    bdim = sysd.get("brownian_dim")
    if bdim is not None:
        bdim = _posint(bdim, "system.brownian_dim", err)
    widths = {len(mat[0]) for mat in (diffusion, lam_sigma) if mat is not None}
    if len(widths) > 1:
        raise err(
            f"dynamics.diffusion and uncertainty.diffusion have different column counts "
            f"{sorted(widths)}; both must be n x d",
            "uncertainty.diffusion",
        )
    if bdim is not None and widths and bdim not in widths:
        raise err(
            f"brownian_dim = {bdim} but the diffusion matrices have {widths.pop()} columns",
            "system.brownian_dim",
        )

    init = doc["initial"]
    horizon = sysd["horizon"]
    if (
        isinstance(horizon, bool)
        or not isinstance(horizon, int | float)
        or not math.isfinite(float(horizon))
        or float(horizon) <= 0
    ):
        raise err(f"the horizon must be a finite number > 0, got {horizon!r}", "system.horizon")
    try:
        system = System(
            name=name.strip(),
            states=states,
            f=f,
            g=g,
            expert=expert,
            support=init["support"],
            horizon=float(horizon),
            t=t,
            inputs=inputs or (),
            learned=learned,
            diffusion=diffusion,
            lambda_mu=lam_mu,
            lambda_sigma=lam_sigma,
            Delta_mu=deltas.get("Delta_mu"),
            Delta_sigma=deltas.get("Delta_sigma"),
            brownian_dim=bdim,
            true_support=init.get("true_support"),
            blocks=blocks,
        )
    except SpecError as exc:
        raise SpecError(str(exc), path=spath) from None
    tables = MappingProxyType({k: MappingProxyType(dict(doc[k])) for k in TABLES if k in doc})
    settings = Settings.from_tables(tables, n, path=spath, support=system.support)
    if structure is not None and settings.tasil.architecture != "residual":
        raise SpecError(
            "[policy] structure is the known part of a residual policy: it is used only with "
            '[tasil] architecture = "residual"; add that line or remove structure',
            field="policy.structure",
            path=spath,
        )
    return Spec(
        path=path,
        system=system,
        settings=settings,
        expert_gain=expert_gain,
        structure=structure,
        structure_text=None if structure is None else tuple(str(e) for e in pol["structure"]),
    )


def _did_you_mean(name: str, known: Any) -> str:
    """``" (did you mean 'support'?)"`` for the closest of ``known``, or ``""``."""
    close = difflib.get_close_matches(name, sorted(known), n=1, cutoff=0.6)
    return f" (did you mean {close[0]!r}?)" if close else ""


def _reserved_clash(kind: str, name: str, tname: str) -> str:
    """The message of a state or block named like a function, a constant or the time."""
    if name == tname:
        what = "the time variable ([system] time, default 't')"
        fix = (
            f'rename the {kind}, or name the time otherwise with [system] time = "tau"'
            if kind == "state"
            else f"rename the {kind}"
        )
    elif name in CONSTANTS:
        what, fix = f"the constant {name}", f"rename the {kind}"
    else:
        what, fix = f"the function {name}()", f"rename the {kind}"
    return (
        f"{kind} name {name!r} clashes with the reserved name {name!r} ({what}): {fix}; "
        f"reserved: {', '.join(sorted(set(FUNCTIONS) | set(CONSTANTS) | {'norm', tname}))}"
    )


def _dynamics_form(dyn: Mapping[str, Any], err) -> str:
    """``"expressions"`` (f, g) or ``"linear"`` (A, B); both, or half of one, is an error."""
    expr_keys = sorted({"f", "g"} & set(dyn))
    lin_keys = sorted({"A", "B"} & set(dyn))
    if expr_keys and lin_keys:
        raise err(
            f"[dynamics] gives both {expr_keys} (expressions) and {lin_keys} (a linear model); "
            "write the dynamics either as f, g or as A, B (f = A x, g = B), not both: remove "
            + ", ".join(lin_keys)
            + " or "
            + ", ".join(expr_keys),
            f"dynamics.{lin_keys[0]}",
        )
    if lin_keys:
        if len(lin_keys) < 2:
            other = "B" if lin_keys == ["A"] else "A"
            raise err(
                f"missing key(s) ['{other}'] in [dynamics]: a linear model needs both A (n x n) "
                "and B (n x m)",
                f"dynamics.{other}",
            )
        return "linear"
    missing = sorted({"f", "g"} - set(expr_keys))
    if missing:
        hint = " (or a linear model: A and B)" if not expr_keys else ""
        raise err(f"missing key(s) {missing} in [dynamics]{hint}", f"dynamics.{missing[0]}")
    return "expressions"


def _names(val: Any, fld: str, err) -> list[str]:
    if not isinstance(val, list) or not val:
        raise err("must be a non-empty list of names", fld)
    out = []
    for i, v in enumerate(val):
        if not isinstance(v, str) or not v.isidentifier() or v.startswith("_"):
            raise err(f"entry {i} ({v!r}) must be an identifier not starting with '_'", fld)
        out.append(v)
    if len(set(out)) != len(out):
        raise err("names must be distinct", fld)
    return out


def _posint(val: Any, fld: str, err) -> int:
    if isinstance(val, bool) or not isinstance(val, int) or val < 1:
        raise err(f"must be a positive integer, got {val!r}", fld)
    return int(val)


def _nonneg(val: Any, fld: str, err) -> float:
    if isinstance(val, bool) or not isinstance(val, int | float):
        raise err(f"must be a number, got {val!r}", fld)
    x = float(val)
    if not math.isfinite(x) or x < 0:
        raise err(f"must be a finite number >= 0, got {val!r}", fld)
    return x
