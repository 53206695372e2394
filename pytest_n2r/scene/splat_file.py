"""A splat scene packed into a ``.n2r`` scene file: the Gaussians and their cameras in one zip.

The zip holds ``scene.json`` (the same header, ``cameras``, ``frames``, ``bounds``, ``reference_length``
and ``metres_per_unit`` as a fitted scene's, see :mod:`pytest_n2r.scene.schema`, plus
``"representation": "splats"``, a ``splats`` object with the count, SH degree and background, and the
``report`` of the import) and ``splats.safetensors`` with the Gaussians' float32 arrays
(:data:`pytest_n2r.splats.gaussians.TENSORS`), exactly as read from the ``.ply``, so a packed scene renders
the same bits as its ply. No pickle anywhere: a scene file never runs code. Writing is atomic and
deterministic.
"""

from __future__ import annotations

import json
import math
import os
import zipfile
from pathlib import Path

from .._validation import as_unit_rgb
from ..data.atomic import atomic_write_bytes
from ..data.extent import scene_bounds
from ..errors import InvalidArgument, SceneFileError
from ..render.splat_render import SplatSettings
from ..splats.gaussians import TENSORS, Gaussians
from . import schema
from .archive import read_member, read_scene_json, zip_bytes
from .base import SceneView
from .memory_guard import check_memory, decode_failure
from .splat_scene import SplatScene

__all__ = ["REPRESENTATION", "SPLATS_FILE", "is_splat_file", "read_splat_file", "save_splat_scene",
           "splat_info"]

#: The archive member holding the Gaussians.
SPLATS_FILE = "splats.safetensors"
#: The ``representation`` value of a splat scene file.
REPRESENTATION = "splats"
_KEYS = ("format", "version", "representation", "cameras", "frames", "bounds", "reference_length",
         "metres_per_unit", "splats", "report")


def is_splat_file(path: str | os.PathLike) -> bool:
    """Whether ``path`` is a zip whose ``scene.json`` says ``"representation": "splats"``."""
    from .archive import MAX_JSON_BYTES

    try:
        with zipfile.ZipFile(path) as archive:
            if archive.getinfo(schema.SCENE_JSON).file_size > MAX_JSON_BYTES:
                return False  # the field reader names the oversized member
            data = json.loads(archive.read(schema.SCENE_JSON))
    except (OSError, KeyError, zipfile.BadZipFile, ValueError, RecursionError, NotImplementedError, RuntimeError):
        return False  # NotImplementedError: "zip file version 9.1"; the field reader names what is wrong
    return isinstance(data, dict) and data.get("representation") == REPRESENTATION


def save_splat_scene(path: str | os.PathLike, scene: SplatScene, report: dict | None = None) -> Path:
    """Write ``scene`` (with its views) as the ``.n2r`` file ``path``, atomically; return the path.

    ``report`` (JSON-ready) records where it came from. ``bounds`` are the box of the Gaussians' means seen
    by the views (:func:`~pytest_n2r.data.extent.scene_bounds`).
    """
    import safetensors.numpy

    if not scene.views:
        raise SceneFileError(f"cannot write {path}: splat scene {scene.name!r} has no cameras; a scene file holds "
                             f"its views ({scene.no_views_reason})")
    for key, value in (("reference_length", scene.reference_length), ("metres_per_unit", scene.metres_per_unit)):
        if value is not None and not (math.isfinite(value) and value > 0):  # what read_splat_file would refuse
            raise InvalidArgument(f"cannot write {path}: splat scene {scene.name!r} has {key}={value!r}; a scene "
                                  "file needs a finite number > 0 (do its cameras see any Gaussian?)")
    views = scene.views
    bounds = scene_bounds(scene.gaussians.means, [v.camera for v in views], [v.c2w for v in views])
    cameras, frames, _ = schema.frames_to_json(views, with_images=False)
    data = {
        "format": schema.FORMAT_NAME, "version": schema.FORMAT_VERSION, "representation": REPRESENTATION,
        "cameras": cameras, "frames": frames, "bounds": bounds.tolist(),
        "reference_length": scene.reference_length, "metres_per_unit": scene.metres_per_unit,
        "splats": {"count": len(scene.gaussians), "sh_degree": scene.gaussians.sh_degree,
                   "background": list(scene.background)},
        "report": report or {},
    }
    text = json.dumps(schema.json_ready(data), indent=1, allow_nan=False)
    payload = safetensors.numpy.save(scene.gaussians.tensors())
    entries = [(schema.SCENE_JSON, text.encode("utf-8"), zipfile.ZIP_DEFLATED, 6),
               (SPLATS_FILE, payload, zipfile.ZIP_DEFLATED, 1)]
    return atomic_write_bytes(path, zip_bytes(entries))


