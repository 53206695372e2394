"""Compile the kernels of a session's other renderers in a helper process while the session renders.

In a fresh checkout (numba's cache empty) each renderer compiles its kernels on its first render: on the
example project about 18 CPU s for the demo ray caster, then 7 for the scene field's renderer when the first
fitted twin is rendered (docs/performance-log.md, 3 December), one after the other, while the session's other
core is mostly idle. When a session
renders for the first time it starts this helper (:func:`start_helper`), which loads the session's scenes in
the order the tests use them (built-in demo scenes and scene files; never a ``module:function`` scene: it
runs no user code) and renders a tiny view of one scene of each renderer kind the session is not rendering
itself, under the kind's lock (:mod:`pytest_n2r.scene.first_render`): numba writes the kernels to
its cache, and the session, reaching that kind later, waits for the helper if it is still compiling and
then loads them. Before that it compiles what the scenes of the session's first family compile apart from
their kernels (:meth:`~pytest_n2r.scene.base.Scene.compile_apart`: the exact demo scenes' row cast, about half
of the ray caster's compile, and their blend masks, which the session's first render waits for or loads after
compiling the rest of the ray caster), for the families in :data:`APART_FAMILIES`.

Only the kernels cross from the helper to the session (through numba's on-disk cache); the helper's renders
are thrown away. One helper runs per render cache directory at a time (pytest-xdist workers share one); a
session without a render cache directory, or on a system without ``fcntl``, starts none.

Run as ``python -m pytest_n2r.plugin.precompile`` with its job as JSON on stdin (:func:`start_helper`).
"""

from __future__ import annotations

import json
import os
import subprocess
import sys
import time
from pathlib import Path
from typing import IO, Any

from ..scene.first_render import claim_kind, collector_paused, kernel_locks, open_own, renderer_kind
from .scenes import SceneSpec
from .session import N2RSession

__all__ = ["APART_FAMILIES", "HELPER_KIND", "apart_specs", "compile_apart_meanwhile", "family", "helper_specs",
           "start_helper", "start_for_session", "run_job"]

#: The lock a running helper holds for its whole life (one helper per render cache directory).
HELPER_KIND = "precompile-helper"
#: Longer side of the helper's renders (pixels): the kernels compiled do not depend on the size.
TINY = 32
#: The helper's output, for a user wondering what it did: in the lock directory of the render cache.
LOG_NAME = "precompile.log"
#: Families whose scenes load in well under a second and compile parts apart from their kernels.
APART_FAMILIES = frozenset({"demo"})


def family(spec: SceneSpec) -> str | None:
    """A guess, from the spec alone, at which scenes share a renderer: the helper loads one scene per family
    (loading a fitted field takes seconds). ``None`` for a ``module:function`` scene: the helper runs no
    user code. A wrong guess costs only time: a kind the helper did not compile is compiled by the session,
    as without the helper."""
    if spec.kind == "demo":
        from ..demo.fitted import FIELD_SUFFIX

        return "demo-field" if spec.name.endswith(FIELD_SUFFIX) else "demo"
    if spec.kind == "file":
        return "file" + Path(spec.source).suffix.lower()
    return None


def helper_specs(planned: list[SceneSpec], rendering: SceneSpec | None) -> list[SceneSpec]:
    """One scene of each :func:`family` in ``planned`` (in order) other than the family of ``rendering`` (the
    scene the session is about to render first): what the helper should compile; empty when there is none."""
    seen: set[str | None] = {None, family(rendering)} if rendering is not None else {None}
    out = []
    for spec in planned:
        if family(spec) not in seen:
            seen.add(family(spec))
            out.append(spec)
    return out


def apart_specs(planned: list[SceneSpec], rendering: SceneSpec | None) -> list[SceneSpec]:
    """The scenes of ``planned`` in the family of ``rendering`` (in order) when it is one of
    :data:`APART_FAMILIES`: what the helper compiles apart while the session compiles their kernels."""
    first = family(rendering) if rendering is not None else None
    return [spec for spec in planned if first in APART_FAMILIES and family(spec) == first]


def open_log(cache_dir: str | Path) -> IO[str]:
    """The helper log of ``cache_dir`` (``kernel-locks/precompile.log``), opened for appending: every xdist worker
    starts a helper, and the one that finds another at work says so below that one's lines instead of erasing them."""
    log_dir = Path(cache_dir) / "kernel-locks"
    log_dir.mkdir(parents=True, exist_ok=True)
    return os.fdopen(open_own(log_dir / LOG_NAME, os.O_WRONLY | os.O_APPEND), "a")  # a planted link is replaced


