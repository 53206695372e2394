"""How far one camera pose lies from others: the nearest fitted view of a held-out view in a fit's report
(:func:`pytest_n2r.fit.evaluate.nearest_fitted`), the nearby photo of a field floor
(:func:`pytest_n2r.relation.floor.nearby.nearest_fitted_view`).

Convention
----------
- Poses are camera-to-world 4x4 matrices with OpenCV axes (:mod:`.pose`): a camera's optical axis is its +z column.
- The gap between two poses is the angle between their optical axes in **degrees** (a roll about the axis does not
  count) and the distance between their centres in **reference lengths** (scene units divided by the scene's
  reference length).
- "Nearest" ranks by that distance plus the angle in radians (one reference length weighs as much as 57.3°); ties
  go to the first pose given.
"""

from __future__ import annotations

from collections.abc import Sequence

import numpy as np

__all__ = ["pose_gap", "nearest_pose"]


def pose_gap(c2w: np.ndarray, other: np.ndarray, reference_length: float) -> tuple[float, float]:
    """``(degrees, distance)``: the angle between the optical axes of poses ``c2w`` and ``other`` (degrees) and the
    distance between their centres (reference lengths; ``reference_length`` in scene units).

    >>> at = lambda x: np.array([[1, 0, 0, x], [0, 1, 0, 0], [0, 0, 1, 0], [0, 0, 0, 1.0]])
    >>> pose_gap(at(0.0), at(0.5), 2.0)
    (0.0, 0.25)
    """
    c2w, other = np.asarray(c2w, dtype=np.float64), np.asarray(other, dtype=np.float64)
    degrees = float(np.degrees(np.arccos(np.clip(other[:3, 2] @ c2w[:3, 2], -1.0, 1.0))))
    return degrees, float(np.linalg.norm(other[:3, 3] - c2w[:3, 3])) / float(reference_length)


def nearest_pose(c2w: np.ndarray, others: Sequence[np.ndarray], reference_length: float) -> tuple[int, float, float]:
    """``(index, degrees, distance)``: which of ``others`` is nearest to pose ``c2w`` (see the Convention; a pose whose
    gap is not finite only when all are) and its :func:`pose_gap`; a ``ValueError`` when ``others`` is empty.

    >>> at = lambda x: np.array([[1, 0, 0, x], [0, 1, 0, 0], [0, 0, 1, 0], [0, 0, 0, 1.0]])
    >>> nearest_pose(at(0.0), [at(0.5), at(-0.2)], 2.0)
    (1, 0.0, 0.1)
    """
    if not len(others):
        raise ValueError("no pose to be nearest to")
    gaps = [pose_gap(c2w, other, reference_length) for other in others]

    def rank(i: int) -> float:  # a pose with a non-finite gap (a NaN entry) is never the nearest
        value = float(np.radians(gaps[i][0]) + gaps[i][1])
        return value if np.isfinite(value) else np.inf

    index = min(range(len(gaps)), key=rank)
    return index, *gaps[index]
