"""Typed settings of a specification: one frozen object per settings table, validated at load.

:func:`~drip_cert.spec.load.load_spec` builds a :class:`Settings` from the optional tables

* ``[contraction]`` -> :class:`ContractionSettings` (the contraction analysis),
* ``[l1drac]`` -> :class:`L1Settings` (the L1-DRAC design inputs),
* ``[tasil]`` -> :class:`TasilSettings` (training and the TaSIL certificate),
* ``[simulation]`` -> :class:`SimSettings` (practical parameters of the Monte Carlo),
* ``[constants]`` -> :class:`ConstantsTable` (user-given values of paper constants),

so that ``drip-cert check-spec`` rejects every bad value and every unknown key before anything is
computed. Each class holds the ONE set of defaults of its table (the dataclass defaults) and
reads its table with the small typed field readers of this module; every error is a
:class:`~drip_cert.errors.SpecError` naming the file, ``table.key`` as written in the spec, the
value, what is allowed and the fix (the default, a "did you mean" for a misspelt key).
"""

from __future__ import annotations

import dataclasses
import difflib
import json
import math
import re
from collections.abc import Callable, Mapping, Sequence
from dataclasses import dataclass, field
from types import MappingProxyType
from typing import Any, ClassVar, TypedDict, cast

import numpy as np

from drip_cert.errors import SpecError
from drip_cert.model.literals import DecimalFloat
from drip_cert.numerics.stats import min_trials_zero_failures
from drip_cert.provenance import Scope
from drip_cert.vocabulary import CONTRACTION_METHODS

TABLES = ("constants", "contraction", "l1drac", "tasil", "simulation")
"""The settings tables of a spec, in the order of the README."""

CONSTANT_NAMES: tuple[str, ...] = (
    "lambda",
    "Delta_f",
    "Delta_p",
    "L_p",
    "L_p_hat",
    "Delta_g",
    "Delta_g_dot",
    "Delta_g_perp",
    "Delta_Theta",
    "Delta_star",
    "Delta_mu",
    "Delta_sigma",
    "Delta_mu_par",
    "Delta_mu_perp",
    "Delta_sigma_par",
    "Delta_sigma_perp",
    "Delta_p_par",
    "Delta_p_perp",
    "L_p_par",
    "L_p_perp",
    "L_p_par_hat",
    "L_p_perp_hat",
    "L_mu",
    "L_mu_hat",
    "L_mu_par",
    "L_mu_par_hat",
    "L_mu_perp",
    "L_mu_perp_hat",
    "L_sigma",
    "L_sigma_hat",
    "L_sigma_par",
    "L_sigma_par_hat",
    "L_sigma_perp",
    "L_sigma_perp_hat",
    "L_f",
    "alpha",
    "eps_r",
    "eps_a",
)
"""The keys of ``[constants]``: every real constant of L1-DRAC Assumptions 1-8 and (16), (18a)
that the certificate computes (the real constants of ``drip_cert.bounds.l1drac.constants``)."""

POSITIVE_CONSTANTS = frozenset({"lambda", "eps_r", "eps_a"})
"""Constants that must be > 0 (a contraction rate, the slacks of (16)); the others bound norms
and must be >= 0."""

_ELSEWHERE = {
    "p_star": "p_star is a design input: give it in [l1drac]",
    "lip_f": "lip_f is a design input: give it in [l1drac]",
    "m": "m is the number of columns of [dynamics] g, not a setting",
}


# ------------------------------------------------------------------------------ field readers
_BARE_KEY = re.compile(r"^[A-Za-z0-9_-]+$")


def toml_key(key: Any) -> str:
    """A TOML key: bare when it may be, else a quoted (basic string) key."""
    key = str(key)
    return key if _BARE_KEY.match(key) else json.dumps(key)


def toml_text(value: Any, *, strict: bool = False, where: str = "") -> str:
    """``value`` as it is written in TOML: for messages, and (``strict``) for the specs
    ``drip-cert train --write-spec`` writes. A :class:`~drip_cert.model.literals.DecimalFloat`
    keeps the text it was read from. A value TOML cannot hold is its ``repr`` in a message, and a
    SpecError naming ``where`` when ``strict``."""

    def text(v: Any) -> str:
        if isinstance(v, bool):
            return "true" if v else "false"
        if isinstance(v, DecimalFloat):
            return v.text
        if isinstance(v, int):
            return str(v)
        if isinstance(v, str):
            return json.dumps(v)  # a TOML basic string: JSON's escapes are TOML's
        if isinstance(v, float):
            if math.isnan(v):
                return "nan"
            if math.isinf(v):
                return "inf" if v > 0 else "-inf"
            return repr(v)
        if isinstance(v, Mapping):
            return "{ " + ", ".join(f"{toml_key(k)} = {text(x)}" for k, x in v.items()) + " }"
        if isinstance(v, list | tuple):
            return "[" + ", ".join(text(x) for x in v) + "]"
        if strict:
            raise SpecError(f"cannot write {type(v).__name__} {v!r} as a spec value", field=where)
        return repr(v)

    return text(value)
    if isinstance(value, Mapping):
        return "{ " + ", ".join(f"{k} = {toml_text(v)}" for k, v in value.items()) + " }"
    if isinstance(value, list | tuple):
        return "[" + ", ".join(toml_text(v) for v in value) + "]"
    return repr(value)


