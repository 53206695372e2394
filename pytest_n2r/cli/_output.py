"""Checks every ``n2r`` command runs on its output paths before doing any work.

An output may replace an existing file only when that file is the command's own kind of output (a scene
file for ``n2r fit``, a PNG for ``n2r render`` ...), never one of the command's inputs, and never anything
else unless ``--force`` asks for it; its folder must exist (or be creatable) and be writable. Files are
then written atomically (:mod:`pytest_n2r.data.atomic`), so an interrupted command leaves the old file.
"""

from __future__ import annotations

import codecs
import contextlib
import json
import os
import sys
import zipfile
from collections.abc import Callable, Iterable, Iterator
from dataclasses import dataclass
from pathlib import Path

from ..data.atomic import unwritable_reason
from ..errors import InvalidArgument

__all__ = [
    "FORCE_HELP",
    "NPY",
    "PNG",
    "POSES_JSON",
    "SCENE",
    "OutputKind",
    "as_text",
    "check_output",
    "check_output_dir",
    "printable",
    "tolerant_streams",
]

FORCE_HELP = "replace an existing output even when it is not what this command writes"


def _has_magic(magic: bytes) -> Callable[[Path], bool]:
    def sniff(path: Path) -> bool:
        with open(path, "rb") as fh:
            return fh.read(len(magic)) == magic
    return sniff


def _is_scene_zip(path: Path) -> bool:
    try:
        with zipfile.ZipFile(path) as archive:
            return "scene.json" in archive.namelist()
    except (zipfile.BadZipFile, OSError, NotImplementedError, RuntimeError):  # "zip file version 9.1": not ours
        return False


def _json_object(path: Path) -> dict | None:
    """The JSON object in the file at ``path``; ``None`` when it is over 256 MiB, not JSON or not an object."""
    if path.stat().st_size > 256 * 2**20:
        return None
    try:
        data = json.loads(path.read_bytes())
    except (ValueError, RecursionError):
        return None
    return data if isinstance(data, dict) else None


@dataclass(frozen=True)
class OutputKind:
    """What a command writes: ``noun`` for messages, the file name ``suffixes`` it accepts and ``sniff``,
    which tells whether an existing file is one (then replacing it needs no ``--force``)."""

    noun: str
    suffixes: tuple[str, ...]
    sniff: Callable[[Path], bool]

    def owns(self, path: Path) -> bool:
        try:
            return path.is_file() and self.sniff(path)
        except OSError:
            return False


SCENE = OutputKind("a .n2r scene file", (".n2r",), _is_scene_zip)
PNG = OutputKind("a PNG image", (".png",), _has_magic(b"\x89PNG\r\n\x1a\n"))
NPY = OutputKind("a NumPy .npy array", (".npy",), _has_magic(b"\x93NUMPY"))
def _poses_json(path: Path) -> bool:
    """A transforms.json ``n2r poses -o`` wrote: its ``n2r`` block names the poses' ``source`` (the block alone is
    not enough: any file n2r writes of turned photos records its ``pixels`` there, a phone capture's too)."""
    block = (_json_object(path) or {}).get("n2r")
    return isinstance(block, dict) and "source" in block


#: ``n2r poses -o``: a transforms.json it wrote before carries its ``n2r`` block with the poses' source; any other
#: one (the capture's own, nerfstudio's, a phone capture's) is the user's data.
POSES_JSON = OutputKind("a transforms.json written by `n2r poses`", (".json",), _poses_json)


def _same_file(a: Path, b: Path) -> bool:
    try:
        if a.exists() and b.exists():
            return os.path.samefile(a, b)
    except OSError:
        pass
    return a.resolve() == b.resolve()


def _check_folder(folder: Path, option: str, shown: Path) -> None:
    """The folder an output goes into must be a folder we can write into, or be creatable."""
    reason = unwritable_reason(folder)
    if reason is not None:
        raise InvalidArgument(f"{option} {shown}: {reason}; choose a writable folder (checked before any work, so "
                              "nothing is lost)")


