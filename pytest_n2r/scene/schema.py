"""The layout of a ``.n2r`` scene file's ``scene.json`` (format version 1), built and checked here.

A scene file is a zip archive holding:

- ``scene.json``: everything but the tensors (the keys of :data:`REQUIRED_KEYS`, described in
  docs/scene-files.md);
- ``field.safetensors``: the field's tensors (:data:`pytest_n2r.field.grid.FIELD_TENSORS`);
- optionally ``images/<name>.jpg``: JPEG copies of the real photos, named by each frame's ``image`` key.

Conventions in ``scene.json``: poses ``c2w`` are camera-to-world 4x4 matrices with OpenCV axes (x right,
y down, z forward) in scene units; cameras are ideal pinhole intrinsics with OpenCV pixel centres
(:class:`~pytest_n2r.geometry.Camera`); ``normalization`` maps scene units into the field's space
(``p = (x - center) / radius``, then the contracted shell of thickness ``shell``); ``bounds`` is the
``[min, max]`` box of the captured region in scene units. Floats are written with Python's shortest
round-trip form, so poses and the field's constants come back bit for bit.
"""

from __future__ import annotations

import math
import re
from collections.abc import Sequence
from typing import Any, Literal, overload

import numpy as np

from .._validation import is_finite, repeated_name
from ..errors import InvalidArgument, InvalidType, SceneFileError
from ..geometry import Camera, check_pose
from ..render.size import MAX_SIDE

__all__ = [
    "FORMAT_NAME", "FORMAT_VERSION", "SCENE_JSON", "FIELD_FILE", "REQUIRED_KEYS", "FRAME_KEYS", "SPLITS",
    "frames_to_json", "check_header", "require", "read_frames", "read_number", "json_ready",
]

#: The ``format`` value of every pytest-n2r scene file.
FORMAT_NAME = "pytest-n2r scene"
#: The layout version this build writes and reads; bump it when a reader of the old layout would misread.
FORMAT_VERSION = 1
#: Archive member names.
SCENE_JSON = "scene.json"
FIELD_FILE = "field.safetensors"
IMAGES_DIR = "images/"
#: Top-level keys of ``scene.json``.
REQUIRED_KEYS = ("format", "version", "cameras", "frames", "normalization", "bounds", "reference_length",
                 "metres_per_unit", "field", "config", "report")
#: Keys of each entry of ``frames``.
FRAME_KEYS = ("name", "camera", "c2w", "split", "image")
SPLITS = ("train", "heldout")

_UNSAFE = re.compile(r"[^A-Za-z0-9._-]+")


def json_ready(value: Any) -> Any:
    """``value`` with NumPy scalars and arrays as plain Python values and non-finite floats as ``None``
    (strict JSON has no NaN or Infinity), so ``json.dumps(..., allow_nan=False)`` accepts it."""
    if isinstance(value, dict):
        return {str(k): json_ready(v) for k, v in value.items()}
    if isinstance(value, (list, tuple)):
        return [json_ready(v) for v in value]
    if isinstance(value, np.ndarray):
        return json_ready(value.tolist())
    if isinstance(value, np.generic):
        value = value.item()
    if isinstance(value, float) and not math.isfinite(value):
        return None
    return value


def _image_member(name: str, index: int, taken: set[str]) -> str:
    """``images/<file name without folder and extension>.jpg`` with unsafe characters replaced, unique within
    the archive (a clash gets the frame index appended)."""
    base = name.replace("\\", "/").rsplit("/", 1)[-1]
    stem = _UNSAFE.sub("_", base.rsplit(".", 1)[0] if "." in base else base).strip("._") or f"frame{index}"
    member = f"{IMAGES_DIR}{stem}.jpg"
    if member in taken:
        member = f"{IMAGES_DIR}{stem}_{index}.jpg"
    taken.add(member)
    return member


def frames_to_json(views: Sequence[Any], with_images: bool) -> tuple[list[dict], list[dict], list[str | None]]:
    """``cameras`` and ``frames`` of ``scene.json`` for ``views`` (objects with ``name``, ``camera``,
    ``c2w``, ``split`` and ``image``), and each frame's image member (``None``: no image stored)."""
    repeat = repeated_name(v.name for v in views)
    if repeat is not None:
        raise InvalidArgument(f"views [{repeat[0]}] and [{repeat[1]}] are both named {repeat[2]!r}; a scene file "
                              "holds one view a name")
    cameras = list(dict.fromkeys(v.camera for v in views))
    camera_index = {cam: i for i, cam in enumerate(cameras)}
    frames: list[dict] = []
    members: list[str | None] = []
    taken: set[str] = set()
    for i, v in enumerate(views):
        if v.split not in SPLITS:
            raise InvalidArgument(f"view {v.name!r} has split={v.split!r}; expected one of {SPLITS}")
        member = _image_member(v.name, i, taken) if with_images and v.image is not None else None
        members.append(member)
        frames.append({"name": v.name, "camera": camera_index[v.camera],
                       "c2w": np.asarray(v.c2w, dtype=np.float64).tolist(), "split": v.split, "image": member})
    return [c.to_dict() for c in cameras], frames, members


def require(data: Any, key: str, where: str, source: str) -> Any:
    """``data[key]``, or a :class:`SceneFileError` naming the file, the place in ``scene.json`` and the key."""
    if not isinstance(data, dict):
        raise SceneFileError(f"{source}: {where} must be a JSON object, found {type(data).__name__}")
    if key not in data:
        raise SceneFileError(f"{source}: {where} has no {key!r} key")
    return data[key]


