"""Read and write nerfstudio / instant-ngp ``transforms.json`` files.

Convention
----------
- ``transform_matrix`` is camera-to-world with **OpenGL** camera axes (x right, y up, z backward); it is
  converted to ours (OpenCV: x right, y down, z forward) on reading and back on writing.
- Intrinsics ``fl_x fl_y cx cy w h`` may be global (top level) or per frame (a frame's value wins).
  ``cx, cy`` put the top-left pixel centre at ``(0.5, 0.5)`` as in COLMAP; ours is ``(0, 0)``, so
  ``cx_ours = cx - 0.5``. Without ``fl_x`` the focal length comes from ``camera_angle_x`` (radians,
  full horizontal field of view): ``fl_x = w / (2 tan(camera_angle_x / 2))``; without ``fl_y``, from
  ``camera_angle_y`` (full vertical field of view, radians) when given, else ``fl_y = fl_x`` (each axis on its own,
  as instant-ngp reads them); ``cx, cy`` fall back to the image centre. ``w, h`` are whole pixels; without them the
  size is the photo's, as its pixels are read (below).
- The cameras describe a photo with an EXIF orientation tag as the file's writer reads it
  (:mod:`~pytest_n2r.data.transforms_pixels`): upright in a file n2r wrote (a top-level ``n2r`` block; its
  ``n2r.pixels`` says ``"stored"`` when the poses came from a COLMAP model or another tool's file), as stored in any
  other (nerfstudio, instant-ngp, Blender read the pixels as stored). Such a file's tagged photos are warned of once.
- ``camera_model`` is one of nerfstudio's pinhole models (``OPENCV`` when absent, ``PINHOLE``, ``SIMPLE_PINHOLE``,
  ``SIMPLE_RADIAL``, ``RADIAL``), whose distortion is nerfstudio's ``k1 k2 k3`` (radial, the terms in r², r⁴, r⁶ of
  OpenCV's model) and ``p1 p2`` (tangential); nerfstudio's ``k4`` is a further radial term in r⁸, which OpenCV's
  model cannot hold, so a non-zero ``k4`` (or ``k5``, ``k6``, no part of these models) is refused. ``FULL_OPENCV``
  (COLMAP's name for OpenCV's rational model, what :func:`write_transforms_json` writes for such a lens, which only
  n2r reads back: nerfstudio has no such model and instant-ngp reads ``k4`` as a radial term) reads
  ``k1 k2 p1 p2 k3 k4 k5 k6`` as OpenCV's. Every other model (fisheye, omnidirectional, VR180, equirectangular,
  orthographic, a typo) and instant-ngp's other lenses (``is_fisheye`` true, ``latlong``, ``equirectangular``,
  ``ftheta_p0``) are refused.
- The split: ``val_filenames`` are held out (else ``test_filenames``: a file that lists only training and test views
  holds the test views out of training); ``train_filenames`` is checked, not used. Each listed name is matched
  to a frame's ``file_path`` as nerfstudio does, as paths relative to the json's folder (``./a.jpg`` is ``a.jpg``);
  one that names no frame is refused.
- ``file_path`` is relative to the json's folder; a path without a suffix gets ``.png`` (the NeRF
  synthetic data sets list ``./train/r_0``); Windows separators (``images\\a.jpg``, written on Windows) are read as
  ``/`` when no file has the name as written, as instant-ngp reads them.
- A frame's ``mask_path`` (nerfstudio leaves the masked pixels out of its loss) is not read: warned of once.
"""

from __future__ import annotations

import json
import math
import os
import warnings
from pathlib import Path, PurePosixPath
from typing import Any

import numpy as np

from .._validation import is_finite, repeated_name
from ..errors import IngestError, N2RError
from ..geometry import Camera, opencv_to_opengl, opengl_to_opencv, orthonormalize
from .atomic import atomic_write_text
from .json_file import read_json_file
from .poses import PoseSet, SourceFrame
from .relative_path import relative_posix
from .transforms_pixels import PIXELS, Pixels, photo_size, pixels_of, tagged_count, tagged_photos_note

