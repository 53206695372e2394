"""Render cache: an in-memory LRU for one session over an on-disk, content-addressed store.

A render is identified by everything that determines its pixels: the scene's content hash (which covers its
render settings), its renderer's version, the pose (exact float64 bytes), the camera, the package version and a
digest of its rendering code. Each output (``rgb``, ``depth``, ``opacity``) is stored on its own, so a later
request for more outputs renders only the missing ones. Beside the renders the disk store keeps *decisions*: small
JSON objects that a check computed from renders alone (a follow-up's validity verdict, a keypoint metric's result),
under a key that names those renders, folded with a digest of the package's source, so a checkout whose code was
edited (its version unchanged) decides again rather than reading what the old code decided. Files are written under
a temporary name and renamed into place (:mod:`~.cache_files`, which also trims the store), so concurrent
pytest-xdist workers sharing one directory never see a torn file: at worst two workers render the same view and the
second rename wins with identical bytes (rendering is deterministic).
"""

from __future__ import annotations

import functools
import hashlib
import io
import json
import math
import os
import re
import shutil
import sys
import warnings
from collections import OrderedDict
from collections.abc import Callable, Iterable
from dataclasses import dataclass
from pathlib import Path
from typing import BinaryIO

import numpy as np

from .. import __version__, defaults
from .._validation import parse_size
from ..errors import InvalidArgument
from ..geometry import Camera, check_pose
from ..render.view import RenderedView
from .base import Scene, normalize_outputs
from .cache_files import CacheNotStored, cache_entries, discard, touch, trim_entries, write_entry
from .cache_folder import claim, foreign_entries, is_ours, not_a_cache
from .first_render import first_render
from .keep_threads import threads_kept

__all__ = ["RenderCache", "CacheStats", "CacheNotStored", "render_key", "source_digest", "parse_size",
           "DEFAULT_DISK_BYTES", "DEFAULT_MEMORY_BYTES"]

DEFAULT_MEMORY_BYTES = 512 * 2**20
#: Check the disk size cap after this many bytes were written (a directory scan is not free).
_TRIM_EVERY_BYTES = 64 * 2**20
_SUBDIR = "renders"
_DECISIONS = "decisions"
_FLOORS = "floors"  # field floors (pytest_n2r.relation.floor), counted in the cap and cleared with the rest

DEFAULT_DISK_BYTES = parse_size(defaults.CACHE_SIZE)


#: The subpackages whose code makes a render's pixels (:func:`render_key`).
RENDERING_CODE = ("demo", "field", "geometry", "render", "scene", "splats")


@functools.cache
def source_digest(*subpackages: str) -> str:
    """Hex SHA-256 of the modules of the package, or of its ``subpackages`` (paths and bytes), read once a process
    (~10 ms): the code that made a decision or a picture, so an edit in a checkout is decided or rendered again."""
    root = Path(__file__).resolve().parents[1]
    h = hashlib.sha256()
    for path in sorted(root.rglob("*.py")):
        if subpackages and path.relative_to(root).parts[0] not in subpackages:
            continue
        h.update(f"{path.relative_to(root).as_posix()}\0".encode())
        h.update(path.read_bytes())
    return h.hexdigest()


def render_key(scene: Scene, c2w: np.ndarray, camera: Camera) -> str:
    """Hex SHA-256 of what determines a render's pixels (the outputs are stored under this key): the package
    version and its rendering code (:data:`RENDERING_CODE`: a renderer edited in a checkout without a version
    bump), the scene's :attr:`~pytest_n2r.scene.base.Scene.content_hash` (which covers its render settings),
    its renderer's version, the camera and the exact pose."""
    spec = {
        "version": __version__,
        "code": source_digest(*RENDERING_CODE),
        "scene": scene.content_hash,
        "renderer": scene.renderer_version,
        "camera": camera.to_dict(),
    }
    h = hashlib.sha256(json.dumps(spec, sort_keys=True, default=repr).encode())
    h.update(np.ascontiguousarray(c2w, dtype="<f8").tobytes())
    return h.hexdigest()


#: The header ``np.save`` writes for the little-endian C-order arrays of renders (version 1.0), read without
#: ``np.load``'s general parser of headers: a warm main job reads about 2 000 entries (docs/performance-log.md).
_NPY_HEADER = re.compile(rb"\{'descr': '(<f4|<f8|\|u1|\|b1)', 'fortran_order': False, "
                         rb"'shape': \((\d+(?:, \d+)*),?\), \} *\n")