_NO_DEFAULT = object()


@dataclass(frozen=True)
class Field:
    """One ``table.key`` of a spec: where it is and what it means (for error messages)."""

    table: str
    key: str
    path: str | None = None
    meaning: str = ""
    default: Any = _NO_DEFAULT
    example: Any = None

    @property
    def name(self) -> str:
        return f"{self.table}.{self.key}"

    def error(self, value: Any, rule: str, fix: str = "") -> SpecError:
        """``SpecError``: the value as written, the rule it breaks (with the key's meaning) and
        the fix (``fix``, else the default, else an example)."""
        what = f"{self.key} ({self.meaning})" if self.meaning else self.key
        msg = f"{self.key} = {toml_text(value)} is not allowed: {what} must be {rule}"
        if not fix:
            if self.default is not _NO_DEFAULT and self.default is not None:
                fix = (
                    f"write e.g. {self.key} = {toml_text(self.default)} "
                    "(the default), or remove the key"
                )
            elif self.example is not None:
                fix = f"write e.g. {self.key} = {toml_text(self.example)}, or remove the key"
            else:
                fix = "correct the value or remove the key"
        return SpecError(f"{msg}; {fix}", field=self.name, path=self.path)


def _is_number(value: Any) -> bool:
    return isinstance(value, int | float) and not isinstance(value, bool)


def read_real(
    value: Any,
    f: Field,
    rule: str,
    ok: Callable[[float], bool],
    *,
    allow_inf: bool = False,
) -> float:
    """A real number (a TOML integer or float, never a boolean, never NaN; ``+inf`` only when
    ``allow_inf``) for which ``ok`` holds; ``rule`` says what is allowed."""
    if not _is_number(value):
        raise f.error(value, rule)
    x = float(value)
    if math.isnan(x) or (math.isinf(x) and not (allow_inf and x > 0)) or not ok(x):
        raise f.error(value, rule)
    return x


def positive_float(value: Any, f: Field) -> float:
    """A finite number > 0."""
    return read_real(value, f, "a finite number > 0", lambda x: x > 0)


def positive_or_inf(value: Any, f: Field) -> float:
    """A number > 0, ``inf`` allowed (a radius or a time limit that may be absent)."""
    return read_real(value, f, "a number > 0 (inf allowed)", lambda x: x > 0, allow_inf=True)


def nonneg_float(value: Any, f: Field) -> float:
    """A finite number >= 0."""
    return read_real(value, f, "a finite number >= 0", lambda x: x >= 0)


def probability(value: Any, f: Field) -> float:
    """A probability in the open interval (0, 1)."""
    return read_real(value, f, "a number in (0, 1)", lambda x: 0 < x < 1)


def integer(value: Any, f: Field, *, minimum: int | None = None, rule: str = "") -> int:
    """A TOML integer (not a float, not a boolean), at least ``minimum``; ``rule`` replaces
    the generated description of what is allowed."""
    if not rule:
        if minimum == 1:
            rule = "a positive integer"
        elif minimum == 0:
            rule = "an integer >= 0"
        elif minimum is not None:
            rule = f"an integer >= {minimum}"
        else:
            rule = "an integer"
    if isinstance(value, bool) or not isinstance(value, int):
        raise f.error(value, rule)
    if minimum is not None and value < minimum:
        raise f.error(value, rule)
    return int(value)


def positive_int(value: Any, f: Field) -> int:
    """An integer >= 1."""
    return integer(value, f, minimum=1)


def nonneg_int(value: Any, f: Field) -> int:
    """An integer >= 0."""
    return integer(value, f, minimum=0)


def boolean(value: Any, f: Field) -> bool:
    """``true`` or ``false``."""
    if not isinstance(value, bool):
        raise f.error(value, "true or false")
    return value


def one_of(value: Any, f: Field, choices: Sequence[Any]) -> Any:
    """One of ``choices`` (strings or integers; booleans never match integers)."""
    ok = any(type(value) is type(c) and value == c for c in choices)
    if not ok:
        raise f.error(value, "one of " + ", ".join(toml_text(c) for c in choices))
    return value


METRIC_CHOICES = ("auto", "euclidean", "lmi")


