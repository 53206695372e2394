"""A folder of this user's in the temporary folder, that no other user can have planted.

Conventions
-----------
- The folder's name is fixed (``<name>-<uid>``), so a later process finds what an earlier one kept there. What is
  kept is read back and trusted (numba loads its cached kernels with pickle), so the folder must be this user's
  alone: made with mode ``0o700``, and one that exists already is used only when it is a real folder (not a
  link), owned by this user, and closed to every other (``mode & 0o077 == 0``).
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
    try:
        folder.mkdir(mode=0o700)
    except FileExistsError:
        pass
    except OSError:
        return Path(tempfile.mkdtemp(prefix=f"{name}-"))
    try:
        info = folder.lstat()
    except OSError:
        return Path(tempfile.mkdtemp(prefix=f"{name}-"))
    if not stat.S_ISDIR(info.st_mode) or (uid is not None and info.st_uid != uid) or info.st_mode & 0o077:
        return Path(tempfile.mkdtemp(prefix=f"{name}-"))
    return folder
