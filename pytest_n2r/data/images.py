"""Reading the photos of a capture (:mod:`.listing` finds them; its names are re-exported here).

Convention
----------
Every image leaves this module as an ``H x W x 3`` ``uint8`` array in **RGB** order (OpenCV reads BGR;
the conversion happens here and nowhere else). The photo's orientation is applied, so the array is upright
as a person would view the photo: a JPEG's EXIF orientation tag (the one Pillow reads, applied here to the pixels
OpenCV decodes as stored, so that :func:`read_image_size` agrees with them); for a HEIF photo
(``.heic``, what iPhones store by default), the container's own rotation and mirror (``irot``, ``imir``), as the
HEIF standard and libheif do, since there an EXIF tag only describes them. A file is read as HEIF by its
content (an ISO media ``ftyp`` box), not by its name. Grayscale is repeated to three channels, an alpha channel is
dropped (the colour under it is kept, warned of), 16-bit images are scaled by ``255 / 65535`` and floating-point
images are clipped to ``[0, 1]`` then scaled by 255; wider integers (a 32-bit TIFF) are refused. An embedded colour
profile other than sRGB is converted to sRGB (:mod:`.colour`).

``read_image(path, oriented=False)`` reads the pixels **as stored** instead, as COLMAP does (its cameras and poses
describe those): no EXIF orientation (OpenCV's ``IMREAD_IGNORE_ORIENTATION``; OpenCV's TIFF decoder orients
whatever the flags, so a TIFF's tag is undone afterwards) and, for a HEIF photo, its ``irot`` / ``imir`` undone (COLMAP
reads through OpenImageIO with ``oiio:reorient=0``, which has libheif ignore them); a HEIF ``clap`` crop stays.
"""

from __future__ import annotations

import os
import threading
import warnings
from collections.abc import Iterator, Sequence
from contextlib import contextmanager
from pathlib import Path
from typing import TYPE_CHECKING, cast

import numpy as np

from ..errors import IngestError
from .colour import has_alpha, to_srgb, warn_if_transparent
from .heif import decode_heif, heif_size, heif_turn, is_iso_media
from .listing import IMAGE_SUFFIXES, images_in_subfolders, list_images, other_files, subfolder_hint

if TYPE_CHECKING:
    import PIL.Image
    import PIL.TiffImagePlugin

__all__ = ["IMAGE_SUFFIXES", "list_images", "read_image", "read_image_size", "read_turn", "to_rgb8",
           "resize_image", "iter_readable", "images_in_subfolders", "subfolder_hint", "other_files"]

