"""Scene specs: how a user names the scenes to test on, the one resolver of ``--n2r-scene``, ``n2r_scenes``,
``n2r render``, ``n2r info`` and ``n2r study``.

An entry is a ``.n2r`` scene file or a 3DGS ``.ply`` (globs allowed), ``demo:<name>`` for a built-in demo
scene (``demo:<name>-field`` for its fitted twin), or ``module:callable`` returning a
:class:`~pytest_n2r.Scene`. It lives below the plugin, with no pytest import, so that the plugin
(:mod:`pytest_n2r.plugin.scenes`) and the command line parse entries and load scenes through the same code.

>>> spec = resolve_scene("demo:wall", ".", "SCENE")
>>> spec.name, spec.kind, str(spec)
('wall', 'demo', 'demo:wall')
>>> load_scene_spec(spec).views[4].name
'wall_004.png'
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

__all__ = ["SceneSpec", "parse_scene_specs", "resolve_scene", "default_scene_specs", "load_scene_spec",
           "DEMO_PREFIX", "ACCEPTED_FORMS"]

DEMO_PREFIX = "demo:"
#: What a scene entry may be, as error messages list it.
ACCEPTED_FORMS = (f"a .n2r scene file (`n2r fit` writes one), a 3DGS .ply, '{DEMO_PREFIX}<name>' for a built-in "
                  "demo scene, or 'module:function' returning a Scene")
_PYTHON_SPEC = re.compile(r"^[A-Za-z_][\w.]*:[A-Za-z_][\w.]*$")


@dataclass(frozen=True)
class SceneSpec:
    """Where a scene comes from: ``kind`` is ``"file"`` (a ``.n2r`` scene file or a 3DGS ``.ply``), ``"demo"``
    (a built-in demo scene) or ``"python"`` (``module:callable`` returning a :class:`~pytest_n2r.Scene`);
    ``name`` is what test ids and reports show."""

    name: str
    kind: str
    source: str

    def __str__(self) -> str:
        return self.source


def _spec_from_text(text: str, base: Path, origin: str, opened: bool = True) -> list[SceneSpec]:
    """One configured entry → scene specs (a glob may give several); ``origin`` names the option; ``opened``:
    check that an existing file is a scene file."""
    text = text.strip()
    if text.startswith(DEMO_PREFIX):
        name = text[len(DEMO_PREFIX):]
        from . import demo_spec_names

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
        return [_file_spec(Path(m), origin, text, opened) for m in matches]
    if not path.exists() and _PYTHON_SPEC.match(text):
        return [SceneSpec(text.rsplit(":", 1)[1].rsplit(".", 1)[-1], "python", text)]
    return [_file_spec(path, origin, text, opened)]


def _file_spec(path: Path, origin: str, text: str, opened: bool) -> SceneSpec:
    if not path.exists():
        raise InvalidArgument(f"{origin} {text!r}: no such file ({path}); expected {ACCEPTED_FORMS}")
    if not opened or path.is_file() and path.suffix.lower() == ".ply":  # a .ply: 3DGS splats, cameras beside it
        return SceneSpec(path.stem, "file", str(path))
    if path.is_dir() or not zipfile.is_zipfile(path):
        raise InvalidArgument(
            f"{origin} {text!r}: {path} is not a scene file (a .n2r scene file is a zip archive written by "
            "`n2r fit`)"
        )
    from ..scene.file import open_scene_archive  # here: the field's modules load only for a scene file

    with open_scene_archive(path, f"{origin} {text!r}: {path}") as archive:  # as the scene file reader opens it
        names = archive.namelist()
    if "scene.json" not in names:
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


def resolve_scene(text: str, base: str | os.PathLike, origin: str) -> SceneSpec:
    """The one scene ``text`` names, for a command that takes one (``n2r render``, ``n2r info``): any entry
    :func:`parse_scene_specs` accepts, a glob only if it matches one file; relative paths from ``base``. An
    existing file is not opened: the command reads it next, and the scene readers' errors say more."""
    specs = _spec_from_text(text, Path(base), origin, opened=False)
    if len(specs) != 1:
        shown = ", ".join(s.source for s in specs[:3]) + (", ..." if len(specs) > 3 else "")
        raise InvalidArgument(f"{origin} {text!r} matched {len(specs)} scene files ({shown}); expected one scene")
    return specs[0]


def default_scene_specs() -> list[SceneSpec]:
    """The scene used when none is configured: the first built-in demo scene."""
    from . import demo_scene_names

    names = demo_scene_names()
    return [SceneSpec(names[0], "demo", DEMO_PREFIX + names[0])] if names else []


def load_scene_spec(spec: SceneSpec, device: str = "auto", *, images: bool = True) -> Scene:
    """The scene a spec names: a demo scene (exact, or its fitted field for ``demo:<name>-field``), a Python
    callable's scene, or a loaded scene file (``images=False`` skips decoding a ``.n2r`` file's photos)."""
    if spec.kind == "demo":
        from . import load_demo

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

    return load_scene(spec.source, device=device, images=images)