def read_splat_file(path: str | os.PathLike, *, settings: SplatSettings | None = None,
                    name: str | None = None) -> SplatScene:
    """The splat scene of the ``.n2r`` file ``path`` (written by :func:`save_splat_scene` / ``n2r import``).

    Raises :class:`~pytest_n2r.errors.SceneFileError` naming the file and what is wrong: not a zip, another
    format or version, missing keys, a malformed frame, missing or mis-shaped tensors, non-finite values.
    """
    import safetensors
    import safetensors.numpy

    path = Path(path)
    source = str(path)
    if not path.is_file():
        raise SceneFileError(f"{source}: no such scene file (`n2r import SCENE.ply -o {path.name}` writes one)")
    try:
        archive = zipfile.ZipFile(path)
    except (zipfile.BadZipFile, OSError) as exc:
        raise SceneFileError(f"{source}: not a zip archive, or truncated ({exc})") from None
    except (NotImplementedError, RuntimeError) as exc:  # e.g. "zip file version 9.1" in the central directory
        raise SceneFileError(f"{source}: not a zip archive this reader can open ({exc})") from None
    with archive:
        data = read_scene_json(archive, source)
        if not isinstance(data, dict) or data.get("format") != schema.FORMAT_NAME:
            raise SceneFileError(f"{source}: {schema.SCENE_JSON} is not a pytest-n2r scene header")
        if data.get("version") != schema.FORMAT_VERSION:
            raise SceneFileError(f"{source}: scene file format version {data.get('version')!r}; this pytest-n2r "
                                 f"reads version {schema.FORMAT_VERSION}")
        missing = [key for key in _KEYS if key not in data]
        if missing:
            raise SceneFileError(f"{source}: {schema.SCENE_JSON} is missing the keys {missing}")
        frames = schema.read_frames(data, source)
        reference_length = schema.read_number(data, "reference_length", source)
        metres_per_unit = schema.read_number(data, "metres_per_unit", source, optional=True)
        meta = data["splats"]
        try:
            background = as_unit_rgb(meta.get("background")) if isinstance(meta, dict) else None
        except OverflowError:  # a JSON integer such as 10**400
            background = None
        if background is None:
            raise SceneFileError(f"{source}: {schema.SCENE_JSON} splats.background={meta!r}; expected three values "
                                 "in [0, 1]")
        count, degree = meta.get("count"), meta.get("sh_degree")
        if isinstance(count, bool) or not isinstance(count, int) or count < 0 or degree not in (0, 1, 2, 3):
            raise SceneFileError(f"{source}: {schema.SCENE_JSON} splats count={count!r}, sh_degree={degree!r}; "
                                 "expected a count >= 0 and a degree in 0..3")
        values = 11 + 3 * (degree + 1) ** 2  # means, quats, log_scales, opacity and SH per Gaussian
        # the member as read, the arrays loaded from it and the Gaussians' own: three float32 copies
        check_memory(3 * 4 * values * count, f"{source}: {schema.SCENE_JSON}",
                     f"splats.count={count:,} Gaussians of SH degree {degree}")
        payload = read_member(archive, SPLATS_FILE, source, 2**20 + 4 * values * count,
                          f"{count} float32 Gaussians of SH degree {degree}")
    try:
        tensors = safetensors.numpy.load(payload)
        if set(tensors) != set(TENSORS):
            raise SceneFileError(f"{source}: {SPLATS_FILE} holds the tensors {sorted(tensors)}; expected "
                                 f"{sorted(TENSORS)}")
        gaussians = Gaussians(**tensors)
    except safetensors.SafetensorError as exc:
        raise SceneFileError(f"{source}: {SPLATS_FILE} is not a valid safetensors file ({exc})") from None
    except (ValueError, TypeError) as exc:
        raise SceneFileError(f"{source}: {SPLATS_FILE}: {exc}") from None
    except (MemoryError, RuntimeError) as exc:  # the allocator, on a machine with less memory than estimated
        raise decode_failure(exc, f"{source}: {SPLATS_FILE}", f"the {count:,} Gaussians do not fit in the memory free",
                             "the file is corrupt") from None
    if len(gaussians) != count or gaussians.sh_degree != degree:
        raise SceneFileError(f"{source}: {SPLATS_FILE} holds {len(gaussians)} Gaussians of SH degree "
                             f"{gaussians.sh_degree}; {schema.SCENE_JSON} says {count!r} of degree {degree!r}")
    views = [SceneView(i, name_, camera, c2w, split) for i, (name_, camera, c2w, split, _) in enumerate(frames)]
    return SplatScene(gaussians, views, name=name or path.stem, reference_length=reference_length,
                      background=background, settings=settings, metres_per_unit=metres_per_unit)


def splat_info(path: str | os.PathLike) -> dict:
    """What ``n2r info`` shows of a splat scene file: views and split, cameras, scale, the Gaussians and the
    import report (plain JSON-ready values; lengths in scene units)."""
    scene = read_splat_file(path)
    with zipfile.ZipFile(path) as archive:
        data = json.loads(archive.read(schema.SCENE_JSON))
    splits = [v.split for v in scene.views]
    return {"path": str(path), "file_bytes": Path(path).stat().st_size, "representation": REPRESENTATION,
            "views": len(scene.views), "train_views": splits.count("train"), "heldout_views": splits.count("heldout"),
            "cameras": data["cameras"], "reference_length": scene.reference_length,
            "metres_per_unit": scene.metres_per_unit, "bounds": data["bounds"], "splats": data["splats"],
            "report": data["report"]}
