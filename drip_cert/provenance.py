"""Value objects that make every number of a certificate traceable.

A :class:`Quantity` is a number together with *how* it was obtained (exact closed form,
sound upper/lower bound, sampled estimate, or given by the user), the paper and equation it
implements, and a free-text note. A :class:`Check` is the verdict of one condition of the
papers: its left and right sides, the signed margin (positive = satisfied) and, for a
failure, a witness. Neither is ever a bare float.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field
from enum import StrEnum
from typing import Any


class How(StrEnum):
    """How a number was obtained."""

    EXACT = "exact"  #: closed form, up to floating-point rounding
    SOUND = "sound"  #: a rigorous bound in the direction the certificate needs
    ESTIMATE = "estimate"  #: sampled / optimised; NOT a bound, never used as one silently
    GIVEN = "given"  #: supplied by the user, taken as true


@dataclass(frozen=True)
class Quantity:
    """A number with its provenance.

    Parameters
    ----------
    name
        Symbol in ASCII, as in the papers (``"Delta_g"``, ``"lambda"``).
    value
        The number (``math.inf`` allowed where a bound does not exist).
    how
        :class:`How` it was obtained.
    source
        Paper and equation, e.g. ``"DRIP Assumption 1"`` or ``"L1-DRAC (A.13)"``.
    note
        Method and scope, e.g. ``"interval branch and bound on the support box, tol 1e-3"``.
    """

    name: str
    value: float
    how: How
    source: str = ""
    note: str = ""

    def __post_init__(self) -> None:
        object.__setattr__(self, "value", float(self.value))
        object.__setattr__(self, "how", How(self.how))

    def to_dict(self) -> dict[str, Any]:
        """JSON-ready dictionary (non-finite values become strings)."""
        return {
            "name": self.name,
            "value": _json_float(self.value),
            "how": self.how.value,
            "source": self.source,
            "note": self.note,
        }


@dataclass(frozen=True)
class Check:
    """The verdict of one condition.

    ``margin`` is signed: positive means the condition holds with that much room
    (``rhs - lhs`` for a condition ``lhs <= rhs``), negative means it fails by that much.
    """

    id: str
    holds: bool
    detail: str
    lhs: float = math.nan
    rhs: float = math.nan
    margin: float = math.nan
    source: str = ""
    how: How = How.EXACT
    witness: tuple[float, ...] | None = None
    extra: dict[str, Any] = field(default_factory=dict)

    def to_dict(self) -> dict[str, Any]:
        """JSON-ready dictionary."""
        out: dict[str, Any] = {
            "id": self.id,
            "holds": bool(self.holds),
            "detail": self.detail,
            "lhs": _json_float(self.lhs),
            "rhs": _json_float(self.rhs),
            "margin": _json_float(self.margin),
            "source": self.source,
            "how": How(self.how).value,
        }
        if self.witness is not None:
            out["witness"] = [float(w) for w in self.witness]
        if self.extra:
            out["extra"] = self.extra
        return out


def _json_float(x: float) -> float | str | None:
    """Finite floats as they are, ``inf``/``-inf`` as strings, NaN as ``None``."""
    x = float(x)
    if math.isnan(x):
        return None
    if math.isinf(x):
        return "inf" if x > 0 else "-inf"
    return x


json_float = _json_float
