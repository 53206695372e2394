"""A pose set: what every source (transforms.json, COLMAP model, SfM) yields before images are loaded.

Convention
----------
Cameras are those of the **source images on disk** (full resolution, lens distortion still present, OpenCV pixel
centres), of their pixels upright or as stored as :attr:`PoseSet.pixels` says; poses are camera-to-world 4x4 float64
with OpenCV camera axes. A pose set can be written back as a nerfstudio ``transforms.json`` that points at the same
image files (:func:`~pytest_n2r.data.transforms_json.write_transforms_json`).
"""

from __future__ import annotations

from dataclasses import dataclass, field
from pathlib import Path
from typing import TYPE_CHECKING

import numpy as np

from ..geometry import Camera

if TYPE_CHECKING:
    from .transforms_pixels import Pixels

__all__ = ["SourceFrame", "PoseSet"]


@dataclass(frozen=True, eq=False)
class SourceFrame:
    """One registered image of a source.

    ``name`` identifies the image across pose sets (the file name as the source lists it, e.g.
    ``images/0001.jpg`` in a transforms.json or ``0001.jpg`` in a COLMAP model); ``path`` is the image
    file on disk (``None`` when the source has no images beside it); ``camera`` has the source image's
    size and distortion; ``c2w`` is camera-to-world, OpenCV axes, float64.
    """

    name: str
    path: Path | None
    camera: Camera
    c2w: np.ndarray


@dataclass(eq=False)
class PoseSet:
    """Registered frames, sparse points and bookkeeping of one source.

    Attributes
    ----------
    frames:
        Registered frames in source order (sorted by name for models and SfM).
    points:
        ``(N, 3)`` float64 sparse surface points in world units (SfM / COLMAP points, or triangulated
        from the given poses); may be empty until :func:`~pytest_n2r.data.triangulate.triangulate_views`
        fills it.
    source:
        The path the set was read from.
    kind:
        ``"transforms.json"``, ``"colmap"``, ``"images"`` or ``"video"`` (structure from motion).
    skipped:
        ``(file, reason)`` for every listed or found image that is not among ``frames``.
    report:
        Plain JSON-ready facts: timings in seconds per stage, counts, the method used for points.
    heldout:
        Names (:attr:`SourceFrame.name`) of the frames the source itself holds out (a transforms.json's
        ``val_filenames``, else its ``test_filenames``); ``None`` when the source has no split.
    pixels:
        Which pixels of a photo with an EXIF orientation tag the cameras and poses describe, so which ingestion
        reads: ``"upright"`` (the tag applied: structure from motion's photos, a transforms.json n2r wrote of such)
        or ``"stored"`` (the tag ignored: a COLMAP model's, and a transforms.json another tool wrote, as COLMAP,
        nerfstudio and instant-ngp read them; :mod:`~pytest_n2r.data.transforms_pixels`).
    """

    frames: list[SourceFrame]
    points: np.ndarray = field(default_factory=lambda: np.zeros((0, 3)))
    source: str = ""
    kind: str = ""
    skipped: list[tuple[str, str]] = field(default_factory=list)
    report: dict = field(default_factory=dict)
    heldout: frozenset[str] | None = None
    pixels: Pixels = "upright"

    @property
    def centres(self) -> np.ndarray:
        """Camera centres ``(N, 3)`` in world units."""
        return np.array([f.c2w[:3, 3] for f in self.frames]).reshape(-1, 3)
