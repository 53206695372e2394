"""The one pytest-n2r session object: resolved settings, scene specs, loaded scenes, the render cache and
the statistics of every relation run. No pytest import: the plugin builds it from the command line and
ini file, and anything else (a script, a notebook) can build one directly.
"""

from __future__ import annotations

import glob
import importlib
import os
import re
import zipfile
from collections.abc import Callable
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

from .cache import DEFAULT_DISK_BYTES, RenderCache
from .errors import InvalidArgument, InvalidType, SceneFileError
from .relation import Relation, RelationStats, RunSettings, check_relation
from .scene.base import Scene

__all__ = ["SceneSpec", "N2RSession", "parse_scene_specs", "default_scene_specs", "DEMO_PREFIX"]

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
        try:
            from .demo import demo_spec_names
        except ImportError:  # a build without demo scenes says so when the scene is loaded
            return [SceneSpec(name, "demo", text)]
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
    try:
        from .demo import demo_scene_names
    except ImportError:
        return []
    names = demo_scene_names()
    return [SceneSpec(names[0], "demo", DEMO_PREFIX + names[0])] if names else []


NO_SCENE_MESSAGE = (
    "no scene configured for pytest-n2r: pass --n2r-scene PATH (a .n2r file from `n2r fit`, "
    "'demo:<name>', or 'module:function'), or set n2r_scenes in the ini file"
)


@dataclass
class N2RSession:
    """Settings, scenes, cache and statistics of one test session (one per pytest-xdist worker)."""

    settings: RunSettings = field(default_factory=RunSettings)
    scenes: list[SceneSpec] = field(default_factory=list)
    device: str = "auto"
    #: Scene fields render at this fraction of the size asked for, upsampled (``RenderSettings.scale``).
    render_scale: float = 1.0
    cache_dir: Path | None = None
    cache_bytes: int = DEFAULT_DISK_BYTES
    stats: list[RelationStats] = field(default_factory=list)
    _loaded: dict[str, Scene] = field(default_factory=dict, repr=False)
    _cache: RenderCache | None = field(default=None, repr=False)

    @property
    def cache(self) -> RenderCache:
        """The render cache (created on first use, so an unused session touches no file)."""
        if self._cache is None:
            self._cache = RenderCache(self.cache_dir, disk_bytes=self.cache_bytes)
        return self._cache

    def scene_specs(self, pins: list[str] | None = None, base: str | os.PathLike = ".") -> list[SceneSpec]:
        """The scenes a test runs on: ``pins`` (scene names or scene entries from an
        ``n2r_scene`` marker) select or add scenes; otherwise every configured scene, or the default."""
        configured = self.scenes or default_scene_specs()
        if not pins:
            return configured
        by_name = {s.name: s for s in configured}
        chosen: list[SceneSpec] = []
        for pin in pins:
            if pin in by_name:
                chosen.append(by_name[pin])
            elif pin.startswith(DEMO_PREFIX) or ":" in pin or "/" in pin or pin.endswith((".n2r", ".ply")):
                chosen.extend(parse_scene_specs([pin], base, "n2r_scene marker"))
            else:
                known = ", ".join(by_name) or "none"
                raise InvalidArgument(
                    f"n2r_scene marker names the scene {pin!r}, which is not configured (configured: {known}); "
                    "pin a configured scene name, or give a .n2r path, 'demo:<name>' or 'module:function'"
                )
        return chosen

    def load(self, spec: SceneSpec) -> Scene:
        """The scene of ``spec``, loaded once per session."""
        scene = self._loaded.get(spec.source)
        if scene is None:
            scene = load_scene_spec(spec, self.device)
            if self.render_scale != 1.0:
                # imported only here: a session on exact scenes alone must not load the field machinery
                # (importing it changed which examples a derandomized run of the example project drew)
                from .scene.field_scene import FieldScene

                if isinstance(scene, FieldScene):
                    scene = scene.with_settings(scene.settings.replace(scale=self.render_scale))
            self._loaded[spec.source] = scene
        return scene

    def run(self, scene: Scene, sut: Callable[[Any], Any], relation: Relation, test_id: str,
            replay: list[Any] | None = None) -> RelationStats:
        """Check ``relation`` for ``sut`` on ``scene`` (replaying ``replay``, a baseline's examples, first);
        the stats are kept whatever the outcome."""
        __tracebackhide__ = True
        return check_relation(scene, sut, relation, settings=self.settings, cache=self.cache, test_id=test_id,
                              replay=replay, on_start=self.stats.append)


def load_scene_spec(spec: SceneSpec, device: str = "auto") -> Scene:
    """The scene a spec names: a demo scene (exact, or its fitted field for ``demo:<name>-field``), a Python
    callable's scene, or a loaded .n2r file."""
    if spec.kind == "demo":
        try:
            from .demo import load_demo
        except ImportError:
            raise InvalidArgument(f"scene {spec.source!r}: this build of pytest-n2r has no demo scenes") from None
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
    load_scene = _scene_loader()
    if load_scene is None:
        raise SceneFileError(f"scene {spec.source!r}: this build of pytest-n2r cannot load .n2r files")
    return load_scene(spec.source, device=device)


def _scene_loader() -> Callable[..., Scene] | None:
    for module in ("pytest_n2r.scene", "pytest_n2r"):
        try:
            loader = getattr(importlib.import_module(module), "load_scene", None)
        except ImportError:
            continue
        if loader is not None:
            return loader
    return None