def check_output(path: Path, kind: OutputKind, *, option: str = "-o", inputs: Iterable[Path] = (),
                 force: bool = False) -> Path:
    """``path`` if ``kind`` may be written there; otherwise an :class:`InvalidArgument` naming ``option``,
    the path, what is wrong and the fix. ``inputs`` are the command's input files (never overwritten)."""
    path = Path(path)
    if not str(path).strip():
        raise InvalidArgument(f"{option}: the output path is empty; expected {kind.noun} to write")
    if path.is_dir():
        raise InvalidArgument(f"{option} {path}: is a folder; expected the path of {kind.noun} to write "
                              f"(e.g. {path / ('out' + kind.suffixes[0])})")
    if path.suffix.lower() not in kind.suffixes:
        raise InvalidArgument(f"{option} {path}: expected {kind.noun}, a name ending in "
                              f"{' or '.join(kind.suffixes)} (e.g. {path.with_suffix(kind.suffixes[0]).name})")
    for source in inputs:
        if _same_file(path, Path(source)):
            raise InvalidArgument(f"{option} {path}: is this command's input {source}; writing there would "
                                  "destroy it; choose another output name")
    if (path.exists() or path.is_symlink()) and not force and not kind.owns(path):
        raise InvalidArgument(f"{option} {path}: exists and is not {kind.noun}, so writing would destroy it; "
                              "choose another name, or pass --force to replace it")
    _check_folder(path.parent, option, path)
    return path


def check_output_dir(path: Path, owned: Callable[[Path], bool], noun: str, *, option: str = "-o",
                     force: bool = False) -> Path:
    """``path`` if this command may write its files into that folder: missing, empty, or holding an earlier
    output of the same command (``owned(folder)``); anything else needs ``force``."""
    path = Path(path)
    if not str(path).strip():
        raise InvalidArgument(f"{option}: the output folder is empty; expected a folder for {noun}")
    if path.exists() and not path.is_dir():
        raise InvalidArgument(f"{option} {path}: is a file; expected a folder for {noun}")
    if path.is_dir() and any(path.iterdir()) and not force and not owned(path):
        raise InvalidArgument(f"{option} {path}: the folder holds other files, and {noun} would be written "
                              "among them (replacing any of the same name); choose an empty or new folder, or "
                              "pass --force")
    _check_folder(path, option, path)
    return path


def as_text(text: object) -> str:
    """``str(text)`` with no lone surrogates, for text a command keeps in a file (a JSON record): the bytes of a
    file name that are UTF-8 as their characters, the others (which Python keeps as lone surrogates) as backslash
    escapes (``\\xff``).

    >>> as_text("bad" + chr(0xDCFF) + ".png"), as_text("caf" + chr(0xDCC3) + chr(0xDCA9))
    ('bad\\\\xff.png', 'café')
    """
    text = str(text)
    try:
        return text.encode("utf-8", "surrogateescape").decode("utf-8", "backslashreplace")
    except UnicodeEncodeError:  # a surrogate surrogateescape did not make
        return text.encode("utf-8", "backslashreplace").decode("utf-8")


def printable(text: object) -> str:
    """``str(text)`` as any stdout can print it: the bytes of a file name that are not UTF-8 (which Python keeps as
    lone surrogates) as backslash escapes (``\\xff``). Every path a command prints goes through it, so printing a
    name it wrote cannot fail after the work is done.

    Where the file system's encoding is not UTF-8 (an ASCII locale: ``LC_ALL=C`` with Python's UTF-8 mode off,
    ``PYTHONUTF8=0``), a name's bytes that encoding does not decode stay lone surrogates: the output streams
    :func:`tolerant_streams` set up write them as the very bytes where the stream takes bytes of that encoding (a
    surrogateescape stdout), else as ``\\xc3`` escapes.

    >>> printable("bad" + chr(0xDCFF) + ".png"), printable(Path("ok.png"))
    ('bad\\\\xff.png', 'ok.png')
    """
    text = str(text)
    if _is_utf8(sys.getfilesystemencoding()):
        return as_text(text)
    return "".join(_escape(c) if 0xD800 <= ord(c) <= 0xDFFF and not _is_byte(c) else c for c in text)


