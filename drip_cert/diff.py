"""``drip-cert diff OLD.json NEW.json``: what changed between two certificates (or two validation
reports), and whether the change is a regression.

Both files are read with :func:`drip_cert.schema.load_output` (same layout, same
``schema_version``; anything else is bad input, exit status 2). Every difference found is a
:class:`Change` with an ``effect``: ``regression``, ``improvement`` or ``change`` (neither). A
certificate is compared as a set of *claims*, not of headline numbers: a bound is the claim
``(radius, delta, p, form, coordinates)`` and a radius is compared only with the radius of the same
claim. The rules (docs/diff.md has them as a table, with the message of each), for certificates
(a validation report's embedded certificate is compared by the same rules, its keys prefixed
with ``certificate.``):

``verdict``
    ``verdict`` and each ``parts.<part>.verdict``, ordered ``certified > conditional >
    not_certified``: a step down is a regression, a step up an improvement; a part that
    disappears is a regression (it is no longer certified), a new one a change.
``claim``
    The claims :data:`CLAIMS`: TaSIL ``P[max_t ||x'_t - x*_t|| <= rho_TaSIL] >= 1 - delta``
    (``tasil.delta``, ``tasil.rho_form``), the L1-DRAC moment bound ``||X_t - x'_t||_{L_2p} <=
    rho_L1`` (``l1drac.p``) and its tail ``P[... > kappa] <= delta`` (``l1drac.delta``), in
    ``rho.coordinates`` / ``coordinates.system``. A larger ``delta`` or a smaller ``p`` at the
    same or a looser radius is a regression (the new claim is weaker), a smaller ``delta`` or a
    larger ``p`` at the same or a tighter radius an improvement, and a trade-off (weaker
    parameter, tighter radius or the reverse: neither claim implies the other) a change. A
    changed ``form`` or ``coordinates`` is a regression (another statement, not comparable:
    its radius is not compared).
``bound``
    The headline bounds :data:`UPPER_BOUNDS` (smaller is tighter) and :data:`RATES` (larger is
    tighter), each compared only while its claim's parameters are unchanged. Loosened beyond the
    tolerance is a regression, tightened an improvement; a finite bound that becomes infinite or
    is no longer computed (``null``) is a regression.
``constant``
    Each ``constants.<name>``: removed is a regression; a value moved beyond the tolerance in the
    loosening direction of :func:`constant_direction` (bounds, growth and Lipschitz constants,
    gains: larger is looser; rates and margins: smaller is looser) a regression, the other way
    an improvement; a constant of unknown direction that moves beyond the tolerance is a
    regression (no one can say it is harmless); new constants are one change.
``soundness``
    ``sound`` true -> false is a regression, a name new in ``estimated_constants`` or
    ``given_constants`` is a regression (the certificate now rests on an estimate or on the
    user's word); the reverse are improvements.
``reason``
    A reason new in ``verdict_reasons`` or ``parts.<part>.reasons`` is a regression, a reason gone
    an improvement. Reasons are matched with their numbers masked (the numbers are compared by
    the other rules; a moved number is not a new reason).
``scope``
    Each check, anywhere in the certificate (assumptions, TaSIL forms and gap checks, parts),
    whose ``scope_justified`` goes true -> false is a regression, false -> true an improvement.
``margin_sign``
    Each assumption (by ``id``) whose signed ``margin`` (positive = satisfied) changed sign: from
    positive to zero, negative or NaN is a regression, the other way an improvement. A status
    change without a sign change is reported under ``status``.
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
``not_checked`` is a regression; of a check that holds in both, a ``ratio`` ``bound / empirical``
grown beyond the tolerance is a regression -- a looser certificate, even one that still holds --
and shrunk an improvement), and ``at_certified_parameters`` (``true`` to ``false`` is a
regression: the run no longer validates the certificate).

Timings are never compared: the top-level key ``timings`` of either layout and every key that
:func:`is_timing_key` names (``time_s``, ``seconds``, ``compile_s``, ``run_s``, ...; not
``lambda_s``, the filter bandwidth) are removed from both outputs before any rule runs.

Tolerance: two numbers ``a`` (old) and ``b`` (new) differ when ``|b - a| > rtol * max(|a|, |b|) +
ATOL``; :data:`DEFAULT_RTOL` is ``1e-3``.
"""

