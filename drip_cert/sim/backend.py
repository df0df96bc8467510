"""Where the chunks of a Monte-Carlo run are computed: this process, worker processes, or Dask.

A :class:`Backend` is an execution choice, not a setting of the run: it never changes a number
(the noise of a path is a function of the seed and its global index, and the chunks are absorbed
in order on the caller's side, whatever computed them), so it is not part of
:class:`~drip_cert.sim.config.SimConfig` nor of the resume hash. A run started on one backend can
be resumed on another.
"""

from __future__ import annotations

import os
from dataclasses import dataclass

from drip_cert.errors import SpecError

__all__ = ["BACKENDS", "SCHEDULER_ENV", "Backend"]

BACKENDS = ("local", "processes", "dask")
"""``local``: compiled chunk calls from a thread pool in this process; ``processes``: one worker
process per core, each pinned to its core before it imports jax
(:mod:`drip_cert.sim.process_backend`); ``dask``: one task per chunk on a ``dask.distributed``
cluster (:mod:`drip_cert.sim.dask_backend`)."""

SCHEDULER_ENV = "DASK_SCHEDULER_ADDRESS"
"""Environment variable read for the scheduler address when none is given (Dask's own name)."""


@dataclass(frozen=True)
class Backend:
    """The executor of :func:`~drip_cert.sim.engine.simulate`.

    Parameters
    ----------
    kind
        ``"local"`` (default), ``"processes"`` or ``"dask"``.
    scheduler
        ``dask`` only: address of a running scheduler (``tcp://host:8786``). ``None``: the
        environment variable ``DASK_SCHEDULER_ADDRESS``, else a ``LocalCluster`` started for the
        run (and closed after it).
    n_workers
        ``processes``: worker processes (``None``: the usable CPU cores; more than those are
        pinned round robin). ``dask`` without a scheduler: worker processes of the
        ``LocalCluster`` (``None``: the usable CPU cores). Each worker runs one chunk at a time.
        ``local`` ignores it (``simulate(workers=...)`` sets its threads).
    connect_timeout
        Seconds to wait for the scheduler before giving up with an error.
    """

    kind: str = "local"
    scheduler: str | None = None
    n_workers: int | None = None
    connect_timeout: float = 30.0

    def __post_init__(self) -> None:
        if self.kind not in BACKENDS:
            raise SpecError(
                f"backend must be one of {BACKENDS}, got {self.kind!r}", field="backend"
            )
        if self.scheduler is not None:
            if self.kind != "dask":
                raise SpecError(
                    f"a scheduler address ({self.scheduler!r}) needs backend 'dask'; "
                    "pass --backend dask or drop --scheduler",
                    field="scheduler",
                )
            if not isinstance(self.scheduler, str) or not self.scheduler.strip():
                raise SpecError(
                    f"scheduler must be an address like 'tcp://host:8786', got {self.scheduler!r}",
                    field="scheduler",
                )
        if self.n_workers is not None and (
            isinstance(self.n_workers, bool) or int(self.n_workers) < 1
        ):
            raise SpecError(
                f"n_workers must be an integer >= 1, got {self.n_workers!r}", field="n_workers"
            )

    @property
    def address(self) -> str | None:
        """The scheduler to connect to: ``scheduler``, else ``$DASK_SCHEDULER_ADDRESS``, else
        ``None`` (start a ``LocalCluster``)."""
        if self.kind != "dask":
            return None
        return self.scheduler or os.environ.get(SCHEDULER_ENV) or None

    def describe(self) -> str:
        """One line for reports: ``local``, ``processes`` or ``dask (scheduler ...)``/``dask
        (LocalCluster)``."""
        if self.kind in ("local", "processes"):
            return self.kind
        addr = self.address
        return f"dask (scheduler {addr})" if addr else "dask (LocalCluster)"
