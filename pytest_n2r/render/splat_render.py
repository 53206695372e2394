"""Rendering 3-D Gaussian splats at a camera and pose on the CPU: RGB, z-depth and opacity.

EWA splatting as the 3D Gaussian Splatting reference rasterizer does it (projection with the 0.3-pixel
low-pass dilation, a depth sort, front-to-back compositing with early termination, SH colour per view
direction), compiled with numba (:mod:`pytest_n2r.render.splat_kernels`). Differences from the reference,
all in how work is organised, none in what a pixel means:

- a Gaussian reaches every pixel where its opacity is at least ``1/255`` (the reference stops at the tiles
  its 3-sigma square touches, so the exact cut depends on tile alignment);
- Gaussians are composited in runs of at most ``max_pairs`` (tile, Gaussian) pairs, front to back, so memory
  stays bounded at any image size and Gaussian count; the result does not depend on the runs.
"""

from __future__ import annotations

import math
import threading
import time
from dataclasses import asdict, dataclass, replace

import numpy as np
from numba import parallel_chunksize

from .._validation import as_unit_rgb, check_array
from ..errors import InvalidArgument
from ..geometry import Camera, invert_pose
from ..splats.gaussians import Gaussians
from . import splat_composite as c
from . import splat_kernels as k
from .threads import run_dealt

__all__ = ["SPLAT_RENDER_VERSION", "SplatRenderer", "SplatSettings"]

#: Part of every splat scene's content hash: bump it whenever the output for the same Gaussians and settings
#: changes, so render caches built by an older pytest-n2r are not reused.
SPLAT_RENDER_VERSION = 3
#: Iterations (Gaussians, pixels) a thread takes at a time in the parallel loops over Gaussians or pixels.
_CHUNK = 2048


@dataclass(frozen=True)
class SplatSettings:
    """The render knobs of splat scenes.

    - ``near``: Gaussians whose mean is at most this far in front of the camera (z-depth, scene units) are
      not drawn (3DGS reference: 0.2; gsplat: 0.01);
    - ``t_stop``: a pixel stops once its transmittance would fall below this (3DGS reference: 1e-4);
    - ``background``: RGB in [0, 1] shown through the transmittance left (``None``: the scene's own);
    - ``tile``: tile side in pixels (work organisation only: the output does not depend on it). 64 by
      default: a Gaussian then falls into fewer tiles, so binning and the per-(tile, Gaussian) work shrink
      (1 thread, 300 000 Gaussians at 480×270: binning 13 → 4 ms, a frame 15-24 % less CPU than with 16;
      docs/performance-log.md), and 40 tiles at 480×270 still share out evenly over a few threads;
    - ``max_pairs``: (tile, Gaussian) pairs composited per run (bounds memory: each tile's copy of its
      Gaussians' records takes 104 B a pair; the output does not depend on it).
    """

    near: float = 0.01
    t_stop: float = 1e-4
    background: tuple[float, float, float] | None = None
    tile: int = 64
    max_pairs: int = 1 << 22

    def __post_init__(self) -> None:
        checks = {
            "near": isinstance(self.near, (int, float)) and math.isfinite(self.near) and self.near > 0,
            "t_stop": isinstance(self.t_stop, (int, float)) and 0.0 <= self.t_stop < 1.0,
            "tile": isinstance(self.tile, int) and not isinstance(self.tile, bool) and 1 <= self.tile <= 256,
            "max_pairs": isinstance(self.max_pairs, int) and not isinstance(self.max_pairs, bool)
            and self.max_pairs >= 1,
        }
        expected = {"near": "a finite number > 0 (scene units)", "t_stop": "a number in [0, 1)",
                    "tile": "an int in 1..256 (pixels)", "max_pairs": "an int >= 1"}
        for name, ok in checks.items():
            if not ok:
                raise InvalidArgument(f"SplatSettings.{name}={getattr(self, name)!r}; expected {expected[name]}")
        if self.background is not None:
            bg = as_unit_rgb(self.background)
            if bg is None:
                raise InvalidArgument(f"SplatSettings.background={self.background!r}; expected None or three values "
                                      "in [0, 1]")
            object.__setattr__(self, "background", bg)

    def to_dict(self) -> dict:
        return asdict(self)

    def replace(self, **changes) -> SplatSettings:
        return replace(self, **changes)


