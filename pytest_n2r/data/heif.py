"""HEIF photos (``.heic``, what iPhones store by default), decoded by pillow-heif (libheif): told by their content,
read upright or as stored, their size read without decoding (see :mod:`.images`' *Convention*)."""

from __future__ import annotations

from collections.abc import Iterator
from contextlib import contextmanager
from pathlib import Path

import numpy as np

from ..errors import IngestError
from .nclx import nclx_icc

__all__ = ["is_iso_media", "decode_heif", "heif_size", "heif_turn", "heif_errors"]


def is_iso_media(head: bytes) -> bool:
    """Whether a file's first 12 bytes open an ISO base media file (its ``ftyp`` box), as HEIF photos do."""
    return head[4:8] == b"ftyp"


@contextmanager
def heif_errors(path: Path) -> Iterator[None]:
    """Turn pillow-heif's errors on a corrupt or truncated file into an :class:`IngestError` naming it."""
    try:
        yield
    # what pillow-heif raises on bad input (its own Pillow plugin catches the same): libheif's errors as ValueError,
    # RuntimeError, EOFError (truncated) or SyntaxError (an unsupported file type, an AV1 payload); IndexError when
    # the container holds no image
    except (ValueError, RuntimeError, OSError, EOFError, SyntaxError, IndexError) as exc:
        raise IngestError(
            f"image file {str(path)!r} cannot be decoded as a HEIF photo (corrupt, truncated or not a photo): {exc}"
        ) from exc


def decode_heif(path: Path, oriented: bool = True) -> tuple[np.ndarray, bytes | None]:
    """The HEIF photo at ``path``, upright (libheif applies ``irot`` / ``imir``) or, with ``oriented=False``, with
    those undone (last applied, first undone), in an array of its own; and its ICC profile: the one it embeds, else
    the one its ``nclx`` colour box states (:func:`.nclx.nclx_icc`), ``None`` for sRGB.

    libheif converts HDR (10- and 12-bit) colour photos to 8 bits; a 16-bit result is scaled by :func:`to_rgb8`.
    """
    import pillow_heif

    with heif_errors(path):
        heif = pillow_heif.open_heif(path, convert_hdr_to_8bit=True)
        image = np.array(heif)  # a copy: pillow-heif's is read-only
    icc = heif.info.get("icc_profile") or nclx_icc(heif.info.get("nclx_profile"), path)
    if oriented:
        return image, icc
    # the primary image's transformative properties in the order libheif applied them (pillow-heif keeps them on its
    # decoded image, not yet under a public name)
    for name, *values in reversed(_transformations(path, heif)):
        if name == "imir":  # libheif's mirror direction: 0 flips top and bottom, 1 left and right
            image = image[::-1] if values[0] == 0 else image[:, ::-1]
        elif name == "irot":  # degrees anticlockwise
            image = np.rot90(image, -values[0] // 90)
    return np.ascontiguousarray(image), icc


def _transformations(path: Path, heif) -> list:
    """The primary image's transformative properties (``("irot", degrees anticlockwise)``, ``("imir", axis)``) in
    the order libheif applies them (pillow-heif keeps them on its image, not yet under a public name)."""
    transformations = getattr(getattr(heif[heif.primary_index], "_c_image", None), "transformations", None)
    if transformations is None:
        raise IngestError(f"image file {str(path)!r}: this pillow-heif does not tell the HEIF photo's rotation and "
                          "mirror, so its pixels cannot be read as stored (as COLMAP reads them); upgrade pillow-heif")
    return list(transformations)


def heif_turn(path: Path) -> tuple[bool, bool]:
    """Whether the HEIF photo at ``path`` is shown otherwise than stored (an ``irot`` or ``imir``), and whether a
    quarter turn swaps its sides, read from its container without decoding."""
    import pillow_heif

    with heif_errors(path):
        steps = _transformations(path, pillow_heif.open_heif(path))
    degrees = sum(values[0] for name, *values in steps if name == "irot") % 360
    return degrees != 0 or any(name == "imir" for name, *_ in steps), degrees % 180 == 90


def heif_size(path: Path) -> tuple[int, int]:
    """Upright ``(width, height)`` of the HEIF photo at ``path``, read from its container without decoding."""
    import pillow_heif

    with heif_errors(path):
        return pillow_heif.open_heif(path).size
