"""Listing and reading the photos of a capture.

Convention
----------
Every image leaves this module as an ``H x W x 3`` ``uint8`` array in **RGB** order (OpenCV reads BGR;
the conversion happens here and nowhere else). The photo's orientation is applied, so the array is upright
as a person would view the photo: a JPEG's EXIF orientation tag (as OpenCV's decoder applies it); for a HEIF photo
(``.heic``, what iPhones store by default), the container's own rotation and mirror (``irot``, ``imir``), as the
HEIF standard and libheif do, since there an EXIF tag only describes them. A file is read as HEIF by its
content (an ISO media ``ftyp`` box), not by its name. Grayscale is repeated to three channels, an alpha channel is
dropped (the colour under it is kept), 16-bit images are scaled by ``255 / 65535`` and floating-point
images are clipped to ``[0, 1]`` then scaled by 255.
"""

from __future__ import annotations

import os
import warnings
from collections.abc import Iterator, Sequence
from contextlib import contextmanager
from pathlib import Path

import numpy as np

from ..errors import IngestError

__all__ = ["IMAGE_SUFFIXES", "list_images", "read_image", "read_image_size", "to_rgb8", "resize_image",
           "iter_readable"]

#: File suffixes of HEIF photos (``.hif``: some cameras' name for the same format), decoded by pillow-heif.
HEIF_SUFFIXES: tuple[str, ...] = (".heic", ".heif", ".hif")
#: File suffixes treated as images when a folder is listed (compared lower-case).
IMAGE_SUFFIXES: tuple[str, ...] = (
    ".jpg", ".jpeg", ".png", ".tif", ".tiff", ".bmp", ".webp", ".ppm", ".pgm", *HEIF_SUFFIXES,
)


def list_images(folder: str | os.PathLike) -> list[Path]:
    """The image files directly inside ``folder``, sorted by name (hidden files ignored).

    Raises :class:`IngestError` naming the folder when it does not exist, is not a folder, or holds
    no file with an image suffix (:data:`IMAGE_SUFFIXES`).
    """
    folder = Path(folder)
    if not folder.exists():
        raise IngestError(f"images folder {str(folder)!r} does not exist")
    if not folder.is_dir():
        raise IngestError(f"{str(folder)!r} is not a folder; expected a folder of images")
    files = sorted(
        p for p in folder.iterdir()
        if p.is_file() and not p.name.startswith(".") and p.suffix.lower() in IMAGE_SUFFIXES
    )
    if not files:
        raise IngestError(
            f"images folder {str(folder)!r} holds no images; expected files ending in {', '.join(IMAGE_SUFFIXES)}"
        )
    return files


