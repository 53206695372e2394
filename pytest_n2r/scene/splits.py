"""Which captured views of a scene serve as the source views of metamorphic tests: the splits.

A scene's views are ``"train"`` views (the field was fitted on them) or ``"heldout"`` views (it was not;
the natural sources, since a field is at its best on its own training views). Exact procedural scenes
have no training views, so every view is held out.
"""

from __future__ import annotations

from ..errors import InvalidArgument
from .base import Scene, SceneView

__all__ = ["SOURCE_SPLITS", "check_source_split", "scene_views"]

#: The source-view selections: held-out views, training views, or every captured view.
SOURCE_SPLITS = ("heldout", "train", "all")


def check_source_split(name: str, split: object) -> str:
    """``split`` if it is one of :data:`SOURCE_SPLITS`, else an error naming the argument ``name``."""
    if split not in SOURCE_SPLITS:
        raise InvalidArgument(f"{name}={split!r} is not a split; expected one of {SOURCE_SPLITS}")
    return split


def scene_views(scene: Scene, split: str = "heldout") -> list[SceneView]:
    """The captured views of ``scene`` in ``split``: ``"heldout"`` (views the field was not fitted on;
    every view when the scene has none, as exact procedural scenes do), ``"train"`` or ``"all"``."""
    check_source_split("split", split)
    views = list(scene.views)
    if not views:
        reason = getattr(scene, "no_views_reason", None)
        raise InvalidArgument(f"scene {scene.name!r} has no views to use as sources"
                              + (f": {reason}" if reason else ""))
    if split == "all":
        return views
    chosen = [v for v in views if v.split == split]
    if split == "heldout" and not chosen:
        return views
    if not chosen:
        raise InvalidArgument(f"scene {scene.name!r} has no {split!r} views; use split='all'")
    return chosen
