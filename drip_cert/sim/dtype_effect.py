"""The measured effect of the float32 paths (the policy alone, or end to end) on a run's gaps.

:func:`dtype_effect` simulates the first paths of a run twice, as asked (the learned policy in
float32, :mod:`drip_cert.sim.precision`, or everything in float32, ``SimConfig.dtype``) and all in
float64; :func:`policy_dtype_effect` is its policy-only case. The engine's noise and initial states
depend only on the seed and a path's global index, so both runs see the same paths and the
differences are the float32 rounding alone. The result, a :class:`DtypeEffect`, is reported next to
a float32 run (``drip-cert validate --dtype float32`` or ``--policy-dtype float32``) so that a user
can decide whether the speed is worth it; the certificate itself is always float64.
"""

from __future__ import annotations

import dataclasses
import math
from collections.abc import Callable
from dataclasses import dataclass

import numpy as np

from drip_cert.errors import SpecError
from drip_cert.sim.engine import simulate

__all__ = ["EFFECT_PATHS", "DtypeEffect", "GapShift", "dtype_effect", "policy_dtype_effect"]

EFFECT_PATHS = 1000
"""Default number of paths (the first ones of the run) on which the float32 effect is measured:
enough for a CI half-width of a few percent of the mean gap, at about 2 x 1000 paths of cost."""


@dataclass(frozen=True)
class GapShift:
    """How far one gap's statistics move when the policy runs in float32 (same paths).

    Attributes
    ----------
    name
        The gap (``"policy"``, ``"total_l1"``, ...).
    max_abs_mean
        ``max_t |mean32(t) - mean64(t)|`` of the gap ``E||a_t - b_t||``.
    max_mean_64, max_mean_32
        ``max_t`` of the mean gap (the number checked against the certificate) in each dtype.
    ci_half_width
        Half-width of the float64 run's confidence interval of ``max_mean``: the Monte-Carlo
        error the float32 shift is to be compared with.
    max_abs_path_max
        ``max |sup_t r32 - sup_t r64|`` over the paths (the per-path worst gaps); ``inf`` when
        the two runs froze different paths for divergence.
    """

    name: str
    max_abs_mean: float
    max_mean_64: float
    max_mean_32: float
    ci_half_width: float
    max_abs_path_max: float

    @property
    def relative_to_ci(self) -> float:
        """``|max_mean_32 - max_mean_64| / ci_half_width`` (NaN without an interval)."""
        d = abs(self.max_mean_32 - self.max_mean_64)
        w = self.ci_half_width
        return d / w if (math.isfinite(w) and w > 0) else math.nan

    def to_dict(self) -> dict:
        """JSON-ready: the fields and ``relative_to_ci``."""
        return {**dataclasses.asdict(self), "relative_to_ci": _finite(self.relative_to_ci)}


@dataclass(frozen=True)
class DtypeEffect:
    """The float32 policy's effect on a run's gap statistics, measured on its first paths.

    Attributes
    ----------
    n_paths
        Paths simulated in both dtypes (the first ``n_paths`` of the run: same initial states,
        same noise).
    gaps
        :class:`GapShift` per gap.
    max_abs_state
        Largest ``|x32 - x64|`` over the kept sample trajectories (all scenarios, times,
        components).
    """

    n_paths: int
    gaps: tuple[GapShift, ...]
    max_abs_state: float
    end_to_end: bool = False
    """``True``: the whole simulation in float32 (``SimConfig.dtype``); ``False``: the policy."""

    @property
    def max_abs_gap_mean(self) -> float:
        """Largest ``max_abs_mean`` over the gaps."""
        return max((g.max_abs_mean for g in self.gaps), default=0.0)

    @property
    def max_relative_to_ci(self) -> float:
        """Largest :attr:`GapShift.relative_to_ci` over the gaps (NaN when none has an
        interval)."""
        vals = [g.relative_to_ci for g in self.gaps if math.isfinite(g.relative_to_ci)]
        return max(vals) if vals else math.nan

    def note(self) -> str:
        """One sentence for a report: what moved and by how much, against the MC error."""
        rel = self.max_relative_to_ci
        worst = max(self.gaps, key=lambda g: g.max_abs_mean, default=None)
        where = f" ({worst.name})" if worst is not None else ""
        what = (
            "simulated in float32 end to end (state, noise, vector fields, policy and L1-DRAC; "
            "statistics in float64)"
            if self.end_to_end
            else "policy evaluated in float32 (state, noise and L1-DRAC in float64)"
        )
        return (
            f"{what}: on the first "
            f"{self.n_paths} paths, simulated again in float64, the mean gaps moved by at most "
            f"{self.max_abs_gap_mean:.3g}{where}, {rel:.3g} times the Monte-Carlo CI half-width "
            f"of the checked maximum, and the sample trajectories by at most "
            f"{self.max_abs_state:.3g}; the certificate is computed in float64 regardless"
        )

    def to_dict(self) -> dict:
        """JSON-ready dictionary."""
        return {
            "n_paths": self.n_paths,
            "float32": "end_to_end" if self.end_to_end else "policy",
            "max_abs_gap_mean": self.max_abs_gap_mean,
            "max_relative_to_ci": _finite(self.max_relative_to_ci),
            "max_abs_state": self.max_abs_state,
            "gaps": [g.to_dict() for g in self.gaps],
            "note": self.note(),
        }