def metric_choice(
    value: Any, f: Field, n: int | None
) -> tuple[str, tuple[tuple[float, ...], ...] | None]:
    """``[contraction] metric``: ``"auto"`` (certify in the coordinates of an LMI metric when the
    Euclidean rate fails or is slower), ``"euclidean"`` (never), ``"lmi"`` (always, when one is
    found), a given ``n x n`` symmetric positive definite matrix ``P``, or ``true`` / ``false``
    (``"auto"`` / ``"euclidean"``)."""
    if isinstance(value, bool):
        return ("auto" if value else "euclidean"), None
    if isinstance(value, str):
        return one_of(value, f, METRIC_CHOICES), None
    rule = (
        'one of "auto", "euclidean", "lmi", true, false, or a symmetric positive definite '
        f"{n} x {n} matrix P"
    )
    if not isinstance(value, list) or n is None or len(value) != n:
        raise f.error(value, rule)
    rows = []
    for row in value:
        if not isinstance(row, list) or len(row) != n:
            raise f.error(value, rule)
        for v in row:
            if isinstance(v, bool) or not isinstance(v, int | float) or not math.isfinite(v):
                raise f.error(value, rule)
        rows.append(tuple(float(v) for v in row))
    P = np.array(rows)
    if not np.array_equal(P, P.T):
        raise f.error(value, rule, "P must be exactly symmetric (P[i][j] == P[j][i])")
    try:
        np.linalg.cholesky(P)
    except np.linalg.LinAlgError:
        raise f.error(value, rule, "P must be positive definite") from None
    return "given", tuple(rows)


def string(value: Any, f: Field) -> str:
    """A non-empty string."""
    if not isinstance(value, str) or not value.strip():
        raise f.error(value, "a non-empty string")
    return value


def int_list(value: Any, f: Field) -> tuple[int, ...]:
    """A non-empty list of positive integers."""
    if (
        not isinstance(value, list)
        or not value
        or any(isinstance(h, bool) or not isinstance(h, int) or h < 1 for h in value)
    ):
        raise f.error(value, "a non-empty list of positive integers")
    return tuple(int(h) for h in value)


def box(value: Any, f: Field, n: int) -> tuple[tuple[float, float], ...]:
    """A box ``[[lo_1, hi_1], ..., [lo_n, hi_n]]`` of finite numbers with ``lo_i <= hi_i``."""
    rule = f"a list of {n} pairs [lo, hi] of finite numbers with lo <= hi (one per state)"
    if not isinstance(value, list) or len(value) != n:
        raise f.error(value, rule)
    out = []
    for i, pair in enumerate(value):
        if not isinstance(pair, list) or len(pair) != 2:
            raise f.error(value, rule, f"entry {i} is not a pair [lo, hi]")
        for v in pair:
            if not _is_number(v) or not math.isfinite(float(v)):
                raise f.error(
                    value, rule, f"bound {toml_text(v)} of state {i} is not a finite number"
                )
        lo, hi = float(pair[0]), float(pair[1])
        if lo > hi:
            raise f.error(value, rule, f"interval {i} is empty (lo = {lo:g} > hi = {hi:g})")
        out.append((lo, hi))
    return tuple(out)


class TableReader:
    """Reads one settings table: rejects unknown keys (with a "did you mean"), then reads each
    key with a typed field reader, falling back to the default when the key is absent.

    Parameters
    ----------
    name
        The table's name (``simulation``).
    table
        Its contents as parsed from TOML (``None``: absent).
    keys
        Every allowed key with its meaning (used in messages).
    path
        The spec file, for messages.
    elsewhere
        Keys that belong in another table or nowhere, with the message to give.
    """

    def __init__(
        self,
        name: str,
        table: Mapping[str, Any] | None,
        keys: Mapping[str, str],
        path: str | None = None,
        elsewhere: Mapping[str, str] | None = None,
    ) -> None:
        self.name = name
        self.path = None if path is None else str(path)
        self.keys = keys
        if table is None:
            table = {}
        if not isinstance(table, Mapping):
            raise SpecError(
                f"[{name}] must be a table of key = value pairs, got {toml_text(table)}",
                field=name,
                path=self.path,
            )
        self.table = table
        for key in table:
            if key not in keys:
                raise self._unknown(str(key), elsewhere or {})

    def _unknown(self, key: str, elsewhere: Mapping[str, str]) -> SpecError:
        allowed = ", ".join(self.keys)
        if key in elsewhere:
            msg = f"{key} is not a key of [{self.name}]: {elsewhere[key]}."
        else:
            close = difflib.get_close_matches(key, list(self.keys), n=3, cutoff=0.6)
            msg = f"unknown key {key} (= {toml_text(self.table[key])}) in [{self.name}]"
            if close:
                msg += ". Did you mean " + " or ".join(close) + "?"
            else:
                msg += "."
        return SpecError(
            f"{msg} Allowed keys: {allowed}", field=f"{self.name}.{key}", path=self.path
        )

    @property
    def given(self) -> frozenset[str]:
        """The keys the spec writes."""
        return frozenset(self.table)

    def field_of(self, key: str, default: Any = _NO_DEFAULT, example: Any = None) -> Field:
        return Field(self.name, key, self.path, self.keys.get(key, ""), default, example)

    def get(self, key: str, read: Callable[..., Any], default: Any, *args: Any, **kw: Any) -> Any:
        """``read(value, field, *args, **kw)`` when ``key`` is written, else ``default``."""
        if key not in self.table:
            return default
        return read(
            self.table[key], self.field_of(key, default, kw.pop("example", None)), *args, **kw
        )