def _read_npy(path: Path) -> np.ndarray:
    """The read-only array of the ``.npy`` file ``path`` (any header that is not a render's goes to ``np.load``);
    :class:`ValueError` when the file is truncated or malformed."""
    data = path.read_bytes()
    size = int.from_bytes(data[8:10], "little") if data[:8] == b"\x93NUMPY\x01\x00" else 0
    match = _NPY_HEADER.fullmatch(data, 10, 10 + size) if size and len(data) >= 10 + size else None
    if match is None:
        if not data.startswith(b"\x93NUMPY"):  # empty, or anything np.load would read another way (a zip)
            raise ValueError(f"{str(path)!r} is not a .npy file")
        stream = io.BytesIO(data)
        try:  # size the array from its header against the file's length before np.load allocates it
            version = np.lib.format.read_magic(stream)
            npy = np.lib.format
            shape, _, dtype = (npy.read_array_header_1_0 if version == (1, 0) else npy.read_array_header_2_0)(stream)
            if dtype.hasobject or math.prod(shape) * dtype.itemsize > len(data) - stream.tell():
                raise ValueError(f"{str(path)!r}: its header declares more data than the file holds")
            value = np.load(io.BytesIO(data), allow_pickle=False)
        except (EOFError, MemoryError) as exc:
            raise ValueError(f"{str(path)!r} is cut short or malformed: {exc!r}") from None
        value.setflags(write=False)
        return value
    shape = tuple(int(n) for n in match.group(2).split(b", "))
    return np.frombuffer(data, dtype=match.group(1).decode(), offset=10 + size).reshape(shape)


def _as_requested(value: np.ndarray, name: str, camera: Camera) -> np.ndarray | None:
    """A render read back as ``scene.render`` gives output ``name`` at ``camera`` (``rgb`` H x W x 3 ``uint8``,
    ``depth`` and ``opacity`` H x W finite ``float32``; the other byte order is converted), or ``None`` when it is
    not that: an entry damaged or planted in the cache directory is not handed to a check."""
    want = np.dtype(np.uint8 if name == "rgb" else np.float32)
    shape = (camera.height, camera.width, 3) if name == "rgb" else (camera.height, camera.width)
    if value.dtype.newbyteorder("=") != want or value.shape != shape:
        return None
    if value.dtype != want:
        value = value.astype(want)
        value.setflags(write=False)
    return value if name == "rgb" or np.isfinite(value).all() else None


@dataclass
class CacheStats:
    """Counts of one cache's lookups (per output) and of scene renders it had to do."""

    memory_hits: int = 0
    disk_hits: int = 0
    renders: int = 0

    def as_dict(self) -> dict[str, int]:
        return {"memory_hits": self.memory_hits, "disk_hits": self.disk_hits, "renders": self.renders}