__all__ = ["read_transforms_json", "write_transforms_json", "find_transforms_json", "camera_model_of",
           "RATIONAL_MODEL_NOTE"]

_DISTORTION_KEYS = ("k1", "k2", "p1", "p2", "k3", "k4", "k5", "k6")
#: camera models read as they are meant (see the module's *Convention*)
_PINHOLE_MODELS = ("OPENCV", "PINHOLE", "SIMPLE_PINHOLE", "SIMPLE_RADIAL", "RADIAL")
_RATIONAL_MODEL = "FULL_OPENCV"
#: what a file written with :data:`_RATIONAL_MODEL` means to the tools that read transforms.json
RATIONAL_MODEL_NOTE = (
    f"camera_model {_RATIONAL_MODEL} (OpenCV's rational lens, k4 k5 k6 non-zero), which n2r reads back exactly but "
    f"nerfstudio and instant-ngp do not: nerfstudio has no {_RATIONAL_MODEL} camera (its dataparser stops on the "
    "name) and instant-ngp reads k4 as a radial term (and p1 p2 where k3 k4 go); no OPENCV camera holds this lens"
)
#: instant-ngp's fields for lenses other than a pinhole one
_OTHER_LENS_FIELDS = ("is_fisheye", "latlong", "equirectangular", "ftheta_p0")
#: nerfstudio's split fields; the first one present of the last two is held out
_SPLIT_FIELDS = ("train_filenames", "val_filenames", "test_filenames")


def find_transforms_json(source: str | os.PathLike) -> Path | None:
    """``source`` itself if it is a ``.json`` file, ``source/transforms.json`` if that exists, else ``None``."""
    source = Path(source)
    if source.is_file() and source.suffix.lower() == ".json":
        return source
    candidate = source / "transforms.json"
    return candidate if candidate.is_file() else None