# ------------------------------------------------------------------------------ declarations
def setting(
    default: Any,
    description: str,
    read: Callable[..., Any] | None = None,
    *args: Any,
    key: str | None = None,
    example: Any = None,
    factory: Callable[[], Any] | None = None,
    **kw: Any,
) -> Any:
    """Declare one key of a settings table, once: its default, its meaning and its reader.

    The dataclass field this returns carries everything else the project needs about the key:
    the table's allowed keys and their meanings (:func:`table_keys`, for messages and the spec
    reference of the documentation), how it is read from TOML (:func:`read_declared`:
    ``read(value, field, *args, **kw)``) and how a value set from Python is checked
    (:func:`validate_declared`). ``read = None`` marks a key whose reading needs more than its
    own value (the region needs the state dimension); its class reads and checks it.
    ``key`` is the TOML key when it differs from the field's name; ``factory`` replaces
    ``default`` when the default must be computed.
    """
    meta = MappingProxyType(
        {
            "description": description,
            "read": read,
            "args": args,
            "kw": MappingProxyType(kw),
            "example": example,
            "key": key,
        }
    )
    if factory is not None:
        return field(default_factory=factory, metadata=meta)
    return field(default=default, metadata=meta)


def declared(cls: Any) -> tuple[dataclasses.Field[Any], ...]:
    """The fields of a settings class that are keys of its table, in declaration order."""
    return tuple(f for f in dataclasses.fields(cls) if "description" in f.metadata)


def _key(f: dataclasses.Field[Any]) -> str:
    return f.metadata["key"] or f.name


def _default(f: dataclasses.Field[Any]) -> Any:
    if f.default is not dataclasses.MISSING:
        return f.default
    return f.default_factory()  # type: ignore[operator]


def table_keys(cls: Any) -> Mapping[str, str]:
    """Every key of a settings table with its meaning, from the declarations."""
    return MappingProxyType({_key(f): f.metadata["description"] for f in declared(cls)})


def read_declared(cls: Any, r: TableReader, names: Sequence[str] | None = None) -> dict[str, Any]:
    """Read each declared key that has a reader (only ``names`` when given) from the table of
    ``r``: the value as written, checked, or the declared default when the key is absent."""
    out: dict[str, Any] = {}
    for f in declared(cls):
        read = f.metadata["read"]
        if read is None or (names is not None and f.name not in names):
            continue
        out[f.name] = r.get(
            _key(f),
            read,
            _default(f),
            *f.metadata["args"],
            example=f.metadata["example"],
            **f.metadata["kw"],
        )
    return out


def _as_toml(value: Any) -> Any:
    """A value set from Python in the form TOML gives it (lists, Python scalars)."""
    if isinstance(value, np.generic):
        return value.item()
    if isinstance(value, tuple | list):
        return [_as_toml(v) for v in value]
    return value


def validate_declared(
    obj: Any,
    table: str,
    names: Sequence[str] | None = None,
    path: str | None = None,
    source: Any = None,
) -> None:
    """Check every declared value of a constructed settings object with its reader, so that a
    value set from Python (keywords, ``dataclasses.replace`` of an override) is checked exactly
    like one read from a spec; ``None`` passes where ``None`` is the default. ``source``: the
    class whose declarations to use (default ``type(obj)``; ``DesignRequest`` borrows
    :class:`L1Settings`'). Raises SpecError naming ``table.key``."""
    for f in declared(source if source is not None else type(obj)):
        read = f.metadata["read"]
        if read is None or (names is not None and f.name not in names):
            continue
        value = getattr(obj, f.name)
        default = _default(f)
        if value is None and default is None:
            continue
        where = Field(
            table, _key(f), path, f.metadata["description"], default, f.metadata["example"]
        )
        read(_as_toml(value), where, *f.metadata["args"], **f.metadata["kw"])


# ------------------------------------------------------------------------------ [contraction]
# the route names are declared once, in drip_cert.vocabulary (their implementations: analysis)


