"""A process's first render of each renderer kind, under a lock file shared with the other processes.

numba compiles a renderer's kernels on their first call in a process and keeps them in its on-disk cache: in
a fresh checkout that first render takes 10-15 s for the demo ray caster and again for the field's marcher.
Two processes that need the same kernels at the same time (pytest-xdist workers, or a session and the
helper that compiles its other renderers meanwhile, :mod:`pytest_n2r.plugin.precompile`) would each compile
them. Here the first render of a kind in a process takes an exclusive lock file named after the kind: a
process that finds it taken waits for the other's compilation and then loads the kernels from numba's cache.

Convention
----------
- A *renderer kind* is the scene's class and its ``renderer_version`` (:func:`renderer_kind`): scenes of one
  kind run the same compiled kernels.
- The lock only orders work; the result never depends on it. Without a lock directory, without ``fcntl``
  (Windows), or after :data:`WAIT_S` seconds of waiting, the render goes ahead unlocked.
"""

from __future__ import annotations

import gc
import os
import re
import time
from collections.abc import Iterator
from contextlib import contextmanager
from pathlib import Path

try:
    import fcntl
except ImportError:  # pragma: no cover - Windows: no lock, each process compiles what it needs
    fcntl = None  # type: ignore[assignment]

from .base import Scene

__all__ = ["WAIT_S", "claim_kind", "collector_paused", "first_render", "renderer_kind"]

#: The longest a process waits for another's first render of a kind (s) before rendering without the lock.
WAIT_S = 600.0
_POLL_S = 0.05
_SUBDIR = "kernel-locks"

#: Renderer kinds this process has rendered (its kernels compiled or loaded: later renders need no lock).
_RENDERED: set[str] = set()


def renderer_kind(scene: Scene) -> str:
    """The renderer kind of ``scene``: its class's module and name and its ``renderer_version``.

    >>> from pytest_n2r.demo import load_demo
    >>> renderer_kind(load_demo("wall")).startswith("pytest_n2r.demo.exact.GroundTruthScene-")
    True
    """
    cls = type(scene)
    return f"{cls.__module__}.{cls.__qualname__}-{scene.renderer_version}"


def rendered(kind: str) -> bool:
    """Whether this process has rendered a scene of ``kind`` already."""
    return kind in _RENDERED


def _lock_path(directory: Path, kind: str) -> Path:
    return directory / _SUBDIR / (re.sub(r"[^\w.-]", "_", kind) + ".lock")


@contextmanager
def claim_kind(directory: str | os.PathLike | None, kind: str, wait: bool = True) -> Iterator[bool]:
    """Hold the lock file of ``kind`` under ``directory`` for the block; yields whether it is held.

    ``wait=False`` gives up at once when another process holds it (yields ``False``); ``wait=True`` waits up
    to :data:`WAIT_S` seconds, then runs the block without it. ``directory=None`` or no ``fcntl``: no lock."""
    if directory is None or fcntl is None:
        yield False
        return
    path = _lock_path(Path(directory), kind)
    try:
        path.parent.mkdir(parents=True, exist_ok=True)
        fd = os.open(path, os.O_RDWR | os.O_CREAT, 0o644)
    except OSError:  # a read-only cache directory: no lock, the render still happens
        yield False
        return
    try:
        held = _acquire(fd, WAIT_S if wait else 0.0)
        try:
            yield held
        finally:
            if held:
                fcntl.flock(fd, fcntl.LOCK_UN)
    finally:
        os.close(fd)


def _acquire(fd: int, wait_s: float) -> bool:
    deadline = time.monotonic() + wait_s
    while True:
        try:
            fcntl.flock(fd, fcntl.LOCK_EX | fcntl.LOCK_NB)
            return True
        except BlockingIOError:
            if time.monotonic() >= deadline:
                return False
            time.sleep(_POLL_S)


@contextmanager
def collector_paused() -> Iterator[None]:
    """Python's cyclic garbage collector off for the block, back on after it (if it was on before): numba's compile
    of a renderer's kernels makes millions of objects that live until it ends, and the collector walked them all
    again in each of its full collections (docs/performance.md). The compile's garbage is collected once, after."""
    if not gc.isenabled():
        yield
        return
    gc.disable()
    try:
        yield
    finally:
        gc.enable()


@contextmanager
def first_render(directory: str | os.PathLike | None, scene: Scene) -> Iterator[None]:
    """Run a render of ``scene``: the first of its kind in this process under the kind's lock (see the module
    docstring) with the collector paused (:func:`collector_paused`: it compiles the kind's kernels or loads them),
    later ones as they are. The kind counts as rendered once the block ends without an error."""
    kind = renderer_kind(scene)
    if kind in _RENDERED:
        yield
        return
    with claim_kind(directory, kind), collector_paused():
        yield
    _RENDERED.add(kind)
