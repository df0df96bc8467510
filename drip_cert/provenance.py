"""Value objects that make every number of a certificate traceable, and the one combinator that
labels derived numbers.

A :class:`Quantity` is a number together with *how* it was obtained (:class:`How`), *where* it
holds (:class:`Scope`: all states and times, a box, a time range), the paper and equation it
implements and a free-text note. A :class:`Check` is the verdict of one condition of the papers:
its left and right sides, the signed margin (positive = satisfied), how its inputs were obtained,
where it holds and, for a failure, a witness. Neither is ever a bare float.

Labels are computed, never written
----------------------------------
Every derived number and every check takes its label from its inputs with :func:`weakest`
(provenance) and :func:`narrowest` (scope): a derived number is never stronger than its weakest
input, and never holds on more than the intersection of its inputs' scopes. The method that
combines them enters the same combinator as one more input: an interval bound computed right here
is ``How.SOUND``, a closed form ``How.EXACT``, a sample ``How.ESTIMATE``
(:meth:`Quantity.derive`, :meth:`Check.derive`). A number that is not a number (NaN) never makes a
check hold (:attr:`Check.status` is ``"unknown"``).

The order of :class:`How` is ``exact > sound > given > estimate``: ``given`` (the user's word) is a
hypothesis the certificate states and rests on, ``estimate`` (sampled) is not a bound at all and
makes every verdict built on it conditional.
"""

from __future__ import annotations

import math
from collections.abc import Iterable, Sequence
from dataclasses import dataclass, field, replace
from enum import StrEnum
from typing import Any


class How(StrEnum):
    """How a number was obtained; ordered ``EXACT > SOUND > GIVEN > ESTIMATE``."""

    EXACT = "exact"  #: closed form, evaluated exactly or verified in rigorous arithmetic
    SOUND = "sound"  #: a rigorous bound in the direction the certificate needs
    GIVEN = "given"  #: supplied by the user, taken as a stated hypothesis
    ESTIMATE = "estimate"  #: sampled / optimised; NOT a bound, never used as one silently

    @property
    def rank(self) -> int:
        """0 for the strongest (exact) to 3 for the weakest (estimate)."""
        return _RANK[self]

    @property
    def proved(self) -> bool:
        """Whether a number with this label is a proved statement (exact or sound)."""
        return self in (How.EXACT, How.SOUND)


_RANK = {How.EXACT: 0, How.SOUND: 1, How.GIVEN: 2, How.ESTIMATE: 3}


def weakest(*hows: How | str | Quantity | Check | Iterable[Any]) -> How:
    """The weakest provenance among ``hows`` (``EXACT`` for none: nothing was approximated).

    Accepts :class:`How` values, their strings, :class:`Quantity` and :class:`Check` objects
    (their ``how``) and iterables of any of these.

    >>> weakest(How.EXACT, "sound", [How.GIVEN])
    <How.GIVEN: 'given'>
    >>> weakest()
    <How.EXACT: 'exact'>
    """
    out = How.EXACT
    for h in _flatten(hows):
        hh = h.how if isinstance(h, Quantity | Check) else How(h)
        if hh.rank > out.rank:
            out = hh
    return out


def _flatten(items: Iterable[Any]) -> Iterable[Any]:
    for it in items:
        if isinstance(it, How | str | Quantity | Check):
            yield it
        elif it is None:
            continue
        else:
            yield from _flatten(it)


# ---------------------------------------------------------------------------------- scope
Box = tuple[tuple[float, float], ...]