@dataclass(frozen=True)
class ContractionSettings:
    """``[contraction]``: settings of the contraction analysis.

    ``region`` defaults to the support box of ``D`` (``None``); the paper asks for all ``x``, so
    a box result is weaker and is reported as such. A region must contain the support.
    """

    method: str = setting(
        "auto", "how the contraction rate is obtained", one_of, CONTRACTION_METHODS
    )
    region: tuple[tuple[float, float], ...] | None = setting(
        None, "box where the rate is proved; default the support of [initial]", example=[[-1, 1]]
    )
    tol: float = setting(
        1e-3,
        "gap between the upper and lower bound of the interval branch and bound",
        positive_float,
    )
    max_boxes: int = setting(
        4000, "largest number of boxes of the interval branch and bound", positive_int
    )
    metric: bool = True  #: search an LMI contraction metric (false only for "euclidean")
    max_time: float = setting(
        math.inf,
        "optional wall-time guard of the branch and bound per closed loop (seconds; default "
        "none): when it fires the rate depends on the machine's speed, and the certificate says "
        "so; max_boxes is the budget that keeps it reproducible",
        positive_or_inf,
    )
    coordinates: str = setting(
        "auto",
        'certify in metric coordinates: "auto", "euclidean", "lmi" or a matrix P',
        key="metric",
    )
    P: tuple[tuple[float, ...], ...] | None = None  #: the given metric (``metric = [[...]]``)
    given: frozenset[str] = field(default=frozenset(), compare=False, repr=False)

    KEYS: ClassVar[Mapping[str, str]]

    def __post_init__(self) -> None:
        validate_declared(self, "contraction")
        if self.region is not None:
            where = Field("contraction", "region", None, self.KEYS["region"])
            box(_as_toml(self.region), where, len(self.region))
        if self.coordinates not in (*METRIC_CHOICES, "given") or (
            (self.P is not None) != (self.coordinates == "given")
        ):
            raise SpecError(
                f"coordinates = {self.coordinates!r} with P = {self.P!r}: coordinates is one of "
                f"{', '.join(METRIC_CHOICES)} (P None) or 'given' with a matrix P",
                field="contraction.metric",
            )

    @classmethod
    def from_table(
        cls,
        table: Mapping[str, Any] | None,
        n: int | None = None,
        path: str | None = None,
        support: Sequence[Sequence[float]] | None = None,
    ) -> ContractionSettings:
        """Validate ``[contraction]`` (``n``: the state dimension, needed for ``region``;
        ``support``: the support of ``D``, which the region must contain)."""
        r = TableReader("contraction", table, cls.KEYS, path)
        region = None
        if "region" in r.table:
            if n is None:
                raise SpecError(
                    "the region needs the state dimension", field="contraction.region", path=path
                )
            region = r.get("region", box, None, n)
            if support is not None and not Scope(region).contains_box(support):
                raise r.field_of("region").error(
                    r.table["region"],
                    "a box that contains the support of the initial law",
                    f"the region does not contain the support {[list(x) for x in support]} of "
                    "the initial law: a rate proved there says nothing about trajectories that "
                    "start outside it; give a region that contains [initial] support",
                )
        choice = r.get("metric", metric_choice, "auto", n)
        coords, P = ("auto", None) if choice == "auto" else choice
        return cls(
            **read_declared(cls, r),
            region=region,
            metric=coords != "euclidean",
            coordinates=coords,
            P=P,
            given=r.given,
        )


# ------------------------------------------------------------------------------ [l1drac]
#: The L1-DRAC design objectives; their meanings are documented at
#: :data:`drip_cert.bounds.l1drac.request.OBJECTIVES`.

ContractionSettings.KEYS = table_keys(ContractionSettings)
L1_OBJECTIVES = ("default", "rho_at_Ts", "Ts_at_rho", "min_rho")


@dataclass(frozen=True)
class L1Settings:
    """``[l1drac]``: the user's inputs of the L1-DRAC design (L1-DRAC Sec. 3.2).

    ``None`` means "let the designer find it" (``lambda_s``, ``omega``, ``Ts``, ``rho_r``,
    ``rho_a``), "no kappa" (``delta``), "the distance of the supports of D and D_bar"
    (``alpha``) or "Assumption 8 holds when L_f is finite" (``lip_f``). ``p_star`` defaults to
    ``p``. ``objective`` ``None`` is inferred: ``"rho_at_Ts"`` with ``Ts``, ``"Ts_at_rho"``
    with ``rho_budget``, else ``"default"`` (:func:`l1_objective`).
    """

    p: int = setting(1, "moment order of the bound, an integer >= 1", positive_int)
    p_star: int | None = setting(
        None, "highest moment order of L1-DRAC Assumption 1, an integer >= p (default p)"
    )
    lambda_s: float | None = setting(None, "predictor pole (15c)", positive_float, example=10.0)
    omega: float | None = setting(None, "filter bandwidth (15a)", positive_float, example=50.0)
    Ts: float | None = setting(None, "sampling period (15b)", positive_float, example=1e-3)
    rho_r: float | None = setting(None, "radius of (16a)", positive_float, example=1.0)
    rho_a: float | None = setting(None, "radius of (16b)", positive_float, example=1.0)
    delta: float | None = setting(
        None, "violation probability of kappa (130a)", probability, example=0.05
    )
    alpha: float | None = setting(None, "initial distance W_2p of (18a)", nonneg_float, example=0.0)
    eps_r: float = setting(1e-3, "slack of (16a)", positive_float)
    eps_a: float = setting(1e-3, "slack of (16b)", positive_float)
    lip_f: bool | None = setting(
        None, "whether L1-DRAC Assumption 8 is used", boolean, example=True
    )
    objective: str | None = setting(
        None,
        'what the design optimises: "default" (the smallest rho at Ts = 1e-3 s, else the '
        'largest Ts of the front that is not a knife edge), "rho_at_Ts" (Ts given), '
        '"Ts_at_rho" (rho_budget given) or "min_rho" (the infimum of rho)',
        one_of,
        L1_OBJECTIVES,
    )
    rho_budget: float | None = setting(
        None, "largest acceptable rho = rho_r + rho_a of (17)", positive_float, example=100.0
    )
    front: bool = setting(True, "compute the (Ts, rho) Pareto front of verified designs", boolean)
    given: frozenset[str] = field(default=frozenset(), compare=False, repr=False)

    KEYS: ClassVar[Mapping[str, str]]

    def __post_init__(self) -> None:
        validate_declared(self, "l1drac")
        if self.p_star is None:
            object.__setattr__(self, "p_star", self.p)
        where = Field("l1drac", "p_star", None, self.KEYS["p_star"])
        integer(self.p_star, where, minimum=self.p, rule=f"an integer >= p = {self.p}")
        if self.objective is None:  # the one the values imply (as from_table)
            obj = l1_objective(None, Ts=self.Ts, rho_budget=self.rho_budget)
            object.__setattr__(self, "objective", obj)

    @classmethod
    def from_table(
        cls, table: Mapping[str, Any] | None, n: int | None = None, path: str | None = None
    ) -> L1Settings:
        """Validate ``[l1drac]`` (``n`` is unused; the same signature as the other tables)."""
        elsewhere = {
            c: f"{c} is a paper constant: give it in [constants]"
            for c in CONSTANT_NAMES
            if c not in cls.KEYS
        }
        r = TableReader("l1drac", table, cls.KEYS, path, elsewhere)
        p = r.get("p", positive_int, 1)
        p_star = r.get("p_star", integer, p, minimum=p, rule=f"an integer >= p = {p}")
        others = [f.name for f in declared(cls) if f.name not in L1_DESIGN_KEYS]
        return cls(
            **read_declared(cls, r, [k for k in others if k not in ("p", "p_star")]),
            p=p,
            p_star=p_star,
            **read_l1_design(r),
            given=r.given,
        )


