"""The one entry point of ingestion: any supported source → :class:`~pytest_n2r.data.capture.Capture`.

Sources (:func:`source_kind` decides):

- a ``transforms.json`` file (nerfstudio / instant-ngp), or a folder holding one;
- a COLMAP sparse model folder (``cameras.bin|txt``, ``images.bin|txt``, ``points3D.bin|txt``), or a
  project folder holding one under ``sparse/0`` or ``sparse``;
- a folder of images (or a project folder with an ``images`` subfolder): structure from motion;
- a video file: its sharpest frames (:mod:`pytest_n2r.data.video`), then structure from motion with
  sequential matching.
"""

from __future__ import annotations

import os
import time
import warnings
from collections.abc import Callable
from pathlib import Path

import numpy as np

from .._validation import check_positive
from ..errors import IngestError, InvalidArgument, InvalidType
from ..geometry import Camera
from .capture import Capture, CapturedView, split_frames
from .extent import reference_length, scene_bounds
from .images import read_image, resize_image
from .poses import PoseSet, SourceFrame
from .transforms_json import find_transforms_json, read_transforms_json
from .triangulate import triangulate_views
from .video import VIDEO_SUFFIXES, extract_frames, is_video

__all__ = ["ingest", "load_poses", "complete_points", "extent", "source_kind", "TRIANGULATION_MAX_SIZE"]

#: Longer image side (pixels) used to triangulate points for sources that come without points.
TRIANGULATION_MAX_SIZE = 480


def source_kind(source: str | os.PathLike) -> tuple[str, Path]:
    """``(kind, path)``: ``kind`` is ``"transforms.json"``, ``"colmap"``, ``"images"`` or ``"video"``;
    ``path`` is the json file, the model folder, the images folder or the video file. Raises
    :class:`IngestError` naming ``source``."""
    path = Path(source)
    if not path.exists():
        raise IngestError(f"source {str(path)!r} does not exist")
    found = find_transforms_json(path)
    if found is not None:
        return "transforms.json", found
    if is_video(path):
        return "video", path
    if path.is_file():
        raise IngestError(
            f"source {str(path)!r} is a file but neither a .json file nor a video ({', '.join(VIDEO_SUFFIXES)}); "
            "expected a transforms.json, a COLMAP model folder, a folder of images or a video"
        )
    from .colmap import find_colmap_model

    model = find_colmap_model(path)
    if model is not None:
        return "colmap", model
    if (path / "images").is_dir():
        return "images", path / "images"
    return "images", path


def load_poses(
    source: str | os.PathLike, *, sfm_max_size: int = 960, matcher: str = "auto", max_frames: int = 120,
    frames_dir: str | os.PathLike | None = None, upright: bool = True, force_frames_dir: bool = False,
) -> PoseSet:
    """Read or compute the poses of a source (see :func:`source_kind`); no images are kept.

    For an images folder this runs structure from motion (:func:`pytest_n2r.data.sfm.run_sfm`) on
    copies downscaled to at most ``sfm_max_size`` pixels, matching ``"exhaustive"``-ly,
    ``"sequential"``-ly (ordered video frames) or ``"auto"`` (exhaustive up to 100 images; sequential
    for a video). A video is first cut into its ``max_frames`` sharpest frames, written to
    ``frames_dir`` (default ``<video stem>_frames`` beside it: a new or empty folder, or one frames were extracted
    into before, unless ``force_frames_dir``), and structure from motion runs on those frames only. Points of a
    transforms.json are not triangulated here (see :func:`ingest`). ``upright=False`` keeps the photos structure
    from motion registers upside down against the others (photos not taken upright;
    :func:`~pytest_n2r.data.sfm.run_sfm`).
    """
    kind, path = source_kind(source)
    start = time.perf_counter()
    if kind == "transforms.json":
        poses = read_transforms_json(path)
    elif kind == "colmap":
        from .colmap import read_colmap_model

        poses = read_colmap_model(path)
    elif kind == "video":
        from .sfm import run_sfm

        frames = extract_frames(path, frames_dir, max_frames=max_frames, force=force_frames_dir)
        extracted = time.perf_counter() - start
        poses = run_sfm(frames[0].parent, max_size=sfm_max_size, matcher="sequential" if matcher == "auto" else matcher,
                        upright=upright, files=frames)
        poses.kind = "video"
        poses.report["video"] = str(path)
        poses.report["frames_dir"] = str(frames[0].parent)
        poses.report["video_frames"] = len(frames)
        poses.report["time_s"] = {"frames": extracted, **poses.report["time_s"]}
    else:
        from .sfm import run_sfm

        poses = run_sfm(path, max_size=sfm_max_size, matcher=matcher, upright=upright)
    if kind in ("transforms.json", "colmap"):  # SfM reports its own stages
        poses.report.setdefault("time_s", {})["poses"] = time.perf_counter() - start
    return poses