def read_transforms_json(path: str | os.PathLike, *, images: bool = True) -> PoseSet:
    """Read the frames of a transforms.json whose image files exist (no pixels are decoded).

    Frames whose image file is missing are skipped with a warning naming the file; with ``images=False``
    (cameras only, e.g. of a splat scene trained elsewhere) they are kept with ``path=None`` and their
    size must be in the json (``w`` and ``h``). The split (``val_filenames``, else ``test_filenames``) becomes
    :attr:`PoseSet.heldout`, as the names of the frames it lists. Raises :class:`IngestError` naming the file, the
    frame index and the field when a field is missing or malformed or names a camera model or lens that is not read
    correctly (see the module's *Convention*), a size is not whole pixels, a matrix is not a finite rigid transform,
    a split names no frame, or no frame has its image. :attr:`PoseSet.pixels` is ``n2r.pixels`` of a file n2r wrote
    (``"upright"`` without it), else ``"stored"``; the photos of such another tool's file that have an EXIF
    orientation tag (read as stored) are warned of once, and frames with a ``mask_path`` (masks are not read), each
    also in ``report["warnings"]``.
    """
    path = Path(path)
    meta = read_json_file(path, 'transforms')
    if not isinstance(meta, dict):
        raise IngestError(f"{path}: expected a JSON object at the top level, found {type(meta).__name__}")
    raw_frames = meta.get("frames")
    if not isinstance(raw_frames, list) or not raw_frames:
        raise IngestError(f"{path}: field 'frames' is missing or empty; expected a list of frames")
    model = _camera_model(meta, str(path), "OPENCV")
    pixels = pixels_of(meta, path)

    root = path.parent
    frames: list[SourceFrame] = []
    skipped: list[tuple[str, str]] = []
    for i, raw in enumerate(raw_frames):
        where = f"{path}: frames[{i}]"
        if not isinstance(raw, dict):
            raise IngestError(f"{where}: expected an object, found {type(raw).__name__}")
        name = raw.get("file_path")
        if not isinstance(name, str) or not name:
            raise IngestError(f"{where}: field 'file_path' is missing or not a string")
        image = _resolve_image(root, name)
        c2w = _read_matrix(raw, where)  # validate every listed frame, even those without images
        frame_model = _camera_model(raw, where, model)
        if image is None and not images:
            camera = _read_camera(meta, raw, where, None, frame_model, pixels)
            frames.append(SourceFrame(name=name, path=None, camera=camera, c2w=c2w))
            continue
        if image is None:
            reason = f"image file {str(root / name)!r} listed in {path.name} frames[{i}] does not exist"
            warnings.warn(f"skipping frame: {reason}", stacklevel=2)
            skipped.append((name, reason))
            continue
        camera = _read_camera(meta, raw, where, image, frame_model, pixels)
        frames.append(SourceFrame(name=name, path=image, camera=camera, c2w=c2w))
    repeat = repeated_name(raw["file_path"] for raw in raw_frames)  # each a string: checked above
    if repeat is not None:  # a view's name is its file_path: two views of one name cannot both be tested or saved
        raise IngestError(f"{path}: frames[{repeat[1]}]: file_path {repeat[2]!r} is also frames[{repeat[0]}]'s; "
                          "expected each image once")
    if not frames:
        raise IngestError(f"{path}: none of the {len(raw_frames)} frames has its image file")
    heldout = _read_split(meta, path, [raw["file_path"] for raw in raw_frames])
    notes: list[str] = []
    if images and pixels == "stored" and not isinstance(meta.get("n2r"), dict):  # another tool's, photos to read
        notes.append(tagged_photos_note(path, [f.path for f in frames if f.path is not None]) or "")
    masked = sum(1 for raw in raw_frames if raw.get("mask_path") is not None)
    if masked:
        notes.append(f"{path}: {masked} of {len(raw_frames)} frames have a 'mask_path' (pixels nerfstudio leaves out "
                     "of its loss); n2r does not read masks: n2r fit fits every pixel of each photo, the masked ones "
                     "too")
    report: dict[str, Any] = {"listed": len(raw_frames)}
    for note in filter(None, notes):
        warnings.warn(note, stacklevel=2)
        report.setdefault("warnings", []).append(note)
    return PoseSet(frames=frames, source=str(path), kind="transforms.json", skipped=skipped, report=report,
                   heldout=heldout, pixels=pixels)


def _camera_model(fields: dict, where: str, default: str) -> str:
    """The camera model ``fields`` (the file's top level, or a frame's) declare, upper case, when it is one read
    correctly (see the module's *Convention*); otherwise an :class:`IngestError` naming ``where`` and the field."""
    model = fields.get("camera_model", default)
    accepted = (*_PINHOLE_MODELS, _RATIONAL_MODEL)
    if not isinstance(model, str) or model.upper() not in accepted:
        raise IngestError(f"{where}: field 'camera_model'={model!r} is not supported; expected one of "
                          f"{', '.join(accepted)} (a pinhole camera with OpenCV's lens model: fisheye, "
                          "omnidirectional, VR180, equirectangular and orthographic cameras are not read)")
    for key in _OTHER_LENS_FIELDS:
        if fields.get(key) not in (None, False):
            raise IngestError(f"{where}: field {key!r}={fields[key]!r} declares an instant-ngp lens other than a "
                              "pinhole one, which is not supported; expected a pinhole camera (no such field, or "
                              "'is_fisheye': false)")
    return model.upper()