#: The keys of ``[l1drac]`` that a ``design-l1`` constants file's ``[design]`` table shares.

L1Settings.KEYS = table_keys(L1Settings)
L1_DESIGN_KEYS = (
    "lambda_s",
    "omega",
    "Ts",
    "rho_r",
    "rho_a",
    "delta",
    "objective",
    "rho_budget",
    "front",
)


class L1DesignValues(TypedDict):
    """The design parameters read by :func:`read_l1_design` (keywords of
    :class:`L1Settings` and of :class:`~drip_cert.bounds.l1drac.request.DesignRequest`)."""

    lambda_s: float | None
    omega: float | None
    Ts: float | None
    rho_r: float | None
    rho_a: float | None
    delta: float | None
    objective: str | None
    rho_budget: float | None
    front: bool


def l1_objective(
    objective: str | None,
    *,
    Ts: float | None,
    rho_budget: float | None,
    rho_r: float | None = None,
    rho_a: float | None = None,
    table: str = "l1drac",
    path: str | None = None,
) -> str:
    """The L1-DRAC design objective: ``objective``, or the one the given values imply when it is
    ``None`` (``"rho_at_Ts"`` with ``Ts``, ``"Ts_at_rho"`` with ``rho_budget``, else
    ``"default"``). Raises SpecError (field ``table.objective`` or ``table.rho_budget``) for a
    combination the objective cannot serve, with the fix."""

    def err(msg: str, key: str = "objective") -> SpecError:
        return SpecError(msg, field=f"{table}.{key}", path=path)

    obj = objective
    if obj is None:
        obj = (
            "rho_at_Ts" if Ts is not None else "Ts_at_rho" if rho_budget is not None else "default"
        )
    if obj not in L1_OBJECTIVES:
        raise err(
            f"objective = {toml_text(obj)} is not one of "
            + ", ".join(toml_text(o) for o in L1_OBJECTIVES)
            + '; write e.g. objective = "rho_at_Ts" together with Ts, or remove the key'
        )
    if obj == "rho_at_Ts" and Ts is None:
        raise err('objective = "rho_at_Ts" needs the sampling period: give Ts (e.g. Ts = 1e-3)')
    if obj == "Ts_at_rho" and (rho_budget is None or Ts is not None):
        raise err(
            'objective = "Ts_at_rho" needs rho_budget and no Ts (Ts is what it finds): give '
            'rho_budget and remove Ts, or write objective = "rho_at_Ts"'
        )
    if obj in ("default", "min_rho") and Ts is not None:
        raise err(
            f"objective = {toml_text(obj)} finds Ts, but Ts = {toml_text(Ts)} is given: remove "
            'Ts, or write objective = "rho_at_Ts"'
        )
    if obj in ("default", "min_rho") and rho_budget is not None:
        raise err(
            f"objective = {toml_text(obj)} takes no rho_budget: remove it, or write objective "
            '= "Ts_at_rho"'
        )
    if rho_budget is not None and rho_r is not None and rho_a is not None:
        if rho_r + rho_a > rho_budget:
            raise err(
                f"rho_budget = {toml_text(rho_budget)} is below the given rho_r + rho_a = "
                f"{toml_text(rho_r + rho_a)}: raise rho_budget or lower the radii",
                "rho_budget",
            )
    return obj


