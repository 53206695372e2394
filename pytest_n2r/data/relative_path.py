"""A file's path as another folder reaches it: what a written file records of the files it names (a pose set's
photos, a baseline's rootdir, a JSON report's failure pictures), so that the two can move together.

Convention
----------
Both paths are resolved first (a folder reached through a link is the folder itself), and the result is
``/``-separated whatever the platform. With ``keep_name=True`` only the path's folder is resolved and its own name is
kept: a photo that is a link to another photo in its folder stays itself (two frames, two names), not its target.
Where no relative path exists (another drive on Windows) the resolved path itself is returned.
"""

from __future__ import annotations

import os
from pathlib import Path

__all__ = ["relative_posix"]


def relative_posix(path: str | os.PathLike, start: str | os.PathLike, *, keep_name: bool = False) -> str:
    """``path`` relative to the folder ``start``, ``/``-separated (see the module's *Convention*).

    >>> relative_posix("/src/proj/out/a.png", "/src/proj/tests")
    '../out/a.png'
    """
    target = Path(path).parent.resolve() / Path(path).name if keep_name else Path(path).resolve()
    try:
        return Path(os.path.relpath(target, Path(start).resolve())).as_posix()
    except ValueError:  # another drive
        return target.as_posix()
