"""Activation functions: one class each, with rigorous enclosures (auto_LiRPA style).

Every activation ``s`` is a frozen value object (:class:`Activation`) that knows

* its value, for numpy (:meth:`~Activation.value_np`) and for jax (:meth:`~Activation.value_jax`);
* a float point derivative (:meth:`~Activation.prime_np`: a sampled estimate, never a bound);
* sound enclosures over an interval ``[lo, hi]`` (elementwise, any shape): of its values
  (:meth:`~Activation.enclose`), of its slopes (:meth:`~Activation.slope_range`: the Clarke
  generalized derivative, i.e. the convex hull of the derivatives of the smooth pieces touching
  ``[lo, hi]``, for the piecewise-linear ones) and, where ``s`` is ``C^{1,1}``, of its second
  derivative (:meth:`~Activation.second_range`, ``None`` otherwise: relu, leaky relu);
* the global constants of the Lipschitz recursions (:attr:`~Activation.bounds`).

``smooth`` is True when ``s'`` is Lipschitz (the TaSIL lemma route and the Hessian enclosures
need it). Rounding: :mod:`drip_cert.numerics.rounding` (outward) and
:mod:`drip_cert.numerics.interval_np` (library functions widened by their error budgets).

Piecewise-monotone rule (:func:`_pm_range`). Each of ``s, s', s''`` of the smooth activations is
monotone between finitely many critical points (proved in each class's docstring). Each critical
point is bracketed by floats ``[a, b]`` whose Arb derivative signs are verified, and the function
is enclosed over the whole bracket in Arb. Over ``[lo, hi]`` the range then lies in the hull of
the end enclosures and of the bracket enclosures of every bracket meeting ``[lo, hi]``: split
``[lo, hi]`` at the brackets; on each piece outside them the function is monotone, so its
extremes are at the piece's ends, which are ``lo``, ``hi`` or points of a bracket.

Registry: :data:`ACTIVATIONS` maps a name to its class; :func:`get_activation` parses
``"relu"``, ``"leaky_relu(0.2)"``, ``"elu(1.0)"``, ``"prelu(0.1, 0.25, ...)"`` (one slope per
unit) (or passes an :class:`Activation` through).
"""

from __future__ import annotations

import functools
import math
import re
from collections.abc import Callable
from dataclasses import dataclass
from typing import Any, ClassVar

import numpy as np
from flint import arb

from drip_cert.errors import SpecError
from drip_cert.numerics.interval_np import (
    Phi_bounds,
    exp_bounds,
    iadd,
    imul,
    log1p_bounds,
    phi_bounds,
    scale_point,
    sech2_bounds,
    tanh_bounds,
)
from drip_cert.numerics.rounding import (
    LIBM_REL,
    add_down_np,
    add_up_np,
    arb_hi,
    arb_lo,
    down_np,
    up_np,
    widen_np,
)

__all__ = [
    "ACTIVATIONS",
    "Activation",
    "ActivationBounds",
    "Elu",
    "Gelu",
    "Identity",
    "LeakyRelu",
    "PRelu",
    "Relu",
    "Sigmoid",
    "Silu",
    "Softplus",
    "Tanh",
    "get_activation",
]

Pair = tuple[np.ndarray, np.ndarray]
_BRACKET_HALF = 1e-12  # half-width of a critical-point bracket (relative to a point of size ~1)
_FAR = 1e4  # every critical point of every activation lies in (-_FAR, _FAR); beyond, monotone
_INV_SQRT_2PI = 1.0 / math.sqrt(2.0 * math.pi)  # float, for point estimates only


@dataclass(frozen=True)
class ActivationBounds:
    """Global slope and curvature bounds of one activation (each rounded outward).

    Attributes
    ----------
    name
        The activation's spec string.
    slope_lo, slope_hi
        ``inf s'`` and ``sup s'`` over the real line (Clarke: over every generalized slope).
    abs_slope
        ``sup |s'|`` (the factor of the product Lipschitz bound).
    abs_curv
        ``sup |s''|`` (the factor of the Jacobian-Lipschitz bound); ``inf`` when ``s'`` is not
        Lipschitz (relu, leaky relu, elu with ``alpha != 1``).
    """

    name: str
    slope_lo: float
    slope_hi: float
    abs_slope: float
    abs_curv: float


# --------------------------------------------------------------------------- helpers


def _arr(x) -> np.ndarray:
    return np.asarray(x, dtype=np.float64)


def _pm_range(lo, hi, point: Callable[[np.ndarray], Pair], crits) -> Pair:
    """The piecewise-monotone rule of the module docstring: ``crits`` holds
    ``(a, b, v_lo, v_hi)``, a bracket of a critical point and an enclosure over it."""
    l_lo, l_hi = point(lo)
    h_lo, h_hi = point(hi)
    rlo, rhi = np.minimum(l_lo, h_lo), np.maximum(l_hi, h_hi)
    for a, b, vlo, vhi in crits:
        meet = (lo <= b) & (hi >= a)
        rlo = np.where(meet, np.minimum(rlo, vlo), rlo)
        rhi = np.where(meet, np.maximum(rhi, vhi), rhi)
    return rlo, rhi