def _finite(v: float) -> float | None:
    return v if math.isfinite(v) else None


def policy_dtype_effect(
    model,
    config,
    x0_sampler: Callable,
    x0_bar_sampler: Callable | None = None,
    *,
    n_paths: int = EFFECT_PATHS,
    backend=None,
) -> DtypeEffect:
    """:func:`dtype_effect` of the policy alone in float32 (``config.policy_dtype`` and
    ``config.dtype`` are ignored)."""
    cfg = dataclasses.replace(config, policy_dtype="float32", dtype="float64")
    return dtype_effect(model, cfg, x0_sampler, x0_bar_sampler, n_paths=n_paths, backend=backend)


def dtype_effect(
    model,
    config,
    x0_sampler: Callable,
    x0_bar_sampler: Callable | None = None,
    *,
    n_paths: int = EFFECT_PATHS,
    backend=None,
) -> DtypeEffect:
    """Simulate the first ``n_paths`` paths of ``config`` as it is and all in float64.

    The engine's noise and initial states depend only on the seed and a path's global index, so
    both runs see the same paths: the differences are the float32 rounding alone (of the policy
    with ``config.policy_dtype="float32"``, of everything with ``config.dtype="float32"``, whose
    normals are the float32 roundings of the same Brownian increments).

    Parameters
    ----------
    model, config, x0_sampler, x0_bar_sampler
        As for :func:`~drip_cert.sim.engine.simulate`; ``config`` must ask for float32.
    n_paths
        Paths compared (at most ``config.n_paths``).
    backend
        :class:`~drip_cert.sim.backend.Backend` of both runs (default local).

    Returns
    -------
    DtypeEffect
    """
    if isinstance(n_paths, bool) or int(n_paths) < 1:
        raise SpecError(f"n_paths must be >= 1, got {n_paths!r}", field="n_paths")
    if config.dtype == "float64" and config.policy_dtype == "float64":
        raise SpecError(
            "the config asks for no float32 arithmetic: set dtype or policy_dtype to 'float32'",
            field="SimConfig.dtype",
        )
    k = min(int(n_paths), config.n_paths)
    base = dataclasses.replace(
        config,
        n_paths=k,
        chunk_size=min(config.chunk_size, k),
        n_sample_paths=min(max(config.n_sample_paths, 8), k),
        w2_times=(),
    )
    r64, r32 = (
        simulate(model, c, x0_sampler, x0_bar_sampler, progress=False, backend=backend)
        for c in (dataclasses.replace(base, policy_dtype="float64", dtype="float64"), base)
    )
    shifts = []
    for g64, g32 in zip(r64.gaps, r32.gaps):
        same = g32.path_max.shape == g64.path_max.shape  # differs only if divergence differs
        shifts.append(
            GapShift(
                name=g64.name,
                max_abs_mean=float(np.nanmax(np.abs(g32.mean - g64.mean))),
                max_mean_64=float(g64.max_mean),
                max_mean_32=float(g32.max_mean),
                ci_half_width=float(0.5 * (g64.max_ci_high - g64.max_ci_low)),
                max_abs_path_max=(
                    float(np.max(np.abs(g32.path_max - g64.path_max), initial=0.0))
                    if same
                    else math.inf
                ),
            )
        )
    return DtypeEffect(
        n_paths=k,
        gaps=tuple(shifts),
        max_abs_state=float(np.nanmax(np.abs(r32.sample_paths - r64.sample_paths))),
        end_to_end=config.dtype != "float64",
    )
