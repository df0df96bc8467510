"""Files the user names, checked before any work starts; errors while reading them named.

Every command and workflow that reads or writes a file the user named calls one of
:func:`input_file`, :func:`output_file` or :func:`output_dir` first, so that a typo costs no
seconds of certification or minutes of training and never ends in a traceback: each raises a
:class:`~drip_cert.errors.SpecError` naming the file, what is wrong and what to give instead.
:func:`reading` wraps the reading of a user file: any error the reader did not anticipate
(a corrupt archive, an encoding error, ...) becomes a :class:`~drip_cert.errors.SpecError` naming
the file and the original error (kept as ``__cause__``, shown by ``drip-cert --debug``).
"""

from __future__ import annotations

import os
from collections.abc import Iterator
from contextlib import contextmanager
from pathlib import Path

import numpy as np

from drip_cert.errors import DripCertError, SpecError

__all__ = ["input_file", "output_dir", "output_file", "read_npz", "reading"]

_ZIP_SIGNATURES = (b"PK\x03\x04", b"PK\x05\x06")
"""The first bytes of a zip archive with members / without (``numpy.savez`` writes zip)."""
_NPY_SIGNATURE = b"\x93NUMPY"
"""The first bytes of a single-array ``.npy`` file (``numpy.save``)."""


def input_file(
    path: str | os.PathLike[str], what: str = "file", *, field: str | None = None
) -> Path:
    """``path`` as a :class:`~pathlib.Path` after checking that it is a readable regular file.

    Parameters
    ----------
    path
        The file the user named.
    what
        What the file is, for the message (``"specification file"``, ``"data file"``).
    field
        The spec key that named the file (``blocks.h.weights``), when one did.

    Raises
    ------
    SpecError
        The path does not exist, is a directory, or cannot be read.
    """
    p = Path(path)
    where = str(p)
    if not p.exists():
        hint = _nearest_missing(p)
        if str(path).endswith(("/", os.sep)):  # `nodir/`: a directory was meant, a file is needed
            hint += f"; and a file is needed here, not a directory: name the {what} itself"
        raise SpecError(f"{what} {str(path)!r} does not exist{hint}", field=field)
    if p.is_dir():
        raise SpecError(f"{what} {where!r} is a directory: give the file inside it", field=field)
    if not p.is_file():
        raise SpecError(f"{what} {where!r} is not a regular file", field=field)
    if not os.access(p, os.R_OK):
        raise SpecError(f"{what} {where!r} cannot be read (permission denied)", field=field)
    return p


def output_file(path: str | os.PathLike[str], what: str = "output file") -> Path:
    """``path`` as a :class:`~pathlib.Path` after checking that a file can be written there.

    The parent directory must exist and be writable (it is not created: a missing one is more
    often a typo than a wish), and ``path`` must not be an existing directory or an existing
    file that cannot be overwritten.

    Raises
    ------
    SpecError
        Naming the path and what to give instead.
    """
    p = Path(path)
    where, parent = str(p), p.parent
    if p.is_dir():
        raise SpecError(
            f"the {what} {where!r} is a directory: give a file name (e.g. {str(p / 'name')!r})"
        )
    if not parent.exists():
        raise SpecError(
            f"the directory {str(parent)!r} of the {what} {where!r} does not exist: create it "
            "first (or fix the path)"
        )
    if not parent.is_dir():
        raise SpecError(f"the {what} {where!r} cannot be written: {str(parent)!r} is a file")
    if not os.access(parent, os.W_OK | os.X_OK):
        raise SpecError(
            f"the {what} {where!r} cannot be written: the directory {str(parent)!r} is not writable"
        )
    if p.exists() and not os.access(p, os.W_OK):
        raise SpecError(f"the {what} {where!r} exists and is not writable")
    return p


