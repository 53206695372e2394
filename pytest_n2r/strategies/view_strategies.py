"""Hypothesis strategies of source views: captured views of a split, or poses along the capture trajectory.

The view selection itself (splits, interpolation) belongs to the scene (:mod:`pytest_n2r.scene.splits`,
:mod:`pytest_n2r.scene.trajectory`); this module only draws from it. Draws shrink toward the first view
(and toward the captured pose itself when interpolating).
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Any

from hypothesis import strategies as st

from ..errors import InvalidType
from ..scene.base import Scene, SceneView
from ..scene.splits import check_source_split, scene_views
from ..scene.trajectory import trajectory_view

__all__ = ["views", "ViewPick"]

#: Interpolated views lie at one of this many steps (plus the start) along a trajectory segment.
_STEPS = 100


@dataclass(frozen=True)
class ViewPick:
    """A source view drawn without the scene at hand (``views()`` with no scene); a scene turns it into
    a :class:`~pytest_n2r.scene.SceneView` with :meth:`resolve` (``scene.pair`` does this for you)."""

    split: str
    index: int
    t: float = 0.0

    def resolve(self, scene: Scene) -> SceneView:
        if self.t:
            return trajectory_view(list(scene.views), self.index, self.t)
        candidates = scene_views(scene, self.split)
        return candidates[self.index % len(candidates)]


def views(
    scene: Scene | None = None, *, split: str = "heldout", interpolate: bool = False
) -> st.SearchStrategy[Any]:
    """Source views: captured views of ``split`` (``"heldout"``, ``"train"`` or ``"all"``), or with
    ``interpolate=True`` poses interpolated along the capture trajectory (consecutive views in capture
    order: slerp of rotations, linear centres), which the field has not seen either.

    With a ``scene`` it draws :class:`~pytest_n2r.scene.SceneView` objects (a scene with fewer than two
    views has no trajectory: it draws from ``split`` then); without one it draws :class:`ViewPick` values
    that ``scene.pair(view, tau)`` resolves. Shrinks toward the first view (and toward the captured pose
    itself when interpolating).
    """
    check_source_split("split", split)
    if not isinstance(interpolate, bool):
        raise InvalidType(f"interpolate={interpolate!r} must be True or False")
    if scene is None:
        t = st.integers(0, _STEPS).map(lambda k: k / _STEPS) if interpolate else st.just(0.0)
        return st.builds(ViewPick, st.just(split), st.integers(0, 4095), t)
    if not isinstance(scene, Scene):
        raise InvalidType(f"scene={scene!r} must be a pytest_n2r.Scene, not {type(scene).__name__}")
    trajectory = list(scene.views)
    if interpolate and len(trajectory) >= 2:
        return st.builds(lambda i, k: trajectory_view(trajectory, i, k / _STEPS),
                         st.integers(0, len(trajectory) - 2), st.integers(0, _STEPS))
    names = [v.name for v in scene_views(scene, split)]  # by name, so a report names the view
    return st.sampled_from(names).map(scene.view)