def _bracket(
    z: float, deriv: Callable[[arb], arb], fn: Callable[[arb], arb]
) -> tuple[float, float, float, float]:
    """A verified bracket ``[a, b]`` of a zero of ``deriv = fn'`` near the float ``z`` (Arb signs
    at ``a`` and ``b`` strictly opposite) and an Arb enclosure of ``fn`` over ``[a, b]``."""
    if z == 0.0:
        a, b = 0.0, 0.0
    else:
        a, b = z - _BRACKET_HALF, z + _BRACKET_HALF
        da, db = deriv(arb(a)), deriv(arb(b))
        if not ((arb_hi(da) < 0.0 < arb_lo(db)) or (arb_hi(db) < 0.0 < arb_lo(da))):
            msg = f"could not bracket a critical point near {z}"
            raise ArithmeticError(msg)  # pragma: no cover
    # mean-value form about the midpoint: the slope over the bracket contains 0, so the excess
    # is second order in its width (plain ball evaluation would be first order)
    mid, rad = arb(0.5 * (a + b)), arb(0.0, 0.5 * (b - a))
    v = fn(mid) + deriv(mid + rad) * rad
    return a, b, arb_lo(v), arb_hi(v)


def _root(f: Callable[[float], float], a: float, b: float) -> float:
    """A float root of ``f`` in ``[a, b]`` (an estimate; :func:`_bracket` verifies it)."""
    from scipy.optimize import brentq  # scipy.optimize: keep off the CLI start-up path

    return float(brentq(f, a, b, xtol=1e-15))


def _hull(*pairs: tuple[float, float]) -> tuple[float, float]:
    return min(p[0] for p in pairs), max(p[1] for p in pairs)


def _arb_sigma(x: arb) -> arb:
    return 1 / (1 + (-x).exp())


# --------------------------------------------------------------------------- the base class


@dataclass(frozen=True)
class Activation:
    """Base class; see the module docstring. Subclasses set ``name``, ``smooth``,
    ``onnx_op`` and implement the value, the point enclosures and the limits at infinity."""

    name: ClassVar[str] = ""
    onnx_op: ClassVar[str] = ""
    #: global range of the values (``(-inf, inf)`` unless bounded); used for output bounds
    value_range: ClassVar[tuple[float, float]] = (-math.inf, math.inf)

    @property
    def smooth(self) -> bool:
        """True when ``s'`` is Lipschitz (a second-derivative enclosure exists)."""
        return True

    @property
    def units(self) -> int | None:
        """The layer width the activation is made for (per-unit parameters), else ``None``."""
        return None

    @property
    def spec(self) -> str:
        """The string :func:`get_activation` parses back to this activation."""
        return self.name

    def __str__(self) -> str:
        return self.spec

    # ---- values
    def apply(self, z, xp=np):
        """The value ``s(z)`` for the array module ``xp`` (numpy or jax.numpy)."""
        raise NotImplementedError

    def value_np(self, z) -> np.ndarray:
        """The value with numpy."""
        return self.apply(_arr(z), np)

    def value_jax(self, z):
        """The value with jax.numpy (traceable)."""
        from drip_cert._jax import jnp  # jax: keep off the CLI start-up path

        return self.apply(z, jnp)

    def prime_np(self, z) -> np.ndarray:
        """A float derivative at points (a sampled estimate; at a kink, one Clarke element)."""
        raise NotImplementedError

    # ---- enclosures
    def enclose(self, lo, hi) -> Pair:
        """Enclosure of ``{s(z) : lo <= z <= hi}`` (elementwise)."""
        lo, hi = _arr(lo), _arr(hi)
        return _pm_range(lo, hi, self._value_point, self._crits()[0])

    def slope_range(self, lo, hi) -> Pair:
        """Enclosure of every (Clarke generalized) derivative of ``s`` on ``[lo, hi]``."""
        lo, hi = _arr(lo), _arr(hi)
        return _pm_range(lo, hi, self._slope_point, self._crits()[1])

    def second_range(self, lo, hi) -> Pair | None:
        """Enclosure of ``s''`` (a.e.) on ``[lo, hi]``; ``None`` when ``s'`` is not Lipschitz."""
        lo, hi = _arr(lo), _arr(hi)
        return _pm_range(lo, hi, self._second_point, self._crits()[2])

    @property
    def bounds(self) -> ActivationBounds:
        """Global slope range and ``sup |s'|``, ``sup |s''|`` (rounded outward)."""
        return _global_bounds(self)

    # ---- per class
    def _value_point(self, z: np.ndarray) -> Pair:
        raise NotImplementedError

    def _slope_point(self, z: np.ndarray) -> Pair:
        raise NotImplementedError

    def _second_point(self, z: np.ndarray) -> Pair:
        raise NotImplementedError

    def _crits(self) -> tuple[tuple, tuple, tuple]:
        """Brackets of the critical points of ``s``, ``s'``, ``s''`` (see :func:`_pm_range`)."""
        return (), (), ()

    def _limits(self) -> tuple[tuple[float, float], tuple[float, float]]:
        """Hulls of the limits of ``s'`` and ``s''`` at ``-inf`` and ``+inf``."""
        raise NotImplementedError

    def onnx_attributes(self) -> dict[str, Any]:
        """Attributes of the ONNX node that computes this activation."""
        return {}