class SplatRenderer:
    """Renders one set of Gaussians with fixed settings over ``background`` (RGB in [0, 1]; the settings'
    background wins). The world-frame covariance factors and opacities are computed once, here."""

    def __init__(self, gaussians: Gaussians, settings: SplatSettings | None = None,
                 background: tuple[float, float, float] = (0.0, 0.0, 0.0)) -> None:
        self.gaussians = gaussians
        self.settings = settings or SplatSettings()
        bg = self.settings.background if self.settings.background is not None else as_unit_rgb(background)
        if bg is None:
            raise InvalidArgument(f"background={background!r}; expected three values in [0, 1]")
        #: The background actually rendered over.
        self.background = bg
        self._means = np.ascontiguousarray(gaussians.means, dtype=np.float64)
        self._factors = gaussians.factors()
        self._opacity = gaussians.opacities
        self._reach = np.empty(len(self._opacity))
        k.reach(self._opacity, self._reach)
        self._sh = gaussians.sh
        self._degree = gaussians.sh_degree
        #: Seconds the last render spent in each stage (``project``, ``sort``, ``bin``, ``composite``,
        #: ``finish``), for benchmarks.
        self.stage_seconds: dict[str, float] = {}
        # per thread, the per-Gaussian buffers of the last render, reused: allocating them anew maps fresh
        # pages every frame (tens of MB at 300 000 Gaussians), which costs more than a stage's work
        self._scratch = threading.local()

    def render(self, c2w: np.ndarray, camera: Camera, outputs: tuple[str, ...] = ("rgb", "depth", "opacity")
               ) -> dict[str, np.ndarray]:
        """``outputs`` (from ``rgb``, ``depth``, ``opacity``) of ``camera`` at ``c2w`` (OpenCV axes, scene units):
        ``rgb`` H×W×3 uint8, ``depth`` H×W float32 z-depth (the weighted mean of the Gaussians' z-depths, 0
        where nothing is drawn), ``opacity`` H×W float32 in [0, 1]."""
        c2w = check_array("c2w", c2w, "4 4", dtype=np.float64)
        s = self.settings
        w, h = camera.width, camera.height
        n = len(self._means)
        w2c = np.ascontiguousarray(invert_pose(c2w))
        clock = _Stages()
        records, rects, keys, tiles, ordered = self._buffers(n)
        # every parallel loop hands out its work in pieces (dynamic scheduling): with a fixed half per thread
        # (OpenMP's static default) a region waits for its slower thread, and on a shared machine one of the
        # two threads is often held up by another process
        with parallel_chunksize(_CHUNK):
            k.project(self._means, self._factors, self._opacity, self._reach, self._sh, self._degree, w2c,
                      np.ascontiguousarray(c2w[:3, 3]), camera.fx, camera.fy, camera.cx, camera.cy, w, h, s.near,
                      s.tile, records, rects, keys, tiles)
        clock.lap("project")
        order = k.depth_order(tiles, keys)
        ordered = ordered[:len(order)]
        sorted_rects = np.empty((len(order), len(k.RECT)), np.int32)
        sorted_tiles = np.empty(len(order), np.int64)
        with parallel_chunksize(_CHUNK):
            k.gather(order, records, rects, tiles, ordered, sorted_rects, sorted_tiles)
        clock.lap("sort")
        tiles_x = -(-w // s.tile)
        live = _tile_pixels(w, h, s.tile)
        trans = np.ones(w * h)
        acc_rgb = np.zeros((w * h, 3))
        acc_depth = np.zeros(w * h)
        tile_start = np.empty(len(live) + 1, np.int64)
        counts = np.cumsum(sorted_tiles)
        background = np.asarray(self.background)
        out_rgb = np.empty((h * w, 3), np.uint8)
        out_depth = np.empty(h * w, np.float32)
        out_opacity = np.empty(h * w, np.float32)
        start, finished = 0, False
        while start < len(order) and live.any():  # runs of at most max_pairs (tile, Gaussian) pairs
            base = counts[start - 1] if start else 0
            stop = max(int(np.searchsorted(counts, base + s.max_pairs, side="right")), start + 1)
            pair_records, pair_rects = self._pair_buffers(int(counts[stop - 1] - base))
            with parallel_chunksize(1):  # a chunk of the depth order at a time
                k.bin_tiles(start, stop, ordered, sorted_rects, tiles_x, live, tile_start, pair_records, pair_rects)
            # the busiest tiles first (a stable order of the list lengths: the same order on every run)
            tile_order = np.argsort(-np.diff(tile_start), kind="stable")
            clock.lap("bin")
            finished = stop == len(order)
            # tiles differ in work: dealt over the render threads in that order, so that they share out evenly
            run_dealt(c.composite_tiles, len(tile_order), tile_start, pair_records, pair_rects, w, s.tile, tiles_x,
                      tile_order, s.t_stop, live, trans, acc_rgb, acc_depth, finished, background, out_rgb, out_depth,
                      out_opacity)
            clock.lap("composite")
            start = stop
        if not finished:  # nothing drawn, or every pixel done before the last run
            with parallel_chunksize(_CHUNK):
                c.finish(trans, acc_rgb, acc_depth, background, out_rgb, out_depth, out_opacity)
        clock.lap("finish")
        self.stage_seconds = clock.seconds
        result: dict[str, np.ndarray] = {"rgb": out_rgb.reshape(h, w, 3), "depth": out_depth.reshape(h, w),
                                         "opacity": out_opacity.reshape(h, w)}
        return {name: result[name] for name in outputs}


    def _buffers(self, n: int) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
        """This thread's per-Gaussian buffers ``records`` (n × ``len(RECORD)`` float64), ``rects`` (n ×
        ``len(RECT)`` int32), ``keys`` (n float32), ``tiles`` (n int64) and ``ordered`` (the records in depth
        order): each render overwrites what it reads of them."""
        buffers = getattr(self._scratch, "buffers", None)
        if buffers is None or len(buffers[3]) != n:
            buffers = (np.empty((n, len(k.RECORD))), np.empty((n, len(k.RECT)), np.int32), np.empty(n, np.float32),
                       np.empty(n, np.int64), np.empty((n, len(k.RECORD))))
            self._scratch.buffers = buffers
        return buffers

    def _pair_buffers(self, pairs: int) -> tuple[np.ndarray, np.ndarray]:
        """This thread's (tile, Gaussian) pair buffers, records (``pairs`` × ``len(RECORD)`` float64) and pixel
        rectangles (``pairs`` × 4 int32), grown when a run needs more rows (views of the first ``pairs``)."""
        buffers = getattr(self._scratch, "pairs", None)
        if buffers is None or len(buffers[0]) < pairs:
            buffers = (np.empty((pairs, len(k.RECORD))), np.empty((pairs, 4), np.int32))
            self._scratch.pairs = buffers
        return buffers[0][:pairs], buffers[1][:pairs]


class _Stages:
    """Wall-clock seconds per named stage, summed over laps."""

    def __init__(self) -> None:
        self.seconds: dict[str, float] = {}
        self._last = time.perf_counter()

    def lap(self, name: str) -> None:
        now = time.perf_counter()
        self.seconds[name] = self.seconds.get(name, 0.0) + now - self._last
        self._last = now


def _tile_pixels(width: int, height: int, tile: int) -> np.ndarray:
    """Pixels per tile (row-major tiles of ``tile`` × ``tile``; the last column and row may be narrower)."""
    xs = np.minimum(tile, width - np.arange(0, width, tile))
    ys = np.minimum(tile, height - np.arange(0, height, tile))
    return np.ascontiguousarray((ys[:, None] * xs[None, :]).ravel(), dtype=np.int64)
