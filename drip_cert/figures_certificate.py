"""A certificate drawn where people look: assumption margins, and the sets the proofs use, in x.

``drip-cert certify SPEC --figure PATH`` writes one figure of two panels from the certificate's
JSON (:meth:`~drip_cert.bounds.certificate.Certificate.to_dict`):

* **Margins.** Each assumption check as a bar of its relative margin
  ``margin / (|lhs| + |rhs|)`` (signed: right of zero holds, left fails; a check with no finite
  margin, such as a design found or a bound compared with infinity, is a marker on the axis);
  the colour is the status, a hatched bar rests on estimates.
* **Sets, in the user's coordinates x** (for ``n >= 2``; the projection onto the first two
  states): the support of the initial law ``D``, the box where the expert's rate is proved, the
  box where the learned loop's rate is proved (absent when proved for all x), and the proved
  forward-invariant ball. A certificate computed in ``z = Theta x`` (docs/math/contraction.md
  section 5) has its boxes and ball in ``z``; they are drawn as their exact images
  ``x = Theta^{-1} z`` (parallelograms, ellipses): where the proof holds in ``x``, not a box
  around it.
"""

from __future__ import annotations

import itertools
import math
import os
from collections.abc import Mapping, Sequence
from pathlib import Path
from typing import Any

import numpy as np

__all__ = ["certificate_figure", "relative_margin"]

#: colours of a check's status (holds, fails, not evaluated)
_COLOURS = {"holds": "#2e7d32", "fails": "#c62828"}
_OTHER = "#9e9e9e"


def relative_margin(check: Mapping[str, Any]) -> float | None:
    """``margin / (|lhs| + |rhs|)`` of a check's JSON, or ``None`` when any is not finite."""
    vals = [check.get(k) for k in ("margin", "lhs", "rhs")]
    if any(not isinstance(v, int | float) or not math.isfinite(v) for v in vals):
        return None
    margin, lhs, rhs = (float(v) for v in vals)  # type: ignore[arg-type]
    scale = abs(lhs) + abs(rhs)
    return margin / scale if scale > 0 else None


def _to_x(cert: Mapping[str, Any]) -> np.ndarray | None:
    """``Theta^{-1}`` of a z-certificate (its boxes are in z), else ``None``."""
    coords = cert.get("coordinates") or {}
    theta = coords.get("theta") if coords.get("system") == "z = Theta x" else None
    return None if theta is None else np.linalg.inv(np.array(theta, dtype=float))


def _box_outline(box: Sequence[Sequence[float]], M: np.ndarray | None) -> np.ndarray:
    """The outline of ``M box`` projected onto the first two coordinates (the convex hull of its
    corners' images, in order), or the box's own rectangle when ``M`` is ``None``."""
    corners = np.array(list(itertools.product(*box)), dtype=float)
    pts = corners if M is None else corners @ M.T
    pts = pts[:, :2]
    centre = pts.mean(axis=0)
    ang = np.arctan2(pts[:, 1] - centre[1], pts[:, 0] - centre[0])
    hull = _convex_hull(pts[np.argsort(ang)])
    return np.vstack([hull, hull[:1]])


def _convex_hull(pts: np.ndarray) -> np.ndarray:
    """Monotone-chain convex hull of 2-D points (counter-clockwise)."""
    P = sorted({(float(a), float(b)) for a, b in pts})
    if len(P) <= 2:
        return np.array(P)

    def cross(o: tuple[float, float], a: tuple[float, float], b: tuple[float, float]) -> float:
        return (a[0] - o[0]) * (b[1] - o[1]) - (a[1] - o[1]) * (b[0] - o[0])

    lower: list[tuple[float, float]] = []
    for p in P:
        while len(lower) >= 2 and cross(lower[-2], lower[-1], p) <= 0:
            lower.pop()
        lower.append(p)
    upper: list[tuple[float, float]] = []
    for p in reversed(P):
        while len(upper) >= 2 and cross(upper[-2], upper[-1], p) <= 0:
            upper.pop()
        upper.append(p)
    return np.array(lower[:-1] + upper[:-1])


