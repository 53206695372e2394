"""The cameras of a scene trained elsewhere: from a 3DGS ``cameras.json``, a ``transforms.json`` or a COLMAP
model, read without their images, and found beside a ``.ply`` when not named.

Each source's conventions are converted on reading (camera-to-world, OpenCV axes, OpenCV pixel centres):
see :mod:`~pytest_n2r.data.gs_cameras`, :mod:`~pytest_n2r.data.transforms_json` and
:mod:`~pytest_n2r.data.colmap`.
"""

from __future__ import annotations

import os
from pathlib import Path

from ..errors import IngestError
from .colmap import find_colmap_model, read_colmap_model
from .gs_cameras import is_gs_cameras, read_gs_cameras
from .poses import PoseSet
from .transforms_json import read_transforms_json

__all__ = ["CAMERA_FILES", "find_cameras", "read_cameras"]

#: Camera files looked for beside a .ply, in this order (then a COLMAP model).
CAMERA_FILES = ("cameras.json", "transforms.json")


def read_cameras(source: str | os.PathLike) -> PoseSet:
    """The frames of ``source``: a 3DGS ``cameras.json``, a ``transforms.json`` (any ``.json`` file: a list of
    cameras is read as the former, an object with ``frames`` as the latter), a COLMAP model folder, or a
    folder holding one of them. Images are not needed (frames get ``path=None`` where they are absent)."""
    path = Path(source)
    if path.is_file() and path.suffix.lower() == ".json":
        return read_gs_cameras(path) if is_gs_cameras(path) else read_transforms_json(path, images=False)
    if path.is_dir():
        for name in CAMERA_FILES:
            if (path / name).is_file():
                return read_cameras(path / name)
        model = find_colmap_model(path)
        if model is not None:
            return read_colmap_model(model)
    raise IngestError(f"cameras {str(path)!r}: expected a 3DGS cameras.json, a transforms.json or a COLMAP model "
                      "folder (cameras.bin|txt and images.bin|txt)" + ("" if path.exists() else "; it does not exist"))


def find_cameras(ply: str | os.PathLike) -> Path | None:
    """The cameras of a trained ``.ply`` when they lie where the training tools put them: a ``cameras.json``,
    a ``transforms.json`` or a COLMAP model in the ply's folder or up to two folders above it (3DGS writes
    ``<run>/point_cloud/iteration_N/point_cloud.ply`` and ``<run>/cameras.json``); ``None`` when there is
    none."""
    ply = Path(ply).resolve()
    for folder in list(ply.parents)[:3]:
        for name in CAMERA_FILES:
            if (folder / name).is_file():
                return folder / name
        model = find_colmap_model(folder)
        if model is not None:
            return model
    return None
