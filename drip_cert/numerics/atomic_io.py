"""Atomic file writes: a temporary file in the target directory, flushed, synced, then renamed.

A reader sees either the old file or the whole new one, never a half-written file, also when the
process is interrupted (the temporary file is removed on any exception). JSON goes through
:func:`jsonable`: numpy values become Python values, NaN becomes ``null`` and +-inf the strings
``"inf"``/``"-inf"``, so the output is strict JSON.
"""

from __future__ import annotations

import json
import os
import tempfile
from collections.abc import Callable
from pathlib import Path
from typing import IO, Any

import numpy as np

from drip_cert.provenance import json_float

__all__ = ["atomic_savez", "atomic_write_json", "atomic_write_text", "jsonable"]


def jsonable(obj: Any) -> Any:
    """Recursively convert to JSON-ready values: numpy scalars/arrays to Python, ``inf`` to the
    strings ``"inf"``/``"-inf"``, NaN to ``None``."""
    if isinstance(obj, dict):
        return {str(k): jsonable(v) for k, v in obj.items()}
    if isinstance(obj, list | tuple):
        return [jsonable(v) for v in obj]
    if isinstance(obj, np.ndarray):
        return jsonable(obj.tolist())
    if isinstance(obj, bool | np.bool_):
        return bool(obj)
    if isinstance(obj, int | np.integer):
        return int(obj)
    if isinstance(obj, float | np.floating):
        return json_float(float(obj))
    return obj


def _atomic(path: str | Path, mode: str, write: Callable[[IO[Any]], object]) -> None:
    path = Path(path)
    path.parent.mkdir(parents=True, exist_ok=True)
    fd, tmp = tempfile.mkstemp(dir=path.parent, prefix=path.name + ".", suffix=".tmp")
    try:
        with os.fdopen(fd, mode) as fh:
            write(fh)
            fh.flush()
            os.fsync(fh.fileno())
        umask = os.umask(0)
        os.umask(umask)
        os.chmod(tmp, 0o666 & ~umask)  # mkstemp creates 0600; give the usual file mode
        os.replace(tmp, path)
    except BaseException:
        if os.path.exists(tmp):
            os.unlink(tmp)
        raise


def atomic_write_text(path: str | Path, text: str) -> None:
    """Write ``text`` to ``path`` atomically (parent directories are created)."""
    _atomic(path, "w", lambda fh: fh.write(text))


def atomic_write_json(path: str | Path, obj: Any) -> None:
    """Write ``obj`` as strict JSON (via :func:`jsonable`) atomically."""
    atomic_write_text(path, json.dumps(jsonable(obj), indent=2, allow_nan=False) + "\n")


_SAVEZ_RESERVED = ("file", "allow_pickle")
"""Keyword names of ``np.savez`` itself: an array of that name would not be saved as an array."""


def atomic_savez(path: str | Path, arrays: dict[str, np.ndarray]) -> None:
    """``np.savez`` of ``arrays`` to ``path`` atomically."""
    clash = [k for k in _SAVEZ_RESERVED if k in arrays]
    if clash:
        raise ValueError(f"array names {clash} are np.savez keywords and cannot be saved")
    # every remaining key is an array name, so the keywords are all arrays (typed Any: np.savez
    # also takes ``allow_pickle: bool`` as a keyword, which mypy matches against **arrays)
    named: dict[str, Any] = dict(arrays)
    _atomic(path, "wb", lambda fh: np.savez(fh, **named))