#: The largest image side (pixels) read: :data:`pytest_n2r.render.size.MAX_SIDE` (``data`` sits below ``render``).
MAX_IMAGE_SIDE = 16384


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
    if img.dtype != np.uint8 and img.shape[2] in (2, 4):  # alpha dropped before the depth is converted
        img = img[:, :, :-1]
    if img.dtype == np.uint8:
        pass
    elif img.dtype == np.uint16:
        img = ((img.astype(np.uint32) * 255 + 32767) // 65535).astype(np.uint8)
    elif img.dtype.kind == "f":
        img = np.round(np.clip(np.nan_to_num(img, nan=0.0), 0.0, 1.0) * 255.0).astype(np.uint8)
    elif img.dtype.kind in "iu" and img.dtype.itemsize <= 2:
        info = np.iinfo(img.dtype)
        img = np.round(np.clip(img.astype(np.float64), 0, info.max) * (255.0 / info.max)).astype(np.uint8)
    else:
        raise IngestError(f"image of dtype {img.dtype} cannot be converted to 8-bit RGB; expected 8- or 16-bit "
                          "integers, or floating point in [0, 1]")
    channels = img.shape[2]
    if channels in (1, 2):  # gray (+ alpha)
        return np.ascontiguousarray(np.repeat(img[:, :, :1], 3, axis=2))
    if not bgr:
        return np.ascontiguousarray(img[:, :, :3])
    return np.ascontiguousarray(cv2.cvtColor(img, cv2.COLOR_BGRA2RGB if channels == 4 else cv2.COLOR_BGR2RGB))


def read_image(path: str | os.PathLike, *, oriented: bool = True) -> np.ndarray:
    """Read one photo as an ``H x W x 3`` RGB uint8 array: upright, or with ``oriented=False`` its pixels as stored
    (see the module's *Convention*).

    Raises :class:`IngestError` naming the file when it is missing or cannot be decoded.
    """
    import cv2

    path = Path(path)
    if not path.is_file():
        raise IngestError(f"image file {str(path)!r} does not exist")
    head = _head(path)
    if is_iso_media(head):
        _check_sides(path, *heif_size(path))
        image, icc = decode_heif(path, oriented)
        if image.ndim == 3 and image.shape[2] == 4:
            warn_if_transparent(path, image[:, :, 3])
        return to_srgb(_named(path, to_rgb8, image, bgr=False), icc, path)
    orientation, icc, alpha = _stored_facts(path)  # refuses a header claiming more than MAX_IMAGE_SIDE a side first
    try:
        data = np.fromfile(path, dtype=np.uint8)
    except OSError as exc:  # no permission, a device gone
        raise IngestError(f"image file {str(path)!r} cannot be read: {exc.strerror or exc}") from exc
    # ANYDEPTH|ANYCOLOR keeps 16-bit and gray data; the orientation applied is the tag read_image_size reads (OpenCV
    # may read another: a JPEG with two EXIF segments), so OpenCV is told to ignore it, which its TIFF decoder does not
    # heed: there it is the TIFF's own tag, and undone below when not oriented.
    flags = cv2.IMREAD_ANYDEPTH | cv2.IMREAD_ANYCOLOR | cv2.IMREAD_IGNORE_ORIENTATION
    if alpha:  # decoded once, with the alpha (a transparent colour or palette entry made one) tested below and then
        flags = cv2.IMREAD_UNCHANGED  # dropped by to_rgb8: the same depth and colours as above, no EXIF orientation
    if not data.size:
        raise IngestError(f"image file {str(path)!r} is empty (0 bytes: a copy that did not finish, or a cloud photo "
                          "not downloaded to this device)")
    with _quiet_opencv():
        img = cv2.imdecode(data, flags)
    if img is None:
        kind = _cut_short(head, data)
        why = f"a {kind} cut short: an interrupted copy?" if kind else "corrupt or not an image"
        raise IngestError(f"image file {str(path)!r} cannot be decoded as an image ({why})")
    if _is_tiff(head) != oriented:  # applying a tag undoes its inverse: 6 and 8 swap, the others undo themselves
        img = _UNDO_ORIENTATION[orientation if _is_tiff(head) else {6: 8, 8: 6}.get(orientation, orientation)](img)
    if alpha:  # a transparent gray level, or a TIFF's gray + alpha, come without it: Pillow reads it (rare)
        warn_if_transparent(path, img[:, :, -1] if img.ndim == 3 and img.shape[2] in (2, 4) else None)
    return to_srgb(_named(path, to_rgb8, img), icc, path)


def _named(path: Path, convert, image: np.ndarray, **kwargs) -> np.ndarray:
    """``convert(image, **kwargs)``, its :class:`IngestError` naming the file at ``path``."""
    try:
        return convert(image, **kwargs)
    except IngestError as exc:
        raise IngestError(f"image file {str(path)!r}: {exc}") from None


def _cut_short(head: bytes, data: np.ndarray) -> str:
    """``"JPEG"``, ``"PNG"`` or ``"WebP"`` when the file's bytes are such a file missing its end (a JPEG's end marker,
    a PNG's ``IEND`` chunk, the length a WebP's RIFF header claims), else ``""``."""
    if head[:2] == b"\xff\xd8" and b"\xff\xd9" not in data[-1024:].tobytes():
        return "JPEG"
    if head[:8] == b"\x89PNG\r\n\x1a\n" and b"IEND" not in data[-12:].tobytes():
        return "PNG"
    if head[:4] == b"RIFF" and head[8:12] == b"WEBP" and int.from_bytes(head[4:8], "little") + 8 > data.size:
        return "WebP"
    return ""


@contextmanager
def _quiet_opencv() -> Iterator[None]:
    """OpenCV's own log (its TIFF decoder's complaints on a broken file) kept off stderr: the error names the file.
    The level is process-wide: the first of overlapping readers silences it, the last puts it back. OpenCV before
    4.13 has no ``cv2.utils.logging`` to set it with: there its log is left as it is."""
    import cv2

    log = getattr(cv2.utils, "logging", None)
    if log is None:
        yield
        return
    with _OPENCV_QUIET:
        if not _quiet_readers:
            _quiet_readers.append(log.getLogLevel())
            log.setLogLevel(log.LOG_LEVEL_SILENT)
        _quiet_readers.append(None)
    try:
        yield
    finally:
        with _OPENCV_QUIET:
            _quiet_readers.pop()
            if len(_quiet_readers) == 1:
                log.setLogLevel(_quiet_readers.pop())


#: Held while OpenCV's log level is changed; the level it had, then one entry per reader within :func:`_quiet_opencv`.
_OPENCV_QUIET = threading.Lock()
_quiet_readers: list[int | None] = []


def read_image_size(path: str | os.PathLike) -> tuple[int, int]:
    """``(width, height)`` of the upright image, as :func:`read_image` decodes it, without decoding its pixels when
    possible."""
    from PIL import UnidentifiedImageError

    path = Path(path)
    head = _head(path)
    if is_iso_media(head):
        return _check_sides(path, *heif_size(path))
    try:
        with _header(path) as im:
            # Pillow reports a TIFF's size upright already (it orients TIFFs on loading); its tags hold the stored one
            tags = cast("PIL.TiffImagePlugin.TiffImageFile", im).tag_v2 if _is_tiff(head) else None  # TIFF bytes
            width, height = (tags[256], tags[257]) if tags is not None else im.size
            orientation = _exif_orientation(im, path)
    except (OSError, UnidentifiedImageError, KeyError):
        height, width = read_image(path).shape[:2]
        return width, height
    _check_sides(path, width, height)
    return (height, width) if orientation in (5, 6, 7, 8) else (width, height)


@contextmanager
def _header(path: Path) -> Iterator[PIL.Image.Image]:
    """Pillow's reading of the file at ``path``, its pixels not decoded.

    Pillow refuses headers past about 179 MP (twice its ``MAX_IMAGE_PIXELS``), a guard against decoding bombs; a
    200 MP phone photo (16 320 x 12 240) is past it yet within :data:`MAX_IMAGE_SIDE` a side, which
    :func:`_check_sides` holds. So a refused header is read again with the limit at ``MAX_IMAGE_SIDE ** 2`` (set
    under a lock and put back on every path), and only a header beyond that is an :class:`IngestError` naming the
    file. The limit is Pillow's, process-wide: the lock keeps two readers here from restoring each other's value,
    but while it is raised (the reading of one header) another thread decoding with Pillow has the raised guard.
    """
    from PIL import Image

    with warnings.catch_warnings():
        warnings.simplefilter("ignore", Image.DecompressionBombWarning)
        try:
            im = Image.open(path)
        except Image.DecompressionBombError:
            with _PILLOW_LIMIT:
                limit, Image.MAX_IMAGE_PIXELS = Image.MAX_IMAGE_PIXELS, MAX_IMAGE_SIDE ** 2
                try:
                    im = Image.open(path)
                except Image.DecompressionBombError as exc:
                    raise IngestError(f"image file {str(path)!r} is too large to read ({exc}); expected at most "
                                      f"{MAX_IMAGE_SIDE} pixels a side") from None
                finally:
                    Image.MAX_IMAGE_PIXELS = limit
    with im:
        yield im


#: Held while Pillow's process-wide pixel limit is lifted (:func:`_header`).
_PILLOW_LIMIT = threading.Lock()


def _check_sides(path: Path, width: int, height: int) -> tuple[int, int]:
    """``(width, height)``, or an :class:`IngestError` naming the file when a side exceeds :data:`MAX_IMAGE_SIDE`."""
    if max(width, height) > MAX_IMAGE_SIDE:
        raise IngestError(f"image file {str(path)!r} is {width}x{height} pixels; expected at most {MAX_IMAGE_SIDE} "
                          "pixels a side")
    return width, height


def read_turn(path: str | os.PathLike) -> tuple[bool, bool]:
    """Whether :func:`read_image` shows the image file ``path`` otherwise than its pixels are stored (its EXIF
    orientation tag, 2 to 8; a HEIF photo's ``irot`` / ``imir``, which its tag only describes), and whether the sides
    are swapped so (a quarter turn); ``(False, False)`` when Pillow cannot read the header (the decoder names the
    file)."""
    path = Path(path)
    if is_iso_media(_head(path)):
        try:
            return heif_turn(path)
        except IngestError:  # a HEIF photo cut short or corrupt: decoding it names the file (its frame is skipped)
            return False, False
    orientation = _stored_facts(path)[0]
    return orientation != 1, orientation in (5, 6, 7, 8)


def _stored_facts(path: Path) -> tuple[int, bytes | None, bool]:
    """From the header: the orientation :func:`_exif_orientation` reads, the embedded ICC profile and whether the
    pixels carry alpha or a transparent colour (``(1, None, False)`` when Pillow cannot read it: the decoder names
    the file), refusing a stored size of more than :data:`MAX_IMAGE_SIDE` pixels a side."""
    from PIL import UnidentifiedImageError

    try:
        with _header(path) as im:
            size, orientation, icc = im.size, _exif_orientation(im, path), im.info.get("icc_profile")
            alpha = has_alpha(im)
    except (OSError, UnidentifiedImageError, ValueError, SyntaxError, KeyError):
        return 1, None, False
    _check_sides(path, *size)
    return orientation, icc, alpha


def _exif_orientation(im: PIL.Image.Image, path: Path) -> int:
    """The EXIF orientation tag Pillow reads (the first EXIF segment's; 1 when none or not one of the eight): the one
    place both :func:`read_image` and :func:`read_image_size` take it from, so that they agree.

    Pillow decodes a PNG's pixels to look for EXIF after them (``eXIf``, text or XMP chunks); when
    :func:`_png_ends_at_pixels` finds none can be there, its header's are read without that decoding."""
    from PIL import Image

    if im.format == "PNG" and "exif" not in im.info and _png_ends_at_pixels(path):
        exif = Image.Image.getexif(im)  # what PngImageFile.getexif returns once it has loaded the pixels
    else:
        exif = im.getexif()
    orientation = exif.get(0x0112, 1)
    return orientation if orientation in _UNDO_ORIENTATION else 1


def _png_ends_at_pixels(path: Path) -> bool:
    """Whether the PNG at ``path`` has no chunk between its pixel data (``IDAT``) and its end (``IEND``); walked
    chunk by chunk, without reading the pixels; ``False`` when that cannot be told."""
    try:
        with open(path, "rb") as f:
            f.seek(8)
            pixels = False
            while len(header := f.read(8)) == 8:
                kind = header[4:]
                if kind == b"IDAT":
                    pixels = True
                elif pixels:
                    return kind == b"IEND"
                f.seek(int.from_bytes(header[:4], "big") + 4, os.SEEK_CUR)
    except OSError:
        pass
    return False


#: EXIF orientation → what takes the upright pixels back to the stored ones (the inverse of the tag's transform:
#: 6 shows the stored pixels turned a quarter clockwise, so undoing it turns them back anticlockwise)
_UNDO_ORIENTATION = {
    1: lambda img: img,
    2: lambda img: img[:, ::-1],
    3: lambda img: img[::-1, ::-1],
    4: lambda img: img[::-1],
    5: lambda img: img.swapaxes(0, 1),
    6: lambda img: np.rot90(img, 1),
    7: lambda img: np.rot90(img, -1)[::-1],
    8: lambda img: np.rot90(img, -1),
}


def _is_tiff(head: bytes) -> bool:
    """Whether a file's first bytes open a TIFF (classic or BigTIFF, either byte order)."""
    return head[:4] in (b"II*\0", b"MM\0*", b"II+\0", b"MM\0+")


def _head(path: Path) -> bytes:
    """The first 12 bytes of the file at ``path`` (fewer when it is shorter; none when it cannot be read)."""
    try:
        with open(path, "rb") as f:
            return f.read(12)
    except OSError:
        return b""  # the decoder that follows names the file


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