def to_rgb8(image: np.ndarray, bgr: bool = True) -> np.ndarray:
    """Convert a decoded image (gray, gray+alpha, 3 or 4 channels; uint8, uint16 or float) to RGB uint8.

    ``bgr`` says the colour channels are in OpenCV's BGR(A) order.
    """
    import cv2

    img = np.asarray(image)
    if img.ndim == 2:
        img = img[:, :, None]
    if img.ndim != 3 or img.shape[2] not in (1, 2, 3, 4):
        raise IngestError(f"image of shape {img.shape} is not gray, gray+alpha, RGB or RGBA")
    if img.dtype == np.uint8:
        pass
    elif img.dtype == np.uint16:
        img = ((img.astype(np.uint32) * 255 + 32767) // 65535).astype(np.uint8)
    elif img.dtype.kind == "f":
        img = np.round(np.clip(np.nan_to_num(img, nan=0.0), 0.0, 1.0) * 255.0).astype(np.uint8)
    elif img.dtype.kind in "iu":
        info = np.iinfo(img.dtype)
        img = np.round(np.clip(img.astype(np.float64), 0, info.max) * (255.0 / info.max)).astype(np.uint8)
    else:
        raise IngestError(f"image of dtype {img.dtype} cannot be converted to 8-bit RGB")
    channels = img.shape[2]
    if channels in (1, 2):  # gray (+ alpha)
        return np.ascontiguousarray(np.repeat(img[:, :, :1], 3, axis=2))
    img = img[:, :, :3]
    return np.ascontiguousarray(cv2.cvtColor(img, cv2.COLOR_BGR2RGB) if bgr else img)


def read_image(path: str | os.PathLike) -> np.ndarray:
    """Read one photo as an upright ``H x W x 3`` RGB uint8 array (see the module's *Convention*).

    Raises :class:`IngestError` naming the file when it is missing or cannot be decoded.
    """
    import cv2

    path = Path(path)
    if not path.is_file():
        raise IngestError(f"image file {str(path)!r} does not exist")
    if _is_iso_media(_head(path)):
        return to_rgb8(_decode_heif(path), bgr=False)
    try:
        data = np.fromfile(path, dtype=np.uint8)
    except OSError as exc:  # no permission, a device gone
        raise IngestError(f"image file {str(path)!r} cannot be read: {exc.strerror or exc}") from exc
    # ANYDEPTH|ANYCOLOR keeps 16-bit and gray data; unlike IMREAD_UNCHANGED it applies EXIF orientation.
    img = cv2.imdecode(data, cv2.IMREAD_ANYDEPTH | cv2.IMREAD_ANYCOLOR) if data.size else None
    if img is None:
        raise IngestError(f"image file {str(path)!r} cannot be decoded as an image (corrupt or not an image)")
    return to_rgb8(img)


def read_image_size(path: str | os.PathLike) -> tuple[int, int]:
    """``(width, height)`` of an upright image without decoding its pixels when possible (orientation applied)."""
    from PIL import Image, UnidentifiedImageError

    path = Path(path)
    if _is_iso_media(_head(path)):
        return _heif_size(path)
    try:
        with Image.open(path) as im:
            width, height = im.size
            orientation = im.getexif().get(0x0112, 1)
    except (OSError, UnidentifiedImageError):
        height, width = read_image(path).shape[:2]
        return width, height
    return (height, width) if orientation in (5, 6, 7, 8) else (width, height)


def _head(path: Path) -> bytes:
    """The first 12 bytes of the file at ``path`` (fewer when it is shorter; none when it cannot be read)."""
    try:
        with open(path, "rb") as f:
            return f.read(12)
    except OSError:
        return b""  # the decoder that follows names the file


def _is_iso_media(head: bytes) -> bool:
    """Whether a file's first 12 bytes open an ISO base media file (its ``ftyp`` box), as HEIF photos do."""
    return head[4:8] == b"ftyp"


@contextmanager
def _heif_errors(path: Path) -> Iterator[None]:
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


def _decode_heif(path: Path) -> np.ndarray:
    """The HEIF photo at ``path``, upright (libheif applies ``irot`` / ``imir``), in an array of its own.

    libheif converts HDR (10- and 12-bit) colour photos to 8 bits; a 16-bit result is scaled by :func:`to_rgb8`.
    """
    import pillow_heif

    with _heif_errors(path):
        return np.array(pillow_heif.open_heif(path, convert_hdr_to_8bit=True))  # a copy: pillow-heif's is read-only


def _heif_size(path: Path) -> tuple[int, int]:
    """Upright ``(width, height)`` of the HEIF photo at ``path``, read from its container without decoding."""
    import pillow_heif

    with _heif_errors(path):
        return pillow_heif.open_heif(path).size


def resize_image(image: np.ndarray, width: int, height: int) -> np.ndarray:
    """Resize an RGB image to ``width x height`` (area averaging when shrinking, bilinear when growing)."""
    import cv2

    if image.shape[1] == width and image.shape[0] == height:
        return image
    shrink = width < image.shape[1] and height < image.shape[0]
    return cv2.resize(image, (width, height), interpolation=cv2.INTER_AREA if shrink else cv2.INTER_LINEAR)


def iter_readable(paths: Sequence[Path], skipped: list[tuple[str, str]]) -> Iterator[tuple[Path, np.ndarray]]:
    """Yield ``(path, image)`` for every decodable file, one at a time (memory stays one image).

    A file that cannot be read is skipped with a warning naming it and recorded in ``skipped`` as
    ``(file name, reason)``; the caller decides how many readable images are enough.
    """
    for path in paths:
        try:
            image = read_image(path)
        except IngestError as exc:
            warnings.warn(f"skipping {path}: {exc}", stacklevel=3)
            skipped.append((Path(path).name, str(exc)))
            continue
        yield Path(path), image
