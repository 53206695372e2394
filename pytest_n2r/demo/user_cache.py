"""The user cache folder of the demo scenes: their fitted files (:mod:`.fitted`) and their textures' digests
(:mod:`.textures`)."""

from __future__ import annotations

import os
from pathlib import Path

__all__ = ["cache_dir"]


def cache_dir() -> Path:
    """The user cache folder of the demo scenes: ``$N2R_CACHE_DIR`` when set, else the platform's user cache
    dir for ``pytest-n2r`` (``~/.cache/pytest-n2r`` on Linux)."""
    env = os.environ.get("N2R_CACHE_DIR")
    if env:
        return Path(env).expanduser()
    import platformdirs

    return Path(platformdirs.user_cache_dir("pytest-n2r", appauthor=False))
