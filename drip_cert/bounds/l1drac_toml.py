"""TOML input of the L1-DRAC calculator (``drip-cert design-l1 CONSTANTS.toml``).

File format (two flat tables, nothing else)::

    [constants]          # every name of drip_cert.bounds.l1drac.CONSTANT_NAMES, exactly once
    lambda = 10.0        # Assumption 2 ('lambda' in the file, ``lam`` in Python)
    Delta_f = 10.0
    ...                  # reals >= 0 (write 0 for an absent term)
    p_star = 8           # integers >= 1: p_star, m
    m = 1
    lip_f = true         # Assumption 8 holds
    alpha = 0.5          # initial distance (18a)
    eps_r = 0.01         # slacks of (16a), (16b), > 0
    eps_a = 0.01

    [design]
    p = 1                # required, integer in 1..p_star
    lambda_s = 100.0     # required, predictor pole > 0
    omega = 1000.0       # optional: filter bandwidth (omitted = minimise rho over omega)
    Ts = 1e-8            # optional: sampling period (omitted = the largest satisfying (24))
    rho_r = 2.1          # optional radii (omitted = the smallest satisfying (16), (21), (24))
    rho_a = 1.0
    delta = 1e-3         # optional: report kappa (130a)
    omega_min = 0.01     # optional: search interval of omega when omega is omitted
    omega_max = 1e8

Every mistake (unknown or missing key, wrong type, NaN/inf, negative value) raises
:class:`~drip_cert.errors.SpecError` naming the file, the field, the value and the fix. A failing
Assumption 7 raises :class:`~drip_cert.errors.AssumptionViolation` (exit status 1 in the CLI).
"""

from __future__ import annotations

import math
import numbers
import tomllib
from dataclasses import dataclass
from pathlib import Path
from typing import Any

from drip_cert.bounds.l1drac import (
    DesignRequest,
    L1Constants,
    L1Design,
    design,
)
from drip_cert.errors import SpecError

__all__ = ["DESIGN_KEYS", "load_l1_constants", "design_from_request", "design_l1_report"]

#: Keys of the [design] table: (name, required).
DESIGN_KEYS: tuple[tuple[str, bool], ...] = (
    ("p", True),
    ("lambda_s", True),
    ("omega", False),
    ("Ts", False),
    ("rho_r", False),
    ("rho_a", False),
    ("delta", False),
    ("omega_min", False),
    ("omega_max", False),
)


@dataclass(frozen=True)
class _Where:
    path: str

    def err(self, msg: str, field: str) -> SpecError:
        return SpecError(msg, field=field, path=self.path)


def _design_request(table: Any, where: _Where) -> DesignRequest:
    if not isinstance(table, dict):
        raise where.err("[design] must be a table", "design")
    allowed = [k for k, _ in DESIGN_KEYS]
    unknown = sorted(set(table) - set(allowed))
    if unknown:
        raise where.err(
            f"unknown key(s) {unknown} in [design]; allowed: {allowed}", "design." + unknown[0]
        )
    for key, required in DESIGN_KEYS:
        if required and key not in table:
            raise where.err(
                f"missing; [design] needs {key} (p: the moment order 1..p_star; lambda_s: the "
                "predictor pole > 0)",
                "design." + key,
            )
    values: dict[str, Any] = {}
    for key, _ in DESIGN_KEYS:
        if key not in table:
            continue
        v = table[key]
        if key == "p":
            if isinstance(v, bool) or not isinstance(v, int):
                raise where.err(
                    f"{v!r} is not an integer; give the moment order 1..p_star", "design.p"
                )
            if v < 1:
                raise where.err(f"{v!r} must be an integer >= 1", "design.p")
            values[key] = v
            continue
        if isinstance(v, bool) or not isinstance(v, numbers.Real):
            raise where.err(f"{v!r} is not a number; give a positive real", "design." + key)
        v = float(v)
        if not math.isfinite(v) or not v > 0.0:
            raise where.err(f"{v!r} must be a finite number > 0", "design." + key)
        if key == "delta" and not v < 1.0:
            raise where.err(f"{v!r} is not a probability in (0, 1); give e.g. 1e-3", "design.delta")
        values[key] = v
    bounds = None
    if "omega_min" in values or "omega_max" in values:
        if not ("omega_min" in values and "omega_max" in values):
            raise where.err("give both omega_min and omega_max, or neither", "design.omega_min")
        if not values["omega_min"] < values["omega_max"]:
            raise where.err(
                f"omega_min = {values['omega_min']!r} must be < omega_max = "
                f"{values['omega_max']!r}",
                "design.omega_min",
            )
        bounds = (values.pop("omega_min"), values.pop("omega_max"))
    try:
        return DesignRequest(omega_bounds=bounds, **values)
    except SpecError as e:  # re-raise with the file name
        raise where.err(str(e), e.field or "design") from None


