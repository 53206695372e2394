"""Writing and reading ``.n2r`` scene files: a zip of ``scene.json``, ``field.safetensors`` and optional
JPEG copies of the photos (layout in :mod:`pytest_n2r.scene.schema` and docs/scene-files.md).

Writing is atomic (a temporary file renamed over the target, so a reader or a crash never sees half a
file) and deterministic: the same field, views and report give the same bytes (fixed member order and
timestamps). Reading never unpickles anything and checks the format, the version, the keys, the tensor
names and shapes and the images, raising :class:`~pytest_n2r.errors.SceneFileError` naming what is wrong.
"""

from __future__ import annotations

import dataclasses
import functools
import hashlib
import json
import math
import os
import zipfile
from collections.abc import Callable, Sequence
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np

from .._validation import as_unit_rgb
from ..data.atomic import atomic_write_bytes
from ..data.capture import Capture
from ..errors import InvalidArgument, SceneFileError
from ..field.config import FieldConfig
from ..field.grid import SceneField, check_field_metadata
from . import schema
from .archive import StoredMember, read_member, read_scene_json, zip_bytes
from .base import MAX_CAMERA_DISTANCE, SceneView
from .field_member import decode_field, field_limit
from .memory_guard import check_memory

__all__ = ["save_scene", "read_scene_file", "check_scene_file", "SceneFile"]

@dataclass(frozen=True, eq=False)
class SceneFile:
    """The contents of a scene file, checked (the field on the CPU).

    ``views`` carry their real photos (H×W×3 uint8 RGB) when the file stores them and they were read;
    ``bounds`` is the ``(2, 3)`` box ``[min, max]`` of the captured region and ``reference_length`` the
    median z-depth of the surface seen by the training cameras, both in scene units; ``field_digest`` is the
    SHA-256 of the stored ``field.safetensors`` member (as stored in the archive, with its compression method,
    size and CRC-32: a digest that needs no inflating) and of the field's settings in ``scene.json`` that
    change its pixels (normalization, density shift, background); ``background`` the field's (RGB in [0, 1]);
    ``size_bytes`` the size of the file. :attr:`field` is decoded from the member's stored bytes when first
    used (at once unless the file was read with ``lazy_field=True``).
    """

    path: Path
    version: int
    views: tuple[SceneView, ...]
    config: FieldConfig
    report: dict
    reference_length: float
    metres_per_unit: float | None
    bounds: np.ndarray
    field_digest: str
    background: tuple[float, float, float]
    size_bytes: int
    images_stored: int
    decode_field: Callable[[], SceneField] = dataclasses.field(repr=False)

    @functools.cached_property
    def field(self) -> SceneField:
        """The scene field (decoded and checked on first use; a :class:`SceneFileError` if it does not check)."""
        return self.decode_field()


def _field_digest(member_digest: str, field_meta: dict) -> str:
    """SHA-256 of the field member's digest and the field's settings read from ``scene.json`` (its space, density
    shift, background): two files whose tensors agree but whose settings differ render different pixels."""
    settings = json.dumps(field_meta, sort_keys=True).encode()
    return hashlib.sha256(member_digest.encode() + b"/" + settings).hexdigest()


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
    for name, value in (("reference_length", reference_length), ("metres_per_unit", metres_per_unit)):
        if value is not None and not (isinstance(value, (int, float, np.floating)) and math.isfinite(value)
                                      and value > 0):
            raise InvalidArgument(f"save_scene: {name}={value!r}; expected a finite number > 0 (scene units)")

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
    try:  # what a reader checks, checked before writing: never replace a file with one that cannot be read
        _check_json(json.loads(text), f"save_scene({str(path)!r})")
    except SceneFileError as exc:
        raise InvalidArgument(f"{exc} (nothing was written)") from None
    # Deflate level 1 for the field: float16 values barely compress at any level (measured on a 160³ field,
    # 1.36 M stored vertices: 33.5 MiB in 1.6 s at level 1, 33.2 MiB in 2.5 s at level 6); JPEGs are stored.
    tensors = field.tensors()
    if not tensors["vertex_values"].isfinite().all():  # NaN, or beyond float16's ±65504
        raise InvalidArgument("save_scene: the field holds NaN or values beyond float16's ±65504, which a scene "
                              "file cannot store (nothing was written); the fit diverged")
    entries: list[tuple[str, bytes, int, int | None]] = [
        (schema.SCENE_JSON, text.encode("utf-8"), zipfile.ZIP_DEFLATED, 6),
        (schema.FIELD_FILE, safetensors.torch.save(tensors), zipfile.ZIP_DEFLATED, 1)]
    for view, member in zip(views, members):
        if member is not None:
            assert view.image is not None, "frames_to_json names a member only for a view with an image"
            entries.append((member, _encode_jpeg(view.image, image_quality, view.name), zipfile.ZIP_STORED, None))
    return atomic_write_bytes(path, zip_bytes(entries))


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


