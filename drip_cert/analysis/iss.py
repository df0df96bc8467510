"""Incremental input-to-state stability (delta-ISS) of the perturbed expert closed loop.

DRIP Proposition 1 (``prop:deltaISS``): under Assumption 2 (``mu_2(J) <= -lambda``) and
``||g(t)||_F <= Delta_g`` (Assumption 1), the solutions ``y`` of ``y' = Fbar(t, y, pi*(y) + s_t)``,
``y_0 = xi_1``, and ``x`` of the unperturbed loop, ``x_0 = xi_2``, satisfy

    ||y_t - x_t|| <= e^{-lambda_theta t / 2} ||xi_1 - xi_2||
                     + (theta lambda_theta)^{-1/2} (1 - e^{-lambda_theta t})^{1/2} sup_s ||s_s||,

with ``lambda_theta = 2 lambda - theta Delta_g^2`` for any ``theta in (0, 2 lambda / Delta_g^2)``.
The asymptotic gain ``(theta lambda_theta)^{-1/2}`` is smallest where ``theta (2 lambda - theta
Delta_g^2)`` is largest: ``theta* = lambda / Delta_g^2``, gain ``Delta_g / lambda`` (decay rate of
the initial term then ``lambda / 2``).

Tighter bound (this project's derivation, valid under DRIP Assumption 2)
-----------------------------------------------------------------------
Let ``e = y - x``. Assumption 2 gives the one-sided Lipschitz inequality
``e^T (F(t, y) - F(t, x)) <= -lambda ||e||^2`` (DRIP eq. (6) via Davydov-Jafarpour-Bullo 2022,
Thm 29; ``F`` the expert closed loop). Where ``e != 0``,

    d/dt ||e|| = e^T e' / ||e|| = e^T (F(t,y) - F(t,x)) / ||e|| + e^T g(t) s_t / ||e||
              <= -lambda ||e|| + ||g(t)||_2 ||s_t||,

and where ``e = 0`` the upper Dini derivative is at most ``||g(t) s_t||``, the same bound. The
comparison lemma (Khalil, *Nonlinear Systems*, Lemma 3.4) then gives, with
``G_2 = sup_t ||g(t)||_2``,

    ||y_t - x_t|| <= e^{-lambda t} ||xi_1 - xi_2|| + (G_2 / lambda) (1 - e^{-lambda t}) sup ||s||.

It is never above the paper's bound, for every ``theta`` and ``t``: the scalar system
``e' = -lambda e + G_2 s`` with constant ``s`` attains it with equality and satisfies the paper's
hypotheses with ``Delta_g = G_2``, and the paper's bound only grows with ``Delta_g`` at fixed
``theta`` (``(1 - e^{-a t}) / a`` decreases in ``a``); ``G_2 <= ||g||_F <= Delta_g``. It keeps the
full rate ``lambda`` on the initial condition and is linear, not square-root, in ``t`` near 0.
This is the gain used downstream.

Discrete-time corollary (DRIP Corollary ``corol:DiscreteDeltaISS``): for a perturbation that is
piecewise constant on a partition, both bounds hold at every ``t`` (the argument above needs only a
bounded measurable input; solutions are absolutely continuous), hence at the partition points with
``sup ||s|| = max_i ||s_{t_i}||``.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Any

import numpy as np
from flint import arb

from drip_cert.errors import AssumptionViolation, SpecError
from drip_cert.numerics.rounding import arb_hi, div_up
from drip_cert.provenance import How, Quantity, json_float, weakest

__all__ = ["DeltaISSResult", "delta_iss", "discrete_bound"]

_PAPER = "DRIP Proposition 1 (prop:deltaISS)"
_TIGHT = "comparison lemma, this project's derivation, valid under DRIP Assumption 2"


G_NORM_REL_TOL = 1e-12
"""Relative tolerance of the input check ``sup ||g||_2 <= Delta_g`` (two bounds computed by
different routes may disagree by rounding); a ``g_norm2`` above ``Delta_g`` is then replaced by
``Delta_g``, which is valid because ``||g||_2 <= ||g||_F <= Delta_g``. Not a soundness pad."""


@dataclass(frozen=True)
class DeltaISSResult:
    """Both delta-ISS bounds of the perturbed expert closed loop.

    Attributes
    ----------
    lam
        Contraction rate ``lambda > 0`` (Assumption 2).
    delta_g
        ``Delta_g >= sup_t ||g(t)||_F`` (Assumption 1), used by the paper's bound.
    g_norm2
        ``sup_t ||g(t)||_2``, used by the tighter bound (``<= delta_g``).
    theta_star
        ``lambda / Delta_g^2``, the ``theta`` of the smallest asymptotic paper gain.
    paper_gain_asymptotic
        ``Delta_g / lambda`` (the paper's gain at ``theta_star``, ``t -> inf``).
    tight_gain_asymptotic
        ``g_norm2 / lambda``.
    how
        Provenance of the gains (the weakest of the inputs').
    used
        Which bound downstream code uses: ``'comparison-lemma'``.
    """

    lam: float
    delta_g: float
    g_norm2: float
    theta_star: float
    paper_gain_asymptotic: float
    tight_gain_asymptotic: float
    how: How = How.EXACT
    used: str = "comparison-lemma"

    # ---- the paper's bound (DRIP Proposition 1) -------------------------------------------

    def _theta(self, theta: float | None) -> float:
        th = self.theta_star if theta is None else float(theta)
        upper = 2.0 * self.lam / self.delta_g**2
        if not 0.0 < th < upper:
            raise SpecError(
                f"theta = {th} outside (0, 2 lambda / Delta_g^2) = (0, {upper}); "
                "Proposition 1 needs lambda_theta > 0",
                field="theta",
            )
        return th

    def lambda_theta(self, theta: float | None = None) -> float:
        """``2 lambda - theta Delta_g^2`` (DRIP Proposition 1)."""
        return 2.0 * self.lam - self._theta(theta) * self.delta_g**2

    def paper_gain(self, t: np.ndarray | float, theta: float | None = None) -> np.ndarray:
        """``(theta lambda_theta)^{-1/2} (1 - e^{-lambda_theta t})^{1/2}``, default theta_star."""
        th = self._theta(theta)
        lt = self.lambda_theta(th)
        t = np.asarray(t, dtype=float)
        return np.sqrt(-np.expm1(-lt * t) / (th * lt))

    def paper_decay(self, t: np.ndarray | float, theta: float | None = None) -> np.ndarray:
        """``e^{-lambda_theta t / 2}``, the factor of ``||xi_1 - xi_2||``."""
        return np.exp(-0.5 * self.lambda_theta(theta) * np.asarray(t, dtype=float))

    def paper_bound(
        self, t: np.ndarray | float, e0: float, sup_s: float, theta: float | None = None
    ) -> np.ndarray:
        """Right side of DRIP Proposition 1 for ``||xi_1 - xi_2|| = e0``, ``sup ||s|| = sup_s``."""
        return self.paper_decay(t, theta) * e0 + self.paper_gain(t, theta) * sup_s

    def best_theta(self, t: float, e0: float = 0.0, sup_s: float = 1.0) -> float:
        """``theta`` minimising :meth:`paper_bound` at a finite time ``t`` (1-D optimisation).

        A grid on ``(0, 2 lambda / Delta_g^2)`` that also crowds towards the upper end, then a
        bounded scalar search between the neighbours of the best grid point. For ``e0 = 0`` and
        ``t -> inf`` the optimum tends to ``theta_star``. For small ``t`` (and ``e0 = 0``) the bound
        keeps decreasing as ``theta -> 2 lambda / Delta_g^2`` (``lambda_theta -> 0``), towards
        ``Delta_g sqrt(t / (2 lambda))``: the infimum is then not attained, and the returned
        ``theta`` is within ``1e-9`` (relative) of that end.
        """
        upper = 2.0 * self.lam / self.delta_g**2
        if t <= 0:
            raise SpecError(f"t must be > 0, got {t}", field="t")
        u = np.unique(
            np.concatenate([np.linspace(1e-6, 1 - 1e-6, 401), 1 - np.logspace(-9, -2, 50)])
        )
        grid = upper * u
        vals = np.array([float(self.paper_bound(t, e0, sup_s, th)) for th in grid])
        i = int(np.argmin(vals))
        a, b = grid[max(i - 1, 0)], grid[min(i + 1, len(grid) - 1)]
        from scipy.optimize import minimize_scalar  # scipy.optimize: 0.4 CPU-s to import, here only

        res = minimize_scalar(
            lambda th: float(self.paper_bound(t, e0, sup_s, th)),
            bounds=(a, b),
            method="bounded",
            options={"xatol": 1e-12 * upper},
        )
        return float(res.x) if res.fun <= vals[i] else float(grid[i])

    # ---- the tighter bound (comparison lemma) ---------------------------------------------

    def tight_gain(self, t: np.ndarray | float) -> np.ndarray:
        """``(G_2 / lambda) (1 - e^{-lambda t})``."""
        return self.g_norm2 / self.lam * -np.expm1(-self.lam * np.asarray(t, dtype=float))

    def tight_decay(self, t: np.ndarray | float) -> np.ndarray:
        """``e^{-lambda t}``."""
        return np.exp(-self.lam * np.asarray(t, dtype=float))

    def tight_bound(self, t: np.ndarray | float, e0: float, sup_s: float) -> np.ndarray:
        """``e^{-lambda t} e0 + (G_2/lambda)(1 - e^{-lambda t}) sup_s``."""
        return self.tight_decay(t) * e0 + self.tight_gain(t) * sup_s

    # ---- what downstream uses -------------------------------------------------------------

    def gain(self, T: float | None = None) -> Quantity:
        """Linear delta-ISS gain ``gamma_0 = sup_{t <= T}`` of the tighter gain (``T=None``: inf).

        This is the ``gamma_0`` of the TaSIL certificate (docs/math/tasil.md, Sec. 2-3).
        """
        value = self.tight_gain_asymptotic if T is None else _tight_gain_up(self, float(T))
        return Quantity(
            "gamma_0",
            value,
            self.how,
            _TIGHT,
            f"(||g||_2 / lambda)(1 - e^(-lambda T)), lambda = {self.lam:.6g}, "
            f"sup||g||_2 = {self.g_norm2:.6g}, T = {'inf' if T is None else T}",
        )

    def paper_gain_quantity(self, T: float | None = None, theta: float | None = None) -> Quantity:
        """The paper's gain at ``T`` (its sup over ``t <= T``); ``T=None``: ``t -> inf``."""
        th = self._theta(theta)
        value = _paper_gain_up(self, th, None if T is None else float(T))
        return Quantity(
            "gamma_0_paper",
            value,
            self.how,
            _PAPER,
            f"theta = {th:.6g}, Delta_g = {self.delta_g:.6g}, T = {'inf' if T is None else T}",
        )

    def to_dict(self) -> dict[str, Any]:
        """JSON-ready dictionary."""
        return {
            "lambda": json_float(self.lam),
            "Delta_g": json_float(self.delta_g),
            "g_norm2": json_float(self.g_norm2),
            "theta_star": json_float(self.theta_star),
            "paper_gain_asymptotic": json_float(self.paper_gain_asymptotic),
            "tight_gain_asymptotic": json_float(self.tight_gain_asymptotic),
            "how": How(self.how).value,
            "used": self.used,
            "source_paper": _PAPER,
            "source_used": _TIGHT,
        }


def _tight_gain_up(r: DeltaISSResult, T: float) -> float:
    """``(G_2 / lambda)(1 - e^{-lambda T})`` evaluated in Arb and rounded up."""
    lam = arb(r.lam)
    return arb_hi(arb(r.g_norm2) / lam * -(-lam * arb(T)).expm1())


def _paper_gain_up(r: DeltaISSResult, theta: float, T: float | None) -> float:
    """The paper's gain ``(theta lambda_theta)^{-1/2} (1 - e^{-lambda_theta T})^{1/2}``
    (``T = None``: without the last factor) at the float ``theta``, in Arb, rounded up."""
    th = arb(theta)
    lt = 2 * arb(r.lam) - th * arb(r.delta_g) ** 2  # lambda_theta, exact up to Arb's radius
    g2 = 1 / (th * lt)
    if T is not None:
        g2 = g2 * -(-lt * arb(T)).expm1()
    return arb_hi(g2.sqrt())


def _value(x: float | Quantity, name: str) -> tuple[float, How]:
    if isinstance(x, Quantity):
        return float(x.value), x.how
    try:
        return float(x), How.GIVEN
    except (TypeError, ValueError) as exc:
        raise SpecError(f"expected a number or Quantity, got {x!r}", field=name) from exc


def delta_iss(
    lam: float | Quantity,
    delta_g: float | Quantity,
    g_norm2: float | Quantity | None = None,
) -> DeltaISSResult:
    """delta-ISS gains of the perturbed expert loop (DRIP Proposition 1 and the tighter bound).

    Parameters
    ----------
    lam
        Contraction rate ``lambda`` of Assumption 2 (a float or a ``Quantity``; must be ``> 0``).
    delta_g
        ``Delta_g``, a bound on ``sup_t ||g(t)||_F`` (Assumption 1).
    g_norm2
        A bound on ``sup_t ||g(t)||_2``; defaults to ``delta_g`` (valid: ``||.||_2 <= ||.||_F``).

    Returns
    -------
    DeltaISSResult

    Raises
    ------
    AssumptionViolation
        ``lam <= 0``: Assumption 2 is not established, no delta-ISS gain follows.
    SpecError
        ``delta_g <= 0`` or ``g_norm2`` outside ``[0, delta_g]``.
    """
    lv, lh = _value(lam, "lambda")
    dv, dh = _value(delta_g, "Delta_g")
    gv, gh = (dv, dh) if g_norm2 is None else _value(g_norm2, "g_norm2")
    if not (math.isfinite(lv) and lv > 0):
        raise AssumptionViolation(
            f"contraction rate lambda = {lv} is not > 0: DRIP Assumption 2 fails, so Proposition 1 "
            "gives no delta-ISS gain; redesign the expert policy or certify on a smaller region"
        )
    if not (math.isfinite(dv) and dv > 0):
        raise SpecError(f"Delta_g must be finite and > 0, got {dv}", field="Delta_g")
    if not (math.isfinite(gv) and 0 <= gv <= dv * (1 + G_NORM_REL_TOL)):
        raise SpecError(
            f"sup ||g||_2 = {gv} must lie in [0, Delta_g = {dv}] (the spectral norm never exceeds "
            "the Frobenius norm); check both bounds",
            field="g_norm2",
        )
    gv = min(gv, dv)
    return DeltaISSResult(
        lam=lv,
        delta_g=dv,
        g_norm2=gv,
        theta_star=lv / dv**2,
        paper_gain_asymptotic=div_up(dv, lv),
        tight_gain_asymptotic=div_up(gv, lv),
        how=weakest(How.SOUND, lh, dh, gh),
    )


def discrete_bound(
    result: DeltaISSResult,
    partition: np.ndarray,
    e0: float,
    s_values: np.ndarray,
    which: str = "tight",
    theta: float | None = None,
) -> np.ndarray:
    """DRIP Corollary (discrete time) at the partition points ``t_0 = 0 < t_1 < ... < t_{k-1}``.

    Parameters
    ----------
    result
        From :func:`delta_iss`.
    partition
        ``(k,)`` increasing times (``T`` excluded, as in the paper).
    e0
        ``||xi_1 - xi_2||``.
    s_values
        ``(k, m)`` or ``(k,)``: the piecewise-constant perturbation ``s_{t_i}`` (or their norms).
    which
        ``'tight'`` (comparison lemma) or ``'paper'`` (Proposition 1 with ``theta``).

    Returns
    -------
    ``(k,)`` bounds on ``||y_{t_i} - x_{t_i}||`` with ``sup ||s|| = max_i ||s_{t_i}||``.
    """
    tp = np.asarray(partition, dtype=float)
    if tp.ndim != 1 or np.any(np.diff(tp) <= 0) or tp[0] < 0:
        raise SpecError("partition must be increasing times >= 0", field="partition")
    s = np.asarray(s_values, dtype=float)
    norms = np.abs(s) if s.ndim == 1 else np.linalg.norm(s, axis=-1)
    if len(norms) != len(tp):
        raise SpecError(
            f"{len(norms)} perturbation values for {len(tp)} partition points", field="s_values"
        )
    smax = float(norms.max())
    if which == "tight":
        return result.tight_bound(tp, e0, smax)
    if which == "paper":
        return result.paper_bound(tp, e0, smax, theta)
    raise SpecError(f"which must be 'tight' or 'paper', got {which!r}", field="which")
