"""Atomic file writes: write to a temporary name in the same folder, then rename over the target."""

from __future__ import annotations

import os
import tempfile
from collections.abc import Callable, Iterable
from pathlib import Path
from typing import BinaryIO

__all__ = ["atomic_write_bytes", "atomic_write_chunks", "atomic_write_text", "created_file_mode", "current_umask",
           "unwritable_reason"]

#: Linux's status of this process; its ``Umask:`` line (kernel 4.7 and later) gives the umask without setting it.
_PROC_STATUS = "/proc/self/status"


def current_umask() -> int:
    """The process's umask now (a conftest may have changed it since import).

    Read from the ``Umask:`` line of ``/proc/self/status`` where there is one (Linux 4.7 and later), which leaves it
    as it is (some 15 µs a read, against some 500 µs for an atomic write and its fsync); elsewhere by
    :func:`os.umask`, which can only read it by setting it and back: a thread creating a file in between gets mode
    ``0o666``.
    """
    try:
        with open(_PROC_STATUS, "rb") as fh:
            for line in fh:
                if line.startswith(b"Umask:"):
                    return int(line.split()[1], 8)
    except (OSError, ValueError, IndexError):
        pass
    mask = os.umask(0)
    os.umask(mask)
    return mask


def created_file_mode() -> int:
    """The mode :func:`open` gives a new file now (``0o666`` less the umask), for a file made another way
    (:func:`tempfile.mkstemp` makes it ``0o600``, readable to its owner alone)."""
    return 0o666 & ~current_umask()


def _atomic_write(path: str | os.PathLike, write: Callable[[BinaryIO], object]) -> Path:
    """Call ``write`` with the temporary file's handle, then rename it over ``path``; on any error (in ``write``
    too) remove it and leave the old file as it was."""
    path = Path(path)
    path.parent.mkdir(parents=True, exist_ok=True)
    try:
        mode = path.stat().st_mode & 0o7777
    except FileNotFoundError:
        mode = created_file_mode()
    fd, tmp = tempfile.mkstemp(prefix=f".{path.name}.", suffix=".tmp", dir=path.parent)
    try:
        with os.fdopen(fd, "wb") as fh:
            write(fh)
            fh.flush()
            os.fsync(fh.fileno())
        os.chmod(tmp, mode)
        os.replace(tmp, path)
    except BaseException:
        Path(tmp).unlink(missing_ok=True)
        raise
    return path


def atomic_write_bytes(path: str | os.PathLike, data: bytes) -> Path:
    """Write ``data`` to ``path`` so that readers see either the old file or the complete new one.

    The new file keeps the old one's permissions, or gets those of a plainly created file (``0o666`` less
    the umask, read as it is written) rather than the owner-only mode of the temporary file.
    """
    return _atomic_write(path, lambda fh: fh.write(data))


def atomic_write_text(path: str | os.PathLike, text: str) -> Path:
    """:func:`atomic_write_bytes` for UTF-8 text. A character that stands for a byte a file name could not decode
    (Python's ``surrogateescape``: under an ASCII locale every non-ASCII name reads so) is written as that byte, so
    a path in a report comes out as the name on disk; strict UTF-8 refused the whole report."""
    return atomic_write_bytes(path, text.encode("utf-8", "surrogateescape"))


def atomic_write_chunks(path: str | os.PathLike, chunks: Iterable[str]) -> Path:
    """:func:`atomic_write_text` for text in pieces (a generator), each encoded and written as it comes, so the
    whole text is never in memory; an exception from ``chunks`` leaves the old file, as a failed write does."""
    return _atomic_write(path, lambda fh: fh.writelines(chunk.encode("utf-8", "surrogateescape") for chunk in chunks))


def unwritable_reason(folder: str | os.PathLike) -> str | None:
    """Why files cannot be written into ``folder``, or ``None`` when they can.

    Tried, not inferred from permission bits (which root, read-only mounts and ``/proc`` defeat): a
    temporary file is created and removed in the nearest folder that exists; nothing is created on the way.
    """
    existing = Path(folder)
    while not existing.exists() and existing.parent != existing:
        existing = existing.parent
    if not existing.is_dir():
        return f"{existing} is a file, not a folder"
    try:
        fd, probe = tempfile.mkstemp(prefix=".n2r-write-check.", dir=existing)
        os.close(fd)
        os.unlink(probe)
    except OSError as exc:
        return f"cannot write into {existing} ({exc.strerror or exc})"
    return None
