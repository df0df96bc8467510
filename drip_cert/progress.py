"""Progress of long computations on stderr: one line per stage with the time the previous took.

Used by ``certify`` (constants, contraction, invariant sets, TaSIL, L1-DRAC design) and the
pipeline; silent unless enabled (the command line enables it unless ``--json`` or ``--quiet``).
"""

from __future__ import annotations

import sys
import time
from typing import TextIO

__all__ = ["Stages"]


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
