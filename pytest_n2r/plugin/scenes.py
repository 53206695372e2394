"""Scene specs: how a user names the scenes to test on (``--n2r-scene``, ``n2r_scenes``, ``n2r study``).

An entry is a ``.n2r`` scene file or a 3DGS ``.ply`` (globs allowed), ``demo:<name>`` for a built-in demo
scene, or ``module:callable`` returning a :class:`~pytest_n2r.Scene`. No pytest import: the plugin and the
command line both parse entries here and load the scenes they name.
"""

from __future__ import annotations

import glob
import importlib
import os
import re
import zipfile
from dataclasses import dataclass
from pathlib import Path
from typing import Any

from ..errors import InvalidArgument, InvalidType
from ..scene.base import Scene

__all__ = ["SceneSpec", "parse_scene_specs", "default_scene_specs", "load_scene_spec", "DEMO_PREFIX",
           "NO_SCENE_MESSAGE"]

DEMO_PREFIX = "demo:"
_PYTHON_SPEC = re.compile(r"^[A-Za-z_][\w.]*:[A-Za-z_][\w.]*$")


@dataclass(frozen=True)
class SceneSpec:
    """Where a scene comes from: ``kind`` is ``"file"`` (a ``.n2r`` scene file), ``"demo"`` (a built-in
    demo scene) or ``"python"`` (``module:callable`` returning a :class:`~pytest_n2r.Scene`); ``name`` is
    what test ids and reports show."""

    name: str
    kind: str
    source: str

    def __str__(self) -> str:
        return self.source


def _spec_from_text(text: str, base: Path, origin: str) -> list[SceneSpec]:
    """One configured entry → scene specs (a glob may give several); ``origin`` names the option."""
    text = text.strip()
    if text.startswith(DEMO_PREFIX):
        name = text[len(DEMO_PREFIX):]
        from ..demo import demo_spec_names

        if name not in demo_spec_names():
            raise InvalidArgument(f"{origin} {text!r}: no such demo scene; expected {DEMO_PREFIX} followed by one "
                                  f"of {demo_spec_names()} (`n2r demo list` shows them)")
        return [SceneSpec(name, "demo", text)]
    path = Path(text).expanduser()
    path = path if path.is_absolute() else base / path
    if glob.has_magic(text):
        matches = sorted(glob.glob(str(path), recursive=True))
        if not matches:
            raise InvalidArgument(f"{origin} {text!r} matched no file (relative to {base})")
        return [_file_spec(Path(m), origin, text) for m in matches]
    if not path.exists() and _PYTHON_SPEC.match(text):
        return [SceneSpec(text.rsplit(":", 1)[1].rsplit(".", 1)[-1], "python", text)]
    return [_file_spec(path, origin, text)]


def _file_spec(path: Path, origin: str, text: str) -> SceneSpec:
    if not path.exists():
        raise InvalidArgument(
            f"{origin} {text!r}: no such file ({path}); expected a .n2r scene file (`n2r fit` writes one), "
            f"a 3DGS .ply, '{DEMO_PREFIX}<name>' for a built-in demo scene, or 'module:function' returning a Scene"
        )
    if path.is_file() and path.suffix.lower() == ".ply":  # a 3DGS splat scene; its cameras are found beside it
        return SceneSpec(path.stem, "file", str(path))
    if path.is_dir() or not zipfile.is_zipfile(path):
        raise InvalidArgument(
            f"{origin} {text!r}: {path} is not a scene file (a .n2r scene file is a zip archive written by "
            "`n2r fit`)"
        )
    with zipfile.ZipFile(path) as archive:
        if "scene.json" not in archive.namelist():
            raise InvalidArgument(f"{origin} {text!r}: {path} is a zip archive without scene.json, not a scene file")
    return SceneSpec(path.stem, "file", str(path))


def parse_scene_specs(entries: list[str], base: str | os.PathLike, origin: str) -> list[SceneSpec]:
    """Configured scene entries (paths, globs, ``demo:<name>``, ``module:callable``) → specs with unique
    names; relative paths and globs are taken from ``base``. Raises naming ``origin`` and the entry."""
    specs: list[SceneSpec] = []
    for entry in entries:
        specs.extend(_spec_from_text(entry, Path(base), origin))
    seen: dict[str, SceneSpec] = {}
    for spec in specs:
        other = seen.get(spec.name)
        if other is not None and other.source != spec.source:
            raise InvalidArgument(
                f"{origin}: two scenes are named {spec.name!r} ({other.source} and {spec.source}); test ids "
                "use the scene name, so rename one of the files"
            )
        seen[spec.name] = spec
    return list(seen.values())


def default_scene_specs() -> list[SceneSpec]:
    """The scene used when none is configured: the first built-in demo scene."""
    from ..demo import demo_scene_names

    names = demo_scene_names()
    return [SceneSpec(names[0], "demo", DEMO_PREFIX + names[0])] if names else []


NO_SCENE_MESSAGE = (
    "no scene configured for pytest-n2r: pass --n2r-scene PATH (a .n2r file from `n2r fit`, "
    "'demo:<name>', or 'module:function'), or set n2r_scenes in the ini file"
)


def load_scene_spec(spec: SceneSpec, device: str = "auto") -> Scene:
    """The scene a spec names: a demo scene (exact, or its fitted field for ``demo:<name>-field``), a Python
    callable's scene, or a loaded .n2r file."""
    if spec.kind == "demo":
        from ..demo import load_demo

        return load_demo(spec.name, device)
    if spec.kind == "python":
        module_name, attr = spec.source.rsplit(":", 1)
        try:
            obj: Any = importlib.import_module(module_name)
            for part in attr.split("."):
                obj = getattr(obj, part)
        except (ImportError, AttributeError) as exc:
            raise InvalidArgument(f"scene {spec.source!r}: cannot import it ({exc})") from None
        scene = obj() if callable(obj) and not isinstance(obj, Scene) else obj
        if not isinstance(scene, Scene):
            raise InvalidType(f"scene {spec.source!r} gave {type(scene).__name__}, not a pytest_n2r.Scene")
        return scene
    from ..scene.loading import load_scene  # here: a session on exact scenes alone never loads the field

    return load_scene(spec.source, device=device)