class RenderCache:
    """Renders through ``scene.render`` only what neither the memory LRU nor the disk store holds.

    ``directory=None`` keeps the cache in memory only. ``memory_bytes`` and ``disk_bytes`` cap the two
    levels; the disk level (renders, decisions and the field floors in ``floors/``) evicts the least recently used
    entries (by modification time, which a hit refreshes) down to 80 % of its cap (:meth:`trim`). A process's first
    render of each renderer kind holds a lock file in ``directory`` (:mod:`~pytest_n2r.scene.first_render`):
    processes sharing the directory compile a kernel once. Entries are deleted (evicted, cleared) only in a
    directory that carries pytest-n2r's ``CACHEDIR.TAG``, written on the first store into a directory that is new,
    empty or holds only pytest-n2r's files: a folder of the user's is never tagged (:func:`foreign_entries`), and
    its ``.gitignore`` never replaced. ``writers``: how many processes store into ``directory`` at once (pytest-xdist's
    workers), which the trim's rhythm counts.
    """

    def __init__(self, directory: str | os.PathLike | None = None, *, memory_bytes: int = DEFAULT_MEMORY_BYTES,
                 disk_bytes: int = DEFAULT_DISK_BYTES, writers: int = 1):
        self.directory = Path(directory) if directory is not None else None
        self.writers = max(1, int(writers))  # processes storing into the directory at once (xdist's workers)
        self.memory_bytes = parse_size(memory_bytes, "memory_bytes")
        self.disk_bytes = parse_size(disk_bytes, "disk_bytes")
        self.stats = CacheStats()
        self._memory: OrderedDict[tuple[str, str], np.ndarray] = OrderedDict()
        self._memory_used = 0
        self._claimed = False  # the directory is pytest-n2r's tagged cache (see _prepare_directory)
        self._written_since_trim, self._held = 0, self.disk_bytes  # bytes held at the last trim: unknown, so full
        self._store_error: OSError | None = None  # set when storing stopped (see _replace)
        self._skipped = 0  # stores skipped in a row because a folder was removed or made under them
        #: Called with the scene just before this cache's first render (a session starts its kernel helper).
        self.on_first_render: Callable[[Scene], None] | None = None
        #: Called with the scene when its first render waits for another process compiling its kind's kernels
        #: (:func:`~.first_render.first_render`): the plugin compiles kernel pieces meanwhile.
        self.while_waiting: Callable[[Scene], None] | None = None

    def __repr__(self) -> str:
        where = str(self.directory) if self.directory else "memory only"
        return f"RenderCache({where})"

    # -- public ---------------------------------------------------------------------------------------

    def render(self, scene: Scene, c2w: np.ndarray, camera: Camera,
               outputs: str | Iterable[str] = ("rgb",)) -> RenderedView:
        """``scene.render(c2w, camera, outputs)``, served from the cache where possible."""
        return self.render_keyed(scene, c2w, camera, outputs)[0]

    def render_keyed(self, scene: Scene, c2w: np.ndarray, camera: Camera,
                     outputs: str | Iterable[str] = ("rgb",)) -> tuple[RenderedView, str]:
        """:meth:`render` and the render's :func:`render_key` (which names it for the SUT outputs kept by
        :class:`~pytest_n2r.relation.sut_outputs.SUTOutputs`: computed once, here)."""
        outputs = normalize_outputs(outputs)
        c2w = check_pose(c2w)
        key = render_key(scene, c2w, camera)
        arrays: dict[str, np.ndarray] = {}
        for name in outputs:
            value = self._memory_get(key, name)
            if value is not None:
                self.stats.memory_hits += 1
            else:
                value = self._disk_get(key, name, camera)
                if value is not None:
                    self.stats.disk_hits += 1
                    self._memory_put(key, name, value)
            if value is not None:
                arrays[name] = value
        missing = tuple(o for o in outputs if o not in arrays)
        if missing:
            if self.stats.renders == 0 and self.on_first_render is not None:
                self.on_first_render(scene)
            self.stats.renders += 1
            # threads_kept: the SUT runs next, with the thread count it chose
            meanwhile = None if self.while_waiting is None else functools.partial(self.while_waiting, scene)
            with first_render(self.directory, scene, meanwhile), threads_kept():
                view = scene.render(c2w, camera, missing)
            for name in missing:
                value = getattr(view, name)
                arrays[name] = value
                self._memory_put(key, name, value)
                self._disk_put(key, name, value)
        return RenderedView(camera=camera, c2w=c2w, **arrays), key

    def decision(self, key: str) -> dict | None:
        """The decision :meth:`put_decision` stored under ``key`` (a hex digest of what it was decided from: render
        keys, thresholds) in this or an earlier session, or ``None`` (none, unreadable, or a memory-only cache)."""
        if self.directory is None:
            return None
        path = self._decision_path(key)
        try:
            value = json.loads(path.read_bytes())
        except (FileNotFoundError, PermissionError):  # none, or another user's that we may not read (nor delete)
            return None
        except (OSError, ValueError, RecursionError):  # torn by a crash, disk trouble, nested too deep: decided again
            discard(path)
            return None
        touch(path)
        return value if isinstance(value, dict) else None

    def put_decision(self, key: str, value: dict) -> None:
        """Store the JSON object ``value`` under ``key`` on disk (nothing for a memory-only cache); counted in the
        cap and evicted by :meth:`trim` with the renders, least recently used first."""
        if self.directory is None:
            return
        data = json.dumps(value, sort_keys=True).encode()
        self._replace(self._decision_path(key), lambda f: f.write(data))
        self._wrote(len(data))

    def clear(self) -> None:
        """Forget everything, in memory and on disk; :class:`InvalidArgument`, with nothing deleted on disk, when
        the directory is not a pytest-n2r cache (no ``CACHEDIR.TAG`` of pytest-n2r's, and other files in it)."""
        self._memory.clear()
        self._memory_used = 0
        if self.directory is None:
            return
        foreign = foreign_entries(self.directory)
        if foreign:
            raise InvalidArgument(f"{not_a_cache(self.directory, foreign)}; nothing was deleted (choose a new or empty "
                                  "folder for the cache)")
        for sub in (_SUBDIR, _DECISIONS, _FLOORS):
            if (self.directory / sub).exists():
                shutil.rmtree(self.directory / sub, ignore_errors=True)

    def disk_usage(self) -> int:
        """Bytes the disk store takes now (allocated blocks, as ``du`` counts them): renders, decisions, floors and
        their writers' temporary files."""
        return 0 if self.directory is None else sum(size for _, _, size, _ in cache_entries(self.directory))

    # -- memory level ---------------------------------------------------------------------------------

    def _memory_get(self, key: str, name: str) -> np.ndarray | None:
        value = self._memory.get((key, name))
        if value is not None:
            self._memory.move_to_end((key, name))
        return value

    def _memory_put(self, key: str, name: str, value: np.ndarray) -> None:
        if value.nbytes > self.memory_bytes:
            return
        value.setflags(write=False)  # shared between callers: nobody may draw on the cached array
        old = self._memory.pop((key, name), None)
        if old is not None:
            self._memory_used -= old.nbytes
        self._memory[(key, name)] = value
        self._memory_used += value.nbytes
        while self._memory_used > self.memory_bytes:
            _, dropped = self._memory.popitem(last=False)
            self._memory_used -= dropped.nbytes

    # -- disk level -----------------------------------------------------------------------------------

    def _path(self, key: str, name: str) -> Path:
        assert self.directory is not None
        return self.directory / _SUBDIR / key[:2] / f"{key}.{name}.npy"

    def _decision_path(self, key: str) -> Path:
        assert self.directory is not None
        key = hashlib.sha256(f"{source_digest()}/{key}".encode()).hexdigest()
        return self.directory / _DECISIONS / key[:2] / f"{key}.json"

    def _disk_get(self, key: str, name: str, camera: Camera) -> np.ndarray | None:
        if self.directory is None:
            return None
        path = self._path(key, name)
        try:
            value = _read_npy(path)
        except (FileNotFoundError, PermissionError):  # none, or another user's that we may not read (nor delete)
            return None
        except (OSError, ValueError):  # unreadable (disk trouble, another version's format): re-render
            discard(path)
            return None
        requested = _as_requested(value, name, camera)
        if requested is None:  # not what was asked for (damaged or planted): re-render
            discard(path)
            return None
        touch(path)
        return requested

    def _disk_put(self, key: str, name: str, value: np.ndarray) -> None:
        if self.directory is None or value.nbytes > self.disk_bytes:
            return
        self._replace(self._path(key, name), lambda f: np.save(f, np.ascontiguousarray(value), allow_pickle=False))
        self._wrote(value.nbytes)

    def _wrote(self, nbytes: int) -> None:
        """Count ``nbytes`` stored; trim after a tenth of the cap (at most 64 MiB) since the last trim once what the
        last trim found held and what the writers stored since (this one's times :attr:`writers`) pass half the cap:
        a cold main job scanned its 4 360 entries 9 times (35-43 ms each, linear in the entries) at a quarter of it."""
        self._written_since_trim += nbytes
        if self._written_since_trim >= min(_TRIM_EVERY_BYTES, self.disk_bytes // 10 + 1) and \
                self._held + self._written_since_trim * self.writers > self.disk_bytes // 2:
            self.trim()

    def _replace(self, path: Path, write: Callable[[BinaryIO], object]) -> None:
        """:func:`~.cache_files.write_entry`. A store only saves later work, so it never fails the caller: a folder
        removed or made under it (a concurrent ``--n2r-cache-clear``) is made again once, then the store is skipped;
        any other :class:`OSError` (a full disk, no permission), or 8 stores in a row skipped so, is warned of once
        (:class:`CacheNotStored`) and this cache stores nothing more."""
        if self._store_error is not None:
            return
        for again in (True, False):
            try:
                self._prepare_directory(path.parent)
                write_entry(path, write)
            except (FileNotFoundError, FileExistsError, NotADirectoryError) as exc:  # a folder gone or made meanwhile
                if again:
                    continue
                self._skipped += 1
                if self._skipped >= 8:
                    self._stop_storing(exc)
                return
            except OSError as exc:
                self._stop_storing(exc)
                return
            self._skipped = 0
            return

    def _stop_storing(self, exc: OSError) -> None:
        self._store_error = exc
        note = CacheNotStored(f"the render cache {str(self.directory)!r} stores nothing more this session: "
                              f"{type(exc).__name__}: {exc}")
        try:
            warnings.warn(note, stacklevel=2)
        except CacheNotStored:  # -W error made the warning an exception: storing never fails a test, so said here
            print(f"pytest-n2r: {note}", file=sys.stderr)

    def _prepare_directory(self, leaf: Path) -> None:
        """Make ``leaf``; tag the directory first where it is new or holds only pytest-n2r's files (a folder of the
        user's is not tagged, so nothing in it is ever deleted), and ignore it in Git unless a .gitignore is there."""
        assert self.directory is not None
        if not self._claimed:  # once a session: the tag's check reads a file, and a store is on the render path
            claim(self.directory)
            self._claimed = is_ours(self.directory)
        leaf.mkdir(parents=True, exist_ok=True)

    def trim(self) -> int:
        """Delete the temporary files a killed writer left (older than :data:`~.cache_files.STALE_TMP_SECONDS`) and,
        while renders, decisions and floors together exceed the cap, the least recently used of them down to 80 %
        of it; returns the bytes freed. Safe to run from several workers at once and beside a clear (a directory
        scan: some 15 ms per 1 000 entries). Nothing in a directory without pytest-n2r's ``CACHEDIR.TAG``."""
        self._written_since_trim = 0
        if self.directory is None or not is_ours(self.directory):
            return 0
        freed, self._held = trim_entries(self.directory, self.disk_bytes)
        return freed
