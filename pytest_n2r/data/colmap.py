"""Read (and write, as text) COLMAP sparse models through ``pycolmap.Reconstruction``.

Convention
----------
- COLMAP stores world-to-camera poses (``cam_from_world``) with OpenCV camera axes; we invert them to
  camera-to-world.
- COLMAP puts the top-left pixel centre at ``(0.5, 0.5)``: ``cx_ours = cx_colmap - 0.5`` (same for cy).
- Camera models map to OpenCV distortion ``(k1, k2, p1, p2[, k3, k4, k5, k6])``:
  ``SIMPLE_PINHOLE (f, cx, cy)``, ``PINHOLE (fx, fy, cx, cy)``, ``SIMPLE_RADIAL (f, cx, cy, k)`` → ``(k, 0, 0, 0)``,
  ``RADIAL (f, cx, cy, k1, k2)`` → ``(k1, k2, 0, 0)``, ``OPENCV (fx, fy, cx, cy, k1, k2, p1, p2)``,
  ``FULL_OPENCV (fx, fy, cx, cy, k1, k2, p1, p2, k3, k4, k5, k6)``. Fisheye and other models are refused.
"""

from __future__ import annotations

import os
import struct
from collections.abc import Iterable, Sequence
from pathlib import Path

import numpy as np

from ..errors import IngestError, N2RError
from ..geometry import Camera, colmap_from_c2w, invert_pose, orthonormalize
from .atomic import atomic_write_text
from .images import IMAGE_SUFFIXES
from .poses import PoseSet, SourceFrame

#: What pycolmap (pybind11) raises for a C++ exception: pybind11 translates std::exception and anything unknown
#: to RuntimeError, std::invalid_argument/domain_error/length_error/range_error to ValueError, std::out_of_range
#: to IndexError, std::overflow_error/underflow_error to ArithmeticError subclasses, std::bad_alloc to
#: MemoryError (COLMAP's failed checks are std::invalid_argument: ValueError).
PYCOLMAP_ERRORS: tuple[type[Exception], ...] = (RuntimeError, ValueError, LookupError, ArithmeticError, MemoryError)

__all__ = ["find_colmap_model", "read_colmap_model", "write_colmap_text", "camera_from_colmap", "colmap_camera_params"]

_MODEL_FILES = ("cameras", "images", "points3D")


#: COLMAP's camera model ids → their number of params (``colmap/sensor/models.h``; pycolmap 4.2 knows these 18)
_PARAM_COUNTS = (3, 4, 4, 5, 8, 8, 12, 5, 4, 5, 12, 16, 4, 5, 3, 4, 6, 2)


def _cut(file: Path, what: str, need: int, left: int) -> IngestError:
    return IngestError(f"{file}: {what} needs {need} bytes, but only {left} are left in the file (a copy cut short, "
                       "or not a COLMAP model); expected a binary model whose counts match its bytes")


def _check_bin(file: Path) -> None:
    """Walk the records of one binary model file (``cameras.bin``, ``images.bin``, ``points3D.bin``,
    ``frames.bin``), checking every count against the bytes left, so that pycolmap never allocates or loops for a
    count the file cannot hold; ``rigs.bin`` (COLMAP 3.12's) by its header's count alone."""
    try:
        data = file.read_bytes()
    except OSError as exc:
        raise IngestError(f"{file}: cannot be read: {exc.strerror or exc}") from None
    end, kind, u64 = len(data), file.name[:-4], struct.Struct("<Q").unpack_from
    if end < 8:
        raise _cut(file, "the count of records", 8, end)
    count = u64(data)[0]
    least = {"cameras": 24 + 8 * min(_PARAM_COUNTS), "images": 73, "points3D": 51, "frames": 68, "rigs": 8}[kind]
    if count * least > end - 8:
        raise IngestError(f"{file}: the header claims {count} records, but its {end - 8} bytes after the count hold "
                          f"at most {(end - 8) // least} (a copy cut short, or not a COLMAP model); expected a binary "
                          "model whose counts match its bytes")
    at = 8
    for index in range(0 if kind == "rigs" else count):  # each record's fixed part fits: count * least was checked
        start = at
        if kind == "frames":  # frame id, rig id, rig-from-world pose; then (sensor type, sensor id, data id) triples
            n, item, at = struct.unpack_from("<I", data, at + 64)[0], 16, at + 68
        elif kind == "points3D":  # id, xyz, rgb, error, track length; then (image id, point2D index) pairs
            n, item, at = u64(data, at + 43)[0], 8, at + 51
        elif kind == "cameras":  # id, model id, width, height; then the model's params
            model = struct.unpack_from("<i", data, at + 4)[0]
            if not 0 <= model < len(_PARAM_COUNTS):
                raise IngestError(f"{file}: camera record {index + 1} of {count} (at byte {start}) has model id "
                                  f"{model}; expected a COLMAP camera model id 0..{len(_PARAM_COUNTS) - 1}")
            n, item, at = _PARAM_COUNTS[model], 8, at + 24
        else:  # id, qvec, tvec, camera id, NUL-terminated name, 2-D point count; then (x, y, point3D id) triples
            name_end = data.find(b"\0", at + 64)
            if name_end < 0 or name_end + 9 > end:
                raise _cut(file, f"image record {index + 1} of {count} (at byte {start}), its name and 2-D point "
                           "count,", (end if name_end < 0 else name_end) + 9 - start, end - start)
            n, item, at = u64(data, name_end + 1)[0], 24, name_end + 9
        if n * item > end - at:
            what = {"points3D": "track entries", "cameras": "params", "images": "2-D points",
                    "frames": "data ids"}[kind]
            name = f" {data[start + 64:at - 9].decode('utf-8', 'replace')!r}" if kind == "images" else ""
            raise _cut(file, f"{kind[:-1] if kind != 'points3D' else 'point'} record {index + 1} of {count}{name} "
                       f"(at byte {start}) claims {n} {what} ({item} bytes each), which", n * item, end - at)
        at += n * item


