"""The one pytest-n2r session object: resolved settings, scene specs, loaded scenes, the render cache and
the records of every relation run. No pytest import: the plugin builds it from the command line and
ini file, and anything else (a script, a notebook) can build one directly.
"""

from __future__ import annotations

import os
import subprocess
from collections.abc import Callable
from dataclasses import dataclass, field, replace
from pathlib import Path
from typing import Any

from .. import defaults
from ..errors import InvalidArgument
from ..relation import Relation, RelationRecord, RunSettings, check_relation
from ..relation.sut_outputs import SUTOutputs
from ..scene.base import Scene
from ..scene.render_cache import DEFAULT_DISK_BYTES, RenderCache
from .scenes import DEMO_PREFIX, SceneSpec, default_scene_specs, load_scene_spec, parse_scene_specs

__all__ = ["N2RSession"]


@dataclass
class N2RSession:
    """Settings, scenes, cache and relation records of one test session (one per pytest-xdist worker)."""

    settings: RunSettings = field(default_factory=RunSettings)
    scenes: list[SceneSpec] = field(default_factory=list)
    device: str = defaults.DEVICE
    #: Scene fields render at this fraction of the size asked for, upsampled (``RenderSettings.scale``).
    render_scale: float = defaults.RENDER_SCALE
    cache_dir: Path | None = None
    cache_bytes: int = DEFAULT_DISK_BYTES
    records: list[RelationRecord] = field(default_factory=list)
    #: The SUTs' outputs on renders, shared by the relations that run one SUT object on one render.
    sut_outputs: SUTOutputs = field(default_factory=SUTOutputs, repr=False)
    #: The scenes the session's tests use, in order (the plugin sets it after collection, :meth:`plan`), for the
    #: kernel helper (:mod:`.precompile`).
    planned: list[SceneSpec] = field(default_factory=list)
    #: The position of the last test on each planned scene in the run's order, by source, until
    #: :meth:`release_done` releases it (:meth:`plan`).
    last_use: dict[str, int] = field(default_factory=dict, repr=False)
    #: Whether this process runs its tests in the order of :meth:`plan` (see :meth:`release_done`).
    in_order: bool = True
    #: The sources of the planned scenes whose last test this process is past: released, and not loaded again for
    #: their kernel pieces (:func:`.precompile.compile_apart_meanwhile`).
    released: set[str] = field(default_factory=set, repr=False)
    #: Called with the scene before the render cache's first render (the plugin starts the kernel helper).
    on_first_render: Callable[[Scene], None] | None = field(default=None, repr=False)
    #: Called with the scene while its first render waits for another process compiling its kernels (the plugin
    #: compiles kernel pieces meanwhile).
    while_waiting: Callable[[Scene], None] | None = field(default=None, repr=False)
    #: The kernel helper process, once started; :meth:`close` ends it.
    helper: subprocess.Popen | None = field(default=None, repr=False)
    _loaded: dict[str, Scene] = field(default_factory=dict, repr=False)  # by source, from load to release_done
    _positions: dict[Any, int] = field(default_factory=dict, repr=False)  # of the tests, by test (:meth:`plan`)
    _cache: RenderCache | None = field(default=None, repr=False)

    @property
    def cache(self) -> RenderCache:
        """The render cache (created on first use, so an unused session touches no file), trimmed to its cap as it
        opens: a session that stores less than the cache's trimming interval would otherwise never trim it."""
        if self._cache is None:
            workers = os.environ.get("PYTEST_XDIST_WORKER_COUNT", "1")  # xdist's workers store into it at once
            self._cache = RenderCache(self.cache_dir, disk_bytes=self.cache_bytes,
                                      writers=int(workers) if workers.isdecimal() else 1)
            self._cache.trim()  # a directory scan (some 15 ms per 1 000 entries)
            self._cache.on_first_render = self.on_first_render
            self._cache.while_waiting = self.while_waiting
        return self._cache

    def spec_of(self, scene: Scene) -> SceneSpec | None:
        """The planned spec this session loaded ``scene`` from, if any."""
        return next((s for s in self.planned if self._loaded.get(s.source) is scene), None)

    def close(self) -> None:
        """End the kernel helper if it still runs (its work only saves time)."""
        if self.helper is not None and self.helper.poll() is None:
            self.helper.terminate()
            self.helper.wait()
        self.helper = None

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
        return list(dict.fromkeys(chosen))  # a scene pinned twice (by name and by entry) runs once

    def plan(self, tests: list[tuple[Any, SceneSpec | None]], dist: str = "no") -> None:
        """Take every test of the run (any hashable: the plugin gives its pytest items) with its scene (``None``: a
        test on no scene), in the run's order: the :attr:`planned` scenes (for the kernel helper, :mod:`.precompile`),
        and the last test on each, after which :meth:`release_done` releases it. ``dist``: ``"no"`` in a serial run,
        else the pytest-xdist worker's ``--dist`` mode (under ``load`` and ``each`` it runs its tests in order)."""
        self.planned = list(dict.fromkeys(spec for _, spec in tests if spec is not None))
        self.last_use = {spec.source: position for position, (_, spec) in enumerate(tests) if spec is not None}
        self._positions = {test: position for position, (test, _) in enumerate(tests)}
        self.in_order = dist in ("no", "load", "each")

    def release_done(self, test: Any, next_test: Any | None) -> list[Scene]:
        """After ``test``, before ``next_test`` (the next test this process runs; ``None``: none), tests of
        :meth:`plan`: release the scenes no later test of this process uses (returned, those that were loaded): in
        order, those whose last test comes before ``next_test`` (a pytest-xdist worker skips the tests others run);
        out of order (``loadfile``, ``loadscope``, ``worksteal``: xdist hands a worker whole files, the largest first
        by default, or tests stolen from another) none before the process's last test, since any later test may
        come back to any scene."""
        if not self.in_order:
            done = list(self.last_use) if next_test is None else []
        else:
            next_position = self._positions.get(next_test)
            done = [s for s, last in self.last_use.items() if next_position is None or last < next_position]
        for source in done:
            del self.last_use[source]
        self.released.update(done)
        return [scene for source in done if (scene := self._loaded.pop(source, None)) is not None]

    def load(self, spec: SceneSpec) -> Scene:
        """The scene of ``spec``, loaded on first use and kept until :meth:`release_done` releases it."""
        scene = self._loaded.get(spec.source)
        if scene is None:
            scene = load_scene_spec(spec, self.device)
            if self.render_scale != 1.0:
                # imported only here: a session on exact scenes alone must not load the field machinery
                # (importing it changed which examples a derandomized run of the example project drew)
                from ..scene.field_scene import FieldScene

                if isinstance(scene, FieldScene):
                    scene = scene.with_settings(scene.settings.replace(scale=self.render_scale))
            _warn_if_unfinished(scene)
            self._loaded[spec.source] = scene
        return scene

    def run(self, scene: Scene, sut: Callable[[Any], Any], relation: Relation, test_id: str,
            replay: list[Any] | None = None, shrink: bool = True) -> RelationRecord:
        """Check ``relation`` for ``sut`` on ``scene`` (replaying ``replay``, a baseline's examples, first; a
        failure shrunk unless ``shrink`` is false); its record is kept in :attr:`records` whatever the outcome."""
        __tracebackhide__ = True
        settings = self.settings if shrink else replace(self.settings, shrink=False)
        return check_relation(scene, sut, relation, settings=settings, cache=self.cache, test_id=test_id,
                              replay=replay, on_start=self.records.append, sut_outputs=self.sut_outputs)


def _warn_if_unfinished(scene: Scene) -> None:
    """Warn (:class:`~pytest_n2r.errors.UnfinishedScene`) when ``scene`` is a checkpoint of a fit that did not
    finish: ``n2r info`` says so, and a test run must too."""
    report = getattr(scene, "report", None)
    if isinstance(report, dict) and report.get("complete", True) is False:
        import warnings

        from ..errors import UnfinishedScene

        warnings.warn(UnfinishedScene(
            f"scene {scene.name!r} is a checkpoint: its fit did not finish ({report.get('steps', '?')} steps), so "
            "these relations test a field still being fitted; fit it to the end (n2r fit) before trusting verdicts "
            "on it"), stacklevel=1)