def load_l1_constants(path: str | Path) -> tuple[L1Constants, DesignRequest]:
    """Read a constants file: ``[constants]`` (the paper's constants) and ``[design]``.

    Returns
    -------
    (L1Constants, DesignRequest)

    Raises
    ------
    SpecError
        Unreadable file, TOML syntax, unknown/missing tables or keys, wrong types, NaN/inf,
        negative values, p > p_star; the message names the file and the field.
    AssumptionViolation
        Assumption 7 fails for the given constants.
    """
    where = _Where(str(path))
    try:
        with open(path, "rb") as fh:
            data = tomllib.load(fh)
    except OSError as e:
        raise where.err(f"cannot read the file ({e.strerror}); check the path", "file") from None
    except tomllib.TOMLDecodeError as e:
        raise where.err(f"not valid TOML: {e}", "file") from None
    unknown = sorted(set(data) - {"constants", "design"})
    if unknown:
        raise where.err(
            f"unknown table(s) {unknown}; the file has exactly [constants] and [design]",
            unknown[0],
        )
    for t in ("constants", "design"):
        if t not in data:
            raise where.err(f"missing table [{t}]", t)
    if not isinstance(data["constants"], dict):
        raise where.err("[constants] must be a table", "constants")
    for k, v in data["constants"].items():
        if isinstance(v, dict | list):
            raise where.err(
                f"{v!r} is not a scalar; [constants] is one flat table", "constants." + k
            )
    try:
        consts = L1Constants.from_mapping(data["constants"], path=str(path))
    except SpecError as e:
        if e.path is None:
            raise where.err(str(e), "constants." + (e.field or "")) from None
        raise
    req = _design_request(data["design"], where)
    if req.p > consts.p_star:
        raise where.err(
            f"p = {req.p} exceeds p_star = {consts.p_star} (Assumption 1): use p <= p_star",
            "design.p",
        )
    if req.omega is not None and req.omega == 2.0 * consts.lam:
        raise where.err(
            f"omega = {req.omega!r} equals 2*lambda, where every |2 lambda - omega| term of "
            "(18b), (18c), (21), (24) divides by zero; choose another omega",
            "design.omega",
        )
    return consts, req


def design_from_request(consts: L1Constants, request: DesignRequest) -> L1Design:
    """Run the designer (:func:`drip_cert.bounds.l1drac.design`) on a loaded request."""
    return design(consts, request)


def design_l1_report(path: str | Path) -> dict[str, Any]:
    """Load ``path``, design, and return the JSON-ready report the CLI prints.

    Keys: those of :meth:`L1Design.to_dict` (``feasible`` decides the exit status: 0 if true,
    1 if false; it is true only when every condition is verified in Arb ball arithmetic, see
    ``verified``, ``backoff`` and each condition's ``margin_lo`` / ``margin_hi``) plus ``file``,
    ``constants`` and ``request``. Bad input raises SpecError (exit 2).
    """
    consts, req = load_l1_constants(path)
    d = design_from_request(consts, req)
    out = d.to_dict()
    out["file"] = str(path)
    out["constants"] = consts.to_dict()
    out["request"] = {
        "p": req.p,
        "lambda_s": req.lambda_s,
        "omega": req.omega,
        "Ts": req.Ts,
        "rho_r": req.rho_r,
        "rho_a": req.rho_a,
        "delta": req.delta,
        "omega_bounds": None if req.omega_bounds is None else list(req.omega_bounds),
    }
    return out