@functools.cache
def _global_bounds(act: Activation) -> ActivationBounds:
    """Global bounds: the range over ``[-_FAR, _FAR]`` (which holds every critical point) joined
    with the limits at infinity (beyond ``_FAR`` each function is monotone towards its limit)."""
    far_lo, far_hi = np.array([-_FAR]), np.array([_FAR])
    s_lim, c_lim = act._limits()
    with np.errstate(over="ignore"):  # exp(_FAR) overflows to inf: a valid (outer) bound
        return _global_bounds_far(act, far_lo, far_hi, s_lim, c_lim)


def _global_bounds_far(act: Activation, far_lo, far_hi, s_lim, c_lim) -> ActivationBounds:
    slo, shi = act.slope_range(far_lo, far_hi)
    slope = _hull((float(slo[0]), float(shi[0])), s_lim)
    if act.smooth:
        sec = act.second_range(far_lo, far_hi)
        assert sec is not None
        curv_pair = _hull((float(sec[0][0]), float(sec[1][0])), c_lim)
        curv = max(abs(curv_pair[0]), abs(curv_pair[1]))
    else:
        curv = math.inf
    return ActivationBounds(act.spec, slope[0], slope[1], max(abs(slope[0]), abs(slope[1])), curv)


# --------------------------------------------------------------------------- piecewise linear


@dataclass(frozen=True)
class Identity(Activation):
    """``s(z) = z``: slope 1, curvature 0 (exact)."""

    name: ClassVar[str] = "identity"
    onnx_op: ClassVar[str] = "Identity"

    def apply(self, z, xp=np):
        return z

    def prime_np(self, z):
        return np.ones_like(_arr(z))

    def enclose(self, lo, hi):
        return _arr(lo), _arr(hi)

    def slope_range(self, lo, hi):
        return np.ones_like(_arr(lo)), np.ones_like(_arr(hi))

    def second_range(self, lo, hi):
        return np.zeros_like(_arr(lo)), np.zeros_like(_arr(hi))

    def _limits(self):
        return (1.0, 1.0), (0.0, 0.0)


@dataclass(frozen=True)
class _Increasing(Activation):
    """An increasing activation whose :meth:`_value_point` encloses ``s`` at points: the values
    over ``[lo, hi]`` come from the ends (rounded outward there)."""

    def enclose(self, lo, hi):
        lo, hi = _arr(lo), _arr(hi)
        return self._value_point(lo)[0], self._value_point(hi)[1]


@dataclass(frozen=True)
class _OneSlope(_Increasing):
    """Shared by :class:`LeakyRelu` and :class:`Elu`: the identity for ``z > 0``, increasing,
    one parameter ``alpha`` (the left slope at 0; in :attr:`spec` and the ONNX attribute);
    ``s'`` is Lipschitz exactly when ``alpha = 1``."""

    alpha: float = 1.0

    @property
    def smooth(self) -> bool:
        return self.alpha == 1.0

    @property
    def spec(self) -> str:
        return f"{self.name}({self.alpha!r})"

    def onnx_attributes(self):
        return {"alpha": self.alpha}


@dataclass(frozen=True)
class LeakyRelu(_OneSlope):
    """``s(z) = z`` for ``z >= 0``, ``alpha z`` for ``z < 0`` (``alpha >= 0``).

    Piecewise linear: the slopes are ``alpha`` and ``1``; the Clarke generalized derivative at 0
    is ``[min(alpha, 1), max(alpha, 1)]``. Over ``[lo, hi]``: ``{alpha}`` if ``hi < 0``, ``{1}``
    if ``lo > 0``, else the hull of both. Increasing, so the values come from the ends
    (``alpha lo`` rounded outward). Not ``C^1``: :meth:`second_range` is ``None``.
    """

    alpha: float = 0.01
    name: ClassVar[str] = "leaky_relu"
    onnx_op: ClassVar[str] = "LeakyRelu"

    def __post_init__(self) -> None:
        a = float(self.alpha)
        if not (math.isfinite(a) and a >= 0.0):
            raise SpecError(f"leaky_relu slope alpha must be finite and >= 0, got {self.alpha!r}")
        object.__setattr__(self, "alpha", a)

    def apply(self, z, xp=np):
        return xp.where(z >= 0, z, self.alpha * z)

    def prime_np(self, z):
        return np.where(_arr(z) > 0, 1.0, self.alpha)

    def _value_point(self, z):
        neg = z < 0
        v = np.where(neg, self.alpha * z, z)
        # alpha z is one rounding when z < 0; z itself is exact
        return np.where(neg, down_np(v), v), np.where(neg, up_np(v), v)

    def slope_range(self, lo, hi):
        lo, hi = _arr(lo), _arr(hi)
        a, one = self.alpha, 1.0
        has_neg, has_pos = lo <= 0.0, hi >= 0.0  # 0 itself carries both slopes (Clarke)
        slo = np.where(has_neg & has_pos, min(a, one), np.where(has_neg, a, one))
        shi = np.where(has_neg & has_pos, max(a, one), np.where(has_neg, a, one))
        return slo.astype(np.float64), shi.astype(np.float64)

    def second_range(self, lo, hi):
        if self.smooth:  # alpha = 1: the identity
            return np.zeros_like(_arr(lo)), np.zeros_like(_arr(hi))
        return None

    def _limits(self):
        return (self.alpha, 1.0), (0.0, 0.0)