def _check_binary_counts(model: Path) -> None:
    """:func:`_check_bin` on each binary file of ``model``: pycolmap trusts their counts (a ``frames.bin`` claiming
    10^12 frames and holding none made it loop on failed reads without end)."""
    for name in (*_MODEL_FILES, "frames", "rigs"):
        if (model / f"{name}.bin").is_file():
            _check_bin(model / f"{name}.bin")


def _is_model(folder: Path) -> bool:
    return all((folder / f"{n}.bin").is_file() or (folder / f"{n}.txt").is_file() for n in _MODEL_FILES[:2])


def find_colmap_model(folder: str | os.PathLike) -> Path | None:
    """The COLMAP model folder at or under ``folder`` (itself, ``sparse/0``, ``sparse`` or
    ``colmap/sparse/0``), or ``None``. A model folder holds ``cameras`` and ``images`` (``.bin`` or ``.txt``)."""
    folder = Path(folder)
    for candidate in (folder, folder / "sparse" / "0", folder / "sparse", folder / "colmap" / "sparse" / "0"):
        if candidate.is_dir() and _is_model(candidate):
            return candidate
    return None


def camera_from_colmap(model: str, width: int, height: int, params: Iterable[float], where: str = "camera") -> Camera:
    """Our :class:`Camera` (OpenCV pixel centres and distortion) from a COLMAP camera model and params."""
    p = [float(x) for x in params]
    expected = {"SIMPLE_PINHOLE": 3, "PINHOLE": 4, "SIMPLE_RADIAL": 4, "RADIAL": 5, "OPENCV": 8, "FULL_OPENCV": 12}
    if model not in expected:
        raise IngestError(
            f"{where}: COLMAP camera model {model!r} is not supported; expected one of {', '.join(expected)}"
        )
    if len(p) != expected[model]:
        raise IngestError(f"{where}: {model} has {len(p)} parameters; expected {expected[model]}")
    if model in ("SIMPLE_PINHOLE", "SIMPLE_RADIAL", "RADIAL"):
        fx = fy = p[0]
        cx, cy = p[1], p[2]
        k = p[3:] + [0.0] * (2 - len(p[3:]))
        dist: tuple[float, ...] = (k[0], k[1], 0.0, 0.0)
    else:
        fx, fy, cx, cy = p[:4]
        dist = tuple(p[4:])
    try:
        return Camera.from_colmap_pixels(int(width), int(height), fx, fy, cx, cy, dist)
    except N2RError as exc:
        raise IngestError(f"{where}: bad intrinsics: {exc}") from None


def colmap_camera_params(camera: Camera) -> tuple[str, list[float]]:
    """The COLMAP model name and params of our camera (inverse of :func:`camera_from_colmap`)."""
    cx, cy = camera.cx + 0.5, camera.cy + 0.5
    if len(camera.distortion) == 8:
        return "FULL_OPENCV", [camera.fx, camera.fy, cx, cy, *camera.distortion, 0.0, 0.0][:12]
    if len(camera.distortion) == 5:
        return "FULL_OPENCV", [camera.fx, camera.fy, cx, cy, *camera.distortion, 0.0, 0.0, 0.0]
    if camera.distortion:
        return "OPENCV", [camera.fx, camera.fy, cx, cy, *camera.distortion]
    return "PINHOLE", [camera.fx, camera.fy, cx, cy]


def _default_images_dir(model: Path, names: list[str]) -> Path | None:
    """The folder beside the model in which the most of ``names`` exist (``images`` folders first)."""
    up = [model, *model.parents[:3]]
    candidates = [p / "images" for p in up[1:]] + [model / "images"] + up[1:]
    best, found = None, 0
    for folder in candidates:
        if folder.is_dir():
            count = sum((folder / n).is_file() for n in names[:50])
            if count > found:
                best, found = folder, count
    return best


