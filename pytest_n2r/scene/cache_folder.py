"""The folder of a render cache, and whether it is pytest-n2r's: only such a folder is tagged, trimmed or cleared.

Convention
----------
A folder is pytest-n2r's when it holds exactly pytest-n2r's ``CACHEDIR.TAG`` (bford.info/cachedir), which
:func:`claim` writes into a folder that is new, empty or holds only what pytest-n2r writes there before its tag. A
folder of the user's named as a cache by mistake (``--n2r-cache-dir=``, the project's root) is never tagged, its
``.gitignore`` never replaced, and nothing in it deleted.
"""

from __future__ import annotations

import os
import re
from pathlib import Path

from ..data.atomic import atomic_write_text

__all__ = ["claim", "foreign_entries", "is_ours", "not_a_cache"]

#: The ``CACHEDIR.TAG`` pytest-n2r writes (bford.info/cachedir): a directory holding exactly this file is one
#: pytest-n2r made, the only kind in which :meth:`RenderCache.clear` and :meth:`RenderCache.trim` delete.
_TAG = "Signature: 8a477f597d28d172789f06886806bc55\n# pytest-n2r render cache\n"
#: What a cache directory may hold before its tag: kernel locks and floors (written before the first render is
#: stored), the tag (or the .gitignore) under its temporary name, the options' writability probe, and a
#: ``.gitignore`` (a folder the user made for the cache and told Git about: it is kept).
_BEFORE_TAG = re.compile(r"kernel-locks|floors|\.gitignore|\.(CACHEDIR\.TAG|gitignore)\..*\.tmp|\.n2r-write-check\..*")


def is_ours(directory: Path) -> bool:
    """Whether ``directory`` carries pytest-n2r's own ``CACHEDIR.TAG``."""
    try:
        return (directory / "CACHEDIR.TAG").read_bytes() == _TAG.encode()
    except OSError:
        return False


def foreign_entries(directory: str | os.PathLike) -> list[str]:
    """The names in ``directory`` that say it is not a pytest-n2r cache (a folder of the user's named by mistake),
    sorted: none when it carries pytest-n2r's ``CACHEDIR.TAG``, does not exist, or holds only what pytest-n2r
    writes there before its tag. Such a folder is never tagged, and nothing in it is deleted."""
    directory = Path(directory)
    if is_ours(directory):
        return []
    try:
        names = os.listdir(directory)
    except FileNotFoundError:
        return []
    return sorted(n for n in names if not _BEFORE_TAG.fullmatch(n))


def claim(directory: Path) -> None:
    """Make ``directory`` and tag it as pytest-n2r's where it is new or holds only pytest-n2r's files; ignore it in
    Git unless a ``.gitignore`` is there. A folder that is not pytest-n2r's is left as it is."""
    if is_ours(directory) or foreign_entries(directory):
        return
    directory.mkdir(parents=True, exist_ok=True)
    atomic_write_text(directory / "CACHEDIR.TAG", _TAG)
    if not (directory / ".gitignore").exists():
        atomic_write_text(directory / ".gitignore", "# created by pytest-n2r\n*\n")


def not_a_cache(directory: Path, foreign: list[str]) -> str:
    """Why ``directory``, holding the :func:`foreign_entries` ``foreign``, is refused as a render cache."""
    shown = ", ".join(foreign[:3]) + (f" and {len(foreign) - 3} more" if len(foreign) > 3 else "")
    return f"{directory} is not a pytest-n2r render cache (no CACHEDIR.TAG written by pytest-n2r) and holds {shown}"