@dataclass(frozen=True)
class Relu(LeakyRelu):
    """``s(z) = max(z, 0)``: :class:`LeakyRelu` with ``alpha = 0`` (Clarke slope ``[0, 1]``
    at 0)."""

    alpha: float = 0.0
    name: ClassVar[str] = "relu"
    onnx_op: ClassVar[str] = "Relu"

    def __post_init__(self) -> None:
        if self.alpha != 0.0:
            raise SpecError("relu has alpha = 0; use leaky_relu(alpha) for another slope")

    @property
    def spec(self) -> str:
        return self.name

    def apply(self, z, xp=np):
        return xp.maximum(z, 0.0)

    def onnx_attributes(self):
        return {}


@dataclass(frozen=True)
class PRelu(_Increasing):
    """Leaky relu with one slope per unit (ONNX ``PRelu`` with a slope tensor of the layer
    width, PyTorch ``nn.PReLU(num_parameters=n)``): ``s_i(z) = z`` for ``z >= 0``,
    ``alpha_i z`` for ``z < 0`` (every ``alpha_i >= 0``).

    Unit ``i`` is :class:`LeakyRelu` ``(alpha_i)``, so every enclosure is that class's, taken
    unit by unit (the slopes broadcast along the last axis, which indexes the layer's units in
    every caller). The global constants (:attr:`bounds`) are the hull over the units:
    slopes in ``[min(min alpha, 1), max(max alpha, 1)]``, a sector every unit satisfies, which
    is what the Lipschitz recursions and LipSDP use. Not ``C^1`` unless every slope is 1.
    """

    slopes: tuple[float, ...] = ()
    name: ClassVar[str] = "prelu"
    onnx_op: ClassVar[str] = "PRelu"

    def __post_init__(self) -> None:
        a = tuple(float(v) for v in self.slopes)
        if not a:
            raise SpecError("prelu needs one slope per unit, got none")
        bad = [v for v in a if not (math.isfinite(v) and v >= 0.0)]
        if bad:
            raise SpecError(f"prelu slopes must be finite and >= 0, got {bad[0]!r}")
        object.__setattr__(self, "slopes", a)

    @property
    def units(self) -> int | None:
        return len(self.slopes)

    @property
    def smooth(self) -> bool:
        return all(v == 1.0 for v in self.slopes)

    @property
    def spec(self) -> str:
        return f"{self.name}({', '.join(repr(v) for v in self.slopes)})"

    def __str__(self) -> str:
        lo, hi = min(self.slopes), max(self.slopes)
        return f"{self.name}({len(self.slopes)} slopes in [{lo!r}, {hi!r}])"

    def _a(self) -> np.ndarray:
        return np.asarray(self.slopes, dtype=np.float64)

    def apply(self, z, xp=np):
        return xp.where(z >= 0, z, xp.asarray(self._a()) * z)

    def prime_np(self, z):
        return np.where(_arr(z) > 0, 1.0, self._a())

    def _value_point(self, z):
        neg = z < 0
        v = np.where(neg, self._a() * z, z)
        return np.where(neg, down_np(v), v), np.where(neg, up_np(v), v)

    def slope_range(self, lo, hi):
        lo, hi = _arr(lo), _arr(hi)
        a = self._a()
        has_neg, has_pos = lo <= 0.0, hi >= 0.0  # 0 itself carries both slopes (Clarke)
        slo = np.where(has_neg & has_pos, np.minimum(a, 1.0), np.where(has_neg, a, 1.0))
        shi = np.where(has_neg & has_pos, np.maximum(a, 1.0), np.where(has_neg, a, 1.0))
        return slo.astype(np.float64), shi.astype(np.float64)

    def second_range(self, lo, hi):
        if self.smooth:
            return np.zeros_like(_arr(lo)), np.zeros_like(_arr(hi))
        return None

    @property
    def bounds(self) -> ActivationBounds:
        lo, hi = min(min(self.slopes), 1.0), max(max(self.slopes), 1.0)
        return ActivationBounds(self.spec, lo, hi, hi, 0.0 if self.smooth else math.inf)

    def _limits(self):
        return (min(min(self.slopes), 1.0), max(max(self.slopes), 1.0)), (0.0, 0.0)


# --------------------------------------------------------------------------- tanh, sigmoid


