"""A folder of this user's in the temporary folder, that no other user can have planted.

Conventions
-----------
- The folder's name is fixed (``<name>-<uid>``), so a later process finds what an earlier one kept there. What is
  kept is read back and trusted (numba loads its cached kernels with pickle), so the folder must be this user's
  alone: made with mode ``0o700``, and one that exists already is used only when it is a real folder (not a
  link), owned by this user, and writable by no other (``mode & 0o022 == 0``; one others may read, as an earlier
  version made it, is closed to them). On Windows, without owners in ``st_mode``, the temporary folder is the
  user's own: a real folder is used.
- Otherwise (another user made it first, or its mode was opened) a fresh folder of ``tempfile.mkdtemp`` is used,
  for this process alone.
"""

from __future__ import annotations

import os
import stat
import tempfile
from pathlib import Path

__all__ = ["private_temp_folder"]


def private_temp_folder(name: str) -> Path:
    """The folder ``<temporary folder>/<name>-<uid>`` made or checked as the module docstring says, else a fresh
    ``mkdtemp`` folder."""
    uid = os.getuid() if hasattr(os, "getuid") else None
    folder = Path(tempfile.gettempdir()) / f"{name}-{uid if uid is not None else 'user'}"
    return folder if _usable(folder, uid) else Path(tempfile.mkdtemp(prefix=f"{name}-"))


def _usable(folder: Path, uid: int | None) -> bool:
    """Whether ``folder``, made now or found, is a real folder of ``uid``'s that no other can write into (closed to
    their reading too, where it was open to it); ``uid=None`` (Windows): whether it is a real folder."""
    try:
        folder.mkdir(mode=0o700)
    except FileExistsError:
        pass
    except OSError:
        return False
    try:
        info = folder.lstat()
        if not stat.S_ISDIR(info.st_mode):  # a file, or a link planted in its place
            return False
        if uid is None:  # Windows: the temporary folder is the user's own, and st_mode says nothing of others
            return True
        if info.st_uid != uid or info.st_mode & 0o022:  # another user's, or one others could have written into
            return False
        if info.st_mode & 0o077:  # this user's and written by no other, but open to reading (made so before)
            folder.chmod(0o700)
    except OSError:
        return False
    return True
