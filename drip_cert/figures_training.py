"""The figure ``drip-cert train`` writes beside the policy: training curves and held-out gaps.

Two panels (``training.png``):

* **Losses**: the training-set and held-out losses of each method trained, at the evaluation
  steps of :class:`~drip_cert.learn.tasil.TrainHistory` (log scale); the step whose parameters
  were restored is marked.
* **Held-out gaps**: for each method, the gap ``max_t ||x'_t - x*_t||`` of every held-out
  trajectory (sorted), their mean, and the threshold above which ``train`` fails
  (``--max-heldout-gap``, ``[tasil] max_heldout_gap``, else the size of the expert's
  trajectories): where the run stands against what it must reach.
"""

from __future__ import annotations

import os
from collections.abc import Mapping, Sequence
from pathlib import Path

import numpy as np

__all__ = ["training_figure"]


def training_figure(
    histories: Mapping[str, tuple[Sequence[int], Sequence[float], Sequence[float], int]],
    gaps: Mapping[str, np.ndarray],
    threshold: float,
    path: str | Path,
) -> Path:
    """Write the training figure to ``path`` (png, svg or pdf: by its suffix).

    Parameters
    ----------
    histories
        Per method: ``(steps, train_loss, val_loss, best_step)``.
    gaps
        Per method: the held-out trajectories' gaps ``max_t ||x'_t - x*_t||``.
    threshold
        The held-out mean gap above which training fails.
    path
        Output file, written atomically (a temporary file, then renamed).

    Returns
    -------
    Path
        ``path``.
    """
    # matplotlib: keep off the command line's start-up path (only train needs it)
    import matplotlib  # matplotlib: see above

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt  # matplotlib: see above

    fig, (ax_l, ax_g) = plt.subplots(1, 2, figsize=(12, 4.4))
    for method, (steps, train, val, best) in histories.items():
        (line,) = ax_l.plot(steps, train, label=f"{method}: training loss")
        ax_l.plot(steps, val, "--", color=line.get_color(), label=f"{method}: held-out loss")
        if best in steps:
            i = list(steps).index(best)
            ax_l.plot([best], [val[i]], "o", color=line.get_color())
    ax_l.set_yscale("log")
    ax_l.set_xlabel("optimiser step")
    ax_l.set_title("losses (o: restored parameters)")
    ax_l.legend(fontsize=8)
    for method, g in gaps.items():
        g = np.sort(np.asarray(g, dtype=float))
        if g.size == 0:
            continue
        (line,) = ax_g.plot(np.arange(1, g.size + 1), g, ".", label=f"{method}: per trajectory")
        ax_g.axhline(
            float(np.mean(g)), color=line.get_color(), linestyle=":", label=f"{method}: mean"
        )
    if np.isfinite(threshold):
        ax_g.axhline(threshold, color="#c62828", label="threshold (train fails above it)")
    ax_g.set_yscale("log")
    ax_g.set_xlabel("held-out trajectory (sorted)")
    ax_g.set_ylabel("max_t ||x'_t - x*_t||")
    ax_g.set_title("held-out gaps against the threshold")
    ax_g.legend(fontsize=8)
    fig.tight_layout()
    out = Path(path)
    tmp = out.with_name(f".{out.stem}.partial{out.suffix}")
    try:
        fig.savefig(tmp)
        os.replace(tmp, out)
    finally:
        plt.close(fig)
        tmp.unlink(missing_ok=True)
    return out
