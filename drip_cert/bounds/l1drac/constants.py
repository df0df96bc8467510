"""The constants of L1-DRAC's Assumptions 1-8, validated: :class:`L1Constants`.

Source: A. Gahlawat, S. H. Karumanchi, N. Hovakimyan, "L1-DRAC: Distributionally Robust Adaptive
Control -- Global Results", arXiv:2509.04619 (2025-09-04), Sec. 2.2 (Assumptions 1-8), (16) and
(18a). The transcription used is ``docs/math/l1drac.md`` section 2.

Public surface
--------------
* :data:`CONSTANT_NAMES` -- every key of a ``[constants]`` table, in the order of the paper.
* :class:`L1Constants` -- the constants plus alpha, eps_r, eps_a (validated on construction).
* :class:`L1ConstantsLike` -- the attributes the formulas read (L1Constants or its Arb view).
* :func:`unmatched_gain_r`, :func:`unmatched_gain_a` -- the Assumption 7 factors of (16a), (16b).

The validators :func:`is_real`, :func:`check_real` and :func:`check_int` are shared with
:mod:`drip_cert.bounds.l1drac.request` and the later modules of this package.
"""

from __future__ import annotations

import math
import numbers
from collections.abc import Callable, Mapping
from dataclasses import dataclass
from typing import Any, ClassVar, Protocol

from drip_cert.bounds.l1drac.backend import FLOAT, Backend, Real
from drip_cert.errors import AssumptionViolation, SpecError
from drip_cert.spec.settings import POSITIVE_CONSTANTS

__all__ = [
    "CONSTANT_NAMES",
    "L1Constants",
    "L1ConstantsLike",
    "unmatched_gain_r",
    "unmatched_gain_a",
]

# The constants of Assumptions 1-8 (ASCII names as in the TOML file; 'lambda' is the attribute
# ``lam``), each with the assumption that defines it.
_REAL_FIELDS: tuple[tuple[str, str], ...] = (
    ("lambda", "Assumption 2 (contraction rate, > 0)"),
    ("Delta_f", "Assumption 1 (growth of f)"),
    ("Delta_p", "Assumption 1 (bound of p)"),
    ("L_p", "Assumption 1 (Hoelder constant of p in x)"),
    ("L_p_hat", "Assumption 1 (Lipschitz constant of p in t)"),
    ("Delta_g", "Assumption 1 (bound of g)"),
    ("Delta_g_dot", "Assumption 1 (bound of dg/dt)"),
    ("Delta_g_perp", "Assumption 1 (bound of g_perp)"),
    ("Delta_Theta", "Assumption 1 (bound of Theta_ad)"),
    ("Delta_star", "Assumption 3 (2p*-moment bound of the nominal state)"),
    ("Delta_mu", "Assumption 4 (growth of Lambda_mu)"),
    ("Delta_sigma", "Assumption 4 (growth of Lambda_sigma)"),
    ("Delta_mu_par", "Assumption 4 (growth of the matched Lambda_mu)"),
    ("Delta_mu_perp", "Assumption 4 (growth of the unmatched Lambda_mu)"),
    ("Delta_sigma_par", "Assumption 4 (growth of the matched Lambda_sigma)"),
    ("Delta_sigma_perp", "Assumption 4 (growth of the unmatched Lambda_sigma)"),
    ("Delta_p_par", "Assumption 5 (bound of p^par)"),
    ("Delta_p_perp", "Assumption 5 (bound of p^perp)"),
    ("L_p_par", "Assumption 5 (Hoelder constant of p^par in x)"),
    ("L_p_perp", "Assumption 5 (Hoelder constant of p^perp in x)"),
    ("L_p_par_hat", "Assumption 5 (Lipschitz constant of p^par in t)"),
    ("L_p_perp_hat", "Assumption 5 (Lipschitz constant of p^perp in t)"),
    ("L_mu", "Assumption 6 (Lipschitz constant of Lambda_mu in x)"),
    ("L_mu_hat", "Assumption 6 (Lipschitz constant of Lambda_mu in t)"),
    ("L_mu_par", "Assumption 6 (Lipschitz constant of Lambda_mu^par in x)"),
    ("L_mu_par_hat", "Assumption 6 (Lipschitz constant of Lambda_mu^par in t)"),
    ("L_mu_perp", "Assumption 6 (Lipschitz constant of Lambda_mu^perp in x)"),
    ("L_mu_perp_hat", "Assumption 6 (Lipschitz constant of Lambda_mu^perp in t)"),
    ("L_sigma", "Assumption 6 (Hoelder constant of Lambda_sigma in x)"),
    ("L_sigma_hat", "Assumption 6 (Lipschitz constant of Lambda_sigma in t)"),
    ("L_sigma_par", "Assumption 6 (Hoelder constant of Lambda_sigma^par in x)"),
    ("L_sigma_par_hat", "Assumption 6 (Lipschitz constant of Lambda_sigma^par in t)"),
    ("L_sigma_perp", "Assumption 6 (Hoelder constant of Lambda_sigma^perp in x)"),
    ("L_sigma_perp_hat", "Assumption 6 (Lipschitz constant of Lambda_sigma^perp in t)"),
    ("L_f", "Assumption 8 (Lipschitz constant of f in x; used only when lip_f = true)"),
    ("alpha", "(18a) (initial distance W_2p or ||X0 - X0*||_L2p)"),
    ("eps_r", "(16a) (slack, > 0)"),
    ("eps_a", "(16b) (slack, > 0)"),
)
_INT_FIELDS: tuple[tuple[str, str], ...] = (
    ("p_star", "Assumption 1 (highest moment order, integer >= 1)"),
    ("m", "Definition 1 (number of inputs, integer >= 1)"),
)
_BOOL_FIELDS: tuple[tuple[str, str], ...] = (("lip_f", "Assumption 8 holds (true/false)"),)