def output_dir(path: str | os.PathLike[str], what: str = "output directory") -> Path:
    """``path`` as a :class:`~pathlib.Path` after checking that it is, or can be made, a
    writable directory.

    An existing ``path`` must be a writable directory; a missing one is created later (with its
    missing parents), so its nearest existing ancestor must be a writable directory.

    Raises
    ------
    SpecError
        ``path`` (or an ancestor) is an existing file, or nothing can be written there.
    """
    p = Path(path)
    where = str(p)
    if p.exists():
        if not p.is_dir():
            raise SpecError(
                f"the {what} {where!r} is an existing file, not a directory: give a directory "
                "(it is created when missing)"
            )
        if not os.access(p, os.W_OK | os.X_OK):
            raise SpecError(f"the {what} {where!r} is not writable")
        return p
    ancestor = p.absolute().parent
    while not ancestor.exists():
        ancestor = ancestor.parent
    if not ancestor.is_dir():
        raise SpecError(
            f"the {what} {where!r} cannot be created: {str(ancestor)!r} is a file, not a directory"
        )
    if not os.access(ancestor, os.W_OK | os.X_OK):
        raise SpecError(
            f"the {what} {where!r} cannot be created: {str(ancestor)!r} is not writable"
        )
    return p


@contextmanager
def reading(path: str | os.PathLike[str], what: str = "file") -> Iterator[None]:
    """Turn any unanticipated error raised while reading the user's ``path`` into a
    :class:`~drip_cert.errors.SpecError` naming it (a :class:`~drip_cert.errors.DripCertError`
    passes through unchanged; the original error is the new one's ``__cause__``).

    Example::

        with reading(path, "data file"):
            arrays = np.load(path)
    """
    try:
        yield
    except DripCertError:
        raise
    except Exception as exc:
        detail = " ".join(str(exc).split()) or "no detail"
        raise SpecError(
            f"cannot read the {what}: {type(exc).__name__}: {detail}", path=str(Path(path))
        ) from exc


def read_npz(
    path: str | os.PathLike[str], what: str = "file", *, field: str | None = None
) -> dict[str, np.ndarray]:
    """The arrays of the ``.npz`` archive ``path`` (read without pickles), or a
    :class:`~drip_cert.errors.SpecError` that says what the file is instead.

    A text file, a single ``.npy`` array, a damaged or truncated archive and an archive of
    pickled (object) arrays are each refused with their own message naming ``path`` (and
    ``field``, the spec key that named it, when given).
    """
    p = input_file(path, what, field=field)
    where = str(p)

    def fail(msg: str) -> SpecError:
        return SpecError(f"{what} {where!r} {msg}", field=field)

    with p.open("rb") as fh:
        head = fh.read(len(_NPY_SIGNATURE))
    if head.startswith(_NPY_SIGNATURE):
        raise fail(
            "is a single .npy array, not an .npz archive: save named arrays with "
            "numpy.savez(file, name=array, ...)"
        )
    if not head.startswith(_ZIP_SIGNATURES):
        raise fail(
            "is not an .npz archive (numpy.savez writes a zip archive; this file does not start "
            f"with the zip signature{', it looks like text' if _looks_like_text(head) else ''})"
        )
    try:
        with np.load(p, allow_pickle=False) as z:
            return {k: np.asarray(z[k]) for k in z.files}
    except ValueError as exc:
        if "pickle" in str(exc):
            raise fail(
                "holds pickled (object) arrays, which are not read (drip-cert loads .npz files "
                "without pickles): save plain numeric arrays with numpy.savez"
            ) from None
        raise fail(f"is a damaged .npz archive ({type(exc).__name__}: {exc})") from exc
    except Exception as exc:  # zipfile.BadZipFile, zlib.error, EOFError, OSError: a damaged file
        raise fail(f"is a damaged .npz archive ({type(exc).__name__}: {exc})") from exc


def _looks_like_text(head: bytes) -> bool:
    try:
        text = head.decode("utf-8")
    except UnicodeDecodeError:
        return False
    return all(c.isprintable() or c.isspace() for c in text)


def _nearest_missing(p: Path) -> str:
    """`` (the directory 'a/b' does not exist either)`` when the parent is missing too."""
    parent = p.parent
    if str(parent) not in ("", ".") and not parent.exists():
        return f" (the directory {str(parent)!r} does not exist either)"
    return ""
