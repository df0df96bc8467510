"""Progress of long computations on stderr: one line per stage with the time the previous took.

Used by ``certify`` (constants, contraction, invariant sets, TaSIL, L1-DRAC design) and the
pipeline; silent unless enabled (the command line enables it unless ``--json`` or ``--quiet``).
Progress *bars* (tqdm, redrawn in place) are shown only when stderr is a terminal
(:func:`bars_enabled`): in a log file or a CI job they would be thousands of lines.
"""

from __future__ import annotations

import sys
import time
from typing import TextIO

__all__ = ["Stages", "bars_enabled"]


def bars_enabled(progress: bool, stream: TextIO | None = None) -> bool:
    """Whether to draw a progress bar: ``progress`` asked for and ``stream`` (default stderr) is
    a terminal. Stage lines (:class:`Stages`) need only ``progress``: one line each, fine in logs.
    """
    if not progress:
        return False
    out = stream if stream is not None else sys.stderr
    try:
        return bool(out.isatty())
    except (AttributeError, ValueError):  # a closed or a file-like stream without isatty
        return False


class Stages:
    """Announce stages of a job: ``stage("what")`` prints ``[job 1.2 s] what`` to ``stream``.

    The time shown is the time since the job started, so a slow stage shows as a jump between
    two lines; :meth:`done` prints the total.
    """

    def __init__(self, job: str, *, enabled: bool, stream: TextIO | None = None) -> None:
        self.job = job
        self.enabled = enabled
        self.stream = stream
        self.t0 = time.perf_counter()

    def __call__(self, what: str) -> None:
        if self.enabled:
            out = self.stream if self.stream is not None else sys.stderr
            elapsed = time.perf_counter() - self.t0
            print(f"[{self.job} {elapsed:7.1f} s] {what}", file=out, flush=True)

    def done(self) -> None:
        self("done")
