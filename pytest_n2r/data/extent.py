"""Scene extent from sparse points: the reference length and the bounding box the cameras observe.

Convention
----------
A point is *seen* by a camera when it lies in front of it (z-depth > 0) and projects inside its image
(:func:`~pytest_n2r.geometry.inside_image`: half-open pixel cells). Occlusion is not
modelled. Depths are **z-depths** (along the optical axis), in world units.
"""

from __future__ import annotations

from collections.abc import Sequence

import numpy as np

from ..errors import IngestError
from ..geometry import Camera, inside_image, project

__all__ = ["seen_depths", "reference_length", "scene_bounds"]


def seen_depths(
    points: np.ndarray, cameras: Sequence[Camera], c2ws: Sequence[np.ndarray]
) -> tuple[np.ndarray, np.ndarray]:
    """``(depths, seen)``: the z-depth of every (camera, point) sighting, and a ``(N,)`` mask of the
    points seen by at least one camera."""
    points = np.asarray(points, dtype=np.float64).reshape(-1, 3)
    seen = np.zeros(len(points), dtype=bool)
    depths = []
    for camera, c2w in zip(cameras, c2ws):
        uv, z = project(points, camera, c2w)
        inside = (z > 0) & inside_image(uv[:, 0], uv[:, 1], camera.width, camera.height)
        depths.append(z[inside])
        seen |= inside
    return (np.concatenate(depths) if depths else np.zeros(0)), seen


def reference_length(points: np.ndarray, cameras: Sequence[Camera], c2ws: Sequence[np.ndarray]) -> float:
    """The median z-depth of the points seen by the cameras, over all sightings (world units).

    Raises :class:`IngestError` when no point is seen by any camera.
    """
    depths, _ = seen_depths(points, cameras, c2ws)
    if depths.size == 0:
        raise IngestError(
            f"none of the {len(np.asarray(points).reshape(-1, 3))} sparse points is seen by the "
            f"{len(cameras)} cameras; the reference length (median z-depth) cannot be measured"
        )
    return float(np.median(depths))


def scene_bounds(
    points: np.ndarray, cameras: Sequence[Camera], c2ws: Sequence[np.ndarray], *,
    percentile: float = 1.0, padding: float = 0.05,
) -> np.ndarray:
    """``(2, 3)`` box ``[min, max]`` of the points seen by the cameras (world units).

    Robust to stray points: per axis the ``percentile``-th and ``100 - percentile``-th percentiles, then
    each side widened by ``padding`` times the box's size on that axis.
    """
    points = np.asarray(points, dtype=np.float64).reshape(-1, 3)
    _, seen = seen_depths(points, cameras, c2ws)
    if not seen.any():
        raise IngestError(f"none of the {len(points)} sparse points is seen by the cameras; no scene bounds")
    lo, hi = np.percentile(points[seen], [percentile, 100.0 - percentile], axis=0)
    pad = padding * (hi - lo)
    return np.stack([lo - pad, hi + pad])
