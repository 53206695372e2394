"""Read and write the ``cameras.json`` that 3D Gaussian Splatting's reference code writes beside its output.

Convention
----------
A JSON list, one object per camera: ``id``, ``img_name`` (the image file name without its extension),
``width``, ``height`` (pixels, at the training resolution), ``position`` (the camera centre, world units),
``rotation`` (the camera-to-world rotation as 3 rows, **OpenCV camera axes**: x right, y down, z forward;
the reference converts Blender / NeRF-synthetic OpenGL matrices before writing) and ``fx``, ``fy``
(focal lengths in pixels). There is no principal point: the reference renders with it at the image
centre, ``cx = width / 2`` in COLMAP's pixel convention, so ``cx_ours = (width - 1) / 2`` (OpenCV pixel
centres). No lens distortion. The reference lists held-out cameras first, then training cameras, and
records no split.
"""

from __future__ import annotations

import json
import os
from pathlib import Path

import numpy as np

from .._validation import is_finite, repeated_name
from ..errors import IngestError, N2RError
from ..geometry import Camera, orthonormalize
from .atomic import atomic_write_text
from .json_file import read_json_file
from .poses import PoseSet, SourceFrame

__all__ = ["is_gs_cameras", "read_gs_cameras", "write_gs_cameras"]


def is_gs_cameras(path: str | os.PathLike) -> bool:
    """Whether ``path`` is a JSON file in the 3DGS layout: a list at the top level (a ``transforms.json`` is an
    object), so that a malformed ``cameras.json`` gets :func:`read_gs_cameras`' errors, not transforms.json's. Only
    the file's first character after white space is looked at, not the whole parsed (the reader that follows names
    what is wrong)."""
    try:
        with open(path, encoding="utf-8") as fh:
            start = fh.read(2**16).lstrip()
    except (OSError, UnicodeDecodeError):
        return False
    return start.startswith("[")


def _number(record: dict, key: str, where: str, positive: bool = True) -> float:
    value = record.get(key)
    if isinstance(value, bool) or not isinstance(value, (int, float)) or not is_finite(value) \
            or (positive and value <= 0):
        raise IngestError(f"{where}: field {key!r}={value!r}; expected a finite number{' > 0' if positive else ''}")
    return float(value)


def read_gs_cameras(path: str | os.PathLike) -> PoseSet:
    """The cameras of a 3DGS ``cameras.json`` (see the module *Convention*), in file order, without images.

    Raises :class:`IngestError` naming the file, the entry and the field when a field is missing or
    malformed or a rotation is not a rotation, and naming both entries when two have one ``img_name``.
    """
    path = Path(path)
    data = read_json_file(path, 'cameras')
    if not isinstance(data, list) or not data:
        raise IngestError(f"{path}: expected a non-empty JSON list of cameras (3DGS cameras.json)")
    frames = []
    for i, record in enumerate(data):
        where = f"{path}: [{i}]"
        if not isinstance(record, dict):
            raise IngestError(f"{where}: expected an object, found {type(record).__name__}")
        name = record.get("img_name", f"camera_{i:05d}")
        if not isinstance(name, str) or not name:
            raise IngestError(f"{where}: field 'img_name'={name!r}; expected a non-empty string")
        width, height = (_number(record, k, where) for k in ("width", "height"))
        if width != int(width) or height != int(height):
            raise IngestError(f"{where}: width x height = {width} x {height}; expected whole pixels")
        fx, fy = _number(record, "fx", where), _number(record, "fy", where)
        try:
            position = np.asarray(record.get("position"), dtype=np.float64)
            rotation = np.asarray(record.get("rotation"), dtype=np.float64)
        except (TypeError, ValueError):
            raise IngestError(f"{where}: fields 'position' and 'rotation' must be numeric (3,) and (3, 3)") from None
        if position.shape != (3,) or rotation.shape != (3, 3):
            raise IngestError(f"{where}: 'position' has shape {position.shape} and 'rotation' {rotation.shape}; "
                              "expected (3,) and (3, 3)")
        if not (np.isfinite(position).all() and np.isfinite(rotation).all()):
            raise IngestError(f"{where}: 'position' or 'rotation' contains NaN or Inf")
        err = float(np.abs(rotation.T @ rotation - np.eye(3)).max())
        if err > 1e-3 or np.linalg.det(rotation) <= 0:
            raise IngestError(f"{where}: field 'rotation' is not a rotation (|RᵀR - I| = {err:.3g}, det = "
                              f"{np.linalg.det(rotation):.4g})")
        c2w = np.eye(4)
        c2w[:3, :3] = orthonormalize(rotation)
        c2w[:3, 3] = position
        try:
            camera = Camera(int(width), int(height), fx, fy, (width - 1) / 2, (height - 1) / 2)
        except N2RError as exc:
            raise IngestError(f"{where}: bad intrinsics: {exc}") from None
        frames.append(SourceFrame(name=name, path=None, camera=camera, c2w=c2w))
    repeat = repeated_name(f.name for f in frames)  # every entry is a frame: positions are the file's
    if repeat is not None:
        raise IngestError(f"{path}: [{repeat[0]}] and [{repeat[1]}] both have img_name {repeat[2]!r}; expected one "
                          "camera a name (a view is looked up and reported by its name)")
    return PoseSet(frames=frames, source=str(path), kind="cameras.json", report={"listed": len(data)})


def write_gs_cameras(path: str | os.PathLike, frames: list[SourceFrame] | PoseSet) -> Path:
    """Write frames as a 3DGS ``cameras.json`` (atomically); ``img_name`` is each name without its extension.

    Raises :class:`IngestError` for a camera whose principal point is not the image centre or that has lens
    distortion (the format has no field for either).
    """
    frames = frames.frames if isinstance(frames, PoseSet) else list(frames)
    records = []
    for i, frame in enumerate(frames):
        cam = frame.camera
        if cam.distortion or abs(cam.cx - (cam.width - 1) / 2) > 1e-9 or abs(cam.cy - (cam.height - 1) / 2) > 1e-9:
            raise IngestError(f"cannot write {path}: camera of {frame.name!r} has its principal point off the image "
                              "centre or lens distortion, which a 3DGS cameras.json cannot hold")
        records.append({"id": i, "img_name": Path(frame.name).stem, "width": cam.width, "height": cam.height,
                        "position": frame.c2w[:3, 3].tolist(), "rotation": frame.c2w[:3, :3].tolist(),
                        "fy": cam.fy, "fx": cam.fx})
    return atomic_write_text(path, json.dumps(records) + "\n")