def _ball_outline(centre: Sequence[float], radius: float, M: np.ndarray | None) -> np.ndarray:
    """The boundary of the ball's image, sliced through its centre in the first two coordinates
    (the ball is Euclidean in the certificate's coordinates)."""
    c = np.array(centre, dtype=float)
    th = np.linspace(0.0, 2.0 * math.pi, 181)
    pts = np.tile(c, (th.size, 1))
    pts[:, 0] += radius * np.cos(th)
    pts[:, 1] += radius * np.sin(th)
    if M is not None:
        pts = pts @ M.T
    return pts[:, :2]


def certificate_figure(
    cert: Mapping[str, Any],
    path: str | Path,
    *,
    support_x: Sequence[Sequence[float]] | None = None,
    states_x: Sequence[str] | None = None,
) -> Path:
    """Write the margins and the sets of a certificate (its ``to_dict()``) to ``path``.

    Parameters
    ----------
    cert
        The certificate's JSON dictionary.
    path
        Output file (png, svg, pdf: by its suffix).
    support_x, states_x
        The support of ``D`` and the state names in the user's coordinates ``x`` (the spec's);
        default: the certificate's own (in ``z`` for a z-certificate).

    Returns
    -------
    Path
        ``path``.
    """
    # matplotlib: keep off the command line's start-up path (only --figure needs it)
    import matplotlib  # matplotlib: see above

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt  # matplotlib: see above

    system = cert.get("system") or {}
    n = int(system.get("n", 0))
    M = _to_x(cert)
    support = support_x if support_x is not None else system.get("support")
    names = list(states_x if states_x is not None else system.get("states", []))
    draw_sets = n >= 2 and support is not None
    fig, axes = plt.subplots(1, 2 if draw_sets else 1, figsize=(12 if draw_sets else 6.5, 4.6))
    ax_m = axes[0] if draw_sets else axes

    checks = list(cert.get("assumptions") or [])
    ys = np.arange(len(checks))[::-1]
    for y, c in zip(ys, checks, strict=True):
        status = c.get("status", "holds" if c.get("holds") else "fails")
        colour = _COLOURS.get(status, _OTHER)
        r = relative_margin(c)
        hatch = "//" if c.get("how") == "estimate" else None
        if r is None:
            ax_m.plot([0.0], [y], marker="D", color=colour)
            ax_m.annotate("no finite margin", (0.0, y), xytext=(6, -3), textcoords="offset points")
        else:
            ax_m.barh(y, r, color=colour, hatch=hatch, edgecolor="black", linewidth=0.4)
    ax_m.set_yticks(ys, [f"{c.get('id')} ({c.get('how')})" for c in checks])
    ax_m.axvline(0.0, color="black", linewidth=0.8)
    ax_m.set_xlabel("relative margin  margin / (|lhs| + |rhs|)   (> 0 holds)")
    ax_m.set_title(f"{system.get('name', '')}: {cert.get('verdict', '')}")

    if draw_sets:
        ax = axes[1]
        contraction = cert.get("contraction") or {}
        sup = np.array(support, dtype=float)
        ax.plot(*_box_outline(sup.tolist(), None).T, color="black", label="support of D")
        for key, style, label in (
            ("expert", "-", "expert's rate proved"),
            ("learned", "--", "learned loop's rate proved"),
        ):
            box = ((contraction.get(key) or {}).get("scope") or {}).get("box")
            if box is not None:
                ax.plot(*_box_outline(box, M).T, style, color="#1565c0", label=label)
        inv = contraction.get("invariant_set") or {}
        if inv.get("proved") and inv.get("radius") and inv.get("centre"):
            ball = _ball_outline(inv["centre"], float(inv["radius"]), M)
            ax.plot(*ball.T, color="#6a1b9a", label="forward-invariant ball")
        x_names = names if support_x is not None else [f"x{i + 1}" for i in range(n)]
        ax.set_xlabel(x_names[0] if x_names else "x1")
        ax.set_ylabel(x_names[1] if len(x_names) > 1 else "x2")
        where = "z-certificate drawn in x" if M is not None else "in x"
        ax.set_title(f"proved sets ({where}; first two states)")
        ax.legend(loc="best", fontsize=8)
        ax.set_aspect("equal", adjustable="datalim")
    fig.tight_layout()
    out = Path(path)
    tmp = out.with_name(f".{out.stem}.partial{out.suffix}")  # the suffix picks the format
    try:
        fig.savefig(tmp)
        os.replace(tmp, out)  # never a half-written figure under the user's name
    finally:
        plt.close(fig)
        tmp.unlink(missing_ok=True)
    return out
