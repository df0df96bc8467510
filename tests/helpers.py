"""Shared pieces of the test suite: paths, spec texts, systems, tolerances and small helpers.

Everything here is used by more than one test module. Test modules import from
``tests.helpers`` (``tests`` is a package), never from one another, so that the suite runs under
every ``--import-mode`` and from any working directory: every file a test names is a path below
:data:`ROOT`, never one relative to the current directory.
"""

from __future__ import annotations

import importlib.util
import textwrap
from collections.abc import Iterable
from pathlib import Path
from types import ModuleType
from typing import Any

import numpy as np

# ------------------------------------------------------------------------------------ paths

ROOT = Path(__file__).resolve().parents[1]
"""The repository root (the directory holding pyproject.toml)."""

EXAMPLES = ROOT / "examples"

PAPER_4D_SPEC = ROOT / "drip_cert" / "data" / "paper_4d" / "paper_4d.toml"
"""The DRIP paper's 4-D example as shipped in the package (what ``reproduce paper-4d`` runs)."""

DOUBLE_INTEGRATOR_CONSTANTS = EXAMPLES / "l1drac_constants" / "double_integrator.toml"
"""The L1-DRAC constants file of docs/math/l1drac.md section 8 (a ``design-l1`` input, not a
spec)."""


def example_spec(name: str) -> Path:
    """``examples/<name>/<name>.toml``: the spec of one bundled example."""
    return EXAMPLES / name / f"{name}.toml"


def load_script(path: Path, name: str) -> ModuleType:
    """Import, as module ``name``, a script of the repository that is not part of the package
    (``ROOT / "examples" / ...``, ``ROOT / "benchmarks" / ...``)."""
    spec = importlib.util.spec_from_file_location(name, path)
    assert spec is not None and spec.loader is not None, path
    mod = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(mod)
    return mod


# ------------------------------------------------------------------------------- tolerances
# Shared where several modules compare for the same reason; a module names its own otherwise.

CLOSED_FORM_TOL = 1e-12
"""A closed form of O(1) numbers evaluated in float64 (or by LAPACK) against another float64
route: a few hundred ulps at most (linear closed-loop rates and gains, log norms, delta-ISS
gains)."""

REL_CLOSED_FORM = 1e-13
"""Relative agreement of two float64 evaluations of one closed form of L1-DRAC's Appendix A (a
few roundings apart)."""

ROUNDING_ATOL = 1e-14
"""O(1) numbers computed by two float64 routes (numpy vs jax, one order of operations vs
another): a few ulps apart."""

MP_DPS = 50
"""Digits of an mpmath reference value: far beyond the 16 of a float64."""

MC_Z = 4.5
"""Monte-Carlo tolerance in standard errors: a correct sampler fails a check with probability
~7e-6; the seeds are fixed, so a pass is reproducible (the width is what makes the test
meaningful)."""

MC_FIVE_SIGMA = 5.0
"""Five standard errors of a sample mean (or correlation) of seeded draws: a false alarm is a
~6e-7 event for a correct generator, and the draws are fixed by the seed."""

# ------------------------------------------------------------------------------- spec texts


def two_state_spec(name: str = "example", uncertainty: bool = True) -> str:
    """The issue's minimal spec: x1' = x2, x2' = -x1 - x2^3 + u under the expert u = -x1 - 2 x2,
    on the support [-1, 1]^2 (contracting, no blocks). With ``uncertainty`` it carries a small
    drift and diffusion (the shape the issue asks ``check-spec`` to accept); without it, it is
    the bare system the settings tests add one table to."""
    text = f"""
[system]
name = "{name}"
states = ["x1", "x2"]
inputs = ["u1"]
horizon = 10.0
[dynamics]
f = ["x2", "-x1 - x2**3"]
g = [["0"], ["1"]]
[policy]
expert = ["-x1 - 2*x2"]
"""
    if uncertainty:
        text += """[uncertainty]
drift = ["0.1*sin(x1)", "0.1"]
diffusion = [["0.05", "0"], ["0", "0.05"]]
"""
    return text + "[initial]\nsupport = [[-1.0, 1.0], [-1.0, 1.0]]\n"


