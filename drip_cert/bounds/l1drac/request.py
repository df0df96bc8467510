"""What the user of the L1-DRAC designer fixes: :class:`DesignRequest`.

Source: A. Gahlawat, S. H. Karumanchi, N. Hovakimyan, "L1-DRAC: Distributionally Robust Adaptive
Control -- Global Results", arXiv:2509.04619 (2025-09-04), Sec. 3.2 (the parameters omega (15a),
Ts (15b), lambda_s (15c) and the radii of (16)) and Theorem 4.1 (delta, (130a)).
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Any

from drip_cert.bounds.l1drac.constants import check_int, check_real
from drip_cert.errors import SpecError

__all__ = ["DesignRequest"]


def _positive(name: str, value: Any) -> float:
    """A finite number > 0 for the design parameter ``name`` (SpecError ``design.name``)."""
    return check_real("design." + name, value, positive=True, where="the design", path=None)


@dataclass(frozen=True, kw_only=True)
class DesignRequest:
    """What the user fixes; ``None`` means "find it".

    Parameters
    ----------
    p
        Moment order, an integer in ``{1, ..., p_star}``.
    lambda_s
        Predictor pole (15c); ``None`` = choose it (maximise Ts; minimise rho_a if Ts is fixed).
    omega
        Filter bandwidth (15a), ``!= 2 lambda``; ``None`` = minimise rho over ``omega_bounds``.
    Ts
        Sampling period (15b); ``None`` = the largest Ts satisfying (24).
    rho_r, rho_a
        Radii (16a), (16b); ``None`` = the smallest satisfying their conditions.
    delta
        Violation probability in (0, 1); when given, the design reports kappa (130a).
    omega_bounds, lambda_s_bounds
        Search intervals ``(lo, hi)``; default ``(1e-3, 1e7) * lambda`` and
        ``(1e-3, 1e5) * lambda``.
    """

    p: int
    lambda_s: float | None = None
    omega: float | None = None
    Ts: float | None = None
    rho_r: float | None = None
    rho_a: float | None = None
    delta: float | None = None
    omega_bounds: tuple[float, float] | None = None
    lambda_s_bounds: tuple[float, float] | None = None

    def __post_init__(self) -> None:
        object.__setattr__(self, "p", check_int("design.p", self.p, where="the design", path=None))
        for name in ("lambda_s", "omega", "Ts", "rho_r", "rho_a", "delta"):
            value = getattr(self, name)
            object.__setattr__(self, name, None if value is None else _positive(name, value))
        if self.delta is not None and not self.delta < 1.0:
            raise SpecError(
                f"{self.delta!r} is not a probability in (0, 1); give e.g. 1e-3",
                field="design.delta",
            )
        for name in ("omega_bounds", "lambda_s_bounds"):
            b = getattr(self, name)
            if b is None:
                continue
            if len(b) != 2:
                raise SpecError(f"{b!r} must be a pair (lo, hi)", field="design." + name)
            lo, hi = _positive(name, b[0]), _positive(name, b[1])
            if not lo < hi:
                raise SpecError(f"{b!r}: need lo < hi", field="design." + name)
            object.__setattr__(self, name, (lo, hi))
