"""A demo scene as a :class:`~pytest_n2r.data.capture.Capture`: exact images, poses and surface points.

This is what a real capture gives after ingestion (photos, poses, sparse points, bounds, reference length),
except that everything is exact: the images are rendered by the ground-truth renderer at the capture poses
and the points lie on the true surface.
"""

from __future__ import annotations

import numpy as np

from .._validation import check_positive
from ..data.capture import Capture, CapturedView, Split
from ..data.extent import scene_bounds
from ..errors import InvalidArgument, InvalidType
from ..geometry import Camera, backproject, pixel_grid
from .exact import GroundTruthScene

__all__ = ["capture_scene", "check_size"]


def check_size(size: int | tuple[int, int], camera: Camera) -> Camera:
    """The capture camera resized to ``size``: ``(width, height)`` in pixels, or an int for the longer side."""
    if isinstance(size, bool):
        raise InvalidType(f"size={size!r} must be an int (longer side, pixels) or a (width, height) pair")
    if isinstance(size, (int, np.integer)):
        check_positive("size", size)
        longer = max(camera.width, camera.height)
        w, h = round(camera.width * size / longer), round(camera.height * size / longer)
    else:
        pair = tuple(size) if isinstance(size, (tuple, list)) else ()
        if len(pair) != 2 or any(isinstance(v, bool) or not isinstance(v, (int, np.integer)) for v in pair):
            raise InvalidType(f"size={size!r} must be an int (longer side, pixels) or a (width, height) pair of ints")
        w, h = int(pair[0]), int(pair[1])
    if w < 8 or h < 8:
        raise InvalidArgument(f"size={size!r} gives {w}x{h} pixels; expected at least 8x8")
    return camera.resized(w, h)


def capture_scene(scene: GroundTruthScene, size: int | tuple[int, int], n_points: int = 4000) -> Capture:
    """Render every view of ``scene`` at ``size`` and sample ``n_points`` true surface points.

    Points are back-projected from the exact depth of the training views at 64 pixels wide, kept up to
    twice the reference length from the camera (like the well-triangulated points of a real capture;
    farther surfaces are background) and thinned with a fixed stride (deterministic). ``bounds`` is
    computed from them as ingestion does for photos (:func:`~pytest_n2r.data.extent.scene_bounds`).
    """
    views = []
    points = []
    for v in scene.views:
        if v.split not in ("train", "heldout"):  # a capture's view is trained on or held out: no third kind
            raise InvalidArgument(f"scene {scene.name!r}: view {v.name!r} has split={v.split!r}; a capture's views "
                                  "are 'train' or 'heldout'")
        split: Split = "train" if v.split == "train" else "heldout"
        camera = check_size(size, v.camera)
        image = scene.render(v.c2w, camera, "rgb").rgb
        views.append(CapturedView(name=v.name, camera=camera, c2w=v.c2w.copy(), split=split, image=image))
        if v.split == "train":
            small = v.camera.fit_within(64)
            rendered = scene.render(v.c2w, small, ("depth", "opacity"))
            depth, opacity = rendered.output("depth").ravel(), rendered.output("opacity").ravel()
            hit = (opacity >= 1.0) & (depth <= 2 * scene.reference_length)
            uv = pixel_grid(small).reshape(-1, 2)[hit]
            points.append(backproject(uv, depth[hit].astype(np.float64), small, v.c2w))
    pts = np.concatenate(points) if points else np.zeros((0, 3))
    if len(pts) > n_points:
        pts = pts[np.linspace(0, len(pts) - 1, n_points).round().astype(np.int64)]
    bounds = scene_bounds(pts, [v.camera for v in views], [v.c2w for v in views])
    return Capture(
        views=views, points=pts, bounds=bounds,
        reference_length=float(scene.reference_length), source=f"demo:{scene.name}",
        report={"scene": scene.name, "content_hash": scene.content_hash, "n_views": len(views),
                "n_points": int(len(pts)), "size": [views[0].camera.width, views[0].camera.height]},
    )