#: Every key of the ``[constants]`` table, in the order of the paper's assumptions.
CONSTANT_NAMES: tuple[str, ...] = tuple(n for n, _ in _REAL_FIELDS + _INT_FIELDS + _BOOL_FIELDS)


def _attr(name: str) -> str:
    """Attribute name of a constant ('lambda' is a Python keyword)."""
    return "lam" if name == "lambda" else name


def is_real(value: Any) -> bool:
    """A real number of Python's numeric tower, not a bool."""
    return isinstance(value, numbers.Real) and not isinstance(value, bool)


def check_real(name: str, value: Any, *, positive: bool, where: str, path: str | None) -> float:
    """``value`` as a finite float, > 0 when ``positive`` else >= 0 (SpecError naming ``name``,
    the ``where`` it is defined and ``path`` otherwise)."""
    if not is_real(value):
        raise SpecError(
            f"{value!r} is not a real number; {name} is the constant of {where}: give a number",
            field=name,
            path=path,
        )
    v = float(value)
    if not math.isfinite(v):
        raise SpecError(
            f"{value!r} is not finite; {name} ({where}) must be a finite number",
            field=name,
            path=path,
        )
    if positive and not v > 0.0:
        raise SpecError(f"{v!r} must be > 0 ({where})", field=name, path=path)
    if v < 0.0:
        raise SpecError(
            f"{v!r} is negative; {name} bounds a norm ({where}) and must be >= 0",
            field=name,
            path=path,
        )
    return v


def check_int(name: str, value: Any, *, where: str, path: str | None) -> int:
    """``value`` as an int >= 1; an integral float is accepted (SpecError otherwise)."""
    if isinstance(value, bool) or not isinstance(value, numbers.Integral):
        if is_real(value) and float(value).is_integer():
            value = int(value)
        else:
            raise SpecError(
                f"{value!r} is not an integer; {name} ({where}) must be an integer >= 1",
                field=name,
                path=path,
            )
    if value < 1:
        raise SpecError(f"{value!r} must be an integer >= 1 ({where})", field=name, path=path)
    return int(value)


def _checked_reals(value_of: Callable[[str], Any], path: str | None) -> dict[str, float]:
    """Every real constant, read by ``value_of(name)`` and checked, keyed by attribute name."""
    return {
        _attr(name): check_real(
            name, value_of(name), positive=name in POSITIVE_CONSTANTS, where=where, path=path
        )
        for name, where in _REAL_FIELDS
    }