@dataclass(frozen=True)
class Scope:
    """Where a number or a check holds.

    Attributes
    ----------
    box
        ``None`` for all states ``x in R^n``; else the closed box ``[lo_i, hi_i]`` per state.
    t_range
        ``None`` for all ``t >= 0``; else the closed range ``[t0, t1]``.
    """

    box: Box | None = None
    t_range: tuple[float, float] | None = None

    def __post_init__(self) -> None:
        if self.box is not None:
            b = tuple((float(lo), float(hi)) for lo, hi in self.box)
            object.__setattr__(self, "box", b)
        if self.t_range is not None:
            object.__setattr__(self, "t_range", (float(self.t_range[0]), float(self.t_range[1])))

    @property
    def all_x(self) -> bool:
        """Whether the scope covers every state."""
        return self.box is None

    @property
    def all_t(self) -> bool:
        """Whether the scope covers every time ``t >= 0``."""
        return self.t_range is None

    @property
    def is_global(self) -> bool:
        """All states and all times (what the papers' assumptions ask for)."""
        return self.all_x and self.all_t

    def covers_time(self, horizon: float) -> bool:
        """Whether the scope contains ``[0, horizon]``."""
        return self.t_range is None or (self.t_range[0] <= 0.0 and self.t_range[1] >= horizon)

    def contains_box(self, box: Sequence[Sequence[float]]) -> bool:
        """Whether the closed box ``box`` lies inside the scope's state set."""
        if self.box is None:
            return True
        if len(box) != len(self.box):
            return False
        return all(a[0] <= b[0] and b[1] <= a[1] for a, b in zip(self.box, box, strict=True))

    def intersect(self, other: Scope) -> Scope:
        """The set where both scopes hold (an empty intersection keeps an empty interval)."""
        if self.box is None:
            box = other.box
        elif other.box is None:
            box = self.box
        else:
            box = tuple(
                (max(a[0], b[0]), min(a[1], b[1])) for a, b in zip(self.box, other.box, strict=True)
            )
        if self.t_range is None:
            tr = other.t_range
        elif other.t_range is None:
            tr = self.t_range
        else:
            tr = (max(self.t_range[0], other.t_range[0]), min(self.t_range[1], other.t_range[1]))
        return Scope(box, tr)

    def describe(self) -> str:
        """Human-readable text, e.g. ``"all x, all t"`` or ``"box [[-1, 1]], t in [0, 5]"``."""
        xs = "all x" if self.box is None else "box " + _fmt_box(self.box)
        ts = "all t" if self.t_range is None else f"t in [{self.t_range[0]:g}, {self.t_range[1]:g}]"
        return f"{xs}, {ts}"

    def to_dict(self) -> dict[str, Any]:
        """JSON-ready dictionary (``null`` for "all")."""
        return {
            "box": None if self.box is None else [list(r) for r in self.box],
            "t_range": None if self.t_range is None else list(self.t_range),
            "text": self.describe(),
        }


def _fmt_box(box: Box) -> str:
    return "[" + ", ".join(f"[{lo:.6g}, {hi:.6g}]" for lo, hi in box) + "]"


GLOBAL = Scope()
"""All states and all times."""


def narrowest(*scopes: Scope | Quantity | Check | Iterable[Any]) -> Scope:
    """The intersection of the scopes (of quantities and checks too); :data:`GLOBAL` for none."""
    out = GLOBAL
    for s in _flatten_scopes(scopes):
        out = out.intersect(s)
    return out


def _flatten_scopes(items: Iterable[Any]) -> Iterable[Scope]:
    for it in items:
        if isinstance(it, Scope):
            yield it
        elif isinstance(it, Quantity | Check):
            yield it.scope
        elif it is None:
            continue
        else:
            yield from _flatten_scopes(it)


def _basis(inputs: Sequence[Any]) -> tuple[str, ...]:
    """Names of the estimated or given leaves under ``inputs`` (in order, without repeats)."""
    out: list[str] = []
    for q in inputs:
        if not isinstance(q, Quantity | Check):
            continue
        if q.rests_on:
            out.extend(q.rests_on)
        elif q.how in (How.ESTIMATE, How.GIVEN):
            out.append(q.name if isinstance(q, Quantity) else q.id)
    return tuple(dict.fromkeys(out))