# Output streams -------------------------------------------------------------------------------------------------
#
# Convention: a character a stream's encoding cannot write is written as Python's backslash escape of it (``\xb3``
# for ``³``, ``\u03c4`` for ``τ``); a lone surrogate U+DC80..U+DCFF (a byte of a file name the file system's
# encoding did not decode) is written as that byte where the stream takes such bytes, else as ``\xNN``.

#: The error handlers :func:`tolerant_streams` gives ``sys.stdout`` and ``sys.stderr``.
ESCAPE, BYTES = "n2r.escape", "n2r.bytes"


def _is_utf8(encoding: str | None) -> bool:
    return codecs.lookup(encoding or "ascii").name == "utf-8"


def _is_byte(char: str) -> bool:
    """Whether ``char`` is a lone surrogate U+DC80..U+DCFF: the byte ``surrogateescape`` could not decode."""
    return 0xDC80 <= ord(char) <= 0xDCFF


def _escape(char: str) -> str:
    """``char`` as a backslash escape; a surrogate-escaped byte as the byte's (``\\xff``, not ``\\udcff``)."""
    if _is_byte(char):
        return f"\\x{ord(char) - 0xDC00:02x}"
    return char.encode("ascii", "backslashreplace").decode("ascii")


def _escape_errors(exc: UnicodeError) -> tuple[str, int]:
    if not isinstance(exc, UnicodeEncodeError):
        raise exc
    return "".join(_escape(c) for c in exc.object[exc.start:exc.end]), exc.end


def _bytes_errors(exc: UnicodeError) -> tuple[str | bytes, int]:
    """Surrogate-escaped bytes as those bytes, anything else as escapes: one run of either kind per call (the
    encoder calls again for the rest)."""
    if not isinstance(exc, UnicodeEncodeError):
        raise exc
    part = exc.object[exc.start:exc.end]
    run = next((i for i, c in enumerate(part) if _is_byte(c) != _is_byte(part[0])), len(part))
    if _is_byte(part[0]):
        return bytes(ord(c) - 0xDC00 for c in part[:run]), exc.start + run
    return "".join(map(_escape, part[:run])), exc.start + run


codecs.register_error(ESCAPE, _escape_errors)
codecs.register_error(BYTES, _bytes_errors)


@contextlib.contextmanager
def tolerant_streams() -> Iterator[None]:
    """Within it, ``sys.stdout`` and ``sys.stderr`` write anything, in their own encoding: what it cannot encode as
    backslash escapes (see the convention above), so that no command fails for its output, and none after its work.
    A stream that takes a file name's raw bytes (``errors="surrogateescape"``, or the file system's own encoding when
    that is not UTF-8) keeps writing them as they are. Streams that are not text files are left as they are; each is
    given back its own handler at the end (``main()`` called from a user's script or a test leaves them as found)."""
    changed = []
    for name in ("stdout", "stderr"):
        stream = getattr(sys, name, None)
        errors, encoding = getattr(stream, "errors", None), getattr(stream, "encoding", None)
        if stream is None or errors in (ESCAPE, BYTES) or not hasattr(stream, "reconfigure"):
            continue
        try:
            raw = errors == "surrogateescape" or (
                not _is_utf8(encoding) and codecs.lookup(encoding or "").name == codecs.lookup(
                    sys.getfilesystemencoding()).name)
            stream.reconfigure(errors=BYTES if raw else ESCAPE)
        except (LookupError, OSError, ValueError):  # an unknown encoding, a closed stream: leave it
            continue
        changed.append((stream, errors))
    try:
        yield
    finally:
        for stream, errors in changed:
            try:
                stream.reconfigure(errors=errors)
            except (OSError, ValueError):  # closed, or a broken pipe's flush: nothing more is written to it
                pass