def _restart_log(cache_dir: str | Path) -> None:
    """Empty the log for the helper that holds the lock (it keeps one session's lines, not every session's)."""
    try:  # never through a link planted in its place
        fd = os.open(Path(cache_dir) / "kernel-locks" / LOG_NAME, os.O_WRONLY | getattr(os, "O_NOFOLLOW", 0))
        try:
            os.ftruncate(fd, 0)
        finally:
            os.close(fd)
    except OSError:  # no log (the helper was started by hand) or none writable: nothing to empty
        pass


def start_helper(specs: list[SceneSpec], skip_kind: str, cache_dir: str | Path | None, device: str,
                 render_scale: float, apart: list[SceneSpec] | None = None) -> subprocess.Popen | None:
    """Start the helper on ``specs`` (in the order the session uses them), leaving out scenes of
    ``skip_kind`` (the session is compiling those now), after compiling the parts of the ``apart`` scenes
    (:func:`apart_specs`); ``None`` without a cache directory or scenes."""
    from ..scene.first_render import fcntl

    if cache_dir is None or fcntl is None or not (specs or apart):
        return None
    job = {"scenes": [[s.name, s.kind, s.source] for s in specs], "skip": skip_kind, "cache_dir": str(cache_dir),
           "device": device, "render_scale": render_scale, "sys_path": list(sys.path),
           "apart": [[s.name, s.kind, s.source] for s in apart or ()]}
    try:
        log = open_log(cache_dir)
    except OSError:
        return None
    with log:
        proc = subprocess.Popen([sys.executable, "-m", "pytest_n2r.plugin.precompile"], stdin=subprocess.PIPE,
                                stdout=log, stderr=subprocess.STDOUT)
    assert proc.stdin is not None
    proc.stdin.write(json.dumps(job).encode())
    proc.stdin.close()
    return proc


def start_for_session(session: N2RSession, scene: Any) -> None:
    """Before ``session``'s first render (of ``scene``): start the helper on the planned scenes of the other
    families (the session's ``on_first_render``, set by the plugin); it is kept as ``session.helper``."""
    rendering = session.spec_of(scene)
    specs, apart = helper_specs(session.planned, rendering), apart_specs(session.planned, rendering)
    if (specs or apart) and session.helper is None:
        session.helper = start_helper(specs, renderer_kind(scene), session.cache_dir, session.device,
                                      session.render_scale, apart)


def compile_apart_meanwhile(session: N2RSession, scene: Any) -> None:
    """While ``session``'s first render of ``scene`` waits for another process compiling its kernels (an xdist
    worker, or the helper): compile what the planned scenes of :data:`APART_FAMILIES` compile apart, which the
    process that compiles their kernels would otherwise compile after them (the session's ``while_waiting``, set
    by the plugin). A piece another process is compiling is waited for and loaded. Not for a scene whose tests
    this process ran already (released: it would be loaded again, and kept to the end, for nothing)."""
    for spec in session.planned:
        if family(spec) in APART_FAMILIES and spec.source not in session.released:
            session.load(spec).compile_apart()


def run_job(job: dict[str, Any]) -> list[str]:
    """The helper's work: returns the scenes whose parts it compiled apart (``apart:NAME``) and the renderer
    kinds it compiled (or loaded from numba's cache)."""
    session = N2RSession(device=job["device"], render_scale=job["render_scale"])
    done: list[str] = []
    with claim_kind(job["cache_dir"], HELPER_KIND, wait=False) as held, kernel_locks(job["cache_dir"]):
        if not held:
            print(f"helper {os.getpid()}: another helper is compiling for this cache directory", flush=True)
            return done
        _restart_log(job["cache_dir"])
        print(f"helper {os.getpid()} started at {time.strftime('%Y-%m-%d %H:%M:%S')}", flush=True)
        for name, kind, source in job.get("apart", ()):
            with collector_paused():
                compiled = session.load(SceneSpec(name, kind, source)).compile_apart()
            if compiled:
                done.append(f"apart:{name}")
                print(f"{name}: compiled apart from its kernels", flush=True)
        seen = {job["skip"]}
        for name, kind, source in job["scenes"]:
            scene = session.load(SceneSpec(name, kind, source))
            scene_kind = renderer_kind(scene)
            if scene_kind in seen:
                continue
            seen.add(scene_kind)
            with claim_kind(job["cache_dir"], scene_kind, wait=False) as mine, collector_paused():
                if not mine:  # a session process is compiling it now
                    print(f"{scene_kind}: another process holds it", flush=True)
                    continue
                view = scene.views[0]
                camera = view.camera.scaled(TINY / max(view.camera.width, view.camera.height))
                scene.render(view.c2w, camera, ("rgb", "depth", "opacity"))
                done.append(scene_kind)
                print(f"{scene_kind}: compiled (scene {name})", flush=True)
    return done


def main() -> int:
    job = json.loads(sys.stdin.read())
    sys.path[:] = job["sys_path"]
    run_job(job)
    return 0


if __name__ == "__main__":
    sys.exit(main())