@dataclass(frozen=True)
class Tanh(Activation):
    """``tanh``: increasing, values in ``(-1, 1)``.

    ``tanh' = sech^2`` is even and decreasing in ``|z|`` (one critical point, 0, value 1);
    ``tanh'' = -2 tanh sech^2`` is odd with ``tanh''' = -2 sech^2 (1 - 3 tanh^2)``: extremes
    ``-+4/(3 sqrt 3)`` at ``+-a*``, ``a* = atanh(1/sqrt 3)``, monotone between. Point values use
    the cancellation-free ``sech^2 = 4 e^{-2|z|} / (1 + e^{-2|z|})^2``, never ``1 - tanh^2``.
    """

    name: ClassVar[str] = "tanh"
    onnx_op: ClassVar[str] = "Tanh"
    value_range: ClassVar[tuple[float, float]] = (-1.0, 1.0)

    def apply(self, z, xp=np):
        return xp.tanh(z)

    def prime_np(self, z):
        e = np.exp(-2.0 * np.abs(_arr(z)))
        return 4.0 * e / ((1.0 + e) * (1.0 + e))

    def _value_point(self, z):
        return tanh_bounds(z)

    def _slope_point(self, z):
        return sech2_bounds(np.abs(z))

    def _second_point(self, z):
        t_lo, t_hi = tanh_bounds(z)
        p_lo, p_hi = imul(t_lo, t_hi, *sech2_bounds(np.abs(z)))
        return -2.0 * p_hi, -2.0 * p_lo

    def _crits(self):
        return _tanh_crits()

    def _limits(self):
        return (0.0, 0.0), (0.0, 0.0)


@functools.cache
def _tanh_crits():
    a = arb(1 / arb(3).sqrt()).atanh()
    # brackets from Arb directly: a* in [arb_lo, arb_hi]; tanh'' over them in Arb
    a_lo, a_hi = arb_lo(a), arb_hi(a)

    def second(x: arb) -> arb:
        return -2 * x.tanh() * x.sech() ** 2

    def crit(lo: float, hi: float):
        v = second(arb(0.5 * (lo + hi), 0.5 * (hi - lo)))
        return lo, hi, arb_lo(v), arb_hi(v)

    return (), ((0.0, 0.0, 1.0, 1.0),), (crit(a_lo, a_hi), crit(-a_hi, -a_lo))


def _sigmoid_point(z: np.ndarray) -> Pair:
    """Enclosure of ``sigma(z) = 1 / (1 + e^{-z})``: decreasing in ``e``, each step outward."""
    e_lo, e_hi = exp_bounds(-z)
    with np.errstate(over="ignore"):
        lo = down_np(1.0 / up_np(1.0 + e_hi))
        hi = up_np(1.0 / down_np(1.0 + e_lo))
    return np.clip(lo, 0.0, 1.0), np.clip(hi, 0.0, 1.0)


def _sigmoid_prime_point(z: np.ndarray) -> Pair:
    """``sigma'(z) = e / (1 + e)^2`` with ``e = e^{-|z|}`` in ``[0, 1]``, where it increases."""
    e_lo, e_hi = exp_bounds(-np.abs(z))
    e_lo, e_hi = np.clip(e_lo, 0.0, 1.0), np.clip(e_hi, 0.0, 1.0)
    d_hi, d_lo = up_np(1.0 + e_lo), down_np(1.0 + e_hi)
    lo = down_np(e_lo / up_np(d_hi * d_hi))
    hi = up_np(e_hi / down_np(d_lo * d_lo))
    return np.clip(lo, 0.0, 0.25), np.clip(hi, 0.0, 0.25)


def _sigmoid_second_point(z: np.ndarray) -> Pair:
    """``sigma'' = -sigma' tanh(z/2)``. ``z/2`` is exact unless subnormal, where its rounding
    (``<= 2^-1075``) is far below the absolute pad ``LIBM_ABS`` of ``tanh_bounds``."""
    t_lo, t_hi = tanh_bounds(0.5 * z)
    p_lo, p_hi = imul(t_lo, t_hi, *_sigmoid_prime_point(z))
    return -p_hi, -p_lo


def _expit(z):
    """scipy's logistic ``1 / (1 + e^{-z})``, elementwise (no overflow for large ``|z|``)."""
    from scipy.special import expit  # scipy: 0.13 CPU-s to import, sigmoid and SiLU only

    return expit(z)


@dataclass(frozen=True)
class Sigmoid(Activation):
    """The logistic ``sigma(z) = 1 / (1 + e^{-z})``: increasing, values in ``(0, 1)``.

    ``sigma' = sigma (1 - sigma) = e^{-|z|} / (1 + e^{-|z|})^2`` is even, decreasing in ``|z|``,
    maximum ``1/4`` at 0; ``sigma'' = sigma' (1 - 2 sigma) = -sigma' tanh(z/2) = tanh''(z/2) / 8``:
    extremes ``-+sqrt 3 / 18`` at ``+-ln(2 + sqrt 3)``, monotone between.
    """

    name: ClassVar[str] = "sigmoid"
    onnx_op: ClassVar[str] = "Sigmoid"
    value_range: ClassVar[tuple[float, float]] = (0.0, 1.0)

    def apply(self, z, xp=np):
        if xp is np:
            return _expit(z)
        import jax  # jax: keep off the CLI start-up path

        return jax.nn.sigmoid(z)

    def prime_np(self, z):
        e = np.exp(-np.abs(_arr(z)))
        return e / ((1.0 + e) * (1.0 + e))

    def _value_point(self, z):
        return _sigmoid_point(z)

    def _slope_point(self, z):
        return _sigmoid_prime_point(z)

    def _second_point(self, z):
        return _sigmoid_second_point(z)

    def _crits(self):
        return _sigmoid_crits()

    def _limits(self):
        return (0.0, 0.0), (0.0, 0.0)


