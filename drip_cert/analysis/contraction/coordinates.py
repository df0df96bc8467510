"""A constant change of coordinates ``z = Theta x`` chosen from a contraction metric, and the
factors that map bounds back (docs/math/contraction.md section 5).

``P = Theta^T Theta`` with ``Theta`` the transposed Cholesky factor of ``P`` (``P = L L^T``,
``Theta = L^T``): triangular, so ``Theta^{-1}`` is exact and cheap in rationals, and every
factorisation of ``P`` differs from it by an orthogonal matrix, which changes no Euclidean
quantity in ``z``. ``Theta`` is the float matrix computed here, taken as the exact rationals it
stores (:meth:`drip_cert.model.system.System.transformed`), so the ``z``-system is exactly
equivalent; ``P`` is then ``Theta^T Theta`` of those rationals, not the LMI's float ``P``.

Proposition 5.3: ``||x|| <= ||Theta^{-1}||_2 ||z||``, so a radius, an ``L_p`` norm or a
Wasserstein distance of states computed in ``z`` is reported in ``x`` multiplied by
:attr:`CoordinateChange.to_x`, a rigorous upper bound of ``||Theta^{-1}||_2`` (the exact
rational ``Theta^{-T} Theta^{-1}``, its largest eigenvalue isolated in Arb); input-space
quantities (policy errors, the L1-DRAC input) are unchanged.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Any

import numpy as np
import sympy as sp

from drip_cert.analysis.contraction.lognorm import mu2_constant_bounds
from drip_cert.errors import SpecError
from drip_cert.numerics.rounding import mul_up, sqrt_down, sqrt_up

__all__ = ["CoordinateChange", "coordinates_from_metric"]


@dataclass(frozen=True)
class CoordinateChange:
    """``z = Theta x`` with rigorous norm bounds of ``Theta`` and ``Theta^{-1}``.

    Attributes
    ----------
    theta
        ``Theta`` (float; read as exact rationals).
    P
        ``Theta^T Theta`` (float of the exact product).
    to_x
        Upper bound of ``||Theta^{-1}||_2``: a state gap in ``z`` times this bounds it in ``x``.
    to_z
        Upper bound of ``||Theta||_2``.
    cond
        Lower bound of ``cond(Theta) = sqrt(cond P)`` (``to_x * to_z`` is its upper bound).
    source
        Where ``P`` came from (the LMI metric of which closed loop, or given by the user).
    """

    theta: np.ndarray
    P: np.ndarray
    to_x: float
    to_z: float
    cond: float
    source: str

    def gap_in_x(self, gap_z: float) -> float:
        """A bound on a state gap in ``x`` from one in ``z`` (rounded up)."""
        return mul_up(self.to_x, gap_z)

    def to_dict(self) -> dict[str, Any]:
        return {
            "theta": self.theta.tolist(),
            "P": self.P.tolist(),
            "factor_to_x": self.to_x,
            "factor_to_z": self.to_z,
            "cond_theta_at_least": self.cond,
            "source": self.source,
            "choice": "Theta = L^T for the Cholesky factor P = L L^T (exact inverse; any other "
            "factor differs by an orthogonal matrix)",
        }


def _norm2_bounds(M: sp.Matrix) -> tuple[float, float]:
    """Rigorous ``(lo, hi)`` of ``||M||_2`` for an exact rational matrix."""
    lo, hi = mu2_constant_bounds(sp.Matrix(M.T * M))
    return sqrt_down(max(lo, 0.0)), sqrt_up(hi)


def coordinates_from_metric(P: np.ndarray, source: str) -> CoordinateChange:
    """The coordinate change of a positive definite metric ``P`` (Cholesky factor)."""
    P = np.asarray(P, dtype=float)
    P = 0.5 * (P + P.T)
    w = np.linalg.eigvalsh(P)
    if not (np.all(np.isfinite(w)) and w[0] > 0):
        raise SpecError(f"the metric P = {P.tolist()} is not positive definite")
    # a metric is defined up to a positive factor (the rate does not change): scale it so that
    # lambda_min(P) = 1, i.e. ||Theta^{-1}||_2 ~ 1 and ||z|| >= ||x||: gaps map back to x with a
    # factor ~1 and ||Theta||_2 = sqrt(cond P) carries the whole distortion
    P = P / w[0]
    try:
        L = np.linalg.cholesky(P)
    except np.linalg.LinAlgError:
        raise SpecError(f"the metric P = {P.tolist()} is not positive definite") from None
    theta = L.T.copy()
    Th = sp.Matrix(theta.tolist()).applyfunc(sp.Rational)
    Ti = Th.inv()
    lo_z, hi_z = _norm2_bounds(Th)
    lo_x, hi_x = _norm2_bounds(Ti)
    P_exact = Th.T * Th
    return CoordinateChange(
        theta=theta,
        P=np.array(P_exact.evalf(17).tolist(), dtype=float),
        to_x=hi_x,
        to_z=hi_z,
        cond=float(np.nextafter(lo_x * lo_z, 0.0)),
        source=source,
    )