def _read_split(meta: dict, path: Path, listed: list[str]) -> frozenset[str] | None:
    """The names (``file_path`` as listed) of the frames the file holds out: those ``val_filenames`` names, else
    ``test_filenames``; ``None`` without either. A split's name matches a frame's ``file_path`` as nerfstudio matches
    them, both taken as paths relative to the json's folder."""
    frames = {PurePosixPath(name): name for name in reversed(listed)}  # the first frame of a path wins
    splits: dict[str, frozenset[str]] = {}
    for key in _SPLIT_FIELDS:
        names = meta.get(key)
        if names is None:
            continue
        if not isinstance(names, list) or not all(isinstance(n, str) and n for n in names):
            raise IngestError(f"{path}: field {key!r} must be a list of frame file paths")
        unknown = [n for n in names if PurePosixPath(n) not in frames]
        if unknown:
            more = f" (and {len(unknown) - 1} more)" if len(unknown) > 1 else ""
            raise IngestError(f"{path}: field {key!r} lists {unknown[0]!r}{more}, which is no frame's file_path; "
                              "expected the file_path of a frame, relative to the json's folder as in 'frames'")
        splits[key] = frozenset(frames[PurePosixPath(n)] for n in names)
    return splits.get("val_filenames", splits.get("test_filenames"))


def _resolve_image(root: Path, name: str) -> Path | None:
    """The image file ``name`` (a frame's ``file_path``) names, relative to ``root``; ``None`` when there is none. A
    name with backslashes (written on Windows) that names no file as written is read with them as ``/`` on POSIX, as
    instant-ngp reads every ``file_path``."""
    image = _existing(root / name)
    if image is None and os.sep == "/" and "\\" in name:
        image = _existing(root / name.replace("\\", "/"))
    return image


def _existing(image: Path) -> Path | None:
    """``image`` if it is a file, else a suffix-less ``image`` with ``.png``, ``.jpg`` or ``.jpeg`` that is one."""
    if image.is_file():
        return image
    if not image.suffix:
        for suffix in (".png", ".jpg", ".jpeg"):
            if image.with_suffix(suffix).is_file():
                return image.with_suffix(suffix)
    return None


def _read_matrix(raw: dict, where: str) -> np.ndarray:
    if "transform_matrix" not in raw:
        raise IngestError(f"{where}: field 'transform_matrix' is missing")
    try:
        M = np.asarray(raw["transform_matrix"], dtype=np.float64)
    except OverflowError:  # a JSON integer beyond a float's range (10**400)
        raise IngestError(f"{where}: field 'transform_matrix' holds a number too large for a float; expected a "
                          "finite camera-to-world matrix") from None
    except (TypeError, ValueError):
        raise IngestError(f"{where}: field 'transform_matrix' is not a numeric matrix") from None
    if M.shape == (3, 4):
        M = np.vstack([M, [0.0, 0.0, 0.0, 1.0]])
    if M.shape != (4, 4):
        raise IngestError(f"{where}: field 'transform_matrix' has shape {M.shape}; expected (4, 4) or (3, 4)")
    if not np.all(np.isfinite(M)):
        raise IngestError(f"{where}: field 'transform_matrix' contains non-finite values (NaN or Inf)")
    R = M[:3, :3]
    err = float(np.abs(R.T @ R - np.eye(3)).max())
    if err > 1e-3 or np.linalg.det(R) <= 0 or not np.allclose(M[3], [0, 0, 0, 1], atol=1e-6):
        raise IngestError(
            f"{where}: field 'transform_matrix' is not a rigid camera-to-world transform "
            f"(|R^T R - I| = {err:.3g}, det(R) = {np.linalg.det(R):.4g}, last row {M[3].tolist()})"
        )
    # Rotations rounded in the file (to ~4 decimals) are accepted, then made exactly orthonormal so every
    # later check (scene files, check_pose at 1e-5) sees a proper rotation.
    M[:3, :3] = orthonormalize(R)
    return opengl_to_opencv(M)


def _number(meta: dict, raw: dict, key: str, where: str) -> float | None:
    value = raw.get(key, meta.get(key))
    if value is None:
        return None
    if isinstance(value, bool) or not isinstance(value, (int, float)) or not is_finite(value):
        big = isinstance(value, int) and not isinstance(value, bool)  # only a huge integer fails is_finite
        shown = f"an integer of {len(str(abs(value)))} digits" if big else repr(value)
        raise IngestError(f"{where}: field {key!r}={shown} must be a finite number")
    return float(value)