def _arb_sigma_second(x: arb) -> arb:
    s = _arb_sigma(x)
    return s * (1 - s) * (1 - 2 * s)


def _arb_sigma_third(x: arb) -> arb:
    s = _arb_sigma(x)
    return s * (1 - s) * (1 - 6 * s + 6 * s * s)


@functools.cache
def _sigmoid_crits():
    z = float(math.log(2.0 + math.sqrt(3.0)))
    return (
        (),
        ((0.0, 0.0, 0.25, 0.25),),
        (
            _bracket(z, _arb_sigma_third, _arb_sigma_second),
            _bracket(-z, _arb_sigma_third, _arb_sigma_second),
        ),
    )


# --------------------------------------------------------------------------- softplus, silu


@dataclass(frozen=True)
class Softplus(Activation):
    """``s(z) = log(1 + e^z) = max(z, 0) + log1p(e^{-|z|})``: increasing;
    ``s' = sigma`` (increasing, in ``(0, 1)``), ``s'' = sigma'`` (see :class:`Sigmoid`)."""

    name: ClassVar[str] = "softplus"
    onnx_op: ClassVar[str] = "Softplus"

    def apply(self, z, xp=np):
        return xp.logaddexp(z, 0.0)

    def prime_np(self, z):
        return _expit(_arr(z))

    def _value_point(self, z):
        e_lo, e_hi = exp_bounds(-np.abs(z))
        l_lo, _ = log1p_bounds(np.clip(e_lo, 0.0, 1.0))
        _, l_hi = log1p_bounds(np.clip(e_hi, 0.0, 1.0))
        m = np.maximum(z, 0.0)
        return add_down_np(m, l_lo), add_up_np(m, l_hi)

    def _slope_point(self, z):
        return _sigmoid_point(z)

    def _second_point(self, z):
        return _sigmoid_prime_point(z)

    def _crits(self):
        return (), (), ((0.0, 0.0, 0.25, 0.25),)

    def _limits(self):
        return (0.0, 1.0), (0.0, 0.0)


def _arb_silu_prime(x: arb) -> arb:
    s = _arb_sigma(x)
    return s + x * s * (1 - s)


def _arb_silu_second(x: arb) -> arb:
    s = _arb_sigma(x)
    return 2 * s * (1 - s) + x * _arb_sigma_second(x)


def _arb_silu_third(x: arb) -> arb:
    return 3 * _arb_sigma_second(x) + x * _arb_sigma_third(x)


@dataclass(frozen=True)
class Silu(Activation):
    """SiLU / swish ``s(z) = z sigma(z)``.

    ``s' = sigma + z sigma'`` vanishes once, at ``z1 ~ -1.2785`` (``s`` decreases before,
    increases after); ``s'' = 2 sigma' + z sigma'' = sigma' (2 - z tanh(z/2))`` is even and
    vanishes at ``+-z2 ~ +-2.3994`` (``s'`` extremes ``~ -0.0998`` and ``~ 1.0998``);
    ``s''' = 3 sigma'' + z sigma'''`` vanishes at 0 and ``+-z3`` (``s''`` peaks at 1/2
    at 0, troughs at ``+-z3 ~ +-3.4358``). Between these points each function is monotone.
    """

    name: ClassVar[str] = "silu"
    onnx_op: ClassVar[str] = ""  # written as Sigmoid and Mul by a PyTorch export; see networks.md

    def apply(self, z, xp=np):
        return z * Sigmoid().apply(z, xp)

    def prime_np(self, z):
        z = _arr(z)
        s = _expit(z)
        return s + z * s * (1.0 - s)

    def _value_point(self, z):
        return scale_point(z, *_sigmoid_point(z))

    def _slope_point(self, z):
        return iadd(*_sigmoid_point(z), *scale_point(z, *_sigmoid_prime_point(z)))

    def _second_point(self, z):
        p_lo, p_hi = _sigmoid_prime_point(z)
        return iadd(2.0 * p_lo, 2.0 * p_hi, *scale_point(z, *_sigmoid_second_point(z)))

    def _crits(self):
        return _silu_crits()

    def _limits(self):
        return (0.0, 1.0), (0.0, 0.0)


def _float_sigma(z: float) -> float:
    return float(_expit(z))