def _jpeg_size(payload: bytes) -> tuple[int, int] | None:
    """``(width, height)`` from a JPEG's start-of-frame marker, read before decoding (so a photo claiming
    60 000 × 60 000 pixels is refused without inflating it); ``None`` when no marker is found."""
    i = 2 if payload[:2] == b"\xff\xd8" else len(payload)
    while i + 9 <= len(payload):
        if payload[i] != 0xFF:
            return None
        marker, length = payload[i + 1], int.from_bytes(payload[i + 2:i + 4], "big")
        if 0xC0 <= marker <= 0xCF and marker not in (0xC4, 0xC8, 0xCC):
            return int.from_bytes(payload[i + 7:i + 9], "big"), int.from_bytes(payload[i + 5:i + 7], "big")
        i += 2 + length
    return None


def _decode_jpeg(payload: bytes, member: str, name: str, source: str, width: int, height: int) -> np.ndarray:
    """The photo of frame ``name`` (H×W×3 uint8 RGB), which must be ``width`` × ``height`` pixels."""
    import cv2

    declared = _jpeg_size(payload)
    if declared is not None and declared != (width, height):
        raise SceneFileError(f"{source}: {member} is {declared[0]}x{declared[1]} pixels; frame {name!r} has a "
                             f"{width}x{height} camera")
    image = cv2.imdecode(np.frombuffer(payload, dtype=np.uint8), cv2.IMREAD_COLOR) if declared else None
    if image is None:
        raise SceneFileError(f"{source}: {member} (the photo of frame {name!r}) does not decode as a JPEG image")
    if image.shape[:2] != (height, width):
        raise SceneFileError(f"{source}: {member} is {image.shape[1]}x{image.shape[0]} pixels; frame {name!r} has "
                             f"a {width}x{height} camera")
    return np.ascontiguousarray(image[:, :, ::-1])  # BGR → RGB


def _read_photos(archive: zipfile.ZipFile, frames: list, source: str) -> dict[str, np.ndarray]:
    """The photos of ``frames`` by member name, each member decoded once (frames naming the same one share its
    array), once their decoded size (3 bytes a pixel, over the distinct members) is known to fit in memory."""
    sizes: dict[str, int] = {}
    for _, camera, _, _, member in frames:
        if member is not None:
            sizes.setdefault(member, 3 * camera.width * camera.height)
    check_memory(sum(sizes.values()), f"{source}: {schema.SCENE_JSON}",
                 f"the {len(sizes)} photos its frames name (width x height of their cameras)")
    photos: dict[str, np.ndarray] = {}
    try:
        for name, camera, _, _, member in frames:
            if member is None:
                continue
            if member not in photos:
                limit = 6 * camera.width * camera.height + 2**20  # a JPEG is smaller than twice its pixels
                payload = read_member(archive, member, source, limit, f"a {camera.width}x{camera.height} photo")
                photos[member] = _decode_jpeg(payload, member, name, source, camera.width, camera.height)
            elif photos[member].shape[:2] != (camera.height, camera.width):
                shape = photos[member].shape
                raise SceneFileError(f"{source}: {member} is {shape[1]}x{shape[0]} pixels; frame {name!r} has a "
                                     f"{camera.width}x{camera.height} camera")
    except MemoryError:
        raise SceneFileError(f"{source}: its photos do not fit in the memory free (decoding {len(photos) + 1} of "
                             f"{len(sizes)}); read it with images=False") from None
    return photos


#: How far the field's normalization may stray from the scene's own scale, in reference lengths: a fit
#: sets its radius to half the captured region (cameras included), a few reference lengths.
_MAX_NORMALIZATION_RATIO = 1e4


