"""What the user of the L1-DRAC designer fixes: :class:`DesignRequest`.

Source: A. Gahlawat, S. H. Karumanchi, N. Hovakimyan, "L1-DRAC: Distributionally Robust Adaptive
Control -- Global Results", arXiv:2509.04619 (2025-09-04), Sec. 3.2 (the parameters omega (15a),
Ts (15b), lambda_s (15c) and the radii of (16)) and Theorem 4.1 (delta, (130a)).
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Any

from drip_cert.bounds.l1drac.constants import check_real
from drip_cert.errors import SpecError
from drip_cert.spec.settings import (
    L1_DESIGN_KEYS,
    L1_OBJECTIVES,
    L1Settings,
    l1_objective,
    validate_declared,
)

__all__ = ["DesignRequest", "OBJECTIVES", "PRACTICAL_TS"]

#: What a design optimises (:attr:`DesignRequest.objective`):
#:
#: * ``"rho_at_Ts"`` -- ``Ts`` given (the hardware's sampling period): the smallest rho.
#: * ``"Ts_at_rho"`` -- ``rho_budget`` given: the largest ``Ts`` with ``rho <= rho_budget``.
#: * ``"default"`` -- neither given: the smallest rho at :data:`PRACTICAL_TS` when a design
#:   there is verified and not a knife edge, else the largest-``Ts`` point of the (Ts, rho) front
#:   that is not a knife edge (:func:`~drip_cert.bounds.l1drac.designer.knife_edge`).
#: * ``"min_rho"`` -- the smallest radii over every free parameter, then the largest ``Ts``
#:   (24) allows with them: the infimum of rho, a knife edge whenever rho_a is found ((21b)
#:   binds and leaves (24) almost no room; with omega free it also sits at the top of the
#:   omega interval, Remarks 3.1-3.2). The designer's only objective before issue 14.
OBJECTIVES = L1_OBJECTIVES

#: The practical sampling period of the ``"default"`` objective, in seconds: 1 kHz, the rate of
#: common embedded control loops (and of the paper-4d simulation's ``dt``), well inside what a
#: microcontroller samples. A design is sought here first; a faster ``Ts`` is accepted only when
#: 1 kHz is infeasible, and then with a note.
PRACTICAL_TS = 1e-3

#: The request's keys that a spec's ``[l1drac]`` table declares (and checks) too.
SHARED = L1_DESIGN_KEYS


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
    objective
        One of :data:`OBJECTIVES`; ``None`` = inferred: ``"rho_at_Ts"`` when ``Ts`` is given,
        ``"Ts_at_rho"`` when ``rho_budget`` is given, else ``"default"``. ``"rho_at_Ts"`` needs
        ``Ts``; ``"Ts_at_rho"`` needs ``rho_budget`` and no ``Ts``.
    rho_budget
        Largest acceptable rho = rho_r + rho_a (17). With ``Ts`` given too, a design whose rho
        exceeds it is infeasible (reason given).
    practical_Ts
        The ``Ts`` the ``"default"`` objective tries first (:data:`PRACTICAL_TS`).
    front
        Compute the (Ts, rho) Pareto front (:func:`~drip_cert.bounds.l1drac.designer.
        pareto_front`) and attach it to the design; ``False`` skips it (a faster design).
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
    objective: str | None = None
    rho_budget: float | None = None
    practical_Ts: float = PRACTICAL_TS
    front: bool = True

    def __post_init__(self) -> None:
        # the keys [l1drac] shares with this request are checked by the readers declared once
        # on L1Settings (the same rules and messages as a spec or a design-l1 file)
        validate_declared(self, "design", ("p", *SHARED), source=L1Settings)
        object.__setattr__(self, "p", int(self.p))
        object.__setattr__(self, "practical_Ts", _positive("practical_Ts", self.practical_Ts))
        for name in SHARED:
            value = getattr(self, name)
            if name not in ("objective", "front") and value is not None:
                object.__setattr__(self, name, float(value))
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
        self._check_objective()

    def _check_objective(self) -> None:
        """Infer ``objective`` when ``None``; reject combinations it cannot serve."""
        obj = l1_objective(
            self.objective,
            Ts=self.Ts,
            rho_budget=self.rho_budget,
            rho_r=self.rho_r,
            rho_a=self.rho_a,
            table="design",
        )
        object.__setattr__(self, "objective", obj)
