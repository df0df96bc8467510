"""The binding condition of each part of a certificate: the one condition, with its numbers, that
keeps the part from ``certified`` (assembly and text only; no verdict is decided here).

For most parts it is the first failing check, else the first reason of a ``conditional`` verdict.
The L1-DRAC part of a learned loop whose rate is not proved for all ``x`` gets the chain that a
user must break, each link with its number:

1. all x: why no global route proves the rate; when the trace condition rules out every
   slope-restricted LMI, ``tr J(s)/n > 0`` at a slope vertex (docs/math/contraction.md section
   11: ``mu_P(J) >= tr J / n`` for every metric ``P``);
2. the box: the bound the box search proved (``max mu_2 <= ...``) against the sampled value, or the
   rate proved there (which L1-DRAC cannot use as it stands);
3. the exit probability of docs/math/l1drac.md section 11: the floor of (11.4) from the radius
   ``rho_L1`` and an upper bound of the room
   (:func:`~drip_cert.bounds.l1drac.exit.exit_floor`), displayed, never used in a verdict
   (section 11.7: the learned loop's invariant set and the extension's second design are not
   computed, so ``delta_exit`` itself is not).

Public surface
--------------
* :func:`part_bindings` -- ``{part: {"text": ..., numbers...}}`` for the parts not certified.
"""

from __future__ import annotations

import math
from collections.abc import Mapping, Sequence
from typing import Any

from drip_cert.bounds.l1drac.exit import ExitFloor, exit_floor, exit_room
from drip_cert.provenance import Check, json_float, verdict_of

__all__ = ["l1drac_learned_binding", "part_bindings"]


#: the L1-DRAC checks that rest on the learned loop's rate (explained by the chain)
_RATE_CHECKS = ("L1DRAC-A2", "L1DRAC-A7")


def _first_reason(checks: Sequence[Check]) -> str | None:
    """The first failing check's detail, else the first reason of the verdict (None: certified)."""
    if not checks:
        return None
    _, reasons = verdict_of(checks)
    return reasons[0] if reasons else None


def l1drac_learned_binding(
    learned: Any,
    support: Sequence[Sequence[float]],
    rho: float | None,
    p: int,
    in_z: bool = False,
) -> dict[str, Any] | None:
    """The chain of the L1-DRAC part when the learned loop's rate is not proved for all x.

    Parameters
    ----------
    learned
        The learned loop's :class:`~drip_cert.bounds.certificate.ContractionAnalysis`.
    support
        The support of the initial law (where the learned nominal trajectories start).
    rho, p
        ``rho_L1`` of the design (``None``: no feasible design) and its moment order ``p``
        (``q = 2p`` in (11.4)).
    in_z
        Whether the numbers are in metric coordinates ``z`` (said in the text).

    Returns
    -------
    dict or None
        ``None`` when the rate is proved for all x; else ``text`` and the numbers of each link
        (``global``, ``box``, ``exit``).
    """
    r = learned.euclidean
    if r.scope.all_x and r.holds and r.how.proved:
        return None
    pieces: list[str] = []
    out: dict[str, Any] = {}
    obs = getattr(learned, "obstruction", None)
    if obs is not None:
        pieces.append(
            "no slope-restricted LMI (any constant metric) proves contraction for all x: "
            + obs.short()
        )
        out["global"] = {"route": "slope-lmi", **obs.to_dict()}
    elif not r.scope.all_x:
        pieces.append("no global route proves contraction for all x")
        out["global"] = {"route": None}
    if not r.scope.all_x:
        box = [list(row) for row in r.scope.box] if r.scope.box is not None else None
        if r.holds and r.how.proved:
            pieces.append(
                f"on the {r.region} the rate {r.rate:.4g} is proved ({r.method}), but L1-DRAC "
                "needs it for all x"
            )
        else:
            pieces.append(
                f"on the {r.region} the proved bound is max mu_2 <= {r.max_mu_upper:.4g} > 0 "
                f"(sampled {r.max_mu_sampled:.4g}; {r.method}, {r.n_boxes} boxes, stop: {r.stop})"
            )
        out["box"] = {
            "region": box,
            "max_mu_upper": json_float(r.max_mu_upper),
            "max_mu_sampled": json_float(r.max_mu_sampled),
            "proved": bool(r.holds and r.how.proved),
            "method": r.method,
            "n_boxes": int(r.n_boxes),
        }
        if box is not None:
            fl = exit_floor(
                rho=math.inf if rho is None else float(rho),
                room=exit_room(support, box),
                q=2 * max(int(p), 1),
            )
            pieces.append(_exit_text(fl, rho, bool(r.holds and r.how.proved)))
            out["exit"] = {
                **fl.to_dict(),
                "used_in_verdict": False,
                "source": "docs/math/l1drac.md section 11 (11.4), Lemma 11.3",
            }
    out["text"] = "learned loop: " + "; ".join(pieces) + (" (in z coordinates)" if in_z else "")
    return out


