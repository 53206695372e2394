"""Built-in demo scenes with exact ground truth: ``wall`` (AUV wall inspection) and ``object`` (UAV vehicle
inspection), and their fitted scene fields ``wall-field`` and ``object-field`` (:mod:`.fitted`).

>>> demo_scene_names()
('wall', 'object')
>>> scene = ground_truth("object")
>>> view = scene.render(scene.views[0].c2w, scene.views[0].camera.fit_within(64), ("rgb", "depth"))
>>> view.rgb.shape, view.depth.dtype
((36, 64, 3), dtype('float32'))
"""

from __future__ import annotations

import functools
import os
from pathlib import Path

from ..data.capture import Capture
from ..errors import InvalidArgument
from ..scene.base import Scene
from .exact import GroundTruthScene
from .fitted import FIELD_SUFFIX, build_fitted, fitted_scene

__all__ = ["demo_scene_names", "demo_spec_names", "ground_truth", "fitted_scene", "build_fitted", "load_demo",
           "capture", "export", "GroundTruthScene", "DEFAULT_SIZE"]

#: The capture size (width, height) in pixels of the demo trajectories.
DEFAULT_SIZE = (480, 270)


def demo_scene_names() -> tuple[str, ...]:
    """Names of the built-in demo scenes."""
    from .scenes import SCENES

    return tuple(SCENES)


def demo_spec_names() -> tuple[str, ...]:
    """Every name ``demo:<name>`` accepts: the exact scenes, then their fitted fields (``<name>-field``).

    >>> demo_spec_names()
    ('wall', 'object', 'wall-field', 'object-field')
    """
    names = demo_scene_names()
    return names + tuple(n + FIELD_SUFFIX for n in names)


def load_demo(spec_name: str, device: str = "auto") -> Scene:
    """The scene ``demo:<spec_name>`` names: the exact scene ``<name>``, or the fitted field of it for
    ``<name>-field`` (rendered on ``device``; the exact scenes render with a compiled kernel on the CPU)."""
    if spec_name in demo_scene_names():
        return ground_truth(spec_name)
    if spec_name.endswith(FIELD_SUFFIX) and spec_name[: -len(FIELD_SUFFIX)] in demo_scene_names():
        return fitted_scene(spec_name[: -len(FIELD_SUFFIX)], device=device)
    raise InvalidArgument(f"demo scene 'demo:{spec_name}' does not exist; expected demo: followed by one of "
                          f"{demo_spec_names()}")


def _check_name(name: str) -> str:
    names = demo_scene_names()
    if name not in names:
        raise InvalidArgument(f"demo scene {name!r} does not exist; expected one of {names}")
    return name


@functools.cache
def ground_truth(name: str) -> GroundTruthScene:
    """The exact scene ``name``: renders the true RGB, z-depth and opacity at any camera and pose."""
    from .scenes import build_scene

    return build_scene(_check_name(name))


def capture(name: str, size: int | tuple[int, int] = DEFAULT_SIZE) -> Capture:
    """The demo scene as a capture to fit: exact images at every trajectory pose (``size``: ``(width,
    height)`` or the longer side in pixels), poses, true surface points, bounds and reference length."""
    from .rendered_capture import capture_scene

    return capture_scene(ground_truth(name), size)


def export(name: str, out_dir: str | os.PathLike, size: int | tuple[int, int] = DEFAULT_SIZE) -> Path:
    """Write the ground-truth images and a nerfstudio ``transforms.json`` to ``out_dir``; return the json."""
    from .nerfstudio_export import export_scene

    return export_scene(ground_truth(name), out_dir, size)
