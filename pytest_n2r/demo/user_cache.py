"""The user cache folder of the demo scenes: their fitted files (:mod:`.fitted`) and their textures' digests
(:mod:`.textures`)."""

from __future__ import annotations

import functools
import os
import warnings
from pathlib import Path

from ..private_folder import private_temp_folder

__all__ = ["cache_dir"]


def cache_dir() -> Path:
    """The user cache folder of the demo scenes: ``$N2R_CACHE_DIR`` when set, else the platform's user cache
    dir for ``pytest-n2r`` (``~/.cache/pytest-n2r`` on Linux); where there is no home folder to find it under (a
    container's user with no ``HOME`` and no passwd entry), a folder of this user's in the temporary folder, said
    once in a warning."""
    env = os.environ.get("N2R_CACHE_DIR")
    if env:
        return Path(env).expanduser()
    import platformdirs

    try:
        return Path(platformdirs.user_cache_dir("pytest-n2r", appauthor=False))
    except (RuntimeError, KeyError, OSError) as exc:  # Path.home() / pwd without a home folder
        return _temporary_cache_dir(str(exc))


@functools.cache
def _temporary_cache_dir(why: str) -> Path:
    folder = private_temp_folder("pytest-n2r-cache")  # its scene files are read back: this user's alone
    warnings.warn(f"no user cache folder ({why}): the demo scenes' cache is {folder}, which the system may clear; "
                  "set N2R_CACHE_DIR to keep it elsewhere", stacklevel=3)
    return folder
