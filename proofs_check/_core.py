"""Registry, result objects and the runner shared by every proof check.

A check is a function ``fn(ctx) -> CheckResult`` registered with :func:`register`. It
re-derives one step of the DRIP paper (``drip_paper.tex``) or of L1-DRAC
(arXiv:2509.04619) by a second, independent computation: a symbolic verification with
sympy where the step is algebra or calculus, a numerical falsification attempt (random
instances, adversarial search with scipy) where it is an inequality over a class.

Verdicts
--------
``PASS``
    The statement holds: the symbolic residual is zero, or no instance violates the
    inequality by more than the check's named tolerance.
``ERRATUM``
    The statement *as printed* is wrong or ambiguous, the corrected statement recorded in
    ``proofs_check/ERRATA.md`` under the check's erratum id holds, and the check shows both.
    A finding, not a failure: the exit status stays 0.
``FAIL``
    The (corrected) statement does not hold: a bug in drip-cert or in the mathematics.
``SKIP``
    The check could not run here (the paper's source text is not available); it says nothing
    either way and does not change the exit status.

``residual`` is the largest violation found, signed so that a positive value is a violation
(``max(lhs - rhs)`` over the instances tried, usually relative to the size of the sides) or,
for a symbolic identity, the size of what is left after simplification.
"""

from __future__ import annotations

import math
import zlib
from collections.abc import Callable
from dataclasses import dataclass
from enum import StrEnum
from typing import Any

import numpy as np


class Verdict(StrEnum):
    """Outcome of one check."""

    PASS = "PASS"
    FAIL = "FAIL"
    ERRATUM = "ERRATUM"
    SKIP = "SKIP"


@dataclass(frozen=True)
class CheckResult:
    """The verdict of one check (see the module docstring for the meaning of the fields)."""

    name: str
    label: str
    verdict: Verdict
    residual: float
    detail: str
    erratum: str | None = None

    def to_dict(self) -> dict[str, Any]:
        """JSON-ready dictionary with the keys {name, label, verdict, residual, detail, erratum}."""
        r = float(self.residual)
        res: float | str | None
        if math.isnan(r):
            res = None
        elif math.isinf(r):
            res = "inf" if r > 0 else "-inf"
        else:
            res = r
        return {
            "name": self.name,
            "label": self.label,
            "verdict": self.verdict.value,
            "residual": res,
            "detail": self.detail,
            "erratum": self.erratum,
        }


@dataclass(frozen=True)
class Context:
    """What a check receives: an explicit generator and the quick/full switch.

    The generator is seeded from ``(seed, check name)`` so that every check draws its own
    reproducible stream whatever subset of checks runs (``--only``).
    """

    rng: np.random.Generator
    quick: bool
    seed: int

    def count(self, full: int, quick: int) -> int:
        """Number of random instances: ``quick`` under ``--quick``, else ``full``."""
        return quick if self.quick else full


CheckFn = Callable[[Context], CheckResult]


@dataclass(frozen=True)
class CheckSpec:
    """A registered check: its name, the paper label it checks, and the function."""

    name: str
    label: str
    fn: CheckFn


_REGISTRY: list[CheckSpec] = []


def register(name: str, label: str) -> Callable[[CheckFn], CheckFn]:
    """Decorator adding a check to the registry (names must be unique)."""

    def deco(fn: CheckFn) -> CheckFn:
        if any(s.name == name for s in _REGISTRY):
            raise ValueError(f"duplicate proof check name {name!r}")
        _REGISTRY.append(CheckSpec(name=name, label=label, fn=fn))
        return fn

    return deco


def registry() -> list[CheckSpec]:
    """All registered checks, in registration order."""
    return list(_REGISTRY)


def make_rng(seed: int, name: str) -> np.random.Generator:
    """Generator seeded from the run seed and the check name (stable across runs)."""
    return np.random.default_rng([int(seed), zlib.crc32(name.encode())])


def result(
    name: str,
    label: str,
    *,
    holds: bool,
    residual: float,
    detail: str,
    erratum: str | None = None,
) -> CheckResult:
    """Build a result: FAIL when ``holds`` is false, else ERRATUM when an erratum id is given."""
    if not holds:
        verdict = Verdict.FAIL
    elif erratum is not None:
        verdict = Verdict.ERRATUM
    else:
        verdict = Verdict.PASS
    return CheckResult(
        name=name,
        label=label,
        verdict=verdict,
        residual=float(residual),
        detail=detail,
        erratum=erratum,
    )


def run_checks(*, quick: bool = False, seed: int = 0, only: str | None = None) -> list[CheckResult]:
    """Run every registered check whose name contains ``only`` (all when None).

    An exception inside a check is reported as a FAIL of that check, never swallowed.
    """
    from proofs_check import load_all

    load_all()
    out: list[CheckResult] = []
    for spec in _REGISTRY:
        if only is not None and only not in spec.name:
            continue
        ctx = Context(rng=make_rng(seed, spec.name), quick=quick, seed=seed)
        try:
            res = spec.fn(ctx)
        except Exception as exc:  # noqa: BLE001 - a crashing check is a failing check
            res = CheckResult(
                name=spec.name,
                label=spec.label,
                verdict=Verdict.FAIL,
                residual=math.nan,
                detail=f"check raised {type(exc).__name__}: {exc}",
            )
        out.append(res)
    return out