def read_l1_design(r: TableReader) -> L1DesignValues:
    """The L1-DRAC design parameters of a table, ``None`` where absent: ``lambda_s``, ``omega``,
    ``Ts``, ``rho_r``, ``rho_a`` (finite numbers > 0; absent = let the designer find it),
    ``delta`` (a probability in (0, 1); absent = no kappa), ``rho_budget`` (> 0), ``front``
    (a boolean) and ``objective`` (one of :data:`L1_OBJECTIVES`, checked against the others by
    :func:`l1_objective`; absent = inferred).

    Shared by ``[l1drac]`` of a spec (:class:`L1Settings`) and ``[design]`` of a ``design-l1``
    constants file (:mod:`drip_cert.bounds.l1drac.toml`), whose keys mean the same
    (:attr:`L1Settings.KEYS`).
    """

    out = cast(L1DesignValues, read_declared(L1Settings, r, L1_DESIGN_KEYS))
    out["objective"] = l1_objective(
        out["objective"],
        Ts=out["Ts"],
        rho_budget=out["rho_budget"],
        rho_r=out["rho_r"],
        rho_a=out["rho_a"],
        table=r.name,
        path=r.path,
    )
    return out


# ------------------------------------------------------------------------------ [tasil]
TRAIN_METHODS = ("tasil", "bc", "dagger", "dart")
"""Training methods of ``[tasil] method`` and ``drip-cert train --method``: the TaSIL and BC losses
on expert demonstrations, and the interactive baselines DAgger and DART (BC loss on the data
they collect, :mod:`drip_cert.learn.baselines`)."""

HELDOUT_FROM_DELTA = -1
"""``TasilSettings.heldout`` default: derive the count from ``delta`` (:func:`heldout_default`)."""


@dataclass(frozen=True)
class TasilSettings:
    """``[tasil]``: training of the learned policy and the TaSIL certificate."""

    method: str = setting("tasil", "the training method (docs/baselines.md)", one_of, TRAIN_METHODS)
    order: int = setting(1, "derivative order of the TaSIL loss", one_of, (1, 2))
    trajectories: int = setting(20, "number n of expert demonstrations", positive_int)
    #: the default :data:`HELDOUT_FROM_DELTA` is replaced by the smallest count at which the
    #: held-out form (3.3 c) can pass at ``delta`` (59 at delta = 0.1; :func:`heldout_default`)
    heldout: int = setting(
        HELDOUT_FROM_DELTA,
        "fresh expert trajectories for the held-out form; 0 for none; default the smallest "
        "count at which that form can pass at delta (59 at delta = 0.1)",
        nonneg_int,
    )
    samples: int = setting(100, "samples k per trajectory on [0, T]", positive_int)
    hidden: tuple[int, ...] = setting((64, 64), "hidden layer widths of the policy MLP", int_list)
    activation: str = setting(
        "tanh", "activation of the policy MLP (smooth)", one_of, ("tanh", "gelu")
    )
    steps: int = setting(2000, "training steps", positive_int)
    lr: float = setting(3e-3, "learning rate", positive_float)
    batch: int = setting(128, "batch size", positive_int)
    seed: int = setting(0, "random seed", integer)
    delta: float = setting(0.1, "failure probability of rho_TaSIL", probability)
    eta: float = setting(
        math.inf, "local delta-ISS radius (the comparison bound is global: inf)", positive_or_inf
    )
    tube_radius: float = setting(
        math.inf, "radius R of assumption A2 (global MLP bounds: inf)", positive_or_inf
    )
    policy: str | None = setting(
        None,
        "path of a trained policy (.npz), relative to the spec",
        string,
        example="policy.npz",
    )
    architecture: str = setting(
        "mlp",
        "policy class: 'mlp', or 'residual' = [policy] structure + K x + MLP",
        one_of,
        ("mlp", "residual"),
    )
    lipschitz_budget: float = setting(
        math.inf, "bound on the policy MLP's product of layer spectral norms", positive_or_inf
    )
    max_heldout_gap: float = setting(
        math.inf, "training fails when the held-out mean gap exceeds this", positive_or_inf
    )
    tube_weight: float = setting(
        0.0,
        "weight of value and Jacobian matching at points drawn on the box of the training "
        "states enlarged by tube_radius (1 when inf) (docs/math/tasil.md section 5.1); 0: off",
        nonneg_float,
    )
    tube_points: int = setting(128, "points drawn on the tube per training step", positive_int)
    given: frozenset[str] = field(default=frozenset(), compare=False, repr=False)

    KEYS: ClassVar[Mapping[str, str]]

    def __post_init__(self) -> None:
        if self.heldout == HELDOUT_FROM_DELTA:
            object.__setattr__(self, "heldout", heldout_default(self.delta))
        validate_declared(self, "tasil")

    @classmethod
    def from_table(
        cls, table: Mapping[str, Any] | None, n: int | None = None, path: str | None = None
    ) -> TasilSettings:
        """Validate ``[tasil]`` (``n`` is unused; the same signature as the other tables)."""
        r = TableReader("tasil", table, cls.KEYS, path)
        return cls(**read_declared(cls, r), given=r.given)


TasilSettings.KEYS = table_keys(TasilSettings)


def heldout_default(delta: float) -> int:
    """The default ``[tasil] heldout``: the smallest number of held-out trajectories at which the
    held-out form (docs/math/tasil.md 3.3 c) can pass at ``delta``: with no trajectory exceeding
    ``tau``, the sound one-sided Clopper-Pearson bound at confidence ``1 - delta/2`` must reach
    ``delta/2`` (:func:`~drip_cert.numerics.stats.min_trials_zero_failures`)."""
    return min_trials_zero_failures(delta / 2.0, delta / 2.0)


