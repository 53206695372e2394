"""Which files of a folder are a capture's photos: the images directly inside it by their suffix, the files left
alone, and the photos in its subfolders (which structure from motion does not read), for the errors and warnings
that name them. :mod:`.images` reads them."""

from __future__ import annotations

import os
from pathlib import Path

from ..errors import IngestError

__all__ = ["IMAGE_SUFFIXES", "HEIF_SUFFIXES", "list_images", "other_files", "images_in_subfolders", "subfolder_hint"]

#: File suffixes of HEIF photos (``.hif``: some cameras' name for the same format), decoded by pillow-heif.
HEIF_SUFFIXES: tuple[str, ...] = (".heic", ".heif", ".hif")
#: File suffixes treated as images when a folder is listed (compared lower-case).
IMAGE_SUFFIXES: tuple[str, ...] = (
    ".jpg", ".jpeg", ".jpe", ".jfif", ".png", ".tif", ".tiff", ".bmp", ".webp", ".ppm", ".pgm", *HEIF_SUFFIXES,
)


def list_images(folder: str | os.PathLike) -> list[Path]:
    """The image files directly inside ``folder``, sorted by name (hidden files ignored).

    Raises :class:`IngestError` naming the folder when it does not exist, is not a folder, or holds
    no file with an image suffix (:data:`IMAGE_SUFFIXES`); then also the subfolders that do hold some
    (:func:`subfolder_hint`), as a phone's ``DCIM/100APPLE`` does.
    """
    folder = Path(folder)
    if not folder.exists():
        raise IngestError(f"images folder {str(folder)!r} does not exist")
    if not folder.is_dir():
        raise IngestError(f"{str(folder)!r} is not a folder; expected a folder of images")
    files = _images_in(folder)
    if not files:
        hint = subfolder_hint(folder)
        expected = f" itself; {hint}" if hint else f"; expected files ending in {', '.join(IMAGE_SUFFIXES)}"
        raise IngestError(f"images folder {str(folder)!r} holds no images{expected}")
    return files


def _images_in(folder: Path) -> list[Path]:
    """The image files directly inside ``folder`` (:func:`_is_image`), sorted by name."""
    return sorted(p for p in folder.iterdir() if _is_image(p))


def other_files(folder: str | os.PathLike) -> int:
    """How many files directly inside ``folder`` (hidden ones aside) are not images by their suffix: left alone."""
    try:
        return sum(p.is_file() and not p.name.startswith(".") and not _is_image(p) for p in Path(folder).iterdir())
    except OSError:
        return 0


def _is_image(path: Path) -> bool:
    """Whether ``path`` is an image file by its suffix (hidden files are not)."""
    return path.is_file() and not path.name.startswith(".") and path.suffix.lower() in IMAGE_SUFFIXES


#: How deep :func:`images_in_subfolders` looks below a folder (``DCIM/100APPLE`` is 2), and at most how many
#: folders it opens, so that a home folder given by mistake costs a moment, not a walk of the whole disk.
SUBFOLDER_DEPTH = 3
SUBFOLDER_LIMIT = 1000


def images_in_subfolders(folder: str | os.PathLike) -> list[tuple[str, int]]:
    """``(subfolder, image count)`` for every subfolder of ``folder`` (down to :data:`SUBFOLDER_DEPTH` levels, hidden
    ones and links skipped: a link back to ``folder`` would count its photos again, at most :data:`SUBFOLDER_LIMIT`
    opened) holding images directly; the path relative to ``folder`` in ``/`` form, sorted by path. ``folder``
    itself is not counted."""
    folder = Path(folder)
    found: list[tuple[str, int]] = []
    queue, opened = [(folder, 0)], 0
    while queue and opened < SUBFOLDER_LIMIT:
        current, depth = queue.pop(0)
        opened += 1
        try:
            entries = sorted(current.iterdir())  # listed once: its images counted, its subfolders queued
            count = sum(_is_image(p) for p in entries) if current != folder else 0
        except OSError:  # no permission, gone meanwhile
            continue
        if count:
            found.append((current.relative_to(folder).as_posix(), count))
        if depth < SUBFOLDER_DEPTH:
            queue += [(p, depth + 1) for p in entries
                      if not p.name.startswith(".") and not p.is_symlink() and p.is_dir()]
    return sorted(found)


def subfolder_hint(folder: str | os.PathLike, own: int = 0) -> str:
    """What to say of the images in ``folder``'s subfolders (:func:`images_in_subfolders`), which structure from
    motion does not read, when ``folder`` itself holds ``own`` images: ``""`` when there are none."""
    below = images_in_subfolders(folder)
    if not below:
        return ""
    if len(below) == 1:
        (name, count), = below
        listing = f"its subfolder {name} holds {count} image{'s' * (count != 1)}"
        advice = "pass that folder"
    else:
        listing = "its subfolders hold images: " + ", ".join(f"{name} ({count})" for name, count in below[:5])
        listing += f" and {len(below) - 5} more folders" if len(below) > 5 else ""
        advice = "pass the folder of one capture"
    if own:
        return (f"{listing}, not read (only the photos directly in the folder are): put the capture's photos in one "
                "folder")
    return f"{listing}: {advice}"
