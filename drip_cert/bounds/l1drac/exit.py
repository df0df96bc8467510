"""Box-only learned loops: the probability that the true process leaves the box (exit bound).

Mathematics: ``docs/math/l1drac.md`` section 11. When the learned closed loop ``F`` contracts
only on a box ``R``, L1-DRAC's Theorem 4.1 is applied to a globally contracting extension
``F~(x) = F(P x) - k (x - P x)`` (Proposition 11.1, (11.1a)); the true process equals the
extended one until it leaves ``R`` (Proposition 11.2); an exit is a deviation of at least the
room ``r`` from the nominal trajectory (Lemma 11.3), whose probability the grid union (11.4)
bounds from fixed-time moments, with the inputs (11.5) of the L1-DRAC closed loop.

Every function rounds outward (:mod:`drip_cert.numerics.rounding`, Arb for ``exp``): the
returned numbers are upper bounds of the closed forms they name. The certificate calls only
:func:`exit_floor` (a number it displays for a box-only learned loop, never a verdict): section
11.7 says what the verdict would still need.

Public surface
--------------
* :func:`extension_gain` -- the slope ``k`` of (11.1a).
* :func:`extension_constants` -- ``(k, L_f~, Delta_f~)`` of Proposition 11.1.
* :func:`l1drac_exit_inputs` -- ``(B, S)`` of (11.5).
* :func:`grid_exit_bound` -- the right side of (11.4), minimised over a finite grid of ``N, a``.
* :func:`exit_room` -- an upper bound of the room ``r`` from the support and the box.
* :func:`exit_floor` -- what (11.4) can give at best from a radius and a room (``>= 1``: nothing).
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from dataclasses import dataclass
from fractions import Fraction
from typing import Any

import numpy as np
from flint import arb

from drip_cert.numerics.rounding import (
    add_up,
    arb_hi,
    div_down,
    div_up,
    mul_down,
    mul_up,
    sqrt_up,
    sub_down,
)

__all__ = [
    "ExitBound",
    "ExitFloor",
    "exit_floor",
    "exit_room",
    "extension_constants",
    "extension_gain",
    "grid_exit_bound",
    "l1drac_exit_inputs",
]

#: Splits ``a = s r`` of the room tried by :func:`grid_exit_bound` (any split is valid).
SPLITS = tuple(i / 20 for i in range(1, 20))


def _pow_up(x: float, q: int) -> float:
    """Upper bound of ``x**q`` for ``x >= 0`` and an integer ``q >= 1`` (repeated rounded up)."""
    out = 1.0
    for _ in range(q):
        out = mul_up(out, x)
    return out


def extension_gain(lam: float, lam_prime: float, lip: float) -> float:
    """Slope ``k >= lam' + L^2 / (4 (lam - lam'))`` of the extension (11.1a), rounded up.

    Parameters
    ----------
    lam : float
        Rate proved on the box: ``mu_2(dF) <= -lam`` there, ``lam > 0``.
    lam_prime : float
        Global rate wanted for the extension, ``0 < lam_prime < lam``.
    lip : float
        ``L >= sup_R ||dF||_2``.
    """
    if not (0.0 < lam_prime < lam) or not lip >= 0.0:
        raise ValueError(f"need 0 < lam' < lam and L >= 0, got {lam_prime}, {lam}, {lip}")
    gap = sub_down(lam, lam_prime)
    if not gap > 0.0:
        raise ValueError(f"lam - lam' rounds to {gap}; take a smaller lam'")
    return add_up(lam_prime, div_up(mul_up(lip, lip), 4.0 * gap))


def extension_constants(
    lam: float, lam_prime: float, lip: float, sup_f: float, d0: float
) -> tuple[float, float, float]:
    """``(k, L_f~, Delta_f~)`` of Proposition 11.1 (ii)-(iii), each rounded up.

    ``sup_f >= sup_R ||F||`` and ``d0 >= ||P 0||`` (distance from the origin to the box);
    ``L_f~ = L + k`` and ``Delta_f~ = sqrt((M + k d0)^2 + k^2)``.
    """
    k = extension_gain(lam, lam_prime, lip)
    lf = add_up(lip, k)
    c0 = add_up(sup_f, mul_up(k, d0))
    df = sqrt_up(add_up(mul_up(c0, c0), mul_up(k, k)))
    return k, lf, df


def l1drac_exit_inputs(
    *,
    rho: float,
    r_x: float,
    sup_f: float,
    delta_f: float,
    delta_mu: float,
    delta_sigma: float,
    delta_p: float,
    delta_g: float,
    delta_theta: float,
    lambda_s: float,
    t_s: float,
    p: int,
) -> tuple[float, float]:
    """``(B, S)`` of Proposition 11.5, eq. (11.5), rounded up.

    ``m = R_x + rho``; ``S = Delta_p + Delta_sigma (1 + m)^{1/2}``;
    ``B_U = Delta_Theta (e^{-lambda_s T_s} Delta_mu (1 + m) + sqrt(p (2p - 1) / T_s) S)``;
    ``B = (Delta_f~ + Delta_mu)(1 + m) + Delta_g B_U + M``.
    """
    one_m = add_up(1.0, add_up(r_x, rho))
    s = add_up(delta_p, mul_up(delta_sigma, sqrt_up(one_m)))
    decay = arb_hi((-(arb(lambda_s) * arb(t_s))).exp())
    noise = mul_up(sqrt_up(div_up(float(p * (2 * p - 1)), t_s)), s)
    b_u = mul_up(delta_theta, add_up(mul_up(decay, mul_up(delta_mu, one_m)), noise))
    b = add_up(
        add_up(mul_up(add_up(delta_f, delta_mu), one_m), mul_up(delta_g, b_u)),
        sup_f,
    )
    return b, s


@dataclass(frozen=True)
class ExitBound:
    """The right side of (11.4) at its best grid ``n`` and split ``a`` (``eta = room - a``)."""

    delta: float
    n: int
    a: float


def grid_exit_bound(
    *, rho: float, b: float, s: float, q: int, room: float, horizon: float, n_max: int = 10**7
) -> ExitBound:
    """``min_{N, a} N (rho/a)^q + N (omega_h/eta)^q`` of Lemma 11.4, eq. (11.4), rounded up.

    ``omega_h = h B + c_q sqrt(h) S`` with ``h = T/N`` and
    ``c_q = q/(q-1) sqrt(q (q-1)/2)``. ``N`` runs over powers of 2 up to ``n_max`` and ``a``
    over :data:`SPLITS` of the room; every pair gives a valid bound, the smallest is returned
    (at most 1 is meaningful; larger values are returned as computed).
    """
    if q < 2 or not (room > 0.0 and horizon > 0.0):
        raise ValueError(f"need q >= 2, room > 0, T > 0; got {q}, {room}, {horizon}")
    cq = mul_up(div_up(float(q), float(q - 1)), sqrt_up(div_up(float(q * (q - 1)), 2.0)))
    best = ExitBound(delta=math.inf, n=1, a=room / 2)
    n = 1
    while n <= n_max:
        h = div_up(horizon, float(n))
        omega = add_up(mul_up(h, b), mul_up(cq, mul_up(sqrt_up(h), s)))
        for frac in SPLITS:
            a = frac * room
            eta = sub_down(room, a)
            if not (a > 0.0 and eta > 0.0):
                continue
            t1 = _pow_up(div_up(rho, a), q)
            t2 = _pow_up(div_up(omega, eta), q)
            d = mul_up(float(n), add_up(t1, t2))
            if d < best.delta:
                best = ExitBound(delta=d, n=n, a=a)
        n *= 2
    return best


def exit_room(support: Sequence[Sequence[float]], box: Sequence[Sequence[float]]) -> float:
    """An upper bound of the room ``r`` of section 11 (rounded up; 0 when the support is not
    inside the open box).

    The learned nominal trajectories start everywhere on the support, so the set ``S'`` they stay
    in contains it, and ``r = dist(S', complement of R) <= dist(support, complement of R) =
    min_i min(lo_i(support) - lo_i(R), hi_i(R) - hi_i(support))`` for boxes.
    """
    sup = np.asarray(support, dtype=float)
    reg = np.asarray(box, dtype=float)
    pairs = list(zip(sup[:, 0], reg[:, 0], strict=True))
    pairs += list(zip(reg[:, 1], sup[:, 1], strict=True))
    gap = min(Fraction(float(a)) - Fraction(float(b)) for a, b in pairs)  # exact
    if gap <= 0:
        return 0.0
    out = float(gap)
    return out if Fraction(out) >= gap else math.nextafter(out, math.inf)


@dataclass(frozen=True)
class ExitFloor:
    """What the exit route of section 11 can give at best (a displayed number, never a verdict).

    ``floor`` is a lower bound of every right side of (11.4) with the radius ``rho`` and a room
    at most ``room`` (``inf`` when ``room = 0``: Lemma 11.3 needs ``r > 0``): ``N (rho / a)^q >
    (rho / r)^q`` for ``N >= 1``, ``a < r``. ``useless`` when ``floor >= 1`` (then ``delta_exit >=
    1``, no probability statement).
    """

    rho: float
    room: float
    q: int
    floor: float

    @property
    def useless(self) -> bool:
        """``delta_exit >= 1`` by this route."""
        return not self.floor < 1.0

    def to_dict(self) -> dict[str, Any]:
        """JSON-ready numbers (``inf`` as the string ``"inf"``)."""

        def num(v: float) -> float | str:
            return v if math.isfinite(v) else ("inf" if v > 0 else "-inf")

        return {
            "rho": num(self.rho),
            "room": self.room,
            "q": self.q,
            "delta_exit_floor": num(self.floor),
            "useless": self.useless,
        }


def exit_floor(*, rho: float, room: float, q: int) -> ExitFloor:
    """``(rho / room)^q`` rounded down (``inf`` for ``room = 0`` or an infinite ``rho``): no
    choice of ``N`` and split in (11.4) goes below it (see :class:`ExitFloor`)."""
    if q < 2 or not room >= 0.0:
        raise ValueError(f"need q >= 2 and room >= 0, got {q}, {room}")
    if room == 0.0 or not math.isfinite(rho):
        return ExitFloor(rho, room, q, math.inf)
    ratio = div_down(rho, room)
    out = 1.0
    for _ in range(q):
        out = mul_down(out, ratio)
    return ExitFloor(rho, room, q, out)
