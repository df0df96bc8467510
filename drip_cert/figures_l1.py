"""Figure of the L1-DRAC (T_s, rho) Pareto front (``drip-cert design-l1 --figure``, ``reproduce``).

Source: A. Gahlawat, S. H. Karumanchi, N. Hovakimyan, "L1-DRAC: Distributionally Robust Adaptive
Control -- Global Results", arXiv:2509.04619 (2025-09-04), Sec. 3.2 (the parameters omega, T_s,
lambda_s and the radius rho = rho_r + rho_a of (17) they buy). The front is
:func:`~drip_cert.bounds.l1drac.designer.pareto_front`; docs/math/l1drac.md section 5.4.
"""

from __future__ import annotations

from collections.abc import Mapping
from pathlib import Path
from typing import Any

from drip_cert.bounds.l1drac.result import KNIFE_EDGE_TS_MIN, L1Design

__all__ = ["l1_front_figure"]

#: The x axis starts this factor below KNIFE_EDGE_TS_MIN; designs with a smaller T_s are drawn at
#: its left edge with their T_s written beside them (else one knife edge at 1e-56 s squeezes
#: every practical point into the right tenth of the figure).
X_MIN_FACTOR = 100.0


def l1_front_figure(design: L1Design | Mapping[str, Any], path: str | Path) -> Path:
    """Write the (T_s, rho) Pareto front of an L1-DRAC design to ``path`` (png, svg, pdf).

    Parameters
    ----------
    design
        An :class:`~drip_cert.bounds.l1drac.result.L1Design` or its ``to_dict()`` (the
        ``l1drac`` part of a certificate's JSON, or the ``design-l1`` JSON).
    path
        Output file; its suffix picks the format.

    Returns
    -------
    Path
        ``path``. Log-log axes: every verified front point (crosses: knife edges,
        :func:`~drip_cert.bounds.l1drac.result.knife_edge`), the returned design (a star), the
        practical T_s (dotted) and the knife-edge region T_s < 1 ns (shaded). An empty front
        gives a figure that says so.
    """
    import matplotlib  # matplotlib: keep off the CLI start-up path

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt  # matplotlib: keep off the CLI start-up path

    rep = design.to_dict() if isinstance(design, L1Design) else dict(design)
    front = [p for p in rep.get("front") or [] if isinstance(p.get("Ts"), float | int)]
    fig, ax = plt.subplots(figsize=(6.4, 4.4))
    # designs below X_MIN (a knife edge's T_s can be 1e-56 s) are drawn at the left edge
    x_min = KNIFE_EDGE_TS_MIN / X_MIN_FACTOR

    def x(p: Mapping[str, Any]) -> float:
        return max(float(p["Ts"]), x_min)

    ok = [p for p in front if not p.get("knife_edge")]
    edge = [p for p in front if p.get("knife_edge")]
    if front:
        ax.plot([x(p) for p in front], [p["rho"] for p in front], "-", color="0.6", lw=1)
    if ok:
        ax.plot(
            [x(p) for p in ok],
            [p["rho"] for p in ok],
            "o",
            color="tab:blue",
            label="front (verified in Arb)",
        )
    if edge:
        ax.plot(
            [x(p) for p in edge],
            [p["rho"] for p in edge],
            "x",
            color="tab:red",
            ms=8,
            label="knife edge (verified, never the default)",
        )
    for p in front:
        if p["Ts"] < x_min:
            ax.annotate(
                f"<- T_s = {p['Ts']:.1e} s",
                (x_min, p["rho"]),
                textcoords="offset points",
                xytext=(6, -12),
                fontsize=7,
                color="tab:red",
            )
    if rep.get("feasible") and rep.get("Ts") and rep.get("rho"):
        ax.plot(
            [max(float(rep["Ts"]), x_min)],
            [rep["rho"]],
            "*",
            color="tab:orange",
            ms=16,
            zorder=3,
            label=f"returned design ({rep.get('objective') or 'design'})",
        )
    pts = rep.get("practical_Ts")
    if isinstance(pts, float | int):
        ax.axvline(pts, color="tab:green", ls=":", label=f"practical T_s = {pts:g} s")
    ax.axvspan(
        x_min,
        KNIFE_EDGE_TS_MIN,
        color="tab:red",
        alpha=0.08,
        label=f"T_s < {KNIFE_EDGE_TS_MIN:g} s",
    )
    ax.set_xscale("log")
    ax.set_xlim(left=x_min / 2)
    ax.set_yscale("log")
    ax.set_xlabel("sampling period T_s [s]")
    ax.set_ylabel("rho_L1 = rho_r + rho_a  (L1-DRAC (17))")
    title = "L1-DRAC (T_s, rho) Pareto front"
    if not front:
        title += ": empty (no verified design)"
    ax.set_title(title)
    ax.grid(True, which="both", alpha=0.3)
    ax.legend(fontsize=8, loc="upper left")
    fig.tight_layout()
    out = Path(path)
    fig.savefig(out)
    plt.close(fig)
    return out