# ------------------------------------------------------------------------------ [simulation]
@dataclass(frozen=True)
class SimSettings:
    """``[simulation]``: practical parameters for Monte-Carlo runs that cannot use the certified
    ones. The L1-DRAC defaults are those of the authors' Julia examples (``T_s = 10 dt``)."""

    dt: float = setting(1e-3, "Euler time step of the Monte Carlo", positive_float)
    paths: int = setting(1000, "number of simulated paths", positive_int)
    chunk_size: int = setting(2048, "paths simulated at once", positive_int)
    omega: float = setting(50.0, "practical filter bandwidth of L1-DRAC", positive_float)
    lambda_s: float = setting(10.0, "practical predictor pole of L1-DRAC", positive_float)
    Ts: float = setting(0.01, "practical sampling period of L1-DRAC", positive_float)
    record_every: int = setting(10, "record the state every this many steps", positive_int)
    given: frozenset[str] = field(default=frozenset(), compare=False, repr=False)

    KEYS: ClassVar[Mapping[str, str]]

    def __post_init__(self) -> None:
        validate_declared(self, "simulation")

    @classmethod
    def from_table(
        cls, table: Mapping[str, Any] | None, n: int | None = None, path: str | None = None
    ) -> SimSettings:
        """Validate ``[simulation]`` (``n`` is unused; the same signature as the other tables)."""
        r = TableReader("simulation", table, cls.KEYS, path)
        return cls(**read_declared(cls, r), given=r.given)


# ------------------------------------------------------------------------------ [constants]

SimSettings.KEYS = table_keys(SimSettings)


@dataclass(frozen=True)
class ConstantsTable:
    """``[constants]``: values of paper constants the user knows better than the computed ones
    (labelled ``given`` in the certificate). Keys are :data:`CONSTANT_NAMES`; every value is a
    finite number >= 0 (> 0 for :data:`POSITIVE_CONSTANTS`)."""

    values: Mapping[str, float] = field(default_factory=lambda: MappingProxyType({}))

    KEYS = MappingProxyType(
        dict.fromkeys(CONSTANT_NAMES, "a constant of the papers; without this key it is computed")
    )

    @classmethod
    def from_table(
        cls, table: Mapping[str, Any] | None, n: int | None = None, path: str | None = None
    ) -> ConstantsTable:
        """Validate ``[constants]`` (``n`` is unused; the same signature as the other tables)."""
        r = TableReader("constants", table, cls.KEYS, path, _ELSEWHERE)
        values = {}
        for key in r.table:
            read = positive_float if key in POSITIVE_CONSTANTS else nonneg_float
            values[key] = r.get(key, read, None)
        return cls(MappingProxyType(values))


# ------------------------------------------------------------------------------ all of them
@dataclass(frozen=True)
class Settings:
    """The validated settings tables of a spec; ``present`` names the tables the spec writes
    (``[l1drac]`` and ``[tasil]`` also ask ``certify`` for those parts)."""

    contraction: ContractionSettings = ContractionSettings()
    l1drac: L1Settings = L1Settings()
    tasil: TasilSettings = field(default_factory=TasilSettings)  # its default needs scipy
    simulation: SimSettings = SimSettings()
    constants: ConstantsTable = ConstantsTable()
    present: frozenset[str] = frozenset()

    @staticmethod
    def table_classes() -> dict[str, Any]:
        """The settings class of each settings table, in the order of :data:`TABLES`."""
        classes = {
            "constants": ConstantsTable,
            "contraction": ContractionSettings,
            "l1drac": L1Settings,
            "tasil": TasilSettings,
            "simulation": SimSettings,
        }
        return {name: classes[name] for name in TABLES}

    @classmethod
    def from_tables(
        cls,
        tables: Mapping[str, Mapping[str, Any]],
        n: int,
        path: str | None = None,
        support: Sequence[Sequence[float]] | None = None,
    ) -> Settings:
        """Validate every settings table of a spec (absent tables: the defaults)."""
        path = None if path is None else str(path)
        return cls(
            contraction=ContractionSettings.from_table(
                tables.get("contraction"), n, path, support=support
            ),
            l1drac=L1Settings.from_table(tables.get("l1drac"), n, path),
            tasil=TasilSettings.from_table(tables.get("tasil"), n, path),
            simulation=SimSettings.from_table(tables.get("simulation"), n, path),
            constants=ConstantsTable.from_table(tables.get("constants"), n, path),
            present=frozenset(k for k in TABLES if k in tables),
        )


__all__ = [
    "CONSTANT_NAMES",
    "ConstantsTable",
    "ContractionSettings",
    "Field",
    "L1DesignValues",
    "L1Settings",
    "Settings",
    "SimSettings",
    "TableReader",
    "TasilSettings",
    "boolean",
    "box",
    "int_list",
    "integer",
    "nonneg_float",
    "nonneg_int",
    "one_of",
    "positive_float",
    "positive_int",
    "positive_or_inf",
    "probability",
    "read_l1_design",
    "L1_OBJECTIVES",
    "l1_objective",
    "read_real",
    "string",
]
