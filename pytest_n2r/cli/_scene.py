"""The SCENE argument of ``n2r render``, ``n2r info`` and ``n2r study``: the names ``--n2r-scene`` accepts,
resolved by :mod:`pytest_n2r.demo.scene_specs` (imported when a command runs, not when ``n2r`` parses)."""

from __future__ import annotations

import os
import sys
from pathlib import Path
from typing import TYPE_CHECKING

if TYPE_CHECKING:
    from ..demo.scene_specs import SceneSpec

__all__ = ["SCENE_HELP", "scene_argument", "scene_arguments", "scene_inputs"]

#: The help of a SCENE argument: every form the plugin's ``--n2r-scene`` accepts.
SCENE_HELP = ("a .n2r scene file or a 3DGS .ply, 'demo:<name>' (a built-in demo scene; 'demo:<name>-field' its "
              "fitted twin) or 'module:function' returning a Scene, as --n2r-scene takes it")


def scene_argument(text: str | os.PathLike) -> SceneSpec:
    """The one scene a command's SCENE argument names (relative paths and globs from the working folder)."""
    from ..demo.scene_specs import resolve_scene

    return _importable([resolve_scene(str(text), Path.cwd(), "SCENE")])[0]


def scene_arguments(texts: list[str]) -> list[SceneSpec]:
    """The scenes of a command's SCENE arguments, each named once (globs may match several files)."""
    from ..demo.scene_specs import parse_scene_specs

    return _importable(parse_scene_specs(texts, Path.cwd(), "SCENE"))


def scene_inputs(spec: SceneSpec) -> list[Path]:
    """The input files of a scene (never overwritten by an output): its scene file, if it has one."""
    return [Path(spec.source)] if spec.kind == "file" else []


def _importable(specs: list[SceneSpec]) -> list[SceneSpec]:
    """``specs``, with the working folder on the module path when one is ``module:function`` (pytest puts the test
    folders there for the plugin). Appended, not put first as ``python -m`` does: a folder holding ``scipy/`` or
    ``cv2.py`` must not shadow the packages the command imports later."""
    cwd = os.getcwd()
    if any(spec.kind == "python" for spec in specs) and cwd not in sys.path and "" not in sys.path:
        sys.path.append(cwd)
    return specs