def ingest(
    source: str | os.PathLike, *, downscale: float = 1.0, max_size: int | None = None,
    load_images: bool = True, heldout_every: int | None = None, sfm_max_size: int = 960,
    matcher: str = "auto", max_frames: int = 120, frames_dir: str | os.PathLike | None = None,
    upright: bool = True, force_frames_dir: bool = False,
) -> Capture:
    """Turn a capture into undistorted images, cameras, poses, split, bounds and reference length.

    Parameters
    ----------
    source:
        A transforms.json (or its folder), a COLMAP model folder, a folder of images or a video (SfM).
    downscale:
        Image scale factor in ``(0, 1]`` (``0.25`` → a quarter of the width and height, rounded to
        whole pixels; intrinsics follow :meth:`Camera.resized`).
    max_size:
        If given, further shrink so the longer side is at most this many pixels.
    load_images:
        Decode the images (``False``: views carry ``image=None``; a transforms.json still reads its
        images once at low resolution to triangulate points).
    heldout_every:
        Every ``heldout_every``-th view (0, n, 2n, ...) is held out (:func:`heldout_split`); 0 holds none.
        ``None``: the source's own split where it has one (a transforms.json's ``val_filenames``, else its
        ``test_filenames``), else 8.
    sfm_max_size, matcher, max_frames, frames_dir, upright, force_frames_dir:
        Structure from motion and video settings for images folders and videos (see :func:`load_poses`).

    Returns
    -------
    Capture
        Views with ideal pinhole cameras (lens distortion removed by remapping the full-resolution
        image, then area-averaged down), camera-to-world poses with OpenCV axes, the sparse points,
        ``bounds`` (:func:`~pytest_n2r.data.extent.scene_bounds`) and ``reference_length`` (median
        z-depth of the points seen by the training cameras). Points of a transforms.json are
        triangulated from its poses (:mod:`pytest_n2r.data.triangulate`).
    """
    downscale = check_positive("downscale", downscale)
    if downscale > 1:
        raise InvalidArgument(f"downscale={downscale!r} is out of range; expected a value in (0, 1]")
    if max_size is not None:
        if isinstance(max_size, bool) or not isinstance(max_size, (int, np.integer)):
            raise InvalidType(f"max_size={max_size!r} must be an int (pixels) or None")
        if max_size < 16:
            raise InvalidArgument(f"max_size={max_size!r} is too small; expected at least 16 pixels")
    every_ok = isinstance(heldout_every, (int, np.integer)) and not isinstance(heldout_every, bool)
    if heldout_every is not None and not (every_ok and heldout_every >= 0):
        raise InvalidArgument(f"heldout_every={heldout_every!r} must be an int >= 0 or None")

    poses = load_poses(source, sfm_max_size=sfm_max_size, matcher=matcher, max_frames=max_frames,
                       frames_dir=frames_dir, upright=upright, force_frames_dir=force_frames_dir)
    images = _load_pixels(poses, (lambda cam: _output_camera(cam, downscale, max_size)) if load_images else None)
    frames = poses.frames  # without those whose image could not be decoded
    out_cameras = [_output_camera(f.camera, downscale, max_size) for f in frames]
    splits = split_frames([f.name for f in poses.frames], poses.heldout, heldout_every)
    views = [
        CapturedView(name=f.name, camera=cam, c2w=f.c2w.copy(), split=split, image=img)
        for f, cam, split, img in zip(frames, out_cameras, splits, images)
    ]
    bounds, ref = extent(poses, heldout_every)
    report = dict(poses.report)
    report.update(kind=poses.kind, registered=len(frames), points=int(len(poses.points)))
    return Capture(
        views=views, points=np.asarray(poses.points, dtype=np.float64), bounds=bounds, reference_length=ref,
        source=str(source), skipped=list(poses.skipped), report=report,
    )


def complete_points(poses: PoseSet) -> PoseSet:
    """Fill ``poses.points`` (in place) by triangulation when the source had none; returns ``poses``.

    Reads each image once at up to :data:`TRIANGULATION_MAX_SIZE` pixels (see
    :mod:`pytest_n2r.data.triangulate` for the method).
    """
    _load_pixels(poses, None)
    return poses


def extent(poses: PoseSet, heldout_every: int | None = None) -> tuple[np.ndarray, float]:
    """``(bounds, reference_length)`` of a pose set with points: the box of the points seen by all
    cameras and the median z-depth of the points seen by the training cameras (scene units; the split
    as :func:`ingest` makes it)."""
    frames = poses.frames
    if len(frames) < 3:
        raise IngestError(f"{poses.source}: only {len(frames)} registered images; at least 3 are needed")
    splits = split_frames([f.name for f in poses.frames], poses.heldout, heldout_every)
    train = [f for f, s in zip(frames, splits) if s == "train"] or frames
    ref = reference_length(poses.points, [f.camera for f in train], [f.c2w for f in train])
    bounds = scene_bounds(poses.points, [f.camera for f in frames], [f.c2w for f in frames])
    return bounds, ref


