"""Writing and reading ``.n2r`` scene files: a zip of ``scene.json``, ``field.safetensors`` and optional
JPEG copies of the photos (layout in :mod:`pytest_n2r.scene.schema` and docs/scene-files.md).

Writing is atomic (a temporary file renamed over the target, so a reader or a crash never sees half a
file) and deterministic: the same field, views and report give the same bytes (fixed member order and
timestamps). Reading never unpickles anything and checks the format, the version, the keys, the tensor
names and shapes and the images, raising :class:`~pytest_n2r.errors.SceneFileError` naming what is wrong.
"""

from __future__ import annotations

import hashlib
import io
import json
import os
import zipfile
import zlib
from collections.abc import Sequence
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np

from ..data.atomic import atomic_write_bytes
from ..data.capture import Capture
from ..errors import InvalidArgument, SceneFileError
from ..field.config import FieldConfig
from ..field.grid import SceneField
from . import schema
from .base import SceneView

__all__ = ["save_scene", "read_scene_file", "SceneFile"]

#: Every member's timestamp (the earliest a zip can hold), so the bytes do not depend on when they were written.
_ZIP_TIME = (1980, 1, 1, 0, 0, 0)


@dataclass(frozen=True, eq=False)
class SceneFile:
    """The contents of a scene file, checked (the field on the CPU).

    ``views`` carry their real photos (H×W×3 uint8 RGB) when the file stores them and they were read;
    ``bounds`` is the ``(2, 3)`` box ``[min, max]`` of the captured region and ``reference_length`` the
    median z-depth of the surface seen by the training cameras, both in scene units; ``field_digest`` is the
    SHA-256 of the stored ``field.safetensors`` bytes; ``size_bytes`` the size of the file.
    """

    path: Path
    version: int
    views: tuple[SceneView, ...]
    field: SceneField
    config: FieldConfig
    report: dict
    reference_length: float
    metres_per_unit: float | None
    bounds: np.ndarray
    field_digest: str
    size_bytes: int
    images_stored: int


def save_scene(
    path: str | os.PathLike,
    field: SceneField,
    config: FieldConfig,
    capture_or_views: Capture | Sequence[Any],
    report: dict,
    *,
    images: bool = True,
    image_quality: int = 95,
    reference_length: float | None = None,
    bounds: np.ndarray | None = None,
    metres_per_unit: float | None = None,
) -> Path:
    """Write ``field`` and the views it was fitted to as the scene file ``path`` (atomically); return the path.

    Parameters
    ----------
    field, config, report:
        The fitted field (stored as float16 at the vertices of occupied cells), the
        :class:`~pytest_n2r.field.config.FieldConfig` it was fitted with and the fit report (JSON-ready values;
        NaN and infinities are stored as ``null``).
    capture_or_views:
        A :class:`~pytest_n2r.data.Capture` (its views, bounds and reference length), or a sequence of views
        (:class:`~pytest_n2r.scene.SceneView` or :class:`~pytest_n2r.data.CapturedView`), which then needs
        ``reference_length``.
    images:
        Store JPEG copies (``image_quality`` 1..100) of the views' photos, for realness checks and reports.
    reference_length, bounds:
        Override the capture's (scene units). Without a capture, ``bounds`` defaults to the field's unit
        cube (``center ± radius``).
    metres_per_unit:
        Metres per scene unit when the capture's scale is known (enables ``units="metres"``).
    """
    if isinstance(capture_or_views, Capture):
        views = list(capture_or_views.views)
        reference_length = capture_or_views.reference_length if reference_length is None else reference_length
        bounds = capture_or_views.bounds if bounds is None else bounds
    else:
        views = list(capture_or_views)
        if reference_length is None:
            raise InvalidArgument("save_scene: reference_length is required when views are passed without a Capture")
    if not views:
        raise InvalidArgument("save_scene: capture_or_views holds no views; a scene file needs at least one")
    if bounds is None:
        c, r = np.asarray(field.space.center), field.space.radius
        bounds = np.stack([c - r, c + r])
    bounds = np.asarray(bounds, dtype=np.float64)
    if bounds.shape != (2, 3) or not np.isfinite(bounds).all():
        raise InvalidArgument(f"save_scene: bounds has shape {bounds.shape}; expected a finite (2, 3) box [min, max]")
    if isinstance(image_quality, bool) or not isinstance(image_quality, int) or not 1 <= image_quality <= 100:
        raise InvalidArgument(f"save_scene: image_quality={image_quality!r}; expected an integer in 1..100")
    if not isinstance(config, FieldConfig):
        raise InvalidArgument(f"save_scene: config must be a FieldConfig, got {type(config).__name__}")

    import safetensors.torch

    cameras, frames, members = schema.frames_to_json(views, images)
    field_meta = field.metadata()
    data = {
        "format": schema.FORMAT_NAME,
        "version": schema.FORMAT_VERSION,
        "cameras": cameras,
        "frames": frames,
        "normalization": field_meta.pop("space"),
        "bounds": bounds.tolist(),
        "reference_length": float(reference_length),
        "metres_per_unit": None if metres_per_unit is None else float(metres_per_unit),
        "field": field_meta,
        "config": config.to_dict(),
        "report": report,
    }
    text = json.dumps(schema.json_ready(data), indent=1, allow_nan=False)
    # Deflate level 1 for the field: float16 values barely compress at any level (measured on a 160³ field,
    # 1.36 M stored vertices: 33.5 MiB in 1.6 s at level 1, 33.2 MiB in 2.5 s at level 6); JPEGs are stored.
    entries = [(schema.SCENE_JSON, text.encode("utf-8"), zipfile.ZIP_DEFLATED, 6),
               (schema.FIELD_FILE, safetensors.torch.save(field.tensors()), zipfile.ZIP_DEFLATED, 1)]
    for view, member in zip(views, members):
        if member is not None:
            entries.append((member, _encode_jpeg(view.image, image_quality, view.name), zipfile.ZIP_STORED, None))
    return atomic_write_bytes(path, _zip_bytes(entries))