# ---------------------------------------------------------------------------------- values
@dataclass(frozen=True)
class Quantity:
    """A number with its provenance.

    Parameters
    ----------
    name
        Symbol in ASCII, as in the papers (``"Delta_g"``, ``"lambda"``).
    value
        The number (``math.inf`` allowed where a bound does not exist; NaN = unknown).
    how
        :class:`How` it was obtained. For a derived number use :meth:`derive`, never a literal.
    source
        Paper and equation, e.g. ``"DRIP Assumption 1"`` or ``"L1-DRAC (A.13)"``.
    note
        Method, e.g. ``"interval branch and bound, tol 1e-3"``.
    scope
        Where the number holds (:class:`Scope`; default all x and t).
    rests_on
        Names of the estimated or given inputs a derived number rests on (set by
        :meth:`derive`; a leaf that is itself an estimate or given names itself).
    """

    name: str
    value: float
    how: How
    source: str = ""
    note: str = ""
    scope: Scope = GLOBAL
    rests_on: tuple[str, ...] = ()

    def __post_init__(self) -> None:
        object.__setattr__(self, "value", float(self.value))
        object.__setattr__(self, "how", How(self.how))

    @property
    def known(self) -> bool:
        """Whether the value is a number (not NaN)."""
        return not math.isnan(self.value)

    @classmethod
    def derive(
        cls,
        name: str,
        value: float,
        *,
        inputs: Iterable[Any] = (),
        method: How = How.EXACT,
        source: str = "",
        note: str = "",
        scope: Scope | None = None,
    ) -> Quantity:
        """A quantity computed from ``inputs`` by a ``method`` of the given strength.

        ``how = weakest(method, *inputs)``, ``scope = narrowest(scope, *inputs)``.

        Examples
        --------
        A sound rate times an estimated constant is an estimate, and says what it rests on:

        >>> rate = Quantity("lambda", 0.5, How.SOUND, scope=Scope(((-1.0, 1.0),)))
        >>> lip = Quantity("L_mu", 0.1, How.ESTIMATE)
        >>> gain = Quantity.derive("gamma", lip.value / rate.value, inputs=[rate, lip])
        >>> gain.how, gain.rests_on, gain.scope.describe()
        (<How.ESTIMATE: 'estimate'>, ('L_mu',), 'box [[-1, 1]], all t')
        """
        ins = list(_flatten(inputs))
        return cls(
            name,
            value,
            weakest(method, ins),
            source,
            note,
            narrowest(scope or GLOBAL, ins),
            _basis(ins),
        )

    def renamed(self, name: str, source: str | None = None, note: str | None = None) -> Quantity:
        """The same number and label under another name (provenance unchanged)."""
        return Quantity(
            name,
            self.value,
            self.how,
            self.source if source is None else source,
            self.note if note is None else note,
            self.scope,
            self.rests_on,
        )

    def to_dict(self) -> dict[str, Any]:
        """JSON-ready dictionary (non-finite values become strings)."""
        return {
            "name": self.name,
            "value": _json_float(self.value),
            "how": self.how.value,
            "scope": self.scope.describe(),
            "source": self.source,
            "note": self.note,
            "rests_on": list(self.rests_on),
        }


class CheckStatus(StrEnum):
    """The status of one :class:`Check` of a certificate (``Check.status``; JSON ``status``).

    The words of a validation (:class:`ValidationStatus`) differ on purpose: a certificate's
    check *fails* (a proved condition is false), an empirical check is *violated* (data
    contradict a bound at a confidence level).
    """

    HOLDS = "holds"  #: the condition holds
    FAILS = "fails"  #: the condition is false (by ``-margin``)
    UNKNOWN = "unknown"  #: a side of the comparison is NaN: it could not be evaluated


class ValidationStatus(StrEnum):
    """The status of an empirical check (``EmpiricalCheck.status``) and of a validation
    (``ValidationReport.status``), as :mod:`drip_cert.validate` computes them."""

    HOLDS = "holds"  #: a finite bound was compared and not violated at the stated confidence
    VIOLATED = "violated"  #: the one-sided lower confidence bound exceeds the bound
    NOT_CHECKED = "not_checked"  #: nothing was compared (the check's ``reason`` says why)
    NOTHING_CHECKED = "nothing_checked"  #: a report's status: no check holds, none is violated