@overload
def read_number(data: dict, key: str, source: str, *, positive: bool = True, optional: Literal[False] = False
                ) -> float: ...
@overload
def read_number(data: dict, key: str, source: str, *, positive: bool = True, optional: bool) -> float | None: ...
def read_number(data: dict, key: str, source: str, *, positive: bool = True, optional: bool = False) -> float | None:
    """A finite (positive, unless ``positive=False``) number of ``scene.json``; ``None`` allowed if ``optional``."""
    value = require(data, key, SCENE_JSON, source)
    if value is None and optional:
        return None
    if isinstance(value, bool) or not isinstance(value, (int, float)) or not is_finite(value) \
            or (positive and value <= 0):
        kind = "a finite number > 0" + (" or null" if optional else "")
        raise SceneFileError(f"{source}: {SCENE_JSON} {key}={value!r}; expected {kind}")
    return float(value)


def check_header(data: Any, source: str) -> None:
    """Check the format name, the version and the presence of every top-level key."""
    if not isinstance(data, dict):
        raise SceneFileError(f"{source}: {SCENE_JSON} must hold a JSON object, found {type(data).__name__}")
    if data.get("format") != FORMAT_NAME:
        raise SceneFileError(f"{source}: {SCENE_JSON} has format={data.get('format')!r}; expected "
                             f"{FORMAT_NAME!r} (this is not a pytest-n2r scene file)")
    version = data.get("version")
    if version != FORMAT_VERSION:
        hint = ("it was written by a newer pytest-n2r; upgrade pytest-n2r to read it"
                if isinstance(version, int) and version > FORMAT_VERSION
                else "refit the scene with `n2r fit` to write the current format")
        raise SceneFileError(f"{source}: scene file format version {version!r}; this pytest-n2r reads version "
                             f"{FORMAT_VERSION} ({hint})")
    missing = [k for k in REQUIRED_KEYS if k not in data]
    if missing:
        raise SceneFileError(f"{source}: {SCENE_JSON} is missing the keys {missing}")


def read_frames(data: dict, source: str) -> list[tuple[str, Camera, np.ndarray, str, str | None]]:
    """``(name, camera, c2w, split, image member)`` of each frame of ``scene.json``, checked (names unique)."""
    records = require(data, "cameras", SCENE_JSON, source)
    if not isinstance(records, list) or not records:
        raise SceneFileError(f"{source}: {SCENE_JSON} 'cameras' must be a non-empty list of camera objects")
    cameras = []
    for i, record in enumerate(records):
        if not isinstance(record, dict):
            raise SceneFileError(f"{source}: {SCENE_JSON} cameras[{i}]={record!r}; expected a camera object")
        for key in ("width", "height"):
            side = record.get(key)
            if isinstance(side, bool) or not isinstance(side, int) or not 1 <= side <= MAX_SIDE:
                raise SceneFileError(f"{source}: {SCENE_JSON} cameras[{i}].{key}={side!r}; expected a whole "
                                     f"number of pixels in 1..{MAX_SIDE}")
        try:
            cameras.append(Camera.from_dict(record))
        except (InvalidArgument, InvalidType, TypeError, ValueError) as exc:
            raise SceneFileError(f"{source}: {SCENE_JSON} cameras[{i}] is not a valid camera ({exc})") from None
    frames = require(data, "frames", SCENE_JSON, source)
    if not isinstance(frames, list) or not frames:
        raise SceneFileError(f"{source}: {SCENE_JSON} 'frames' must be a non-empty list")
    out = []
    for i, frame in enumerate(frames):
        where = f"frames[{i}]"
        name, cam, c2w, split, image = (require(frame, k, where, source) for k in FRAME_KEYS)
        if not isinstance(name, str) or not name:
            raise SceneFileError(f"{source}: {where}.name={name!r}; expected a non-empty string")
        if isinstance(cam, bool) or not isinstance(cam, int) or not 0 <= cam < len(cameras):
            raise SceneFileError(f"{source}: {where}.camera={cam!r}; expected an index into the "
                                 f"{len(cameras)} cameras")
        try:
            pose = check_pose(np.asarray(c2w, dtype=np.float64), f"{where}.c2w")
        except OverflowError:  # a JSON integer beyond float's range, such as 10**400
            raise SceneFileError(f"{source}: {SCENE_JSON} {where}.c2w holds a number beyond float's range (expected a "
                                 "rigid 4x4 camera-to-world matrix)") from None
        except (InvalidArgument, InvalidType, TypeError, ValueError) as exc:
            raise SceneFileError(f"{source}: {exc} (expected a rigid 4x4 camera-to-world matrix)") from None
        if split not in SPLITS:
            raise SceneFileError(f"{source}: {where}.split={split!r}; expected one of {SPLITS}")
        if image is not None and not (isinstance(image, str) and image.startswith(IMAGES_DIR)):
            raise SceneFileError(f"{source}: {where}.image={image!r}; expected null or '{IMAGES_DIR}<name>.jpg'")
        out.append((name, cameras[cam], pose, split, image))
    repeat = repeated_name(frame[0] for frame in out)
    if repeat is not None:
        raise SceneFileError(f"{source}: {SCENE_JSON} frames[{repeat[0]}] and frames[{repeat[1]}] are both named "
                             f"{repeat[2]!r}; expected one frame a name")
    return out