def _zip_bytes(entries: list[tuple[str, bytes, int, int | None]]) -> bytes:
    """A zip archive of ``(name, data, compression, level)`` in the given order, with fixed timestamps and
    modes."""
    buffer = io.BytesIO()
    with zipfile.ZipFile(buffer, "w") as archive:
        for name, payload, compression, level in entries:
            info = zipfile.ZipInfo(name, date_time=_ZIP_TIME)
            info.compress_type = compression
            info.create_system = 3  # Unix, whatever the platform, so the bytes match everywhere
            info.external_attr = 0o644 << 16
            archive.writestr(info, payload, compresslevel=level)
    return buffer.getvalue()


def _encode_jpeg(image: np.ndarray, quality: int, name: str) -> bytes:
    import cv2

    image = np.asarray(image)
    if image.dtype != np.uint8 or image.ndim != 3 or image.shape[2] != 3:
        raise InvalidArgument(f"view {name!r}: image is {image.dtype} {image.shape}; expected H×W×3 uint8 RGB")
    ok, encoded = cv2.imencode(".jpg", np.ascontiguousarray(image[:, :, ::-1]),  # OpenCV wants BGR
                               [cv2.IMWRITE_JPEG_QUALITY, quality])
    if not ok:
        raise InvalidArgument(f"view {name!r}: OpenCV could not encode the image as JPEG")
    return encoded.tobytes()


def _decode_jpeg(payload: bytes, member: str, name: str, source: str) -> np.ndarray:
    import cv2

    image = cv2.imdecode(np.frombuffer(payload, dtype=np.uint8), cv2.IMREAD_COLOR) if payload else None
    if image is None:
        raise SceneFileError(f"{source}: {member} (the photo of frame {name!r}) does not decode as an image")
    return np.ascontiguousarray(image[:, :, ::-1])  # BGR → RGB


def _member(archive: zipfile.ZipFile, name: str, source: str) -> bytes:
    """The bytes of member ``name``, or a :class:`SceneFileError` saying it is missing or corrupt."""
    try:
        return archive.read(name)
    except KeyError:
        raise SceneFileError(f"{source}: the archive has no {name!r}") from None
    except (zipfile.BadZipFile, zlib.error, EOFError, OSError) as exc:
        raise SceneFileError(f"{source}: {name!r} is corrupt or truncated ({exc})") from None


