"""Which pixels of a photo a transforms.json's cameras describe: as stored, or upright (its EXIF orientation applied).

Convention
----------
A transforms.json describes its photos the way the tool that wrote it reads them, and n2r reads them so:

- A file :func:`~pytest_n2r.data.transforms_json.write_transforms_json` wrote (n2r's, a top-level ``n2r`` block)
  records it as ``n2r.pixels``: ``"upright"`` (photos posed by n2r's structure from motion, which reads them upright)
  or ``"stored"`` (a COLMAP model's or another tool's transforms.json, re-written by ``n2r poses -o``); an ``n2r``
  block without ``pixels`` (written before it was recorded) is ``"upright"``.
- Any other transforms.json (nerfstudio, instant-ngp, Blender, COLMAP's converters) describes the pixels **as
  stored**, the EXIF orientation tag ignored, as those tools read them:

  * nerfstudio decodes a frame with ``PIL.Image.open`` and ``np.array`` and no ``ImageOps.exif_transpose``
    (``nerfstudio/data/datasets/base_dataset.py``, ``InputDataset.get_numpy_image``), and the dataparser's
    downscaled copies are made with ``ffmpeg -noautorotate`` (``nerfstudio_dataparser.py``, ``_downscale_images``);
  * instant-ngp decodes with stb_image (``src/nerf_loader.cu``: ``load_stbi(path, &dst.res.x, &dst.res.y, ...)``),
    which reads no EXIF orientation, and takes the resolution from the decoded pixels;
  * ``ns-process-data`` and instant-ngp's ``colmap2nerf.py`` pose the photos with COLMAP, which ignores the tag
    (colmap/colmap#1456: removed in #1406 "because in structure-from-motion what we care about is geometry"), and
    ``ns-process-data`` copies the photos as they are (``process_data_utils.copy_images_list``: ``shutil.copy`` when
    every photo has one size, the tag kept), so its cameras describe the stored pixels of the copies it points at.

  Such a file's photos are read as stored, like a COLMAP model's; a photo with an orientation tag is warned of once
  per file (the user may have meant the upright photo).
"""

from __future__ import annotations

from pathlib import Path
from typing import Literal

from ..errors import IngestError
from .images import read_image_size, read_turn

__all__ = ["Pixels", "PIXELS", "pixels_of", "photo_size", "tagged_count", "tagged_photos_note"]

Pixels = Literal["upright", "stored"]
#: the values of :attr:`~pytest_n2r.data.poses.PoseSet.pixels` and of a written file's ``n2r.pixels``
PIXELS: tuple[Pixels, ...] = ("upright", "stored")


def pixels_of(meta: dict, path: Path) -> Pixels:
    """Which pixels the transforms.json ``meta`` (read from ``path``) describes (see the module's *Convention*):
    ``n2r.pixels`` of a file n2r wrote (``"upright"`` without it), else ``"stored"``. Raises :class:`IngestError`
    naming the file and the field for a ``pixels`` that is neither."""
    block = meta.get("n2r")
    if not isinstance(block, dict):
        return "stored"
    pixels = block.get("pixels", "upright")
    if pixels not in PIXELS:
        raise IngestError(f"{path}: field 'n2r.pixels'={pixels!r} is not one of {', '.join(map(repr, PIXELS))} "
                          "(whether the cameras describe the photos upright or their pixels as stored)")
    return pixels


def photo_size(image: Path, pixels: Pixels) -> tuple[int, int]:
    """``(width, height)`` of the photo ``image`` as ``pixels`` reads it: upright, or as stored (a quarter turn by its
    EXIF tag, orientations 5 to 8, or a HEIF photo's ``irot``, swaps the sides back)."""
    width, height = read_image_size(image)
    if pixels == "stored" and read_turn(image)[1]:
        return height, width
    return width, height


def tagged_count(images: list[Path]) -> int:
    """How many of the photos ``images`` are shown otherwise than stored: an EXIF orientation tag other than 1, a
    HEIF photo's rotation or mirror (read from their headers)."""
    return sum(1 for image in images if read_turn(image)[0])


def tagged_photos_note(path: Path, images: list[Path]) -> str | None:
    """The warning for a transforms.json not written by n2r whose photos ``images`` are read as stored: ``None`` when
    none has an EXIF orientation tag, else one line naming the file and how many have one."""
    tagged = tagged_count(images)
    if not tagged:
        return None
    return (f"{path}: {tagged} of {len(images)} photos have an EXIF orientation tag; read as stored (the tag "
            "ignored; a HEIF photo's rotation undone), as nerfstudio and instant-ngp read a transforms.json's photos, "
            "so the file's cameras and poses are taken to describe the stored pixels; if they describe the photos as "
            "shown (upright), save the photos turned, the tag removed, or, for a file n2r wrote before 7 December "
            "2026, add \"n2r\": {\"pixels\": \"upright\"}")
