"""``drip-cert diff OLD.json NEW.json``: what changed between two certificates (or two validation
reports), and whether the change is a regression.

Both files are read with :func:`drip_cert.schema.load_output` (same layout, same
``schema_version``; anything else is bad input, exit status 2). Every difference found is a
:class:`Change` with an ``effect``: ``regression``, ``improvement`` or ``change`` (neither). The
rules, for certificates (a validation report's embedded certificate is compared by the same rules,
its keys prefixed with ``certificate.``):

``verdict``
    ``verdict`` and each ``parts.<part>.verdict``, ordered ``certified > conditional >
    not_certified``: a step down is a regression, a step up an improvement; a part that
    disappears is a regression (it is no longer certified), a new one a change.
``bound``
    The headline bounds :data:`UPPER_BOUNDS` (smaller is tighter: ``rho``, its two parts, the
    delta-ISS gain, the TaSIL deterministic gap bound, the L1-DRAC tail threshold ``kappa``) and
    :data:`RATES` (larger is tighter: the contraction rates). A bound *loosened* beyond the
    tolerance is a regression, *tightened* beyond it an improvement; within the tolerance
    nothing is reported. A finite bound that becomes infinite or is no longer computed (``null``)
    is a regression.
``margin_sign``
    Each assumption (by ``id``) whose signed ``margin`` (positive = satisfied) changed sign: from
    positive to zero, negative or NaN is a regression, the other way an improvement. A status
    change without a sign change (e.g. an unjustified scope) is reported under ``status``.
``provenance``
    Each constant (``constants.<name>.how``), assumption (``assumptions[<id>].how``) and the
    rates' and gain's ``how``, ordered as :class:`~drip_cert.provenance.How`
    (``exact > sound > given > estimate``): weakened is a regression, strengthened an
    improvement.
``removed`` / ``added``
    An assumption that is no longer checked is a regression; a new one is a change (a regression
    if it does not hold).

For validation reports also: ``status`` (``holds`` to anything else, or ``nothing_checked`` to
``violated``, is a regression), each check by ``name`` (``holds`` to ``violated`` or
``not_checked`` is a regression), and ``at_certified_parameters`` (``true`` to ``false`` is a
regression: the run no longer validates the certificate).

Tolerance: two numbers ``a`` (old) and ``b`` (new) differ when ``|b - a| > rtol * max(|a|, |b|) +
ATOL``; :data:`DEFAULT_RTOL` is ``1e-3``.
"""

from __future__ import annotations

import math
from collections.abc import Mapping
from dataclasses import dataclass
from pathlib import Path
from typing import Any

from drip_cert.errors import SpecError
from drip_cert.provenance import How
from drip_cert.schema import LoadedOutput, load_output

__all__ = [
    "ATOL",
    "DEFAULT_RTOL",
    "RATES",
    "UPPER_BOUNDS",
    "Change",
    "DiffResult",
    "diff_files",
    "diff_outputs",
    "diff_text",
]

DEFAULT_RTOL = 1e-3
"""Default relative tolerance of ``drip-cert diff`` and the pytest baseline. The same code on the
same inputs gives the same numbers bit for bit, and another machine's BLAS moves the closed forms
by ~1e-12 relative; what moves more without a change of model, policy or data is a time-limited
search (a branch and bound that stops at another depth on a slower machine returns a slightly
different sound bound). 0.1 % ignores both and is far below what a changed model, policy or data
set does to a bound; a trained policy, reproducible only to a few per cent across code versions
(README "Findings"), wants ``--rtol 0.05``."""

ATOL = 1e-12
"""Absolute floor of the tolerance: a bound of 0 (an exactly cancelled term) that becomes 1e-17
is rounding, not a loosening."""

UPPER_BOUNDS: tuple[tuple[str, str], ...] = (
    ("rho.rho_total", "rho = rho_TaSIL + rho_L1"),
    ("rho.rho_tasil", "rho_TaSIL"),
    ("rho.rho_l1", "rho_L1"),
    ("delta_iss.gain", "delta-ISS gain"),
    ("tasil.gap_bound", "TaSIL deterministic gap bound"),
    ("l1drac.kappa", "L1-DRAC tail threshold kappa"),
)
"""Certificate keys holding upper bounds (smaller is tighter) and their names."""

RATES: tuple[tuple[str, str], ...] = (
    ("contraction.rate", "expert contraction rate"),
    ("contraction.metric_rate", "expert metric contraction rate"),
    ("contraction.learned.rate", "learned contraction rate"),
)
"""Certificate keys holding lower bounds on a rate (larger is tighter) and their names."""

_HOW_KEYS = ("contraction.how", "contraction.learned.how", "delta_iss.how")

_VERDICT_RANK = {"certified": 0, "conditional": 1, "not_certified": 2}
_STATUS_RANK = {"holds": 0, "nothing_checked": 1, "violated": 2}