def _load_pixels(
    poses: PoseSet, out_camera: Callable[[Camera], Camera] | None,
) -> list[np.ndarray | None]:
    """Decode, undistort and resize each frame's image to ``out_camera(frame.camera)`` (``None``: keep
    no images); triangulate points on the way when the pose set has none. Each file is read once.

    Frames whose image cannot be decoded are dropped from ``poses.frames`` with a warning naming the
    file and recorded in ``poses.skipped``; fewer than 3 remaining frames is an error.
    """
    if len(poses.frames) < 3:
        raise IngestError(f"{poses.source}: only {len(poses.frames)} registered images; at least 3 are needed")
    need_points = len(poses.points) == 0
    as_stored = poses.pixels == "stored"  # a COLMAP model's, another tool's transforms.json: the tag ignored
    kept: list[SourceFrame] = []
    images: list[np.ndarray | None] = []
    small: list[np.ndarray] = []
    small_cameras: list[Camera] = []
    start = time.perf_counter()
    earlier = len(poses.skipped)  # skipped before this pass (not registered, missing files, ...)
    for frame in poses.frames:
        if out_camera is None and not need_points:
            kept.append(frame)
            images.append(None)
            continue
        try:
            full = _undistorted_image(frame, as_stored, poses.kind)
        except _Undecodable as exc:
            warnings.warn(f"skipping frame {frame.name!r}: {exc}", stacklevel=3)
            poses.skipped.append((frame.name, str(exc)))
            continue
        kept.append(frame)
        if out_camera is not None:
            cam = out_camera(frame.camera)
            images.append(resize_image(full, cam.width, cam.height))
        else:
            images.append(None)
        if need_points:
            cam = frame.camera.undistorted().fit_within(TRIANGULATION_MAX_SIZE)
            small.append(resize_image(full, cam.width, cam.height))
            small_cameras.append(cam)
    poses.frames = kept
    if len(kept) < 3:
        unreadable = poses.skipped[earlier:]
        raise IngestError(
            f"{poses.source}: only {len(kept)} images could be read; at least 3 are needed. Unreadable: "
            + "; ".join(f"{name}: {reason}" for name, reason in unreadable)
            + (f" (and {earlier} frames not used before they were read: not registered or missing)" if earlier else "")
        )
    times = poses.report.setdefault("time_s", {})
    if out_camera is not None or need_points:
        times["images"] = time.perf_counter() - start
    if need_points:
        start = time.perf_counter()
        poses.points = triangulate_views(small, small_cameras, [f.c2w for f in kept])
        poses.report["points_method"] = "SIFT matches between neighbouring views, triangulated with the given poses"
        times["triangulation"] = time.perf_counter() - start
    return images


def _output_camera(camera: Camera, downscale: float, max_size: int | None) -> Camera:
    cam = camera.undistorted()
    if downscale != 1.0:
        cam = cam.scaled(downscale)
    return cam if max_size is None else cam.fit_within(max_size)


#: why a photo read as stored has another size than its camera, by the source's kind
_STORED_SIZE_HINT = {
    "colmap": ("its pixels as stored: COLMAP ignores a photo's orientation tag, so a model made from these files has "
               "cameras of their stored size; was it made from turned copies? give it those)"),
    "transforms.json": ("its pixels as stored: the transforms.json describes the photos as stored (another tool's "
                        "file, read as nerfstudio and instant-ngp read it, the orientation tag ignored, or n2r's with "
                        "n2r.pixels 'stored'); was it made from turned copies? give it those)"),
}


class _Undecodable(IngestError):
    """An image file that exists but cannot be decoded (the frame is skipped, not fatal)."""


def _undistorted_image(frame: SourceFrame, as_stored: bool, kind: str = "colmap") -> np.ndarray:
    """The frame's photo with its lens distortion removed: upright, or its pixels as stored (``as_stored``: the photo
    of a COLMAP model or of a transforms.json another tool wrote, of the source ``kind``, whose camera and pose
    describe the pixels as COLMAP, nerfstudio and instant-ngp read them, the orientation ignored)."""
    if frame.path is None:
        raise IngestError(
            f"image {frame.name!r} listed in the COLMAP model was not found; put the images in an 'images' "
            "folder beside the model (they are needed to load views, and to triangulate points when the "
            "model has none)"
        )
    try:
        image = read_image(frame.path, oriented=not as_stored)
    except IngestError as exc:
        raise _Undecodable(str(exc)) from None
    cam = frame.camera
    if image.shape[:2] != (cam.height, cam.width):
        raise IngestError(
            f"image {str(frame.path)!r} is {image.shape[1]}x{image.shape[0]} pixels but its camera says "
            f"{cam.width}x{cam.height} ("
            + (_STORED_SIZE_HINT.get(kind, _STORED_SIZE_HINT["transforms.json"]) if as_stored
               else "after EXIF orientation)")
        )
    try:
        return cam.undistort_image(image)
    except InvalidArgument as exc:  # a lens model that folds over within the photo (Camera.check_lens)
        raise IngestError(f"image {str(frame.path)!r} ({frame.name!r}): its camera ({cam.width}x{cam.height}, "
                          f"fx={cam.fx:g}, fy={cam.fy:g}) cannot undistort it: {exc}. A wide lens posed by "
                          "structure from motion (`n2r poses`, one radial term) can fold so; give the capture a "
                          "calibrated lens (transforms.json with k1 k2 [k3] or a COLMAP OPENCV camera) or crop the "
                          "photos to their centre") from None
