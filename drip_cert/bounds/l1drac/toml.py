"""TOML input of the L1-DRAC calculator (``drip-cert design-l1 CONSTANTS.toml``).

File format (two flat tables, nothing else)::

    [constants]          # every name of l1drac.constants.CONSTANT_NAMES, exactly once
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
    rho_budget = 50.0    # optional: the largest acceptable rho (objective "Ts_at_rho")
    objective = "default"  # optional: "default", "rho_at_Ts", "Ts_at_rho", "min_rho"
                         # (omitted: "rho_at_Ts" with Ts, "Ts_at_rho" with rho_budget, else
                         # "default" = the smallest rho at Ts = 1e-3 s, else the largest Ts of
                         # the (Ts, rho) front that is not a knife edge)
    front = true         # optional: compute the (Ts, rho) Pareto front (default true)

Every mistake (unknown or missing key, wrong type, NaN/inf, negative value) raises
:class:`~drip_cert.errors.SpecError` naming the file, the field, the value and the fix. A failing
Assumption 7 raises :class:`~drip_cert.errors.AssumptionViolation` (exit status 1 in the CLI).
"""

from __future__ import annotations

import dataclasses
import tomllib
from functools import partial
from pathlib import Path
from types import MappingProxyType
from typing import Any

from drip_cert.bounds.l1drac.constants import L1Constants
from drip_cert.bounds.l1drac.decomposition import decompose
from drip_cert.bounds.l1drac.designer import design
from drip_cert.bounds.l1drac.request import DesignRequest
from drip_cert.errors import SpecError
from drip_cert.spec.settings import (
    L1_DESIGN_KEYS,
    L1Settings,
    TableReader,
    positive_float,
    positive_int,
    read_l1_design,
)

__all__ = ["DESIGN_KEYS", "load_l1_constants", "design_l1_report"]

#: Keys of the [design] table with their meanings; ``p`` and ``lambda_s`` are required. The keys
#: a spec's ``[l1drac]`` has too mean the same and are read by the same reader
#: (:func:`drip_cert.spec.settings.read_l1_design`).
DESIGN_KEYS = MappingProxyType(
    {
        **{k: L1Settings.KEYS[k] for k in ("p", *L1_DESIGN_KEYS)},
        "omega_min": "lower end of the omega search interval",
        "omega_max": "upper end of the omega search interval",
    }
)
_REQUIRED = ("p", "lambda_s")


def _design_request(table: Any, path: str) -> DesignRequest:
    r = TableReader("design", table, DESIGN_KEYS, path)
    for key in _REQUIRED:
        if key not in r.table:
            raise SpecError(
                f"missing; [design] needs {key} (p: the moment order 1..p_star; lambda_s: the "
                "predictor pole > 0)",
                field="design." + key,
                path=path,
            )
    p = r.get("p", positive_int, None)
    values = read_l1_design(r)
    lo = r.get("omega_min", positive_float, None)
    hi = r.get("omega_max", positive_float, None)
    if (lo is None) != (hi is None):
        raise SpecError(
            "give both omega_min and omega_max, or neither", field="design.omega_min", path=path
        )
    if lo is not None and not lo < hi:
        raise SpecError(
            f"omega_min = {lo!r} must be < omega_max = {hi!r}", field="design.omega_min", path=path
        )
    bounds = None if lo is None else (lo, hi)
    return DesignRequest(p=p, omega_bounds=bounds, **values)


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
    err = partial(SpecError, path=str(path))
    try:
        with open(path, "rb") as fh:
            data = tomllib.load(fh)
    except OSError as e:
        raise err(f"cannot read the file ({e.strerror}); check the path", field="file") from None
    except UnicodeDecodeError as e:
        raise err(f"not a TOML text file ({e})", field="file") from None
    except tomllib.TOMLDecodeError as e:
        raise err(f"not valid TOML: {e}", field="file") from None
    unknown = sorted(set(data) - {"constants", "design"})
    if unknown:
        raise err(
            f"unknown table(s) {unknown}; the file has exactly [constants] and [design]",
            field=unknown[0],
        )
    for t in ("constants", "design"):
        if t not in data:
            raise err(f"missing table [{t}]", field=t)
    if not isinstance(data["constants"], dict):
        raise err("[constants] must be a table", field="constants")
    for k, v in data["constants"].items():
        if isinstance(v, dict | list):
            raise err(
                f"{v!r} is not a scalar; [constants] is one flat table", field="constants." + k
            )
    consts = L1Constants.from_mapping(data["constants"], path=str(path))
    req = _design_request(data["design"], str(path))
    if req.p > consts.p_star:
        raise err(
            f"p = {req.p} exceeds p_star = {consts.p_star} (Assumption 1): use p <= p_star",
            field="design.p",
        )
    if req.omega is not None and req.omega == 2.0 * consts.lam:
        raise err(
            f"omega = {req.omega!r} equals 2*lambda, where every |2 lambda - omega| term of "
            "(18b), (18c), (21), (24) divides by zero; choose another omega",
            field="design.omega",
        )
    return consts, req


def design_l1_report(
    path: str | Path, *, Ts: float | None = None, rho_budget: float | None = None
) -> dict[str, Any]:
    """Load ``path``, design, and return the JSON-ready report the CLI prints.

    Keys: those of :meth:`~drip_cert.bounds.l1drac.result.L1Design.to_dict` (``feasible``
    decides the exit status: 0 if true, 1 if false; it is true only when every condition is
    verified in Arb ball arithmetic, see ``verified``, ``backoff`` and each condition's
    ``margin_lo`` / ``margin_hi``; ``objective``, ``choice``, ``knife_edge`` and ``front`` say
    what was optimised, why this point, and the (Ts, rho) Pareto front) plus ``decomposition``
    (rho_L1 term by term, :mod:`~drip_cert.bounds.l1drac.decomposition`), ``file``,
    ``constants`` and ``request``. ``Ts`` and ``rho_budget`` (the CLI's ``--Ts`` and
    ``--rho-budget``) replace the file's values; the objective is then re-inferred unless the
    file names one. Bad input raises SpecError (exit 2).
    """
    consts, req = load_l1_constants(path)
    if Ts is not None or rho_budget is not None:
        changes: dict[str, Any] = {}
        if Ts is not None:
            changes["Ts"] = Ts
        if rho_budget is not None:
            changes["rho_budget"] = rho_budget
        explicit = _file_objective(path)
        req = dataclasses.replace(req, objective=explicit, **changes)
    d = design(consts, req)
    out = d.to_dict()
    dec = decompose(consts, d)
    out["decomposition"] = None if dec is None else dec.to_dict()
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
        "objective": req.objective,
        "rho_budget": req.rho_budget,
        "front": req.front,
    }
    return out


def _file_objective(path: str | Path) -> str | None:
    """The ``objective`` the file's ``[design]`` writes, or None (then it is inferred)."""
    with open(path, "rb") as fh:
        obj = tomllib.load(fh).get("design", {}).get("objective")
    return obj if isinstance(obj, str) else None
