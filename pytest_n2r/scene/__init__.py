"""Scenes: the renderable interface, scene files and loading."""

from .base import Scene, SceneView, normalize_outputs

__all__ = ["Scene", "SceneView", "normalize_outputs"]