@functools.cache
def _silu_crits():
    def d1(z: float) -> float:
        s = _float_sigma(z)
        return s + z * s * (1 - s)

    def d2(z: float) -> float:
        s = _float_sigma(z)
        return 2 * s * (1 - s) + z * s * (1 - s) * (1 - 2 * s)

    def d3(z: float) -> float:
        s = _float_sigma(z)
        p = s * (1 - s)
        return 3 * p * (1 - 2 * s) + z * p * (1 - 6 * s + 6 * s * s)

    def silu(x: arb) -> arb:
        return x * _arb_sigma(x)

    z1 = _root(d1, -2.0, -1.0)
    z2 = _root(d2, 2.0, 3.0)
    z3 = _root(d3, 3.0, 5.0)
    return (
        (_bracket(z1, _arb_silu_prime, silu),),
        (
            _bracket(z2, _arb_silu_second, _arb_silu_prime),
            _bracket(-z2, _arb_silu_second, _arb_silu_prime),
        ),
        (
            (0.0, 0.0, 0.5, 0.5),
            _bracket(z3, _arb_silu_third, _arb_silu_second),
            _bracket(-z3, _arb_silu_third, _arb_silu_second),
        ),
    )


# --------------------------------------------------------------------------- elu


@dataclass(frozen=True)
class Elu(_OneSlope):
    """``s(z) = z`` for ``z > 0``, ``alpha (e^z - 1)`` for ``z <= 0`` (``alpha > 0``).

    Increasing. ``s' = 1`` on ``z > 0`` and ``alpha e^z`` (increasing) on ``z < 0``; at 0 the
    Clarke derivative is the hull of ``alpha`` and 1. ``s'`` is Lipschitz only for ``alpha = 1``
    (then ``s`` is ``C^{1,1}``, ``s'' = e^z`` on ``z < 0``, 0 on ``z > 0``, and the mean-value
    forms hold with this a.e. second derivative since ``s'`` is absolutely continuous).
    """

    alpha: float = 1.0
    name: ClassVar[str] = "elu"
    onnx_op: ClassVar[str] = "Elu"

    def __post_init__(self) -> None:
        a = float(self.alpha)
        if not (math.isfinite(a) and a > 0.0):
            raise SpecError(f"elu alpha must be finite and > 0, got {self.alpha!r}")
        object.__setattr__(self, "alpha", a)

    def apply(self, z, xp=np):
        return xp.where(z > 0, z, self.alpha * xp.expm1(xp.minimum(z, 0.0)))

    def prime_np(self, z):
        z = _arr(z)
        return np.where(z > 0, 1.0, self.alpha * np.exp(np.minimum(z, 0.0)))

    def _value_point(self, z):
        neg = z < 0
        zn = np.minimum(z, 0.0)
        m_lo, m_hi = widen_np(np.expm1(zn), LIBM_REL)
        m_lo, m_hi = np.clip(m_lo, -1.0, 0.0), np.clip(m_hi, -1.0, 0.0)
        lo = np.where(neg, down_np(self.alpha * m_lo), z)
        hi = np.where(neg, up_np(self.alpha * m_hi), z)
        return lo, hi

    def _neg_exp(self, lo, hi, scale: float) -> Pair:
        """``scale * e^z`` over ``[lo, min(hi, 0)]`` (increasing), outward."""
        e_lo, _ = exp_bounds(np.minimum(lo, 0.0))
        _, e_hi = exp_bounds(np.minimum(hi, 0.0))
        return np.maximum(down_np(scale * e_lo), 0.0), up_np(scale * np.minimum(e_hi, 1.0))

    def slope_range(self, lo, hi):
        lo, hi = _arr(lo), _arr(hi)
        n_lo, n_hi = self._neg_exp(lo, hi, self.alpha)
        has_neg, has_pos = lo <= 0.0, hi >= 0.0
        slo = np.where(has_neg, np.where(has_pos, np.minimum(n_lo, 1.0), n_lo), 1.0)
        shi = np.where(has_neg, np.where(has_pos, np.maximum(n_hi, 1.0), n_hi), 1.0)
        if self.alpha != 1.0:  # at 0 the left slope alpha joins the hull
            at0 = has_neg & has_pos
            slo = np.where(at0, np.minimum(slo, self.alpha), slo)
            shi = np.where(at0, np.maximum(shi, self.alpha), shi)
        return slo, shi

    def second_range(self, lo, hi):
        if not self.smooth:
            return None
        lo, hi = _arr(lo), _arr(hi)
        n_lo, n_hi = self._neg_exp(lo, hi, 1.0)
        has_neg, has_pos = lo < 0.0, hi > 0.0
        slo = np.where(has_neg, np.where(has_pos, 0.0, n_lo), 0.0)
        shi = np.where(has_neg, n_hi, 0.0)
        return slo, shi

    def _limits(self):
        return (0.0, 1.0), (0.0, 0.0)


# --------------------------------------------------------------------------- gelu


def _arb_Phi(z: arb) -> arb:
    """Normal CDF in Arb, ``erfc(-z / sqrt 2) / 2`` (no cancellation in the left tail)."""
    return (-z / arb(2).sqrt()).erfc() / 2


def _arb_phi(z: arb) -> arb:
    return (-z * z / 2).exp() / (2 * arb.pi()).sqrt()


def _arb_gelu(z: arb) -> arb:
    return z * _arb_Phi(z)


def _arb_gelu_prime(z: arb) -> arb:
    return _arb_Phi(z) + z * _arb_phi(z)


def _arb_gelu_second(z: arb) -> arb:
    return _arb_phi(z) * (2 - z * z)