class L1ConstantsLike(Protocol):
    """The fields of :class:`L1Constants` and its ``num``, read-only: what the formulas read.

    :class:`L1Constants` (floats, backend :data:`~drip_cert.bounds.l1drac.backend.FLOAT`) and
    :class:`drip_cert.bounds.l1drac.verify.ArbConstants` (Arb balls, backend
    :data:`~drip_cert.bounds.l1drac.backend.ARB`) both have them, so the same formulas evaluate
    either (the reals typed :data:`~drip_cert.bounds.l1drac.backend.Real`). Read-only.
    """

    @property
    def num(self) -> Backend: ...

    @property
    def lam(self) -> Real: ...

    @property
    def Delta_f(self) -> Real: ...

    @property
    def Delta_p(self) -> Real: ...

    @property
    def L_p(self) -> Real: ...

    @property
    def L_p_hat(self) -> Real: ...

    @property
    def Delta_g(self) -> Real: ...

    @property
    def Delta_g_dot(self) -> Real: ...

    @property
    def Delta_g_perp(self) -> Real: ...

    @property
    def Delta_Theta(self) -> Real: ...

    @property
    def Delta_star(self) -> Real: ...

    @property
    def p_star(self) -> int: ...

    @property
    def Delta_mu(self) -> Real: ...

    @property
    def Delta_sigma(self) -> Real: ...

    @property
    def Delta_mu_par(self) -> Real: ...

    @property
    def Delta_mu_perp(self) -> Real: ...

    @property
    def Delta_sigma_par(self) -> Real: ...

    @property
    def Delta_sigma_perp(self) -> Real: ...

    @property
    def Delta_p_par(self) -> Real: ...

    @property
    def Delta_p_perp(self) -> Real: ...

    @property
    def L_p_par(self) -> Real: ...

    @property
    def L_p_perp(self) -> Real: ...

    @property
    def L_p_par_hat(self) -> Real: ...

    @property
    def L_p_perp_hat(self) -> Real: ...

    @property
    def L_mu(self) -> Real: ...

    @property
    def L_mu_hat(self) -> Real: ...

    @property
    def L_mu_par(self) -> Real: ...

    @property
    def L_mu_par_hat(self) -> Real: ...

    @property
    def L_mu_perp(self) -> Real: ...

    @property
    def L_mu_perp_hat(self) -> Real: ...

    @property
    def L_sigma(self) -> Real: ...

    @property
    def L_sigma_hat(self) -> Real: ...

    @property
    def L_sigma_par(self) -> Real: ...

    @property
    def L_sigma_par_hat(self) -> Real: ...

    @property
    def L_sigma_perp(self) -> Real: ...

    @property
    def L_sigma_perp_hat(self) -> Real: ...

    @property
    def L_f(self) -> Real: ...

    @property
    def lip_f(self) -> bool: ...

    @property
    def m(self) -> int: ...

    @property
    def alpha(self) -> Real: ...

    @property
    def eps_r(self) -> Real: ...

    @property
    def eps_a(self) -> Real: ...


