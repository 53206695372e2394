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
- A *kernel piece* is a kernel a renderer compiles apart from the rest of its kind's, under its own lock
  (:func:`claim_piece`), so that two processes can compile one kind's kernels at once.
- The lock only orders work; the result never depends on it. Without a lock directory, without ``fcntl``
  (Windows), or after :data:`WAIT_S` seconds of waiting, the render goes ahead unlocked.
"""

from __future__ import annotations

import gc
import os
import re
import time
from collections.abc import Callable, Iterator
from contextlib import contextmanager
from contextvars import ContextVar
from pathlib import Path

try:
    import fcntl
except ImportError:  # pragma: no cover - Windows: no lock, each process compiles what it needs
    fcntl = None  # type: ignore[assignment]

from .base import Scene

__all__ = ["WAIT_S", "claim_kind", "claim_piece", "collector_paused", "first_render", "kernel_locks", "open_own",
           "renderer_kind"]

#: The longest a process waits for another's first render of a kind (s) before rendering without the lock.
WAIT_S = 600.0
_POLL_S = 0.05
_SUBDIR = "kernel-locks"

#: Renderer kinds this process has rendered (its kernels compiled or loaded: later renders need no lock).
_RENDERED: set[str] = set()
#: The lock directory of the first render or helper job in progress (:func:`kernel_locks`), for its pieces.
_DIRECTORY: ContextVar[str | os.PathLike | None] = ContextVar("n2r_kernel_lock_directory", default=None)


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


def open_own(path: Path, flags: int) -> int:
    """``os.open(path, flags | O_CREAT, 0o644)`` without following a symbolic link at ``path``: a link planted in
    place of a lock or log file of the cache directory is removed (never what it points to) and a file made in its
    place, so nothing is created, truncated or written through it."""
    nofollow = getattr(os, "O_NOFOLLOW", 0)
    if not nofollow and path.is_symlink():  # pragma: no cover - no O_NOFOLLOW (Windows)
        path.unlink(missing_ok=True)
    try:
        return os.open(path, flags | os.O_CREAT | nofollow, 0o644)
    except OSError:
        if not path.is_symlink():
            raise
    path.unlink(missing_ok=True)  # the link itself
    return os.open(path, flags | os.O_CREAT | nofollow, 0o644)


def _lock_path(directory: Path, kind: str) -> Path:
    return directory / _SUBDIR / (re.sub(r"[^\w.-]", "_", kind) + ".lock")


@contextmanager
def claim_kind(directory: str | os.PathLike | None, kind: str, wait: bool = True,
               meanwhile: Callable[[], object] | None = None) -> Iterator[bool]:
    """Hold the lock file of ``kind`` under ``directory`` for the block; yields whether it is held.

    ``wait=False`` gives up at once when another process holds it (yields ``False``); ``wait=True`` waits up
    to :data:`WAIT_S` seconds, then runs the block without it; if it finds the lock held, it first calls
    ``meanwhile`` once (other work, such as compiling kernel pieces, which never waits for a kind's lock).
    ``directory=None`` or no ``fcntl``: no lock."""
    if directory is None or fcntl is None:
        yield False
        return
    path = _lock_path(Path(directory), kind)
    try:
        path.parent.mkdir(parents=True, exist_ok=True)
        fd = open_own(path, os.O_RDWR)
    except OSError:  # a read-only cache directory: no lock, the render still happens
        yield False
        return
    try:
        held = _acquire(fd, WAIT_S if wait else 0.0, meanwhile)
        try:
            yield held
        finally:
            if held:
                fcntl.flock(fd, fcntl.LOCK_UN)
    finally:
        os.close(fd)


def _acquire(fd: int, wait_s: float, meanwhile: Callable[[], object] | None = None) -> bool:
    deadline = time.monotonic() + wait_s
    while True:
        try:
            fcntl.flock(fd, fcntl.LOCK_EX | fcntl.LOCK_NB)
            return True
        except BlockingIOError:
            if time.monotonic() >= deadline:
                return False
            if meanwhile is not None:
                meanwhile()
                meanwhile = None
            else:
                time.sleep(_POLL_S)


@contextmanager
def kernel_locks(directory: str | os.PathLike | None) -> Iterator[None]:
    """Kernel pieces compiled in the block (:func:`claim_piece`) take their locks under ``directory``."""
    token = _DIRECTORY.set(directory)
    try:
        yield
    finally:
        _DIRECTORY.reset(token)


@contextmanager
def claim_piece(name: str) -> Iterator[bool]:
    """Hold the lock of kernel piece ``name`` for the block (waiting as :func:`claim_kind` does); yields whether
    it is held. A *piece* is a kernel a renderer compiles apart from its others, so that the kernel helper can
    compile it while the session compiles the rest (:meth:`~.base.Scene.compile_apart`): a process that finds it
    held waits for the other's compile, then loads it from numba's cache. No lock outside :func:`kernel_locks`
    (or :func:`first_render`, which sets it)."""
    with claim_kind(_DIRECTORY.get(), f"piece-{name}") as held:
        yield held


@contextmanager
def collector_paused() -> Iterator[None]:
    """Python's cyclic garbage collector off for the block, back on after it (if it was on before): numba's compile
    of a renderer's kernels makes millions of objects that live until it ends, and the collector walked them all
    again in each of its full collections (docs/performance-log.md). The compile's garbage is collected once, after."""
    if not gc.isenabled():
        yield
        return
    gc.disable()
    try:
        yield
    finally:
        gc.enable()


@contextmanager
def first_render(directory: str | os.PathLike | None, scene: Scene,
                 meanwhile: Callable[[], object] | None = None) -> Iterator[None]:
    """Run a render of ``scene``: the first of its kind in this process under the kind's lock (see the module
    docstring; ``meanwhile`` is called once if it must wait for it) with the collector paused
    (:func:`collector_paused`: it compiles the kind's kernels or loads them), later ones as they are. The kind
    counts as rendered once the block ends without an error."""
    kind = renderer_kind(scene)
    if kind in _RENDERED:
        yield
        return
    with kernel_locks(directory), collector_paused(), claim_kind(directory, kind, meanwhile=meanwhile):
        yield
    _RENDERED.add(kind)