@dataclass(frozen=True)
class Check:
    """The verdict of one condition.

    ``margin`` is signed: positive means the condition holds with that much room
    (``rhs - lhs`` for a condition ``lhs <= rhs``), negative means it fails by that much.
    ``how`` and ``scope`` are those of the inputs (:meth:`derive`, :meth:`compare`).
    ``scope_ok`` says whether using the check where it is used is justified: ``True`` when it
    holds where it is needed (globally, or on a region proved sufficient, ``scope_reason`` says
    how), ``False`` when it rests on an unproved region (``scope_reason`` says which).
    """

    id: str
    holds: bool
    detail: str
    lhs: float = math.nan
    rhs: float = math.nan
    margin: float = math.nan
    source: str = ""
    how: How = How.ESTIMATE  #: a check built without its inputs' label is never stronger
    scope: Scope = GLOBAL
    scope_ok: bool = True
    scope_reason: str = ""
    witness: tuple[float, ...] | None = None
    extra: dict[str, Any] = field(default_factory=dict)
    rests_on: tuple[str, ...] = ()  #: names of the estimated / given inputs

    def __post_init__(self) -> None:
        object.__setattr__(self, "how", How(self.how))
        # a comparison with one side not a number never holds (both NaN: not a comparison)
        if self.holds and self._one_side_nan:
            object.__setattr__(self, "holds", False)

    @property
    def _one_side_nan(self) -> bool:
        return math.isnan(self.lhs) != math.isnan(self.rhs)

    @property
    def status(self) -> CheckStatus:
        """``holds``, ``fails`` or ``unknown`` (a side of the comparison is NaN)."""
        if self.holds:
            return CheckStatus.HOLDS
        return CheckStatus.UNKNOWN if self._one_side_nan else CheckStatus.FAILS

    @property
    def proved(self) -> bool:
        """Holds, every input exact or sound (or the user's given word), scope justified."""
        return self.holds and self.how != How.ESTIMATE and self.scope_ok

    @classmethod
    def derive(
        cls,
        id: str,
        holds: bool,
        detail: str,
        *,
        inputs: Iterable[Any] = (),
        method: How = How.EXACT,
        scope: Scope | None = None,
        **kw: Any,
    ) -> Check:
        """A check whose ``how`` and ``scope`` follow from ``inputs`` (and the method)."""
        ins = list(_flatten(inputs))
        rests = _basis(ins)
        return cls(
            id=id,
            holds=bool(holds),
            detail=detail,
            how=weakest(method, ins),
            scope=narrowest(scope or GLOBAL, ins),
            rests_on=kw.pop("rests_on", rests),
            **kw,
        )

    @classmethod
    def compare(
        cls,
        id: str,
        lhs: Quantity | float,
        rhs: Quantity | float,
        detail: str,
        *,
        strict: bool = False,
        inputs: Iterable[Any] = (),
        method: How = How.EXACT,
        **kw: Any,
    ) -> Check:
        """The check ``lhs <= rhs`` (``lhs < rhs`` when ``strict``) with margin ``rhs - lhs``.

        NaN on either side makes the check fail with status ``"unknown"``; an infinite side
        compares as IEEE floats do (``inf <= inf`` holds only when not strict).
        """
        lv = lhs.value if isinstance(lhs, Quantity) else float(lhs)
        rv = rhs.value if isinstance(rhs, Quantity) else float(rhs)
        holds = (lv < rv) if strict else (lv <= rv)
        if math.isnan(lv) or math.isnan(rv):
            holds = False
        margin = rv - lv if math.isfinite(lv) and math.isfinite(rv) else math.nan
        if holds and not math.isfinite(margin):
            margin = math.inf
        extra_in = [q for q in (lhs, rhs) if isinstance(q, Quantity)]
        return cls.derive(
            id,
            holds,
            detail,
            inputs=[*extra_in, *_flatten(inputs)],
            method=method,
            lhs=lv,
            rhs=rv,
            margin=margin,
            **kw,
        )

    def with_scope(self, ok: bool, reason: str) -> Check:
        """The same check with its use justified (``ok``) or not, and why."""
        return replace(self, scope_ok=bool(ok), scope_reason=reason)

    def to_dict(self) -> dict[str, Any]:
        """JSON-ready dictionary."""
        out: dict[str, Any] = {
            "id": self.id,
            "holds": bool(self.holds),
            "status": self.status,
            "detail": self.detail,
            "lhs": _json_float(self.lhs),
            "rhs": _json_float(self.rhs),
            "margin": _json_float(self.margin),
            "source": self.source,
            "how": self.how.value,
            "scope": self.scope.describe(),
            "scope_justified": bool(self.scope_ok),
            "scope_reason": self.scope_reason,
            "rests_on": list(self.rests_on),
        }
        if self.witness is not None:
            out["witness"] = [float(w) for w in self.witness]
        if self.extra:
            out["extra"] = self.extra
        return out