def _check_normalization(space: Any, reference_length: float, bounds: np.ndarray, source: str) -> None:
    """The field's normalization must fit the scene it belongs to: a radius within a factor
    :data:`_MAX_NORMALIZATION_RATIO` of the reference length and a centre within as many reference lengths
    of the bounds (otherwise every ray misses the grid or crosses it in one sample: a flat image)."""
    where = f"{source}: {schema.SCENE_JSON} normalization"
    if not isinstance(space, dict):
        raise SceneFileError(f"{where} must be a JSON object with center, radius and shell")
    radius, center = space.get("radius"), space.get("center")
    limit = _MAX_NORMALIZATION_RATIO
    if isinstance(radius, bool) or not isinstance(radius, (int, float)) \
            or not reference_length / limit <= radius <= reference_length * limit:
        raise SceneFileError(f"{where}.radius={radius!r}; expected a number within a factor {limit:g} of the "
                             f"reference length {reference_length:.4g} (scene units)")
    try:
        offset = np.abs(np.asarray(center, dtype=np.float64) - bounds.mean(axis=0))
    except (TypeError, ValueError, OverflowError):
        offset = np.full(3, np.nan)
    if offset.shape != (3,) or not offset.max() <= reference_length * limit:
        raise SceneFileError(f"{where}.center={center!r}; expected three numbers within {limit:g} reference "
                             f"lengths ({reference_length * limit:.4g} scene units) of the bounds' centre")


def _check_json(data: Any, source: str) -> tuple[list, float, float | None, np.ndarray, FieldConfig, dict]:
    """Check a parsed ``scene.json`` (what :func:`read_scene_file` and, before writing, :func:`save_scene`
    do); return its frames, reference length, metres per unit, bounds, config and field metadata."""
    schema.check_header(data, source)
    frames = schema.read_frames(data, source)
    reference_length = schema.read_number(data, "reference_length", source)
    metres_per_unit = schema.read_number(data, "metres_per_unit", source, optional=True)
    try:
        bounds = np.asarray(data["bounds"], dtype=np.float64)
    except (TypeError, ValueError, OverflowError):  # OverflowError: an integer such as 10**400
        bounds = np.zeros(0)
    if bounds.shape != (2, 3) or not np.isfinite(bounds).all() or not (bounds[0] <= bounds[1]).all():
        raise SceneFileError(f"{source}: {schema.SCENE_JSON} bounds={data['bounds']!r}; expected [[min x, y, z], "
                             "[max x, y, z]] (scene units, each min at most its max)")
    _check_normalization(data["normalization"], reference_length, bounds, source)
    limit = MAX_CAMERA_DISTANCE * reference_length
    for i, (_, _, c2w, _, _) in enumerate(frames):
        offset = float(np.abs(c2w[:3, 3] - bounds.mean(axis=0)).max())
        if not offset <= limit:
            raise SceneFileError(f"{source}: {schema.SCENE_JSON} frames[{i}].c2w puts the camera {offset:.3g} scene "
                                 f"units from the bounds' centre; expected within {MAX_CAMERA_DISTANCE:g} reference "
                                 f"lengths ({limit:.4g} scene units), where renders are defined")
    try:
        config = FieldConfig.from_dict(data["config"])
    except (InvalidArgument, TypeError) as exc:
        raise SceneFileError(f"{source}: {schema.SCENE_JSON} 'config' is not a valid FieldConfig ({exc})") from None
    if not isinstance(data["report"], dict):
        raise SceneFileError(f"{source}: {schema.SCENE_JSON} 'report' must be a JSON object")
    field_meta = schema.require(data, "field", schema.SCENE_JSON, source)
    if not isinstance(field_meta, dict):
        raise SceneFileError(f"{source}: {schema.SCENE_JSON} 'field' must be a JSON object")
    if "background" not in field_meta:
        # written before fields stored their background: a fit whose config has random_background on was
        # composited over random colours (mid-grey in expectation), an older one over black
        grey = data["config"].get("random_background") is True
        field_meta = {**field_meta, "background": [0.5 if grey else 0.0] * 3}
    field_meta = {**field_meta, "space": data["normalization"]}
    check_field_metadata(field_meta, f"{source}: {schema.SCENE_JSON}")
    return frames, reference_length, metres_per_unit, bounds, config, field_meta