def _exit_text(fl: ExitFloor, rho: float | None, box_proved: bool) -> str:
    """The exit-probability link as text: what (11.4) needs and the floor it cannot go below."""
    if rho is None:
        head = "the exit probability needs rho_L1 < room: no feasible L1-DRAC design (rho_L1 = inf)"
    else:
        head = (
            f"the exit probability needs rho_L1 < room: {rho:.4g} "
            + (">=" if fl.useless else "<")
            + f" {fl.room:.4g}"
        )
    if fl.room == 0.0:
        head += " (the box does not extend beyond the support: the learned trajectories start on "
        head += "its boundary, no room)"
    floor = "inf" if math.isinf(fl.floor) else f"{fl.floor:.4g}"
    if fl.room == 0.0:
        tail = ", so (11.4) gives no bound: delta_exit = 1, no probability statement"
    elif fl.useless:
        tail = (
            f", so (11.4) at this rho_L1 is >= (rho_L1/room)^{fl.q} = {floor} >= 1 (the "
            "extension's rho~ uses a smaller rate, l1drac.md 11.7): no probability statement"
        )
    else:
        tail = (
            f"; (rho_L1/room)^{fl.q} = {floor} < 1 is only a floor of (11.4) at this rho_L1: "
            "delta_exit needs the learned loop's invariant set and the extension's design "
            "(docs/math/l1drac.md 11.6, steps 1 and 3), not computed"
        )
    if not box_proved:
        tail += " (and (11.1) needs a rate proved on the box)"
    return head + tail


def part_bindings(
    parts: Mapping[str, Mapping[str, Any]],
    checks: Mapping[str, Sequence[Check]],
    l1_learned: Mapping[str, Any] | None,
) -> dict[str, dict[str, Any]]:
    """``{part: binding}`` for every computed part that is not ``certified``.

    ``parts`` is :meth:`~drip_cert.bounds.certificate.Certificate.part_verdicts` without the
    bindings, ``checks`` the checks of each part, ``l1_learned`` the chain of
    :func:`l1drac_learned_binding` (``None`` when it does not apply). A binding is ``{"text":
    ...}`` plus the chain's numbers for the L1-DRAC part.
    """
    out: dict[str, dict[str, Any]] = {}
    for part, v in parts.items():
        if v["verdict"] in ("certified", "not_requested", "not_applicable"):
            continue
        if part == "l1drac" and l1_learned is not None:
            # the chain explains L1-DRAC Assumptions 2 and 7 (both on the learned rate) and the
            # design's resting on that rate; another failing check of the part is named after it
            failing = [c for c in checks.get(part, ()) if c.id not in _RATE_CHECKS and not c.holds]
            other = _first_reason(failing) if failing else None
            b = dict(l1_learned)
            if other is not None:
                b["text"] = f"{b['text']}; also {other}"
            out[part] = b
            continue
        text = _first_reason(checks.get(part, ()))
        if text is not None:
            out[part] = {"text": text}
    return out
