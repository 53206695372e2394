"""A neighbouring photo brought to a view's pose: what a real image taken nearby scores against the reference,
the yardstick for a render's reality-to-field shift (imported as ``_neighbours``: scripts run from this folder).

Convention
----------
- Poses are camera-to-world (OpenCV axes), depth is z-depth in scene units, pixel centres at integers
  (:mod:`pytest_n2r.geometry.projection`).
- "Brought to the pose": each pixel of the view is placed in the world by the *field's* depth there, projected
  into the neighbour and coloured from the neighbour's image (bilinear) where the neighbour sees that point (its
  own field depth agrees within :data:`SEEN_DEPTH_TOLERANCE`); elsewhere, and where the view's render is not
  opaque, the pixel keeps the render's colour. So the image has the photo's texture and the field's geometry.
- "Aligned": the brought image moved onto the reference by dense optical flow (OpenCV's DIS), which removes
  what is left of placement error, the field's geometry included: what remains is what differs between two
  real photos (sensor, blur, exposure, view-dependent light, the detector's own noise).
"""

from __future__ import annotations

import cv2
import numpy as np

from pytest_n2r.geometry import Camera
from pytest_n2r.geometry.projection import backproject, inside_image, pixel_grid, project

__all__ = ["SEEN_DEPTH_TOLERANCE", "aligned_onto", "brought_to", "nearest_other"]

#: A point counts as seen by the neighbour when the neighbour's own depth there is within this fraction of the
#: point's depth in the neighbour (3 %: the field's depth noise on the fox's surfaces is well inside it, a
#: surface in front of the point is not).
SEEN_DEPTH_TOLERANCE = 0.03


def nearest_other(c2w: np.ndarray, others: list, reference_length: float):
    """The view in ``others`` (each with ``.c2w``) closest to pose ``c2w`` by camera distance in reference
    lengths plus the angle between the optical axes in radians, skipping a view at the same pose; with that
    angle in degrees and the distance in reference lengths."""
    def gap(view) -> tuple[float, float]:
        distance = float(np.linalg.norm(view.c2w[:3, 3] - c2w[:3, 3])) / reference_length
        angle = float(np.arccos(np.clip(view.c2w[:3, 2] @ c2w[:3, 2], -1.0, 1.0)))
        return distance, angle

    candidates = [(sum(gap(v)), v) for v in others if not np.array_equal(v.c2w, c2w)]
    if not candidates:
        raise ValueError("no other view to bring to this pose")
    _, view = min(candidates, key=lambda pair: pair[0])
    distance, angle = gap(view)
    return view, float(np.degrees(angle)), distance


def brought_to(camera: Camera, c2w: np.ndarray, depth: np.ndarray, opacity: np.ndarray, render: np.ndarray,
               image: np.ndarray, image_c2w: np.ndarray, image_depth: np.ndarray,
               image_camera: Camera) -> tuple[np.ndarray, float]:
    """``image`` (H'×W'×3 uint8, seen by ``image_camera`` at ``image_c2w`` with field depth ``image_depth``)
    brought to the view of ``camera`` at ``c2w`` whose field render is ``render`` with ``depth`` and
    ``opacity``; and the share of the view's pixels coloured from ``image``."""
    uv = pixel_grid(camera).reshape(-1, 2)
    world = backproject(uv, depth.reshape(-1).astype(np.float64), camera, c2w)
    there, z = project(world, image_camera, image_c2w)
    map_u = np.nan_to_num(there[:, 0], nan=-1e6).astype(np.float32).reshape(depth.shape)
    map_v = np.nan_to_num(there[:, 1], nan=-1e6).astype(np.float32).reshape(depth.shape)
    inside = inside_image(map_u, map_v, image_camera.width, image_camera.height)
    own_depth = cv2.remap(np.ascontiguousarray(image_depth, dtype=np.float32), map_u, map_v, cv2.INTER_NEAREST,
                          borderMode=cv2.BORDER_CONSTANT, borderValue=0.0)
    z = z.reshape(depth.shape)
    seen = inside & (z > 0) & (np.abs(z - own_depth) < SEEN_DEPTH_TOLERANCE * np.abs(z)) & (opacity >= 0.5)
    colour = cv2.remap(np.ascontiguousarray(image), map_u, map_v, cv2.INTER_LINEAR, borderMode=cv2.BORDER_REPLICATE)
    return np.where(seen[..., None], colour, render), float(seen.mean())


def aligned_onto(reference: np.ndarray, image: np.ndarray) -> np.ndarray:
    """``image`` moved onto ``reference`` (both H×W×3 uint8 RGB) by the dense optical flow between their grey
    images (DIS, medium preset), resampled bilinearly."""
    grey = [cv2.cvtColor(np.ascontiguousarray(x), cv2.COLOR_RGB2GRAY) for x in (reference, image)]
    flow = cv2.DISOpticalFlow_create(cv2.DISOPTICAL_FLOW_PRESET_MEDIUM).calc(grey[0], grey[1], None)
    h, w = grey[0].shape
    u, v = np.meshgrid(np.arange(w, dtype=np.float32), np.arange(h, dtype=np.float32))
    return cv2.remap(np.ascontiguousarray(image), u + flow[..., 0], v + flow[..., 1], cv2.INTER_LINEAR,
                     borderMode=cv2.BORDER_REPLICATE)
