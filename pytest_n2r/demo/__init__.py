"""Built-in demo scenes with exact ground truth: ``wall`` (AUV wall inspection) and ``object`` (UAV vehicle
inspection).

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
from .exact import GroundTruthScene

__all__ = ["demo_scene_names", "ground_truth", "capture", "export", "GroundTruthScene", "DEFAULT_SIZE"]

#: The capture size (width, height) in pixels of the demo trajectories.
DEFAULT_SIZE = (480, 270)


def demo_scene_names() -> tuple[str, ...]:
    """Names of the built-in demo scenes."""
    from .scenes import SCENES

    return tuple(SCENES)


def _check_name(name: str) -> str:
    names = demo_scene_names()
    if name not in names:
        raise InvalidArgument(f"demo scene {name!r} does not exist; expected one of {names}")
    return name


@functools.lru_cache(maxsize=None)
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