def _arb_gelu_third(z: arb) -> arb:
    return _arb_phi(z) * z * (z * z - 4)


@dataclass(frozen=True)
class Gelu(Activation):
    """The exact (erf) GELU ``s(z) = z Phi(z)``.

    ``s' = Phi + z phi`` is negative before its single zero ``z* ~ -0.7518`` and positive after
    (``s`` decreases, then increases); ``s'' = phi (2 - z^2)`` vanishes at ``+-sqrt 2``
    (``s'`` extremes ``~ -0.12893`` and ``~ 1.12893``); ``s''' = phi z (z^2 - 4)`` vanishes at
    0 and ``+-2`` (``s''`` peaks at ``sqrt(2/pi)``, troughs at ``-2 phi(2)``). Point values use
    ``Phi`` from ``ndtr`` (``erfc`` in the tail), never ``1 + erf``.
    """

    name: ClassVar[str] = "gelu"
    onnx_op: ClassVar[str] = "Gelu"

    def apply(self, z, xp=np):
        if xp is np:
            from scipy.special import erf  # scipy: 0.13 CPU-s to import, GELU only

            return 0.5 * z * (1.0 + erf(z / np.sqrt(2.0)))
        from jax.scipy.special import erf as jax_erf  # jax: keep off the CLI start-up path

        return 0.5 * z * (1.0 + jax_erf(z / np.sqrt(2.0)))

    def prime_np(self, z):
        from scipy.special import ndtr  # scipy: 0.13 CPU-s to import, GELU only

        z = _arr(z)
        return ndtr(z) + z * _INV_SQRT_2PI * np.exp(-0.5 * z * z)

    def _value_point(self, z):
        return scale_point(z, *Phi_bounds(z))

    def _slope_point(self, z):
        p_lo, p_hi = Phi_bounds(z)
        q_lo, q_hi = scale_point(z, *phi_bounds(z))
        return down_np(p_lo + q_lo), up_np(p_hi + q_hi)

    def _second_point(self, z):
        zz_lo, zz_hi = down_np(z * z), up_np(z * z)
        return imul(*phi_bounds(z), down_np(2.0 - zz_hi), up_np(2.0 - zz_lo))

    def _crits(self):
        return _gelu_crits()

    def _limits(self):
        return (0.0, 1.0), (0.0, 0.0)


@functools.cache
def _gelu_crits():
    z1 = _root(lambda z: float(Gelu().prime_np(z)), -1.0, -0.5)
    s2 = math.sqrt(2.0)
    return (
        (_bracket(z1, _arb_gelu_prime, _arb_gelu),),
        (
            _bracket(s2, _arb_gelu_second, _arb_gelu_prime),
            _bracket(-s2, _arb_gelu_second, _arb_gelu_prime),
        ),
        (
            _bracket(0.0, _arb_gelu_third, _arb_gelu_second),
            _bracket(2.0, _arb_gelu_third, _arb_gelu_second),
            _bracket(-2.0, _arb_gelu_third, _arb_gelu_second),
        ),
    )


# --------------------------------------------------------------------------- registry

ACTIVATIONS: dict[str, type[Activation]] = {
    cls.name: cls
    for cls in (Identity, Relu, LeakyRelu, PRelu, Tanh, Sigmoid, Softplus, Silu, Elu, Gelu)
}
"""Every activation by name (one registry: the spec, the readers and the writer use it)."""
_ALIASES = {"swish": "silu", "linear": "identity"}
_PARAM = re.compile(r"^\s*([a-z_]+)\s*(?:\(\s*([^()]*?)\s*\))?\s*$")


def get_activation(spec: str | Activation | None) -> Activation:
    """The activation named by ``spec``: a registry name (``"relu"``, ``"swish"`` = ``"silu"``),
    a parameterised one (``"leaky_relu(0.2)"``, ``"elu(0.5)"``), ``None`` (identity) or an
    :class:`Activation` (returned as is). Unknown names raise
    :class:`~drip_cert.errors.SpecError` listing the registry."""
    if spec is None:
        return Identity()
    if isinstance(spec, Activation):
        return spec
    m = _PARAM.match(str(spec))
    known = ", ".join(sorted(ACTIVATIONS))
    if m is None:
        raise SpecError(f"activation {spec!r} is not one of {known} (optionally 'name(alpha)')")
    name = _ALIASES.get(m.group(1), m.group(1))
    cls = ACTIVATIONS.get(name)
    if cls is None:
        raise SpecError(f"activation {spec!r} is not one of {known}", field="activation")
    if m.group(2) is None or m.group(2) == "":
        return cls()
    if cls is PRelu:
        try:
            return PRelu(tuple(float(v) for v in m.group(2).split(",")))
        except ValueError:
            raise SpecError(
                f"activation {spec!r}: the slopes {m.group(2)!r} are not numbers separated by "
                "commas"
            ) from None
    if cls not in (LeakyRelu, Elu):
        raise SpecError(f"activation {name!r} takes no parameter, got {spec!r}")
    try:
        alpha = float(m.group(2))
    except ValueError:
        raise SpecError(f"activation {spec!r}: parameter {m.group(2)!r} is not a number") from None
    return cls(alpha)