REGRESSION = "regression"
IMPROVEMENT = "improvement"
CHANGE = "change"

_MISSING = object()


@dataclass(frozen=True)
class Change:
    """One difference between the old and the new output.

    Attributes
    ----------
    rule
        ``verdict``, ``bound``, ``margin_sign``, ``status``, ``provenance``, ``removed``,
        ``added``, ``check`` or ``parameters`` (module docstring).
    key
        Where, as a key path: ``"rho.rho_total"``, ``"assumptions[DRIP-A2].margin"``,
        ``"constants.L_mu.how"``, ``"checks[policy_radius].status"``.
    old, new
        The two values (``None`` for absent or NaN).
    effect
        ``regression``, ``improvement`` or ``change``.
    text
        One line for a person.
    """

    rule: str
    key: str
    old: Any
    new: Any
    effect: str
    text: str

    @property
    def regression(self) -> bool:
        """``effect == "regression"``."""
        return self.effect == REGRESSION

    def to_dict(self) -> dict[str, Any]:
        """JSON-ready dictionary of the fields."""
        return {
            "rule": self.rule,
            "key": self.key,
            "old": self.old,
            "new": self.new,
            "effect": self.effect,
            "text": self.text,
        }


@dataclass(frozen=True)
class DiffResult:
    """Every change between two outputs of one layout.

    ``exit_status`` is 1 when a change is a regression, else 0 (what ``drip-cert diff``
    returns).
    """

    kind: str
    old: str
    new: str
    rtol: float
    changes: tuple[Change, ...]
    notes: tuple[str, ...] = ()

    @property
    def regressions(self) -> tuple[Change, ...]:
        return tuple(c for c in self.changes if c.effect == REGRESSION)

    @property
    def improvements(self) -> tuple[Change, ...]:
        return tuple(c for c in self.changes if c.effect == IMPROVEMENT)

    @property
    def regression(self) -> bool:
        """Whether any change is a regression."""
        return bool(self.regressions)

    @property
    def exit_status(self) -> int:
        return 1 if self.regression else 0

    def to_dict(self) -> dict[str, Any]:
        """JSON-ready: the files, the tolerance, the counts and every change."""
        return {
            "kind": self.kind,
            "old": self.old,
            "new": self.new,
            "rtol": self.rtol,
            "atol": ATOL,
            "regression": self.regression,
            "counts": {
                REGRESSION: len(self.regressions),
                IMPROVEMENT: len(self.improvements),
                CHANGE: len(self.changes) - len(self.regressions) - len(self.improvements),
            },
            "changes": [c.to_dict() for c in self.changes],
            "notes": list(self.notes),
        }


# ----------------------------------------------------------------------------- helpers
def _get(d: Any, key: str) -> Any:
    """``d["a"]["b"]`` for ``key = "a.b"``; :data:`_MISSING` where a level is absent or null."""
    for part in key.split("."):
        if not isinstance(d, Mapping) or part not in d:
            return _MISSING
        d = d[part]
    return d


def _num(v: Any) -> float | None:
    """A number as drip-cert writes it (``"inf"``, ``null``) as a float; ``None`` for none."""
    if v is _MISSING or v is None or isinstance(v, bool):
        return None
    if v == "inf":
        return math.inf
    if v == "-inf":
        return -math.inf
    if isinstance(v, int | float):
        return None if math.isnan(v) else float(v)
    return None


def _plain(v: Any) -> Any:
    return None if v is _MISSING else v


def _fmt(v: Any) -> str:
    x = _num(v)
    if x is None:
        return "n/a" if v is _MISSING or v is None else str(v)
    return f"{x:.6g}"


def _differ(a: float, b: float, rtol: float) -> bool:
    if a == b:
        return False
    if math.isinf(a) or math.isinf(b):
        return True
    return abs(b - a) > rtol * max(abs(a), abs(b)) + ATOL


def _rel(a: float, b: float) -> str:
    if a == 0 or math.isinf(a) or math.isinf(b):
        return ""
    return f" ({(b - a) / abs(a):+.3g} relative)"


# ------------------------------------------------------------------------------ rules
def _verdicts(old: Mapping, new: Mapping, pre: str) -> list[Change]:
    out = []
    keys = [("verdict", "verdict")]
    parts = sorted(set(_get(old, "parts") or {}) | set(_get(new, "parts") or {}))
    keys += [(f"parts.{p}.verdict", f"part {p}") for p in parts]
    for key, name in keys:
        a, b = _get(old, key), _get(new, key)
        if a == b:
            continue
        if b is _MISSING:
            effect, what = REGRESSION, f"{name}: {a} -> no longer computed"
        elif a is _MISSING:
            effect, what = CHANGE, f"{name}: new, {b}"
        else:
            ra, rb = _VERDICT_RANK.get(a, 3), _VERDICT_RANK.get(b, 3)
            effect = REGRESSION if rb > ra else IMPROVEMENT
            what = f"{name}: {a} -> {b}"
        out.append(Change("verdict", pre + key, _plain(a), _plain(b), effect, what))
    return out


