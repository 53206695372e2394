"""Parsers of the plugin's options whose value is a path: folders it writes into, files it writes at the end."""

from __future__ import annotations

from pathlib import Path
from typing import TYPE_CHECKING

from ..errors import InvalidArgument

if TYPE_CHECKING:
    from .options import Where

__all__ = ["folder", "cache_folder", "output_file"]


def folder(value: str | bool, where: Where) -> Path | None:
    """A writable folder, relative to the rootdir; ``none`` (a TOML ``false``): ``None`` (nothing written). An empty
    value (``--n2r-cache-dir "$UNSET"``) is refused: taken as a path it would be the rootdir itself. A default
    folder that cannot be written (a read-only checkout) is ``None`` with a warning, as pytest's own cache does: only
    a folder the user chose refuses the run."""
    if isinstance(value, bool):
        if value:
            raise InvalidArgument("true is not a folder; expected a folder path, or 'none' (or false)")
        return None
    value = f"{value}"
    if not value.strip():
        raise InvalidArgument(f"{value!r} is empty; expected a folder path, or 'none'")
    if value.strip().lower() == "none":
        return None
    from ..data.atomic import unwritable_reason

    path = Path(value).expanduser()
    target = path if path.is_absolute() else where.root / path
    reason = unwritable_reason(target)
    if reason is not None and where.origin == "default":
        where.warn(f"pytest-n2r: the default folder {target}: {reason}: nothing is written there this run; "
                   "choose a writable folder, or 'none'")
        return None
    if reason is not None:
        raise InvalidArgument(f"{target}: {reason}; choose a writable folder, or 'none'")
    return target


def cache_folder(value: str | bool, where: Where) -> Path | None:
    """:func:`folder`, refused where it holds files of its own and no pytest-n2r ``CACHEDIR.TAG``: the cache
    would write into it and never trim it, nor clear it (``--n2r-cache-clear``)."""
    path = folder(value, where)
    from ..scene.cache_folder import foreign_entries, not_a_cache

    if path is not None and (foreign := foreign_entries(path)):
        raise InvalidArgument(f"{not_a_cache(path, foreign)}; choose a new or empty folder, or 'none'")
    return path


def output_file(value: str, where: Where) -> Path:
    """A file to write at the end of the session: not a folder, in a folder that exists or can be created and
    is writable (checked now, so a bad path never costs the run's result)."""
    if not str(value).strip():
        raise InvalidArgument("the path is empty; expected the path of a file to write")
    path = Path(value).expanduser()
    if path.is_dir():
        raise InvalidArgument(f"{path} is a folder; expected the path of a file to write (e.g. {path / 'n2r.json'})")
    from ..data.atomic import unwritable_reason

    reason = unwritable_reason(path.absolute().parent)
    if reason is not None:
        raise InvalidArgument(f"{path}: {reason}; choose a path in a writable folder")
    return path