@dataclass(frozen=True, kw_only=True)
class L1Constants:
    """The constants of L1-DRAC's Assumptions 1-8 (Sec. 2.2), the initial distance and the slacks.

    Every field is keyword-only and required: a forgotten constant must not silently become 0.
    ``lam`` is the paper's lambda (printed and read as ``'lambda'``, see :meth:`from_mapping` and
    :meth:`to_dict`). Validated on construction: reals finite and >= 0, ``lam``, ``eps_r``,
    ``eps_a`` > 0, ``p_star`` and ``m`` integers >= 1, ``lip_f`` a bool
    (:class:`~drip_cert.errors.SpecError` naming the field otherwise), and Assumption 7,
    ``lambda > Delta_g_perp * max(Delta_mu_perp, L_mu_perp)``
    (:class:`~drip_cert.errors.AssumptionViolation` with the numbers otherwise).

    Three constants are accepted but appear in no formula of the paper: ``L_mu_perp_hat``,
    ``L_sigma_perp_hat``, ``L_p_perp_hat`` (and hat-L_f, which is not a field).

    ``num`` (a class attribute, not a field) is the float64 backend of the appendix formulas
    (:data:`drip_cert.bounds.l1drac.backend.FLOAT`); the Arb view of
    :class:`drip_cert.bounds.l1drac.verify.ArbConstants` carries the Arb one.
    """

    num: ClassVar[Backend] = FLOAT

    lam: float
    Delta_f: float
    Delta_p: float
    L_p: float
    L_p_hat: float
    Delta_g: float
    Delta_g_dot: float
    Delta_g_perp: float
    Delta_Theta: float
    Delta_star: float
    p_star: int
    Delta_mu: float
    Delta_sigma: float
    Delta_mu_par: float
    Delta_mu_perp: float
    Delta_sigma_par: float
    Delta_sigma_perp: float
    Delta_p_par: float
    Delta_p_perp: float
    L_p_par: float
    L_p_perp: float
    L_p_par_hat: float
    L_p_perp_hat: float
    L_mu: float
    L_mu_hat: float
    L_mu_par: float
    L_mu_par_hat: float
    L_mu_perp: float
    L_mu_perp_hat: float
    L_sigma: float
    L_sigma_hat: float
    L_sigma_par: float
    L_sigma_par_hat: float
    L_sigma_perp: float
    L_sigma_perp_hat: float
    L_f: float
    lip_f: bool
    m: int
    alpha: float
    eps_r: float
    eps_a: float

    def __post_init__(self) -> None:
        for attr, v in _checked_reals(lambda name: getattr(self, _attr(name)), None).items():
            object.__setattr__(self, attr, v)
        for name, where in _INT_FIELDS:
            v_int = check_int(name, getattr(self, name), where=where, path=None)
            object.__setattr__(self, name, v_int)
        if not isinstance(self.lip_f, bool):
            raise SpecError(
                f"{self.lip_f!r} is not a boolean; lip_f says whether Assumption 8 holds: "
                "give true or false",
                field="lip_f",
            )
        # Assumption 7 (unmatched small gain)
        gain = self.Delta_g_perp * max(self.Delta_mu_perp, self.L_mu_perp)
        if not self.lam > gain:
            raise AssumptionViolation(
                "Assumption 7 fails: lambda = "
                f"{self.lam!r} must exceed Delta_g_perp * max(Delta_mu_perp, L_mu_perp) = "
                f"{self.Delta_g_perp!r} * max({self.Delta_mu_perp!r}, {self.L_mu_perp!r}) = "
                f"{gain!r}; the unmatched uncertainty is too strong for the nominal contraction"
            )

    @classmethod
    def from_mapping(cls, data: Mapping[str, Any], *, path: str | None = None) -> L1Constants:
        """Build from a mapping whose keys are exactly :data:`CONSTANT_NAMES` ('lambda', ...).

        Raises
        ------
        SpecError
            Unknown or missing keys, wrong types, NaN/inf, negative values (naming the key and
            ``path`` when given).
        """
        unknown = sorted(set(data) - set(CONSTANT_NAMES))
        if unknown:
            raise SpecError(
                f"unknown constant(s) {unknown}; the allowed keys are {list(CONSTANT_NAMES)}",
                field="constants." + unknown[0],
                path=path,
            )
        missing = [n for n in CONSTANT_NAMES if n not in data]
        if missing:
            raise SpecError(
                f"missing constant(s) {missing}: every constant must be given explicitly "
                "(write 0 for a term that is absent)",
                field="constants." + missing[0],
                path=path,
            )
        kwargs: dict[str, Any] = _checked_reals(data.__getitem__, path)
        for name, where in _INT_FIELDS:
            value = data[name]
            if isinstance(value, bool) or not isinstance(value, numbers.Integral):
                raise SpecError(
                    f"{value!r} is not an integer; {name} ({where}) must be an integer >= 1",
                    field="constants." + name,
                    path=path,
                )
            kwargs[name] = check_int(name, value, where=where, path=path)
        for name, where in _BOOL_FIELDS:
            if not isinstance(data[name], bool):
                raise SpecError(
                    f"{data[name]!r} is not a boolean; {name}: {where}",
                    field="constants." + name,
                    path=path,
                )
            kwargs[name] = data[name]
        return cls(**kwargs)

    def to_dict(self) -> dict[str, Any]:
        """JSON-ready dictionary with the TOML key names ('lambda' for ``lam``)."""
        return {n: getattr(self, _attr(n)) for n in CONSTANT_NAMES}

    @property
    def k_r(self) -> float:
        """Delta_g_perp Delta_mu_perp / lambda in [0, 1) (Assumption 7); the factor of (16a)."""
        return unmatched_gain_r(self)

    @property
    def k_a(self) -> float:
        """Delta_g_perp L_mu_perp / lambda in [0, 1) (Assumption 7); the factor of (16b)."""
        return unmatched_gain_a(self)


def unmatched_gain_r(c: L1ConstantsLike) -> Real:
    """k_r = Delta_g_perp Delta_mu_perp / lambda, in [0, 1) by Assumption 7; the factor of (16a)."""
    return c.Delta_g_perp * c.Delta_mu_perp / c.lam


def unmatched_gain_a(c: L1ConstantsLike) -> Real:
    """k_a = Delta_g_perp L_mu_perp / lambda, in [0, 1) by Assumption 7; the factor of (16b)."""
    return c.Delta_g_perp * c.L_mu_perp / c.lam