def _bounds(old: Mapping, new: Mapping, pre: str, rtol: float) -> list[Change]:
    out = []
    for table, upper in ((UPPER_BOUNDS, True), (RATES, False)):
        for key, name in table:
            ra, rb = _get(old, key), _get(new, key)
            a, b = _num(ra), _num(rb)
            if a is None and b is None:
                continue
            if b is None:
                effect = REGRESSION if a is not None and math.isfinite(a) else CHANGE
                what = f"{name} ({key}): {_fmt(ra)} -> no longer computed"
            elif a is None:
                effect, what = CHANGE, f"{name} ({key}): newly computed, {_fmt(rb)}"
            elif not _differ(a, b, rtol):
                continue
            else:
                looser = (b > a) if upper else (b < a)
                effect = REGRESSION if looser else IMPROVEMENT
                what = (
                    f"{name} ({key}) {'loosened' if looser else 'tightened'}: {_fmt(ra)} -> "
                    f"{_fmt(rb)}{_rel(a, b)}, beyond rtol {rtol:g}"
                )
            out.append(Change("bound", pre + key, _plain(ra), _plain(rb), effect, what))
    return out


def _by(items: Any, field: str) -> dict[str, Mapping]:
    if not isinstance(items, list):
        return {}
    return {str(x[field]): x for x in items if isinstance(x, Mapping) and field in x}


def _how_change(rule_key: str, a: Any, b: Any, name: str) -> Change | None:
    if a == b or a is _MISSING or b is _MISSING or a is None or b is None:
        return None
    try:
        ra, rb = How(a).rank, How(b).rank
    except ValueError:
        return None
    effect = REGRESSION if rb > ra else IMPROVEMENT
    verb = "weakened" if rb > ra else "strengthened"
    return Change("provenance", rule_key, a, b, effect, f"{name}: provenance {verb}, {a} -> {b}")


def _assumptions(old: Mapping, new: Mapping, pre: str) -> list[Change]:
    out: list[Change] = []
    ao, an = _by(_get(old, "assumptions"), "id"), _by(_get(new, "assumptions"), "id")
    for cid in [*ao, *[i for i in an if i not in ao]]:
        key = f"{pre}assumptions[{cid}]"
        a, b = ao.get(cid), an.get(cid)
        if b is None:
            was = a.get("status") if a else None
            out.append(
                Change("removed", key, was, None, REGRESSION, f"{cid}: no longer checked ({was})")
            )
            continue
        if a is None:
            holds = b.get("status") == "holds"
            what = f"{cid}: new check, {b.get('status')} (margin {_fmt(b.get('margin'))})"
            effect = CHANGE if holds else REGRESSION
            out.append(Change("added", key, None, b.get("status"), effect, what))
            continue
        ma, mb = _num(a.get("margin")), _num(b.get("margin"))
        pa, pb = ma is not None and ma > 0, mb is not None and mb > 0
        if pa != pb:
            out.append(
                Change(
                    "margin_sign",
                    key + ".margin",
                    a.get("margin"),
                    b.get("margin"),
                    REGRESSION if pa else IMPROVEMENT,
                    f"{cid}: margin changed sign, {_fmt(a.get('margin'))} -> "
                    f"{_fmt(b.get('margin'))} ({a.get('status')} -> {b.get('status')})",
                )
            )
        elif a.get("status") != b.get("status"):
            worse = b.get("status") != "holds"
            out.append(
                Change(
                    "status",
                    key + ".status",
                    a.get("status"),
                    b.get("status"),
                    REGRESSION if worse else IMPROVEMENT,
                    f"{cid}: {a.get('status')} -> {b.get('status')}",
                )
            )
        c = _how_change(key + ".how", a.get("how"), b.get("how"), cid)
        if c is not None:
            out.append(c)
    return out


def _provenance(old: Mapping, new: Mapping, pre: str) -> list[Change]:
    out = []
    co, cn = _get(old, "constants"), _get(new, "constants")
    co = co if isinstance(co, Mapping) else {}
    cn = cn if isinstance(cn, Mapping) else {}
    for name in co:
        if name in cn and isinstance(co[name], Mapping) and isinstance(cn[name], Mapping):
            c = _how_change(
                f"{pre}constants.{name}.how", co[name].get("how"), cn[name].get("how"), name
            )
            if c is not None:
                out.append(c)
    for key in _HOW_KEYS:
        c = _how_change(pre + key, _get(old, key), _get(new, key), key.rsplit(".", 1)[0])
        if c is not None:
            out.append(c)
    return out


