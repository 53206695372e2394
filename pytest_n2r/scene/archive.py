"""The zip container of scene files (``.n2r`` field scenes and packed splat scenes): written with fixed member
order, timestamps and modes, so the same content gives the same bytes; read one member at a time, each checked
against a size cap before it is inflated, so a corrupt or hostile archive is refused with a
:class:`~pytest_n2r.errors.SceneFileError` naming the file and the member."""

from __future__ import annotations

import io
import json
import zipfile
import zlib
from typing import Any

from ..errors import SceneFileError
from . import schema

__all__ = ["MAX_JSON_BYTES", "zip_bytes", "read_member", "read_scene_json"]

#: Every member's timestamp (the earliest a zip can hold), so the bytes do not depend on when they were written.
ZIP_TIME = (1980, 1, 1, 0, 0, 0)
#: The most bytes ``scene.json`` may inflate to (a scene of 10 000 frames takes about 4 MiB).
MAX_JSON_BYTES = 64 * 2**20


def zip_bytes(entries: list[tuple[str, bytes, int, int | None]]) -> bytes:
    """A zip archive of ``(name, data, compression, level)`` in the given order, with fixed timestamps and
    modes."""
    buffer = io.BytesIO()
    with zipfile.ZipFile(buffer, "w") as archive:
        for name, payload, compression, level in entries:
            info = zipfile.ZipInfo(name, date_time=ZIP_TIME)
            info.compress_type = compression
            info.create_system = 3  # Unix, whatever the platform, so the bytes match everywhere
            info.external_attr = 0o644 << 16
            archive.writestr(info, payload, compresslevel=level)
    return buffer.getvalue()


def read_member(archive: zipfile.ZipFile, name: str, source: str, limit: int, why: str) -> bytes:
    """The bytes of member ``name``, or a :class:`SceneFileError` saying it is missing, corrupt or inflates
    to more than ``limit`` bytes (``why``: what the limit follows from), checked before inflating it."""
    try:
        info = archive.getinfo(name)
    except KeyError:
        raise SceneFileError(f"{source}: the archive has no {name!r}") from None
    if info.file_size > limit:
        raise SceneFileError(f"{source}: {name!r} inflates to {info.file_size:,} bytes, more than the {limit:,} "
                             f"bytes {why} allows; the file is corrupt or was not written by pytest-n2r")
    try:
        with archive.open(info) as fh:
            data = fh.read(limit + 1)
    except (zipfile.BadZipFile, zlib.error, EOFError, OSError, RuntimeError) as exc:
        raise SceneFileError(f"{source}: {name!r} is corrupt or truncated ({exc})") from None
    if len(data) > limit:  # pragma: no cover - zipfile stops at the declared size
        raise SceneFileError(f"{source}: {name!r} inflates past its declared size")
    return data


def _not_strict_json(token: str) -> Any:
    raise ValueError(f"{token} is not a number in strict JSON; scene files store null for it")


def read_scene_json(archive: zipfile.ZipFile, source: str) -> Any:
    """The archive's ``scene.json``, parsed as strict JSON (no NaN or Infinity); a :class:`SceneFileError`
    when it is missing, too large or not valid JSON."""
    try:
        return json.loads(read_member(archive, schema.SCENE_JSON, source, MAX_JSON_BYTES,
                                      f"the cap on {schema.SCENE_JSON}"), parse_constant=_not_strict_json)
    except (ValueError, RecursionError) as exc:  # JSONDecodeError and UnicodeDecodeError are ValueErrors
        raise SceneFileError(f"{source}: {schema.SCENE_JSON} is not valid JSON ({exc})") from None


