"""Where numba keeps the compiled kernels, so that a read-only installation still imports them.

Conventions
-----------
- The kernels are compiled with ``cache=True``: numba keeps them in ``NUMBA_CACHE_DIR`` when set, else beside each
  source file (``__pycache__``) when that folder can be written, else in the user's cache folder
  (``~/.cache/numba``). Where none of these can be written (a package installed by root, run by a container's
  ``--user`` whose home is ``/`` or missing), numba refuses every ``cache=True`` kernel at import with
  ``RuntimeError: cannot cache function ...: no locator available``: an INTERNALERROR for the whole run.
- :func:`ensure_kernel_cache`, run when ``pytest_n2r`` is imported, names a folder of this user's alone in the
  temporary folder (:func:`~pytest_n2r.private_folder.private_temp_folder`) in ``NUMBA_CACHE_DIR`` then (numba's
  own ``config.CACHE_DIR`` when numba is loaded already); it changes nothing where numba has a place to write, or
  where ``NUMBA_CACHE_DIR`` is set. It looks at the package's own folder and at ``$XDG_CACHE_HOME/numba`` or
  ``~/.cache/numba`` (numba's folder on Linux; elsewhere a writable package folder is the usual case).
"""

from __future__ import annotations

import os
import sys
from pathlib import Path

__all__ = ["ensure_kernel_cache"]


def ensure_kernel_cache(package: Path = Path(__file__).parent) -> Path | None:
    """Give numba a cache folder it can write where it would find none (see the module docstring); the folder
    named, or ``None`` where nothing was changed. ``package``: the installed package's folder."""
    if os.environ.get("NUMBA_CACHE_DIR") or os.access(package, os.W_OK) or _writable(_user_cache()):
        return None
    from .private_folder import private_temp_folder  # here: every import of pytest_n2r runs this function

    folder = private_temp_folder("pytest-n2r-numba")  # numba unpickles what it finds there: this user's alone
    os.environ["NUMBA_CACHE_DIR"] = str(folder)
    numba_config = sys.modules.get("numba.core.config")
    if numba_config is not None:  # read at numba's import: set where its locators look now
        numba_config.CACHE_DIR = str(folder)  # type: ignore[attr-defined]  # numba's config sets its names at run time
    return folder


def _user_cache() -> Path | None:
    """numba's user-wide cache folder (``$XDG_CACHE_HOME/numba``, else ``~/.cache/numba``), ``None`` without a home."""
    if os.environ.get("XDG_CACHE_HOME"):
        return Path(os.environ["XDG_CACHE_HOME"]) / "numba"
    try:
        return Path.home() / ".cache" / "numba"
    except (RuntimeError, KeyError):
        return None


def _writable(folder: Path | None) -> bool:
    """Whether ``folder`` exists and can be written, or can be made in the nearest folder above it that exists."""
    if folder is None:
        return False
    while not folder.exists():
        if folder.parent == folder:
            return False
        folder = folder.parent
    return folder.is_dir() and os.access(folder, os.W_OK | os.X_OK)