def read_scene_file(path: str | os.PathLike, *, images: bool = True) -> SceneFile:
    """Read and check the scene file ``path``; ``images=False`` skips decoding the stored photos.

    Raises :class:`~pytest_n2r.errors.SceneFileError` when the file is missing, not a zip or truncated, has
    no ``scene.json``, is of another format or version, lacks keys, or holds missing or mis-shaped tensors
    or an image that does not decode.
    """
    import safetensors
    import safetensors.torch

    path = Path(path)
    source = str(path)
    if not path.is_file():
        raise SceneFileError(f"{source}: no such scene file (`n2r fit SOURCE -o {path.name}` writes one)")
    size = path.stat().st_size
    try:
        archive = zipfile.ZipFile(path)
    except (zipfile.BadZipFile, OSError) as exc:
        raise SceneFileError(f"{source}: not a zip archive, or truncated ({exc}); a .n2r scene file is the zip "
                             "archive `n2r fit` writes") from None
    with archive:
        try:
            data = json.loads(_member(archive, schema.SCENE_JSON, source))
        except (json.JSONDecodeError, UnicodeDecodeError) as exc:
            raise SceneFileError(f"{source}: {schema.SCENE_JSON} is not valid JSON ({exc})") from None
        schema.check_header(data, source)
        frames = schema.read_frames(data, source)
        reference_length = schema.read_number(data, "reference_length", source)
        metres_per_unit = schema.read_number(data, "metres_per_unit", source, optional=True)
        try:
            bounds = np.asarray(data["bounds"], dtype=np.float64)
        except (TypeError, ValueError):
            bounds = np.zeros(0)
        if bounds.shape != (2, 3) or not np.isfinite(bounds).all():
            raise SceneFileError(f"{source}: {schema.SCENE_JSON} bounds={data['bounds']!r}; expected [[min x, y, z], "
                                 "[max x, y, z]] (scene units)")
        try:
            config = FieldConfig.from_dict(data["config"])
        except (InvalidArgument, TypeError) as exc:
            raise SceneFileError(f"{source}: {schema.SCENE_JSON} 'config' is not a valid FieldConfig ({exc})") from None
        if not isinstance(data["report"], dict):
            raise SceneFileError(f"{source}: {schema.SCENE_JSON} 'report' must be a JSON object")
        field_meta = schema.require(data, "field", schema.SCENE_JSON, source)
        if not isinstance(field_meta, dict):
            raise SceneFileError(f"{source}: {schema.SCENE_JSON} 'field' must be a JSON object")
        payload = _member(archive, schema.FIELD_FILE, source)
        try:
            tensors = safetensors.torch.load(payload)
        except safetensors.SafetensorError as exc:
            raise SceneFileError(f"{source}: {schema.FIELD_FILE} is not a valid safetensors file ({exc})") from None
        if "background" not in field_meta:
            # written before fields stored their background: a fit whose config has random_background on was
            # composited over random colours (mid-grey in expectation), an older one over black
            grey = data["config"].get("random_background") is True
            field_meta = {**field_meta, "background": [0.5 if grey else 0.0] * 3}
        field = SceneField.from_tensors({**field_meta, "space": data["normalization"]}, tensors,
                                        f"{source}: {schema.FIELD_FILE}")
        views = []
        for index, (name, camera, c2w, split, member) in enumerate(frames):
            image = None
            if images and member is not None:
                image = _decode_jpeg(_member(archive, member, source), member, name, source)
                if image.shape[:2] != (camera.height, camera.width):
                    raise SceneFileError(f"{source}: {member} is {image.shape[1]}x{image.shape[0]} pixels; frame "
                                         f"{name!r} has a {camera.width}x{camera.height} camera")
            views.append(SceneView(index, name, camera, c2w, split, image))
    return SceneFile(
        path=path, version=schema.FORMAT_VERSION, views=tuple(views), field=field, config=config,
        report=data["report"], reference_length=reference_length, metres_per_unit=metres_per_unit,
        bounds=bounds, field_digest=hashlib.sha256(payload).hexdigest(), size_bytes=size,
        images_stored=sum(m is not None for *_, m in frames),
    )