def open_scene_archive(path: Path, name: str | None = None) -> zipfile.ZipFile:
    """The zip archive of the scene file at ``path``, else a :class:`~pytest_n2r.errors.SceneFileError` that starts
    with ``name`` (default: the path) and says what is wrong (a folder, no file, not a zip archive, truncated)."""
    source = str(path) if name is None else name
    if path.is_dir():
        raise SceneFileError(f"{source}: is a folder; expected a .n2r scene file (`n2r fit SOURCE -o scene.n2r` "
                             "writes one)")
    if not path.is_file():
        raise SceneFileError(f"{source}: no such scene file (`n2r fit SOURCE -o {path.name}` writes one)")
    try:
        return zipfile.ZipFile(path)
    except (zipfile.BadZipFile, OSError) as exc:
        raise SceneFileError(f"{source}: not a zip archive, or truncated ({exc}); a .n2r scene file is the zip "
                             "archive `n2r fit` writes") from None
    except (NotImplementedError, RuntimeError) as exc:  # e.g. "zip file version 9.1" in the central directory
        raise SceneFileError(f"{source}: not a zip archive this reader can open ({exc}); a .n2r scene file is the "
                             "zip archive `n2r fit` writes") from None


def check_scene_file(path: str | os.PathLike) -> None:
    """The checks of :func:`read_scene_file` that need no inflating of the field or the photos (its
    ``scene.json`` and the field's declared tensors), in a fraction of the time; raises
    :class:`~pytest_n2r.errors.SceneFileError` the same way. Splat scenes (a ``.ply``, or a scene file
    ``n2r import`` wrote) are left to their own reader, past the cap on ``scene.json``."""
    path = Path(path)
    if path.suffix.lower() == ".ply":  # a 3DGS splat scene: its reader checks it
        return
    with open_scene_archive(path) as archive:
        data = read_scene_json(archive, str(path))
        if isinstance(data, dict) and data.get("representation") == "splats":  # `n2r import`: its reader checks it
            return
        field_meta = _check_json(data, str(path))[-1]
        field_limit(archive, field_meta, str(path))


def read_scene_file(path: str | os.PathLike, *, images: bool = True, lazy_field: bool = False) -> SceneFile:
    """Read and check the scene file ``path``; ``images=False`` skips decoding the stored photos.

    Raises :class:`~pytest_n2r.errors.SceneFileError` when the file is missing, not a zip or truncated, has
    no ``scene.json``, is of another format or version, lacks keys, or holds missing or mis-shaped tensors
    or an image that does not decode. ``lazy_field=True`` leaves inflating and checking the field's tensors
    to the first use of :attr:`SceneFile.field` (which raises then): a session whose renders all come from
    the render cache needs only the scene's views and content hash (on the demo twins 0.3-0.5 s a scene).
    """
    path = Path(path)
    source = str(path)
    archive = open_scene_archive(path)
    size = path.stat().st_size
    with archive:
        data = read_scene_json(archive, source)
        frames, reference_length, metres_per_unit, bounds, config, field_meta = _check_json(data, source)
        limit = field_limit(archive, field_meta, source)
        stored = StoredMember.read(archive, path, schema.FIELD_FILE, source, limit, "its safetensors header")
        background = as_unit_rgb(field_meta["background"])
        assert background is not None, "checked by _check_json"
        photos = _read_photos(archive, frames, source) if images else {}
        views = [SceneView(index, name, camera, c2w, split, photos.get(member))
                 for index, (name, camera, c2w, split, member) in enumerate(frames)]
    scene = SceneFile(
        path=path, version=schema.FORMAT_VERSION, views=tuple(views), config=config, report=data["report"],
        reference_length=reference_length, metres_per_unit=metres_per_unit, bounds=bounds,
        field_digest=_field_digest(stored.digest, field_meta), background=background, size_bytes=size,
        images_stored=sum(m is not None for *_, m in frames),
        decode_field=functools.partial(decode_field, stored, field_meta, source),
    )
    if not lazy_field:
        scene.field  # noqa: B018 - decoded and checked now: a bad field fails the read
    return scene
