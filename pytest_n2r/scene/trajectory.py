"""Views between the captured ones: poses interpolated along the capture trajectory.

The trajectory is the scene's captured views in capture order; segment ``i`` runs from view ``i`` to view
``i + 1``. A pose between them is one the field was not fitted on either (see
:func:`~pytest_n2r.geometry.interpolation.interpolate_c2w` for the interpolation's convention).
"""

from __future__ import annotations

from collections.abc import Sequence

from .._validation import check_range
from ..geometry.interpolation import interpolate_c2w
from .base import SceneView

__all__ = ["interpolate_view", "trajectory_view"]


def interpolate_view(a: SceneView, b: SceneView, t: float) -> SceneView:
    """The view a fraction ``t`` in [0, 1] of the way from ``a`` to ``b``: rotation by slerp (constant
    angular speed about one axis), camera centre by linear interpolation, ``a``'s camera; ``a`` itself
    at ``t = 0``."""
    t = check_range("t", t, 0.0, 1.0)
    if t == 0.0:
        return a
    return SceneView(index=a.index, name=f"{a.name}~{b.name}@{t:.2f}", camera=a.camera,
                     c2w=interpolate_c2w(a.c2w, b.c2w, t), split="interpolated")


def trajectory_view(trajectory: Sequence[SceneView], segment: int, t: float) -> SceneView:
    """The view a fraction ``t`` in [0, 1] along segment ``segment`` (modulo the number of segments) of
    ``trajectory``; its only view when it has one."""
    if len(trajectory) < 2:
        return trajectory[0]
    i = segment % (len(trajectory) - 1)
    return interpolate_view(trajectory[i], trajectory[i + 1], t)