def _read_camera(meta: dict, raw: dict, where: str, image: Path | None, model: str, pixels: Pixels) -> Camera:
    w, h = _number(meta, raw, "w", where), _number(meta, raw, "h", where)
    if (w is None or h is None) and image is None:
        raise IngestError(f"{where}: no image size; expected fields 'w' and 'h' (the image is not there to read it)")
    for key, side in (("w", w), ("h", h)):
        if side is not None and not side.is_integer():
            raise IngestError(f"{where}: field {key!r}={side!r} must be a whole number of pixels (the image's "
                              f"{'width' if key == 'w' else 'height'})")
    if w is None or h is None:
        assert image is not None, "refused above: no size and no image"
        w, h = photo_size(image, pixels)
    fx, fy = _number(meta, raw, "fl_x", where), _number(meta, raw, "fl_y", where)
    if fx is None:
        angle_x = _number(meta, raw, "camera_angle_x", where)
        if angle_x is None:
            raise IngestError(f"{where}: no focal length; expected field 'fl_x' or 'camera_angle_x'")
        if not 0 < angle_x < math.pi:
            raise IngestError(f"{where}: field 'camera_angle_x'={angle_x!r} must be in (0, pi) radians")
        fx = 0.5 * w / math.tan(0.5 * angle_x)
    if fy is None:
        angle_y = _number(meta, raw, "camera_angle_y", where)
        if angle_y is not None:
            if not 0 < angle_y < math.pi:
                raise IngestError(f"{where}: field 'camera_angle_y'={angle_y!r} must be in (0, pi) radians")
            fy = 0.5 * h / math.tan(0.5 * angle_y)
        else:
            fy = fx
    cx = _number(meta, raw, "cx", where)
    cy = _number(meta, raw, "cy", where)
    coeffs = [_number(meta, raw, k, where) or 0.0 for k in _DISTORTION_KEYS]  # Camera drops trailing zeros
    beyond = [(k, v) for k, v in zip(_DISTORTION_KEYS[5:], coeffs[5:]) if v]
    if beyond and model != _RATIONAL_MODEL:
        key, value = beyond[0]
        meaning = ("in nerfstudio's pinhole models k4 is a radial term in r⁸ (1 + k1·r² + k2·r⁴ + k3·r⁶ + k4·r⁸), "
                   "which OpenCV's lens model cannot hold" if key == "k4" else f"it is no part of nerfstudio's {model}")
        raise IngestError(f"{where}: field {key!r}={value!r}: {meaning}; expected 0 (camera_model {_RATIONAL_MODEL} "
                          "reads k4 k5 k6 as OpenCV's rational terms)")
    try:
        return Camera.from_colmap_pixels(
            int(w), int(h), fx, fy, w / 2 if cx is None else cx, h / 2 if cy is None else cy,
            tuple(coeffs),
        )
    except N2RError as exc:
        raise IngestError(f"{where}: bad intrinsics: {exc}") from None