# ---------------------------------------------------------------------------------- verdict
class Verdict(StrEnum):
    """The verdict of a certificate (or of one of its parts)."""

    CERTIFIED = "certified"  #: every link holds, proved (exact/sound/given), every scope justified
    CONDITIONAL = "conditional"  #: every link holds, some rest on estimates or unproved regions
    NOT_CERTIFIED = "not_certified"  #: a link fails or could not be evaluated


def verdict_of(checks: Sequence[Check]) -> tuple[Verdict, tuple[str, ...]]:
    """The verdict of a list of checks and the reasons for anything short of ``certified``.

    ``not_certified`` when a check fails or is unknown (NaN); else ``conditional`` when a check
    rests on an estimate or on an unproved region; else ``certified``. An empty list is
    ``not_certified`` (nothing was shown).
    """
    if not checks:
        return Verdict.NOT_CERTIFIED, ("nothing was checked",)
    failing = [c for c in checks if not c.holds]
    if failing:
        return Verdict.NOT_CERTIFIED, tuple(
            f"{c.id} {'could not be evaluated' if c.status == CheckStatus.UNKNOWN else 'fails'}: "
            f"{c.detail}"
            for c in failing
        )
    reasons: list[str] = []
    for c in checks:
        if c.how == How.ESTIMATE:
            names = ", ".join(c.rests_on) if c.rests_on else "a sampled estimate"
            reasons.append(f"{c.id} rests on estimates: {names}")
        if not c.scope_ok:
            reasons.append(f"{c.id} rests on an unproved region: {c.scope_reason}")
    if reasons:
        return Verdict.CONDITIONAL, tuple(reasons)
    return Verdict.CERTIFIED, ()


def _json_float(x: float) -> float | str | None:
    """Finite floats as they are, ``inf``/``-inf`` as strings, NaN as ``None``."""
    x = float(x)
    if math.isnan(x):
        return None
    if math.isinf(x):
        return "inf" if x > 0 else "-inf"
    return x


json_float = _json_float


# ---------------------------------------------------------------------------------- timings
#: keys that hold wall-clock measurements in the JSON of a result: they vary from run to run, so
#: :func:`split_timings` moves them under one top-level key (``timings``) that ``diff`` ignores.
#: Not every key ending in ``_s`` is a time (``lambda_s`` is the L1-DRAC predictor pole), so the
#: names are explicit, plus the suffixes of :func:`is_timing_key`
TIMING_KEYS = frozenset(
    {"seconds", "time_s", "wall_s", "elapsed_s", "cpu_s", "compile_s", "run_s", "time_to_below"}
)


def is_timing_key(key: str) -> bool:
    """Whether a JSON key holds a wall-clock timing: one of :data:`TIMING_KEYS`, ``timings``
    (where they are kept) or a key ending in ``_time_s``, ``_wall_s`` or ``_seconds``."""
    return (
        key in TIMING_KEYS or key == "timings" or key.endswith(("_time_s", "_wall_s", "_seconds"))
    )


def split_timings(d: dict[str, Any], prefix: str = "") -> dict[str, Any]:
    """Remove every timing (:func:`is_timing_key`) from the nested dict ``d`` in place and
    return them flat, keyed by their dotted path (``contraction.expert.time_s``).

    Lists are walked too (the path takes the index). What remains of ``d`` is a function of the
    inputs alone: the reproducible part of a certificate.
    """
    out: dict[str, Any] = {}

    def walk(node: Any, path: str) -> None:
        if isinstance(node, dict):
            for k in [k for k in node if is_timing_key(k) and k != "timings"]:
                out[f"{path}{k}"] = node.pop(k)
            for k, v in node.items():
                walk(v, f"{path}{k}.")
        elif isinstance(node, list):
            for i, v in enumerate(node):
                walk(v, f"{path}{i}.")

    walk(d, prefix)
    return out