def write_spec(tmp_path: Path, text: str, name: str = "spec.toml") -> Path:
    """Write a spec text (dedented, so it may be indented inside a test) to ``tmp_path/name``."""
    path = tmp_path / name
    path.write_text(textwrap.dedent(text))
    return path


# --------------------------------------------------------------------------------- the CLI


def run_cli(capsys: Any, *argv: str) -> tuple[int, str, str]:
    """Run ``drip-cert argv...`` in-process: (exit status, stdout, stderr)."""
    from drip_cert.cli import main

    code = main(list(argv))
    out, err = capsys.readouterr()
    return code, out, err


# ---------------------------------------------------------------------------- indexing


def by_name(items: Iterable[Any]) -> dict[str, Any]:
    """Checks (or check results) keyed by their ``name``."""
    return {c.name: c for c in items}


def by_id(items: Iterable[Any]) -> dict[str, Any]:
    """Assumption checks keyed by their ``id`` (e.g. ``"L1DRAC-A7"``, ``"tasil.sharp.b"``)."""
    return {c.id: c for c in items}


def by_eq(items: Iterable[Any]) -> dict[str, Any]:
    """L1-DRAC condition results keyed by their equation (``"16a"`` ... ``"24"``)."""
    return {r.eq: r for r in items}


# ------------------------------------------------------------------ L1-DRAC constant sets


def di_constants():
    """The double-integrator constants of :data:`DOUBLE_INTEGRATOR_CONSTANTS` (docs/math/l1drac.md
    section 8): the worked example every hand computation of L1-DRAC's Appendix A refers to."""
    from drip_cert.bounds.l1drac.toml import load_l1_constants

    return load_l1_constants(DOUBLE_INTEGRATOR_CONSTANTS)[0]


def random_constants(rng: np.random.Generator, **fixed: float):
    """Random L1-DRAC constants with every one positive (so that every term of Appendix A is
    exercised) and Assumption 7 kept (lambda >= 4 > Delta_g_perp * max(...), each below 2);
    ``fixed`` overrides single constants."""
    from drip_cert.bounds.l1drac.constants import CONSTANT_NAMES, L1Constants

    d: dict = {}
    for n in CONSTANT_NAMES:
        if n in ("p_star", "m"):
            d[n] = int(rng.integers(1, 5))
        elif n == "lip_f":
            d[n] = bool(rng.integers(0, 2))
        else:
            d[n] = float(rng.uniform(0.1, 2.0))
    d["lambda"] = float(rng.uniform(4.0, 20.0))  # >= 4 > Delta_g_perp * max(...), each < 2
    d["p_star"] = 8
    d.update(fixed)
    return L1Constants.from_mapping(d)


# ------------------------------------------------------------- the paper-like 4-D system
# x' = -0.05 x - 0.25 h(x) + 0.25 u with h a seeded tanh 4-16-4 MLP: the shape of the DRIP
# paper's example, small enough to train on in seconds. The expert u = -0.2 x + h(x) cancels h,
# so its closed loop is x' = -0.1 x (a closed form the integrators are checked against).


def _paper_like_h_mlp():
    from drip_cert.model.mlp import init_mlp

    return init_mlp((4, 16, 4), np.random.default_rng(12345), "tanh")


PAPER_LIKE_H_MLP = _paper_like_h_mlp()
"""The seeded tanh 4-16-4 MLP h of the paper-like system."""

PAPER_LIKE_BOX = np.array([[-1.0, 1.0]] * 4)
"""The support of the initial states of the paper-like system: [-1, 1]^4."""


def paper_like_h(x):
    """h(x), evaluated with jax."""
    return PAPER_LIKE_H_MLP.apply_jax(x)


def paper_like_field(t, x, u):
    """The paper-like 4-D example: x' = -0.05 x - 0.25 h(x) + 0.25 u."""
    return -0.05 * x - 0.25 * paper_like_h(x) + 0.25 * u


def paper_like_expert(x):
    """u = -0.2 x + h(x): cancels h; the expert closed loop is x' = -0.1 x."""
    return -0.2 * x + paper_like_h(x)
