"""Scenes: the renderable interface, scene files and loading.

``Scene``, ``SceneView`` and ``normalize_outputs`` are light; ``load_scene``, ``save_scene``,
``read_scene_file``, ``FieldScene`` and the splat scenes (``SplatScene``, ``load_splat_scene``,
``save_splat_scene``, ``read_splat_file``) are loaded on first use, so importing the package loads no
field or splat machinery; type checkers read them from the ``TYPE_CHECKING`` imports.
"""

from __future__ import annotations

import importlib
from typing import TYPE_CHECKING, Any

from .base import Scene, SceneView, normalize_outputs

if TYPE_CHECKING:  # what type checkers and IDEs see; a test keeps it in step with _LAZY
    from .field_scene import FieldScene
    from .file import SceneFile, read_scene_file, save_scene
    from .loading import load_scene
    from .splat_file import read_splat_file, save_splat_scene
    from .splat_scene import SplatScene, load_splat_scene

#: lazily exported name -> module of this package that defines it
_LAZY = {
    "load_scene": "loading",
    "save_scene": "file",
    "read_scene_file": "file",
    "SceneFile": "file",
    "FieldScene": "field_scene",
    "SplatScene": "splat_scene",
    "load_splat_scene": "splat_scene",
    "save_splat_scene": "splat_file",
    "read_splat_file": "splat_file",
}

#: the eager names and those of _LAZY, spelled out for type checkers and linters; a test
#: (tests/test_project.py) keeps it in step with them
__all__ = [
    "Scene", "SceneView", "normalize_outputs", "load_scene", "save_scene", "read_scene_file", "SceneFile",
    "FieldScene", "SplatScene", "load_splat_scene", "save_splat_scene", "read_splat_file",
]


if not TYPE_CHECKING:  # hidden from type checkers, which read the imports above: a misspelt name is an error, not Any
    def __getattr__(name: str) -> Any:
        module = _LAZY.get(name)
        if module is None:
            raise AttributeError(f"module 'pytest_n2r.scene' has no attribute {name!r}")
        value = getattr(importlib.import_module(f"{__name__}.{module}"), name)
        globals()[name] = value
        return value


def __dir__() -> list[str]:
    return sorted(__all__)
