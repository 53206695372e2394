"""Hypothesis strategies of source views: captured views of a split, or poses between them.

The view selection itself (splits, interpolation) belongs to the scene (:mod:`pytest_n2r.scene.splits`,
:mod:`pytest_n2r.scene.trajectory`); this module only draws from it. Draws shrink toward the first view of
the split (and toward that captured view itself when interpolating).
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import overload

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
        """The scene's view of :attr:`split` (``t = 0``), or the pose a fraction ``t`` along a segment between
        two consecutive views of the split."""
        candidates = scene_views(scene, self.split)
        if self.t:
            return trajectory_view(candidates, self.index, self.t)
        return candidates[self.index % len(candidates)]


@overload
def views(scene: None = None, *, split: str = "heldout", interpolate: bool = False) -> st.SearchStrategy[ViewPick]: ...
@overload
def views(scene: Scene, *, split: str = "heldout", interpolate: bool = False) -> st.SearchStrategy[SceneView]: ...
def views(
    scene: Scene | None = None, *, split: str = "heldout", interpolate: bool = False
) -> st.SearchStrategy[ViewPick] | st.SearchStrategy[SceneView]:
    """Source views: captured views of ``split`` (``"heldout"``, ``"train"`` or ``"all"``), or with
    ``interpolate=True`` poses interpolated between consecutive views *of that split* in capture order
    (slerp of rotations, linear centres), which the field has not seen either.

    Interpolation keeps to the split: with ``"heldout"`` every draw is a held-out view or a pose between two
    of them, never a training view (``t = 0`` is the segment's first held-out view itself, which a failure
    shrinks toward); ``"all"`` interpolates along the whole capture trajectory.

    With a ``scene`` it draws :class:`~pytest_n2r.scene.SceneView` objects (a split with fewer than two
    views has nothing to interpolate between: it draws its view then); without one it draws
    :class:`ViewPick` values that ``scene.pair(view, tau)`` resolves. Shrinks toward the first view of the
    split.
    """
    check_source_split("split", split)
    if not isinstance(interpolate, bool):
        raise InvalidType(f"interpolate={interpolate!r} must be True or False")
    if scene is None:
        t = st.integers(0, _STEPS).map(lambda k: k / _STEPS) if interpolate else st.just(0.0)
        return st.builds(ViewPick, st.just(split), st.integers(0, 4095), t)
    if not isinstance(scene, Scene):
        raise InvalidType(f"scene={scene!r} must be a pytest_n2r.Scene, not {type(scene).__name__}")
    candidates = scene_views(scene, split)
    if interpolate and len(candidates) >= 2:
        return st.builds(lambda i, k: trajectory_view(candidates, i, k / _STEPS),
                         st.integers(0, len(candidates) - 2), st.integers(0, _STEPS))
    return st.sampled_from(candidates)
