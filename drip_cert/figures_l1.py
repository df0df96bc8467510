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

__all__ = ["l1_front_figure", "l1_terms_figure"]

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

    def points(pts: list[Mapping[str, Any]], fmt: str, **style: Any) -> None:
        """``(T_s, rho)`` of ``pts`` in the format ``fmt`` (nothing when there are none)."""
        if pts:
            ax.plot([x(p) for p in pts], [p["rho"] for p in pts], fmt, **style)

    points(front, "-", color="0.6", lw=1)
    points(
        [p for p in front if not p.get("knife_edge")],
        "o",
        color="tab:blue",
        label="front (verified in Arb)",
    )
    points(
        [p for p in front if p.get("knife_edge")],
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
    return _save(fig, path)


def l1_terms_figure(design: L1Design | Mapping[str, Any], path: str | Path) -> Path:
    """Write rho_L1 term by term to ``path``: stacked bars and rho_L1(T_s) with rho_L1(0).

    Parameters
    ----------
    design
        A report with ``decomposition`` (:func:`~drip_cert.bounds.l1drac.decomposition.decompose`,
        the ``design-l1`` JSON or a certificate's ``l1drac`` part) and ``front``.
    path
        Output file; its suffix picks the format.

    Returns
    -------
    Path
        ``path``. Left: for ``rho_r`` and ``rho_a``, one stacked bar of the shares of
        ``(1 - k) rho^2`` each term of the binding condition takes (docs/math/l1drac.md section
        5.5). Right: the verified front's ``rho_L1(T_s)`` (log-log), the returned design and the
        ``T_s -> 0`` end ``rho_L1(0)`` (dashed). A report without a decomposition gives a figure
        that says so.
    """
    import matplotlib  # matplotlib: keep off the CLI start-up path

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt  # matplotlib: keep off the CLI start-up path

    rep = design.to_dict() if isinstance(design, L1Design) else dict(design)
    dec = rep.get("decomposition")
    fig, (ax, bx) = plt.subplots(1, 2, figsize=(12.0, 5.6))
    if not dec:
        ax.set_title("no decomposition (no feasible design)")
    else:
        cmap = plt.get_cmap("tab20")
        names: list[str] = []
        for i, key in enumerate(("rho_r", "rho_a")):
            left = 0.0
            for term in dec[key]["terms"]:
                if not term["share"] > 0:
                    continue
                if term["name"] not in names:
                    names.append(term["name"])
                j = names.index(term["name"])
                ax.barh(i, term["share"], left=left, color=cmap(j % 20), label=term["name"])
                left += term["share"]
        ax.set_yticks(
            [0, 1], [f"rho_r = {dec['rho_r']['value']:.4g}", f"rho_a = {dec['rho_a']['value']:.4g}"]
        )
        ax.set_xlim(0, 1.0)
        ax.set_xlabel("share of (1 - k) rho^2 (binding condition)")
        ax.set_title(f"rho_L1 term by term at T_s = {dec['Ts']:.3g} s")
        handles, labels = ax.get_legend_handles_labels()
        uniq = dict(zip(labels, handles, strict=True))
        ax.legend(
            uniq.values(),
            uniq.keys(),
            fontsize=6,
            loc="upper center",
            bbox_to_anchor=(0.5, -0.16),
            ncol=2,
        )
    front = [p for p in rep.get("front") or [] if isinstance(p.get("Ts"), float | int)]
    ok = [p for p in front if p["Ts"] >= KNIFE_EDGE_TS_MIN]
    if ok:
        bx.plot(
            [p["Ts"] for p in ok],
            [p["rho"] for p in ok],
            "o-",
            color="tab:blue",
            label="rho_L1(T_s), verified front",
        )
    if dec and dec.get("rho_Ts0") is not None:
        bx.axhline(
            dec["rho_Ts0"],
            color="tab:red",
            ls="--",
            label=f"rho_L1(T_s -> 0) = {dec['rho_Ts0']:.4g}",
        )
    if rep.get("feasible") and rep.get("Ts") and rep.get("rho"):
        bx.plot([rep["Ts"]], [rep["rho"]], "*", color="tab:orange", ms=14, label="returned design")
    bx.set_xscale("log")
    bx.set_yscale("log")
    bx.set_xlabel("sampling period T_s [s]")
    bx.set_ylabel("rho_L1")
    bx.grid(True, which="both", alpha=0.3)
    if bx.get_legend_handles_labels()[0]:
        bx.legend(fontsize=8, loc="upper left")
    return _save(fig, path)


def _save(fig: Any, path: str | Path) -> Path:
    """Lay ``fig`` out, write it to ``path`` (its suffix picks the format) and close it."""
    import matplotlib.pyplot as plt  # matplotlib: keep off the CLI start-up path

    fig.tight_layout()
    out = Path(path)
    fig.savefig(out)
    plt.close(fig)
    return out
