"""The zip container of scene files (``.n2r`` field scenes and packed splat scenes): written with fixed member
order, timestamps and modes, so the same content gives the same bytes; read one member at a time, each checked
against a size cap before it is inflated, so a corrupt or hostile archive is refused with a
:class:`~pytest_n2r.errors.SceneFileError` naming the file and the member."""

from __future__ import annotations

import copy
import hashlib
import io
import json
import struct
import zipfile
import zlib
from collections.abc import Sequence
from pathlib import Path
from typing import Any

from ..errors import SceneFileError
from . import schema

__all__ = ["MAX_JSON_BYTES", "StoredMember", "zip_bytes", "read_member", "read_scene_json"]

#: Every member's timestamp (the earliest a zip can hold), so the bytes do not depend on when they were written.
ZIP_TIME = (1980, 1, 1, 0, 0, 0)
#: The most bytes ``scene.json`` may inflate to (a scene of 10 000 frames takes about 4 MiB).
MAX_JSON_BYTES = 64 * 2**20


def zip_bytes(entries: Sequence[tuple[str, bytes, int, int | None]]) -> bytes:
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


def _member_info(archive: zipfile.ZipFile, name: str, source: str, limit: int, why: str) -> zipfile.ZipInfo:
    """The entry of member ``name``, refused when missing or declaring more than ``limit`` bytes."""
    try:
        info = archive.getinfo(name)
    except KeyError:
        raise SceneFileError(f"{source}: the archive has no {name!r}") from None
    if info.file_size > limit:
        raise SceneFileError(f"{source}: {name!r} inflates to {info.file_size:,} bytes, more than the {limit:,} "
                             f"bytes {why} allows; the file is corrupt or was not written by pytest-n2r")
    return info


def read_member(archive: zipfile.ZipFile, name: str, source: str, limit: int, why: str) -> bytes:
    """The bytes of member ``name``, or a :class:`SceneFileError` saying it is missing, corrupt or inflates
    to more than ``limit`` bytes (``why``: what the limit follows from), checked before inflating it."""
    info = _member_info(archive, name, source, limit, why)
    try:
        with archive.open(info) as fh:
            data = fh.read(limit + 1)
    except NotImplementedError as exc:  # a compression method zipfile has no codec for (bzip2, lzma, ...)
        raise SceneFileError(f"{source}: {name!r} is stored in a way this reader cannot open ({exc}); expected a "
                             "member stored or deflated, as n2r fit and n2r import write them") from None
    except (zipfile.BadZipFile, zlib.error, EOFError, OSError, RuntimeError) as exc:
        raise SceneFileError(f"{source}: {name!r} is corrupt or truncated ({exc})") from None
    if len(data) > limit:  # pragma: no cover - zipfile stops at the declared size
        raise SceneFileError(f"{source}: {name!r} inflates past its declared size")
    return data


#: The fixed part of a zip local file header: signature, then fields up to the name and extra lengths.
_LOCAL_HEADER = struct.Struct("<4s22xHH")


class StoredMember:
    """One member of a zip archive as it is stored (compressed), read once: its :attr:`digest` names its
    content without inflating it, and :meth:`inflate` gives its bytes later, from the same stored bytes (so
    what is inflated is what the digest names, even if the file changes on disk meanwhile). Only deflated and
    stored members, not encrypted (what pytest-n2r writes); :meth:`read` says ``None`` for others."""

    def __init__(self, info: zipfile.ZipInfo, stored: bytes, source: str):
        self.info, self.stored, self.source = info, stored, source

    @classmethod
    def read(cls, archive: zipfile.ZipFile, path: Path, name: str, source: str, limit: int,
             why: str) -> StoredMember:
        """Member ``name`` of ``archive`` (the file at ``path``) as stored, refused as :func:`read_member`
        refuses it (missing, corrupt, or inflating to more than ``limit`` bytes). A member compressed
        otherwise than pytest-n2r writes is inflated now and kept as if stored uncompressed."""
        info = _member_info(archive, name, source, limit, why)
        stored = cls._stored_bytes(path, info, source)
        if stored is None:
            data = read_member(archive, name, source, limit, why)
            info = copy.copy(info)
            info.compress_type, info.compress_size, info.flag_bits = zipfile.ZIP_STORED, len(data), 0
            return cls(info, data, source)
        return cls(info, stored, source)

    @staticmethod
    def _stored_bytes(path: Path, info: zipfile.ZipInfo, source: str) -> bytes | None:
        """The stored bytes of ``info`` in the archive at ``path``; ``None`` for a member this class does not
        inflate; a :class:`SceneFileError` when its local header or data is cut short."""
        if info.compress_type not in (zipfile.ZIP_STORED, zipfile.ZIP_DEFLATED) or info.flag_bits & 0x1:
            return None
        try:
            with open(path, "rb") as fh:
                fh.seek(info.header_offset)
                signature, name_length, extra_length = _LOCAL_HEADER.unpack(fh.read(_LOCAL_HEADER.size))
                if signature != b"PK\x03\x04":
                    raise ValueError("no local file header where the central directory points")
                fh.seek(info.header_offset + _LOCAL_HEADER.size + name_length + extra_length)
                stored = fh.read(info.compress_size)
        except (OSError, ValueError, struct.error) as exc:
            raise SceneFileError(f"{source}: {info.filename!r} is corrupt or truncated ({exc})") from None
        if len(stored) != info.compress_size:
            raise SceneFileError(f"{source}: {info.filename!r} is corrupt or truncated ({len(stored):,} of "
                                 f"{info.compress_size:,} stored bytes)")
        return stored

    @property
    def digest(self) -> str:
        """Hex SHA-256 of the member as stored, with its compression method, size and CRC-32."""
        i = self.info
        h = hashlib.sha256(f"{i.compress_type}/{i.file_size}/{i.CRC}/".encode())
        h.update(self.stored)
        return h.hexdigest()

    def inflate(self) -> bytes:
        """The member's bytes; a :class:`SceneFileError` when they do not inflate to its size and CRC-32."""
        i = self.info
        try:
            data = self.stored if i.compress_type == zipfile.ZIP_STORED else \
                zlib.decompressobj(-zlib.MAX_WBITS).decompress(self.stored, i.file_size + 1)
        except zlib.error as exc:
            raise SceneFileError(f"{self.source}: {i.filename!r} is corrupt or truncated ({exc})") from None
        if len(data) != i.file_size or zlib.crc32(data) != i.CRC:
            raise SceneFileError(f"{self.source}: {i.filename!r} is corrupt or truncated (it does not inflate to "
                                 f"its {i.file_size:,} bytes and CRC-32)")
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