def _certificate(old: Mapping, new: Mapping, rtol: float, pre: str = "") -> list[Change]:
    return [
        *_verdicts(old, new, pre),
        *_bounds(old, new, pre, rtol),
        *_assumptions(old, new, pre),
        *_provenance(old, new, pre),
    ]


def _validation(old: Mapping, new: Mapping) -> list[Change]:
    out = []
    a, b = old.get("status"), new.get("status")
    if a != b:
        worse = _STATUS_RANK.get(str(b), 3) > _STATUS_RANK.get(str(a), 3)
        out.append(
            Change(
                "status",
                "status",
                a,
                b,
                REGRESSION if worse else IMPROVEMENT,
                f"validation status: {a} -> {b}",
            )
        )
    a, b = old.get("at_certified_parameters"), new.get("at_certified_parameters")
    if a != b:
        out.append(
            Change(
                "parameters",
                "at_certified_parameters",
                a,
                b,
                REGRESSION if a else IMPROVEMENT,
                "L1-DRAC runs " + ("no longer at" if a else "now at") + " the certified parameters",
            )
        )
    co, cn = _by(old.get("checks"), "name"), _by(new.get("checks"), "name")
    for name in [*co, *[n for n in cn if n not in co]]:
        sa = co[name].get("status") if name in co else None
        sb = cn[name].get("status") if name in cn else None
        if sa == sb:
            continue
        if sa == "holds":
            effect = REGRESSION
        elif sb == "holds":
            effect = IMPROVEMENT
        else:
            effect = REGRESSION if sb == "violated" else CHANGE
        reason = cn[name].get("reason") if name in cn else None
        out.append(
            Change(
                "check",
                f"checks[{name}].status",
                sa,
                sb,
                effect,
                f"check {name}: {sa or 'absent'} -> {sb or 'absent'}"
                + (f" ({reason})" if reason else ""),
            )
        )
    return out


# ------------------------------------------------------------------------- public API
def diff_outputs(old: LoadedOutput, new: LoadedOutput, *, rtol: float = DEFAULT_RTOL) -> DiffResult:
    """Compare two loaded outputs of one layout (see the module docstring for the rules).

    Raises
    ------
    SpecError
        The two are of different layouts, or ``rtol`` is not a finite number >= 0.
    """
    if not (isinstance(rtol, int | float) and math.isfinite(rtol) and rtol >= 0):
        raise SpecError(f"rtol must be a finite number >= 0, got {rtol!r}", field="--rtol")
    if old.kind != new.kind:
        raise SpecError(
            f"{old.path} is a {old.kind} and {new.path} a {new.kind}: compare two certificates "
            "or two validation reports",
            path=str(new.path),
        )
    notes = []
    so, sn = _get(old.certificate, "system.name"), _get(new.certificate, "system.name")
    if so != sn:
        notes.append(f"different systems: {so!r} (old) and {sn!r} (new)")
    if old.kind == "validation":
        changes = _validation(old.data, new.data) + _certificate(
            old.certificate, new.certificate, rtol, pre="certificate."
        )
    else:
        changes = _certificate(old.data, new.data, rtol)
    return DiffResult(
        kind=old.kind,
        old=str(old.path),
        new=str(new.path),
        rtol=float(rtol),
        changes=tuple(changes),
        notes=tuple(notes),
    )


def diff_files(old: str | Path, new: str | Path, *, rtol: float = DEFAULT_RTOL) -> DiffResult:
    """:func:`diff_outputs` of two files (each read and checked by
    :func:`~drip_cert.schema.load_output`)."""
    return diff_outputs(load_output(old), load_output(new), rtol=rtol)


def diff_text(res: DiffResult) -> str:
    """What ``drip-cert diff`` prints: the outcome, then regressions, improvements and other
    changes, one line each."""
    n_reg, n_imp = len(res.regressions), len(res.improvements)
    n_other = len(res.changes) - n_reg - n_imp
    head = "REGRESSION" if res.regression else ("no regression" if res.changes else "no change")
    lines = [
        f"drip-cert diff ({res.kind}s): {head} ({n_reg} regression(s), {n_imp} improvement(s), "
        f"{n_other} other change(s); rtol {res.rtol:g})",
        f"  old: {res.old}",
        f"  new: {res.new}",
    ]
    for title, effect in (
        ("Regressions", REGRESSION),
        ("Improvements", IMPROVEMENT),
        ("Other changes", CHANGE),
    ):
        items = [c for c in res.changes if c.effect == effect]
        if items:
            lines += ["", f"{title}:"] + [f"  {c.text}" for c in items]
    for note in res.notes:
        lines += ["", f"note: {note}"]
    return "\n".join(lines)