def read_colmap_model(model: str | os.PathLike, images_dir: str | os.PathLike | None = None) -> PoseSet:
    """Read a COLMAP sparse model (binary or text) into a :class:`PoseSet`, frames sorted by image name.

    ``images_dir`` defaults to the folder near the model that holds the most of its image names
    (``project/images`` for ``project/sparse/0``, else ``project``); frames whose file is not
    there get ``path=None``. Images in that folder that
    the model did not register are listed in ``skipped``. Raises :class:`IngestError` naming the folder.
    """
    import pycolmap

    model = Path(model)
    found = find_colmap_model(model)
    if found is None:
        raise IngestError(
            f"{str(model)!r} is not a COLMAP model folder; expected cameras.bin|txt and images.bin|txt in it"
        )
    try:
        _check_binary_counts(found)
        rec = pycolmap.Reconstruction(str(found))
    except PYCOLMAP_ERRORS as exc:  # plain RuntimeError/ValueError carrying C++ messages
        raise IngestError(f"COLMAP model {str(found)!r} cannot be read: {exc}") from None
    names = sorted(im.name for im in rec.images.values())
    images_dir = Path(images_dir) if images_dir is not None else _default_images_dir(found, names)

    cameras: dict[int, Camera] = {}
    for cam_id, cam in rec.cameras.items():
        cameras[cam_id] = camera_from_colmap(
            cam.model.name, cam.width, cam.height, cam.params, where=f"{found}: camera {cam_id}"
        )
    frames = []
    for image in sorted(rec.images.values(), key=lambda im: im.name):
        if not image.has_pose:
            continue
        cam_from_world = image.cam_from_world()
        if not np.any(np.asarray(cam_from_world.rotation.quat, dtype=np.float64)):  # pycolmap keeps it as read
            images_file = found / ("images.bin" if (found / "images.bin").is_file() else "images.txt")
            raise IngestError(f"{images_file}: image {image.name!r} has the quaternion (0, 0, 0, 0); a rotation needs "
                              "a non-zero quaternion (QW, QX, QY, QZ)")
        w2c = np.eye(4)
        w2c[:3] = np.asarray(cam_from_world.matrix(), dtype=np.float64)
        if not np.all(np.isfinite(w2c)):
            raise IngestError(f"{found}: image {image.name!r} has a non-finite pose")
        w2c[:3, :3] = orthonormalize(w2c[:3, :3])
        path = images_dir / image.name if images_dir is not None else None
        frames.append(SourceFrame(
            name=image.name, path=path if path is not None and path.is_file() else None,
            camera=cameras[image.camera_id], c2w=invert_pose(w2c),
        ))
    if not frames:
        raise IngestError(f"COLMAP model {str(found)!r} has no registered images")
    points = np.array([p.xyz for _, p in sorted(rec.points3D.items())], dtype=np.float64).reshape(-1, 3)
    skipped = []
    if images_dir is not None:
        registered = {f.name for f in frames}
        for file in sorted(images_dir.rglob("*")):
            name = file.relative_to(images_dir).as_posix()
            if file.is_file() and file.suffix.lower() in IMAGE_SUFFIXES and name not in registered:
                skipped.append((name, "not registered in the COLMAP model"))
    return PoseSet(frames=frames, points=points, source=str(found), kind="colmap", skipped=skipped, pixels="stored",
                   report={"images_dir": None if images_dir is None else str(images_dir),
                           "points_method": "points3D of the COLMAP model" if len(points) else ""})


def write_colmap_text(folder: str | os.PathLike, poses: PoseSet | Sequence[SourceFrame]) -> Path:
    """Write frames (and points, without tracks) as a COLMAP text model in ``folder`` (atomically per file).

    Frames with equal cameras share one COLMAP camera; image names are the frames' names.
    """
    folder = Path(folder)
    frames = poses.frames if isinstance(poses, PoseSet) else list(poses)
    points = poses.points if isinstance(poses, PoseSet) else np.zeros((0, 3))
    cam_ids: dict[Camera, int] = {}
    cam_lines, img_lines = ["# Camera list: CAMERA_ID, MODEL, WIDTH, HEIGHT, PARAMS[]"], [
        "# Image list: IMAGE_ID, QW, QX, QY, QZ, TX, TY, TZ, CAMERA_ID, NAME; then POINTS2D[] as (X, Y, POINT3D_ID)"
    ]
    for k, frame in enumerate(frames, start=1):
        if frame.camera not in cam_ids:
            cam_ids[frame.camera] = len(cam_ids) + 1
            model, params = colmap_camera_params(frame.camera)
            cam_lines.append(" ".join([str(cam_ids[frame.camera]), model, str(frame.camera.width),
                                       str(frame.camera.height), *(repr(float(x)) for x in params)]))
        q, t = colmap_from_c2w(frame.c2w)
        img_lines.append(" ".join([str(k), *(repr(float(x)) for x in (*q, *t)), str(cam_ids[frame.camera]),
                                   frame.name]))
        img_lines.append("")
    pt_lines = ["# 3D point list: POINT3D_ID, X, Y, Z, R, G, B, ERROR, TRACK[] as (IMAGE_ID, POINT2D_IDX)"]
    pt_lines += [f"{k} {x!r} {y!r} {z!r} 128 128 128 0" for k, (x, y, z) in enumerate(points.tolist(), start=1)]
    for name, lines in (("cameras", cam_lines), ("images", img_lines), ("points3D", pt_lines)):
        atomic_write_text(folder / f"{name}.txt", "\n".join(lines) + "\n")
    return folder
