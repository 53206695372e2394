"""The files of a render cache directory: writing one (:func:`write_entry`), what it holds and its trimming:
renders, decisions and field floors counted together against the cap and evicted oldest-first (by modification
time, which a hit refreshes), and the temporary files a killed writer left deleted once :data:`STALE_TMP_SECONDS`
old.

Every scan and deletion tolerates a folder removed or made under it (a concurrent ``--n2r-cache-clear``, another
worker trimming) and never follows a link.
"""

from __future__ import annotations

import math
import os
import tempfile
import time
from collections.abc import Callable
from pathlib import Path
from typing import BinaryIO

from ..data.atomic import created_file_mode

__all__ = ["STALE_TMP_SECONDS", "CacheNotStored", "cache_entries", "discard", "touch", "trim_entries", "write_entry"]

#: A temporary file (``.{name}.XXXX.tmp``) older than this (seconds) was left by a killed writer; a younger one
#: may be a concurrent writer's, about to be renamed into place.
STALE_TMP_SECONDS = 300.0
#: The folders of a cache directory that hold its entries, and how deep its files lie below each (renders and
#: decisions in folders named by their keys' first two digits, floors flat).
_LAYOUT = (("renders", 1), ("decisions", 1), ("floors", 0))


class CacheNotStored(UserWarning):
    """A render cache stopped storing for the session: its folder cannot be written (the error is named)."""


def write_entry(path: Path, write: Callable[[BinaryIO], object]) -> None:
    """Write a cache file under a temporary name in its folder, then rename it into place (no fsync, unlike
    :func:`~pytest_n2r.data.atomic.atomic_write_bytes`: an entry lost in a power cut is just computed again), with
    the mode :func:`open` would give it (:func:`~pytest_n2r.data.atomic.created_file_mode`), not the temporary
    file's ``0o600``: a cache shared between users (a CI cache restored by another uid, a group's folder) is
    readable to them as the umask allows."""
    fd, tmp = tempfile.mkstemp(prefix=f".{path.name}.", suffix=".tmp", dir=path.parent)
    try:
        with os.fdopen(fd, "wb") as f:
            write(f)
        os.chmod(tmp, created_file_mode())
        os.replace(tmp, path)
    except BaseException:
        Path(tmp).unlink(missing_ok=True)
        raise


def touch(path: Path) -> None:
    """Mark the entry at ``path`` recently used, so that :func:`trim_entries` evicts it last; an entry removed
    meanwhile (another worker's trim, a clear) is no error."""
    try:
        os.utime(path)
    except OSError:
        pass


def discard(path: Path) -> None:
    """Delete the entry at ``path``, which could not be used (damaged, not what was asked for); one already gone or
    that cannot be deleted (another user's, a read-only cache) is left as it is: a miss never fails a test."""
    try:
        path.unlink()
    except OSError:
        pass


def _scan(folder: str) -> list[os.DirEntry]:
    """The entries of ``folder``, none when it is gone, was replaced by a file, or cannot be read."""
    try:
        with os.scandir(folder) as it:
            return list(it)
    except OSError:
        return []


def _files(folder: str, depth: int) -> list[tuple[float, Path, int, bool]]:
    """``(mtime, path, bytes, is_tmp)`` of the files ``depth`` folders below ``folder``, not through a link."""
    found = []
    for entry in _scan(folder):
        try:
            if entry.is_symlink():  # never count nor delete through a link
                continue
            if depth:
                if entry.is_dir(follow_symlinks=False):
                    found.extend(_files(entry.path, depth - 1))
                continue
            if not entry.is_file(follow_symlinks=False):
                continue
            st = entry.stat(follow_symlinks=False)
        except OSError:  # removed by another worker or a clear meanwhile
            continue
        tmp = entry.name.startswith(".") and entry.name.endswith(".tmp")
        found.append((st.st_mtime, Path(entry.path), _taken(st), tmp))
    return found


def _taken(st: os.stat_result) -> int:
    """Bytes a file takes on disk: its allocated blocks (a 90-byte decision takes a 4 KiB block), else its size."""
    return max(st.st_size, getattr(st, "st_blocks", 0) * 512)


def cache_entries(directory: Path) -> list[tuple[float, Path, int, bool]]:
    """``(mtime, path, bytes, is_tmp)`` of every file of the cache in ``directory``: renders, decisions, floors and
    the temporary files of their writers (bytes: what the file takes on disk, as ``du`` counts it)."""
    return [f for sub, depth in _LAYOUT for f in _files(os.path.join(directory, sub), depth)]


def _unlink(path: Path) -> bool:
    try:
        path.unlink()
    except FileNotFoundError:  # evicted by another worker meanwhile: freed all the same
        return True
    except OSError:
        return False
    return True


def trim_entries(directory: Path, cap: int, *, now: float | None = None) -> tuple[int, int]:
    """Delete the temporary files older than :data:`STALE_TMP_SECONDS`, then, when the cache holds more than
    ``cap`` bytes, the least recently used entries (renders, decisions and floors alike) until it holds at most
    80 % of ``cap``; returns the bytes freed and the bytes it holds then. The caller checks that ``directory`` is
    pytest-n2r's.

    A time later than ``now`` by more than :data:`STALE_TMP_SECONDS` was set under another clock (a cache CI restored
    from a machine whose clock ran ahead): such an entry has not been used here since (a use sets it to now), so it
    goes first, and such a temporary file is no writer's here (a time a little later is another worker's store or
    use during the scan, or an NFS server's clock); under a clock behind (a board that boots in 1970) the entries
    used here are the ones at or before ``now``, and they stay."""
    now = time.time() if now is None else now
    freed, kept = 0, []
    for mtime, path, size, tmp in cache_entries(directory):
        if tmp and abs(now - mtime) > STALE_TMP_SECONDS and _unlink(path):
            freed += size
        else:
            kept.append((mtime, path, size, tmp))
    total = sum(size for _, _, size, _ in kept)
    if total <= cap:
        return freed, total
    target = 0.8 * cap
    ahead = now + STALE_TMP_SECONDS  # later than this: another clock's (not a worker's store during the scan)
    for _, path, size, tmp in sorted(kept, key=lambda f: f[0] if f[0] <= ahead else -math.inf):
        if total <= target:
            break
        if not tmp and _unlink(path):  # a fresh temporary file is a concurrent writer's
            total -= size
            freed += size
    return freed, total