def write_transforms_json(
    path: str | os.PathLike, frames: list[SourceFrame] | PoseSet, *, extra: dict[str, Any] | None = None,
    pixels: Pixels | None = None,
) -> Path:
    """Write frames as a transforms.json (atomically) and return its path: nerfstudio's and instant-ngp's format, which
    both read as meant unless a lens needs ``FULL_OPENCV`` (below) or the cameras describe turned photos upright
    (``pixels``: those tools read the pixels as stored).

    ``file_path`` is the image's path relative to the json's folder when the frame knows its file
    (else the frame's name), so two pose sets of the same images can be compared frame by frame.
    Intrinsics shared by every frame are written once at the top level, otherwise per frame;
    ``camera_model`` is :func:`camera_model_of` the frames: ``OPENCV``, which nerfstudio and instant-ngp read, or
    ``FULL_OPENCV`` when a lens has OpenCV's rational terms (k4 k5 k6), which only n2r reads
    (:data:`RATIONAL_MODEL_NOTE`: tell the user).
    A pose set's own split (:attr:`PoseSet.heldout`) is written as ``train_filenames`` and ``val_filenames``
    (the same ``file_path`` strings). ``extra`` adds top-level fields (e.g. ``{"reference_length": ...}``).
    The ``n2r`` block (``extra["n2r"]``; made when absent and a photo has an EXIF orientation tag, the one case where
    it matters) gets ``pixels``: ``pixels``, else the pose set's :attr:`PoseSet.pixels`, else ``"upright"``, so the
    file reads back to the same cameras and the same pixels (:mod:`~pytest_n2r.data.transforms_pixels`).
    """
    path = Path(path)
    if pixels is None:
        pixels = frames.pixels if isinstance(frames, PoseSet) else "upright"
    if pixels not in PIXELS:
        raise IngestError(f"cannot write {path}: pixels={pixels!r} is not one of {', '.join(map(repr, PIXELS))}")
    heldout = frames.heldout if isinstance(frames, PoseSet) else None
    frames = frames.frames if isinstance(frames, PoseSet) else list(frames)
    if not frames:
        raise IngestError(f"cannot write {path}: no frames")
    cameras = [_camera_fields(f.camera) for f in frames]
    shared = cameras[0] if all(c == cameras[0] for c in cameras) else None
    out: dict[str, Any] = {"camera_model": camera_model_of(frames)}
    if shared is not None:
        out.update(shared)
    names = [_relative_name(frame, path.parent) for frame in frames]
    repeat = repeated_name(names)  # a file n2r would refuse to read back
    if repeat is not None:
        first, second, name = repeat
        raise IngestError(f"cannot write {path}: frames {first} ({frames[first].name!r}) and {second} "
                          f"({frames[second].name!r}) would both have file_path {name!r}; each frame needs a photo of "
                          "its own")
    if heldout is not None:
        out["train_filenames"] = [n for f, n in zip(frames, names) if f.name not in heldout]
        out["val_filenames"] = [n for f, n in zip(frames, names) if f.name in heldout]
    out.update(extra or {})
    block = out.get("n2r")
    if isinstance(block, dict) or tagged_count([f.path for f in frames if f.path is not None]):
        out["n2r"] = {**(block or {}), "pixels": pixels}
    records = []
    for frame, name, cam in zip(frames, names, cameras):
        record: dict[str, Any] = {"file_path": name}
        if shared is None:
            record.update(cam)
        record["transform_matrix"] = opencv_to_opengl(frame.c2w).tolist()
        records.append(record)
    out["frames"] = records
    atomic_write_text(path, json.dumps(out, indent=2) + "\n")
    return path


def camera_model_of(frames: list[SourceFrame] | PoseSet) -> str:
    """The ``camera_model`` :func:`write_transforms_json` writes for ``frames``: ``FULL_OPENCV`` when a camera has a
    non-zero rational term (k4 k5 k6: its distortion has all eight of OpenCV's coefficients, trailing zeros being
    dropped), else ``OPENCV``, which holds every other lens n2r reads (k1 k2 p1 p2 k3)."""
    frames = frames.frames if isinstance(frames, PoseSet) else frames
    return _RATIONAL_MODEL if any(len(f.camera.distortion) == 8 for f in frames) else "OPENCV"


def _camera_fields(camera: Camera) -> dict[str, float]:
    fields: dict[str, float] = {
        "w": camera.width, "h": camera.height, "fl_x": camera.fx, "fl_y": camera.fy,
        "cx": camera.cx + 0.5, "cy": camera.cy + 0.5,
    }
    for key, value in zip(_DISTORTION_KEYS, camera.distortion or (0.0, 0.0, 0.0, 0.0)):
        fields[key] = value
    return fields


def _relative_name(frame: SourceFrame, root: Path) -> str:
    if frame.path is None:
        return frame.name
    return relative_posix(frame.path, root, keep_name=True)  # a link keeps its own name: it is another frame