from __future__ import annotations

import math
import re
from collections.abc import Mapping
from dataclasses import dataclass
from pathlib import Path
from typing import Any

from drip_cert.errors import SpecError
from drip_cert.provenance import How, is_timing_key
from drip_cert.schema import LoadedOutput, load_output

__all__ = [
    "ATOL",
    "CLAIMS",
    "CONSTANT_DIRECTIONS",
    "DEFAULT_RTOL",
    "RATES",
    "UPPER_BOUNDS",
    "Change",
    "Claim",
    "DiffResult",
    "constant_direction",
    "diff_files",
    "diff_outputs",
    "diff_text",
    "is_timing_key",
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

LARGER_IS_LOOSER = "larger is looser"
SMALLER_IS_LOOSER = "smaller is looser"
UNKNOWN_DIRECTION = "direction unknown"

CONSTANT_DIRECTIONS: tuple[tuple[str, str, str], ...] = (
    (r"lambda.*|.*rate.*|.*margin.*", SMALLER_IS_LOOSER, "rate or margin"),
    (r"Delta_.*|Theta.*|\|\|.*|sup.*|max.*|(max_)?mu_?2.*", LARGER_IS_LOOSER, "bound"),
    (r"L_.*|Lip\(.*", LARGER_IS_LOOSER, "Lipschitz constant"),
    (r"gamma.*", LARGER_IS_LOOSER, "gain"),
    (r"h[01]", LARGER_IS_LOOSER, "TaSIL policy error along the trajectories"),
    (r"alpha", LARGER_IS_LOOSER, "W_2p distance of the initial laws"),
    (r"eps_[ra]", LARGER_IS_LOOSER, "slack of (16): a larger slack makes the radii larger"),
    (r"kappa.*|rho.*", LARGER_IS_LOOSER, "radius"),
)
"""``(regex, direction, kind)`` for the constants of ``constants.<name>``, first full match wins
(:func:`constant_direction`). Rates (``lambda``, ``lambda_learned``, ``lambda_P``) are lower
bounds: smaller is looser. Everything else the certificate lists is an upper bound (``Delta_*``
norms and growth bounds, ``L_*`` Lipschitz constants, ``gamma*`` gains, sups and log norms
``mu_2``, TaSIL ``h0``/``h1``, the initial-law distance ``alpha``, the design slacks ``eps_r``,
``eps_a`` of (16), radii): larger is looser. A name matching none has an unknown direction."""


def constant_direction(name: str) -> tuple[str, str]:
    """``(direction, kind)`` of constant ``name`` by :data:`CONSTANT_DIRECTIONS`:
    ``"larger is looser"``, ``"smaller is looser"`` or ``"direction unknown"``."""
    for pattern, direction, kind in CONSTANT_DIRECTIONS:
        if re.fullmatch(pattern, name):
            return direction, kind
    return UNKNOWN_DIRECTION, "constant"


WEAKER_WHEN_LARGER = -1  #: a parameter like delta: larger is a weaker claim
STRONGER_WHEN_LARGER = 1  #: a parameter like p: larger is a stronger claim
MUST_BE_EQUAL = 0  #: a parameter like form or coordinates: any change is another claim


@dataclass(frozen=True)
class Claim:
    """One claim of a certificate: a radius and the parameters that say what it bounds.

    Attributes
    ----------
    name
        For a person (``"TaSIL"``).
    radius
        ``(key, name)`` of the radius (an upper bound: smaller is tighter).
    params
        ``(key, name, order)`` of each parameter, ``order`` one of
        :data:`WEAKER_WHEN_LARGER` (``delta``), :data:`STRONGER_WHEN_LARGER` (``p``),
        :data:`MUST_BE_EQUAL` (``form``, ``coordinates``).
    statement
        The claim, written out.
    """

    name: str
    radius: tuple[str, str]
    params: tuple[tuple[str, str, int], ...]
    statement: str


CLAIMS: tuple[Claim, ...] = (
    Claim(
        "TaSIL",
        ("rho.rho_tasil", "rho_TaSIL"),
        (
            ("tasil.delta", "delta", WEAKER_WHEN_LARGER),
            ("tasil.rho_form", "form", MUST_BE_EQUAL),
            ("rho.coordinates", "coordinates", MUST_BE_EQUAL),
        ),
        "P[max_t ||x'_t - x*_t|| <= rho_TaSIL] >= 1 - delta",
    ),
    Claim(
        "L1-DRAC moment",
        ("rho.rho_l1", "rho_L1"),
        (
            ("l1drac.p", "p", STRONGER_WHEN_LARGER),
            ("rho.coordinates", "coordinates", MUST_BE_EQUAL),
        ),
        "||X_t - x'_t||_{L_2p} <= rho_L1",
    ),
    Claim(
        "L1-DRAC tail",
        ("l1drac.kappa", "kappa"),
        (
            ("l1drac.delta", "delta", WEAKER_WHEN_LARGER),
            ("coordinates.system", "coordinates", MUST_BE_EQUAL),
        ),
        "P[||X_t - x'_t|| > kappa] <= delta",
    ),
    Claim(
        "rho",
        ("rho.rho_total", "rho"),
        (
            ("tasil.delta", "delta", WEAKER_WHEN_LARGER),
            ("tasil.rho_form", "form", MUST_BE_EQUAL),
            ("l1drac.p", "p", STRONGER_WHEN_LARGER),
            ("rho.coordinates", "coordinates", MUST_BE_EQUAL),
        ),
        "rho_TaSIL + rho_L1 (reported through its two parts)",
    ),
)
"""The claims of a certificate. A radius is compared by the ``bound`` rule only while every
parameter of its claim is unchanged; otherwise the ``claim`` rule reports the claim as a whole
(``rho`` is the sum of two claims of different kinds: its parts' lines report it)."""

_REPORTED_CLAIMS = ("TaSIL", "L1-DRAC moment", "L1-DRAC tail")

_VERDICT_RANK = {"certified": 0, "conditional": 1, "not_certified": 2}
#: part verdicts of a part that was not computed: read as an absent part
_NOT_COMPUTED = ("not_requested", "not_applicable")
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
        ``verdict``, ``claim``, ``bound``, ``constant``, ``soundness``, ``reason``, ``scope``,
        ``margin_sign``, ``status``, ``provenance``, ``removed``, ``added``, ``check`` or
        ``parameters`` (module docstring; docs/diff.md).
    key
        Where, as a key path: ``"rho.rho_total"``, ``"assumptions[DRIP-A2].margin"``,
        ``"constants.L_mu.how"``, ``"tasil.delta"``, ``"checks[policy_radius].status"``.
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
        # a part named but not computed (schema 4) counts as absent
        a = _MISSING if a in _NOT_COMPUTED else a
        b = _MISSING if b in _NOT_COMPUTED else b
        if b is _MISSING and a is _MISSING:
            effect, what = CHANGE, f"{name}: {_get(old, key)} -> {_get(new, key)}"
            out.append(Change("verdict", pre + key, None, None, effect, what))
            continue
        if b is _MISSING:
            effect, what = REGRESSION, f"{name}: {a} -> no longer computed"
        elif a is _MISSING:
            effect, what = CHANGE, f"{name}: new, {b}"
        else:
            ra, rb = _VERDICT_RANK.get(str(a), 3), _VERDICT_RANK.get(str(b), 3)
            effect = REGRESSION if rb > ra else IMPROVEMENT
            what = f"{name}: {a} -> {b}"
        out.append(Change("verdict", pre + key, _plain(a), _plain(b), effect, what))
    return out


def _bounds(old: Mapping, new: Mapping, pre: str, rtol: float) -> list[Change]:
    out = []
    skip = _radii_of_changed_claims(old, new)
    for table, upper in ((UPPER_BOUNDS, True), (RATES, False)):
        for key, name in table:
            ra, rb = _get(old, key), _get(new, key)
            a, b = _num(ra), _num(rb)
            if (a is None and b is None) or key in skip:
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


def _present(v: Any) -> bool:
    return v is not _MISSING and v is not None


def _changed_params(old: Mapping, new: Mapping) -> dict[str, tuple[Any, Any]]:
    """The claim parameters (``tasil.delta``, ``l1drac.p``, ...) present in both and different."""
    out = {}
    for claim in CLAIMS:
        for key, _, _ in claim.params:
            a, b = _get(old, key), _get(new, key)
            if _present(a) and _present(b) and a != b:
                out[key] = (a, b)
    return out


def _radii_of_changed_claims(old: Mapping, new: Mapping) -> set[str]:
    """Radius keys whose claim changed a parameter while both radii are numbers (the ``claim``
    rule reports those; a radius no longer computed is still the ``bound`` rule's)."""
    changed = _changed_params(old, new)
    out = set()
    for claim in CLAIMS:
        key = claim.radius[0]
        if any(k in changed for k, _, _ in claim.params) and all(
            _num(_get(d, key)) is not None for d in (old, new)
        ):
            out.add(key)
    return out


_PARAM_NOTES = {
    "coordinates.system": " (rates, gains, constants and the TaSIL and L1-DRAC sections are in "
    "these coordinates; rho.* stay in x)",
}


def _param_text(name: str, a: Any, b: Any) -> str:
    text = f"{name} {_fmt(a)} -> {_fmt(b)}"
    x, y = _num(a), _num(b)
    if name == "p" and x is not None and y is not None:
        return text + f" (an L_{2 * x:g} -> L_{2 * y:g} moment bound)"
    if name == "delta" and x is not None and y is not None:
        return text + f" (confidence 1 - delta {1 - x:.6g} -> {1 - y:.6g})"
    return text


def _claims(old: Mapping, new: Mapping, pre: str, rtol: float) -> list[Change]:
    """The ``claim`` rule (module docstring): a changed form or coordinates, then each claim whose
    ordered parameters (``delta``, ``p``) changed, judged with its radius."""
    out: list[Change] = []
    changed = _changed_params(old, new)
    seen: set[str] = set()
    for claim in CLAIMS:  # a changed form or coordinates: another claim, one line per key
        for key, name, order in claim.params:
            if order != MUST_BE_EQUAL or key not in changed or key in seen:
                continue
            seen.add(key)
            a, b = changed[key]
            radii = [
                f"{c.radius[1]} {_fmt(_get(old, c.radius[0]))} -> {_fmt(_get(new, c.radius[0]))}"
                for c in CLAIMS
                if c.name in _REPORTED_CLAIMS and any(k == key for k, _, _ in c.params)
            ]
            out.append(
                Change(
                    "claim",
                    pre + key,
                    a,
                    b,
                    REGRESSION,
                    f"claim changed: {name} ({key}) {a} -> {b}; another statement, not "
                    f"compared: {', '.join(radii)}{_PARAM_NOTES.get(key, '')}",
                )
            )
    for claim in CLAIMS:
        if claim.name not in _REPORTED_CLAIMS:
            continue
        moved = [(k, n, o) for k, n, o in claim.params if o != MUST_BE_EQUAL and k in changed]
        if not moved:
            continue
        comparable = not any(o == MUST_BE_EQUAL and k in changed for k, _, o in claim.params)
        weaker = stronger = False
        for k, _, o in moved:
            a, b = (_num(v) for v in changed[k])
            if a is None or b is None:
                continue
            larger = b > a
            weaker |= larger == (o == WEAKER_WHEN_LARGER)
            stronger |= larger != (o == WEAKER_WHEN_LARGER)
        key, rname = claim.radius
        ra, rb = _get(old, key), _get(new, key)
        a, b = _num(ra), _num(rb)
        if a is None or b is None or not comparable:
            rdir, rtext = "", f"radius {rname} {_fmt(ra)} -> {_fmt(rb)} (not compared)"
        elif not _differ(a, b, rtol):
            rdir, rtext = "same", f"the same radius {rname} = {_fmt(rb)} (within rtol {rtol:g})"
        else:
            rdir = "looser" if b > a else "tighter"
            rtext = f"a {rdir} radius {rname} {_fmt(ra)} -> {_fmt(rb)}{_rel(a, b)}"
        if weaker and not stronger and rdir in ("", "same", "looser"):
            effect, verb = REGRESSION, "weakened"
        elif stronger and not weaker and rdir in ("same", "tighter"):
            effect, verb = IMPROVEMENT, "strengthened"
        elif weaker != stronger and rdir in ("looser", "tighter"):
            effect, verb = CHANGE, "traded (neither claim implies the other)"
        else:
            effect, verb = CHANGE, "changed"
        first = moved[0][0]
        params = ", ".join(_param_text(n, *changed[k]) for k, n, _ in moved)
        out.append(
            Change(
                "claim",
                pre + first,
                changed[first][0],
                changed[first][1],
                effect,
                f"{claim.name} claim {verb}: {params} at {rtext}; claim {claim.statement}",
            )
        )
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


def _mapping(v: Any) -> Mapping:
    return v if isinstance(v, Mapping) else {}


def _constants(old: Mapping, new: Mapping, pre: str, rtol: float) -> list[Change]:
    """The ``constant`` rule: removed constants, values moved beyond ``rtol`` by
    :func:`constant_direction`, and one line naming the new constants."""
    out: list[Change] = []
    co, cn = _mapping(_get(old, "constants")), _mapping(_get(new, "constants"))
    for name, qa in co.items():
        key = f"{pre}constants.{name}"
        va = _mapping(qa).get("value")
        if name not in cn:
            how = _mapping(qa).get("how")
            out.append(
                Change(
                    "constant",
                    key,
                    _plain(va),
                    None,
                    REGRESSION,
                    f"constant {name} removed (was {_fmt(va)}, {how}): the certificate no "
                    "longer states it",
                )
            )
            continue
        vb = _mapping(cn[name]).get("value")
        c = _constant_value(name, key + ".value", va, vb, rtol)
        if c is not None:
            out.append(c)
    added = [n for n in cn if n not in co]
    if added:
        out.append(
            Change(
                "constant",
                pre + "constants",
                None,
                added,
                CHANGE,
                f"new constant(s): {', '.join(added)}",
            )
        )
    return out


def _constant_value(name: str, key: str, va: Any, vb: Any, rtol: float) -> Change | None:
    a, b = _num(va), _num(vb)
    direction, kind = constant_direction(name)
    if a is None and b is None:
        return None
    if b is None:
        effect, what = REGRESSION, f"{_fmt(va)} -> not a number"
    elif a is None:
        effect, what = IMPROVEMENT, f"not a number -> {_fmt(vb)}"
    elif not _differ(a, b, rtol):
        return None
    else:
        what = f"{_fmt(va)} -> {_fmt(vb)}{_rel(a, b)}, beyond rtol {rtol:g}"
        if direction == UNKNOWN_DIRECTION:
            effect = REGRESSION
            what = f"moved {what} (direction unknown: any move is flagged)"
        else:
            looser = (b > a) if direction == LARGER_IS_LOOSER else (b < a)
            effect = REGRESSION if looser else IMPROVEMENT
            what = f"{'loosened' if looser else 'tightened'} {what}"
    return Change(
        "constant",
        key,
        _plain(va),
        _plain(vb),
        effect,
        f"constant {name} ({kind}, {direction}): {what}",
    )


def _soundness(old: Mapping, new: Mapping, pre: str) -> list[Change]:
    """The ``soundness`` rule: ``sound`` lost or gained, names new in (or gone from)
    ``estimated_constants`` / ``given_constants``."""
    out: list[Change] = []
    a, b = _get(old, "sound"), _get(new, "sound")
    if isinstance(a, bool) and isinstance(b, bool) and a != b:
        est = _get(new if a else old, "estimated_constants")
        names = ", ".join(est) if isinstance(est, list) and est else "none listed"
        what = (
            f"sound: true -> false (the certificate now rests on estimates: {names})"
            if a
            else f"sound: false -> true (it no longer rests on estimates: {names})"
        )
        out.append(Change("soundness", pre + "sound", a, b, REGRESSION if a else IMPROVEMENT, what))
    constants_new = _mapping(_get(new, "constants"))
    for key, word in (("estimated_constants", "estimated"), ("given_constants", "given")):
        la, lb = _get(old, key), _get(new, key)
        la = la if isinstance(la, list) else []
        lb = lb if isinstance(lb, list) else []
        for name in lb:
            if name not in la:
                value = _fmt(_mapping(constants_new.get(name)).get("value"))
                what = f"new {word} constant: {name} = {value} (not proved"
                what += ": the user's word)" if word == "given" else ": a sampled estimate)"
                out.append(Change("soundness", f"{pre}{key}", None, name, REGRESSION, what))
        for name in la:
            if name not in lb:
                what = f"no longer {word}: {name}"
                out.append(Change("soundness", f"{pre}{key}", name, None, IMPROVEMENT, what))
    return out


_NUMBER = re.compile(r"(?<![\w.])[-+]?(?:\d+\.?\d*|\.\d+)(?:[eE][-+]?\d+)?")


def _reasons_of(cert: Mapping) -> dict[str, tuple[str, list[str]]]:
    """``{reason with numbers masked: (first text, [where])}`` over ``verdict_reasons`` and
    ``parts.<part>.reasons``."""
    out: dict[str, tuple[str, list[str]]] = {}
    places = [("verdict", _get(cert, "verdict_reasons"))]
    for part, body in _mapping(_get(cert, "parts")).items():
        places.append((f"part {part}", _mapping(body).get("reasons")))
    for where, reasons in places:
        for r in reasons if isinstance(reasons, list) else []:
            text = str(r)
            out.setdefault(_NUMBER.sub("#", text), (text, []))[1].append(where)
    return out


def _reasons(old: Mapping, new: Mapping, pre: str) -> list[Change]:
    """The ``reason`` rule: each verdict reason new (a regression) or gone (an improvement)."""
    ro, rn = _reasons_of(old), _reasons_of(new)
    out = []
    for masked, (text, where) in rn.items():
        if masked not in ro:
            out.append(
                Change(
                    "reason",
                    pre + "verdict_reasons",
                    None,
                    text,
                    REGRESSION,
                    f"new verdict reason ({', '.join(where)}): {text}",
                )
            )
    for masked, (text, where) in ro.items():
        if masked not in rn:
            out.append(
                Change(
                    "reason",
                    pre + "verdict_reasons",
                    text,
                    None,
                    IMPROVEMENT,
                    f"verdict reason gone ({', '.join(where)}): {text}",
                )
            )
    return out


def _scope_flags(node: Any, path: str, out: dict[str, tuple[bool, str]]) -> None:
    """Every ``scope_justified`` under ``node``, by a key path whose list items are named by
    their ``id`` (or ``name``) where they have one."""
    if isinstance(node, Mapping):
        flag = node.get("scope_justified")
        if isinstance(flag, bool):
            out[path] = (flag, str(node.get("scope_reason") or ""))
        for k, v in node.items():
            if isinstance(v, Mapping | list):
                _scope_flags(v, f"{path}.{k}" if path else str(k), out)
    elif isinstance(node, list):
        for i, v in enumerate(node):
            name = v.get("id", v.get("name", i)) if isinstance(v, Mapping) else i
            _scope_flags(v, f"{path}[{name}]", out)


def _scopes(old: Mapping, new: Mapping, pre: str) -> list[Change]:
    """The ``scope`` rule: each check whose ``scope_justified`` changed."""
    so: dict[str, tuple[bool, str]] = {}
    sn: dict[str, tuple[bool, str]] = {}
    _scope_flags(old, "", so)
    _scope_flags(new, "", sn)
    out = []
    for path, (a, _) in so.items():
        if path not in sn or sn[path][0] == a:
            continue
        b, reason = sn[path]
        what = (
            f"{path}: scope no longer justified ({reason or 'no reason given'})"
            if a
            else f"{path}: scope now justified"
        )
        key = f"{pre}{path}.scope_justified"
        out.append(Change("scope", key, a, b, REGRESSION if a else IMPROVEMENT, what))
    return out


def _certificate(old: Mapping, new: Mapping, rtol: float, pre: str = "") -> list[Change]:
    return [
        *_verdicts(old, new, pre),
        *_reasons(old, new, pre),
        *_claims(old, new, pre, rtol),
        *_bounds(old, new, pre, rtol),
        *_soundness(old, new, pre),
        *_constants(old, new, pre, rtol),
        *_assumptions(old, new, pre),
        *_scopes(old, new, pre),
        *_provenance(old, new, pre),
    ]


def _without_timings(node: Any) -> Any:
    """A copy of ``node`` without the keys :func:`is_timing_key` names, at any depth."""
    if isinstance(node, Mapping):
        return {k: _without_timings(v) for k, v in node.items() if not is_timing_key(str(k))}
    if isinstance(node, list):
        return [_without_timings(v) for v in node]
    return node


def _validation(old: Mapping, new: Mapping, rtol: float = DEFAULT_RTOL) -> list[Change]:
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
    for name in [n for n in co if n in cn]:
        ch = _ratio_change(name, co[name], cn[name], rtol)
        if ch is not None:
            out.append(ch)
    return out


def _ratio_change(name: str, a: Mapping, b: Mapping, rtol: float) -> Change | None:
    """``bound / empirical`` of a check that holds in both reports: grown beyond ``rtol`` is a
    regression (a looser certificate, even one that still holds), shrunk an improvement."""
    if a.get("status") != "holds" or b.get("status") != "holds":
        return None
    ra, rb = _num(a.get("ratio")), _num(b.get("ratio"))
    if ra is None or rb is None or not _differ(ra, rb, rtol):
        return None
    return Change(
        "tightness",
        f"checks[{name}].ratio",
        ra,
        rb,
        REGRESSION if rb > ra else IMPROVEMENT,
        f"check {name}: bound / empirical {_fmt(ra)} -> {_fmt(rb)}{_rel(ra, rb)}"
        + (" (looser)" if rb > ra else " (tighter)"),
    )


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
    od, nd = _without_timings(old.data), _without_timings(new.data)
    oc = od["certificate"] if old.kind == "validation" else od
    nc = nd["certificate"] if new.kind == "validation" else nd
    so, sn = _get(oc, "system.name"), _get(nc, "system.name")
    if so != sn:
        notes.append(f"different systems: {so!r} (old) and {sn!r} (new)")
    if old.kind == "validation":
        changes = _validation(od, nd, rtol) + _certificate(oc, nc, rtol, pre="certificate.")
    else:
        changes = _certificate(od, nd, rtol)
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
