"""Adaptive pixel sampling: trace a coarse grid of pixels, interpolate where the image is smooth, trace the rest.

A fitted field has no more detail than its grid, so at most image sizes neighbouring pixels mostly agree.
:func:`sample_adaptively` traces the pixels of a coarse grid (every ``stride``-th pixel in x and y, plus the
last column and row, so every pixel lies in a cell whose four corners are traced). A cell whose corners agree
(colour and opacity within ``tolerance``, z-depth within ``depth_tolerance`` relatively) is filled by bilinear
interpolation of its corners; any other cell is split in four: the grid of half the spacing is traced inside it
and its sub-cells are judged the same way, down to single pixels. At that last split (cells of 2×2 pixels) the
pixels left are leaves, never judged again: one in the middle of a cell's edge is interpolated between the
edge's two traced ends when those two agree (the same test on two pixels); then the cell's centre, between its
two traced neighbours on its row, or else on its column, when they agree; every other leaf is traced. Edges,
occlusion boundaries and texture are therefore traced pixel by pixel across them (along an edge, its sides'
pixels are interpolated); flat colour, sky and slowly shaded surfaces are interpolated. A pixel
interpolated to opacity 0 is traced too (its ray sees nothing, which is cheap, and its depth is its own ray's
far end).

Convention: pixel ``(x, y)`` (column, row) has flat index ``y·width + x`` and is traced at its centre, exactly
as a full render traces it, so every traced pixel holds the full render's value to the bit. The result
depends only on the traced values (not on the thread count or on the order of the work): deterministic.
A feature narrower than the spacing of the coarsest grid that lies between its traced pixels can be missed,
and at the last split a feature of one pixel between two agreeing pixels; the stride is therefore chosen by
image size (docs/performance-log.md measures the error).
"""

from __future__ import annotations

from collections.abc import Callable

import numpy as np
from numba import njit

from .borrow import borrowed
from .threads import run_parts

__all__ = ["sample_adaptively", "grid_axis"]

#: ``trace(want, rgb, depth, opacity)`` traces the pixels where ``want`` (``(H·W,)`` bool, row-major) is set into
#: ``rgb (H·W, 3)``, ``depth (H·W,)`` and ``opacity (H·W,)`` (float32), leaving the others as they are.
Tracer = Callable[[np.ndarray, np.ndarray, np.ndarray, np.ndarray], None]


def grid_axis(n: int, stride: int) -> np.ndarray:
    """The traced coordinates of one image axis of ``n`` pixels at ``stride``: multiples of it and ``n - 1``.

    >>> grid_axis(10, 4).tolist()
    [0, 4, 8, 9]
    """
    axis = np.arange(0, n, stride, dtype=np.int64)
    return axis if axis[-1] == n - 1 else np.append(axis, n - 1)


@njit(cache=True, inline="always")
def _agree(i00, i01, i10, i11, rgb, depth, opacity, tolerance, depth_tolerance):
    """Whether pixels ``i00, i01, i10, i11`` agree: colour and opacity spread within ``tolerance``, z-depth within
    ``depth_tolerance`` of the smallest (a cell's four corners; two pixels: :func:`_agree_two`)."""
    for c in range(3):
        v00, v01, v10, v11 = rgb[i00, c], rgb[i01, c], rgb[i10, c], rgb[i11, c]
        if max(v00, v01, v10, v11) - min(v00, v01, v10, v11) > tolerance:
            return False
    v00, v01, v10, v11 = opacity[i00], opacity[i01], opacity[i10], opacity[i11]
    if max(v00, v01, v10, v11) - min(v00, v01, v10, v11) > tolerance:
        return False
    v00, v01, v10, v11 = depth[i00], depth[i01], depth[i10], depth[i11]
    return max(v00, v01, v10, v11) - min(v00, v01, v10, v11) <= depth_tolerance * min(v00, v01, v10, v11)


@njit(cache=True, nogil=True)
def _judge_cells(first, last, ys, xs, active, width, rgb, depth, opacity, traced, tolerance, depth_tolerance, split):
    """For each active cell of the rows of cells ``first <= a < last``: ``split`` it where its corners disagree,
    else interpolate its untraced pixels.

    Rows of cells in parallel (:func:`~.threads.run_parts`): a cell reads only its traced corners, and
    a pixel on the edge two agreeing cells share gets the same value from both (its weights on the far corners are
    exactly 0)."""
    # the helpers receive views without reference counts (render/borrow.py)
    rgb, depth, opacity, traced = borrowed(rgb), borrowed(depth), borrowed(opacity), borrowed(traced)
    for a in range(first, last):
        y0, y1 = ys[a], ys[a + 1]
        for b in range(xs.shape[0] - 1):
            split[a, b] = False
            if not active[a, b]:
                continue
            x0, x1 = xs[b], xs[b + 1]
            i00, i01, i10, i11 = y0 * width + x0, y0 * width + x1, y1 * width + x0, y1 * width + x1
            if not _agree(i00, i01, i10, i11, rgb, depth, opacity, tolerance, depth_tolerance):
                split[a, b] = True
                continue
            for y in range(y0, y1 + 1):
                fy = (y - y0) / (y1 - y0)
                for x in range(x0, x1 + 1):
                    i = y * width + x
                    if traced[i]:
                        continue
                    fx = (x - x0) / (x1 - x0)
                    w00, w01, w10, w11 = (1 - fy) * (1 - fx), (1 - fy) * fx, fy * (1 - fx), fy * fx
                    for c in range(3):
                        rgb[i, c] = w00 * rgb[i00, c] + w01 * rgb[i01, c] + w10 * rgb[i10, c] + w11 * rgb[i11, c]
                    depth[i] = w00 * depth[i00] + w01 * depth[i01] + w10 * depth[i10] + w11 * depth[i11]
                    opacity[i] = w00 * opacity[i00] + w01 * opacity[i01] + w10 * opacity[i10] + w11 * opacity[i11]


@njit(cache=True, inline="always")
def _agree_two(p, q, rgb, depth, opacity, tolerance, depth_tolerance):
    """:func:`_agree` of two pixels (their spread is the difference), without a branch: a leaf's two pixels agree or
    not about as often as not, and branching on each test cost more than making them all (1.4x the time a leaf)."""
    a, b = depth[p], depth[q]
    return ((abs(rgb[p, 0] - rgb[q, 0]) <= tolerance) & (abs(rgb[p, 1] - rgb[q, 1]) <= tolerance)
            & (abs(rgb[p, 2] - rgb[q, 2]) <= tolerance) & (abs(opacity[p] - opacity[q]) <= tolerance)
            & (abs(a - b) <= depth_tolerance * min(a, b)))


@njit(cache=True, inline="always")
def _between(i, p, q, f, traced, rgb, depth, opacity, tolerance, depth_tolerance):
    """Whether traced pixels ``p`` and ``q`` agree; if so, pixel ``i`` is set to their mix at ``f`` (0 at ``p``)."""
    if not (traced[p] and traced[q] and _agree_two(p, q, rgb, depth, opacity, tolerance, depth_tolerance)):
        return False
    for c in range(3):
        rgb[i, c] = (1 - f) * rgb[p, c] + f * rgb[q, c]
    depth[i] = (1 - f) * depth[p] + f * depth[q]
    opacity[i] = (1 - f) * opacity[p] + f * opacity[q]
    return True


@njit(cache=True)
def _grid_to_trace(ys, xs, split, stride, traced):
    """The mask of the untraced pixels of the grid of spacing ``stride`` inside split cells (their corners
    included)."""
    width = xs[-1] + 1
    want = np.zeros((ys[-1] + 1) * width, dtype=np.bool_)
    for a in range(ys.shape[0] - 1):
        y0, y1 = ys[a], ys[a + 1]
        for b in range(xs.shape[0] - 1):
            if not split[a, b]:
                continue
            x0, x1 = xs[b], xs[b + 1]
            # the grid's lines in the cell: y0 (a multiple of 2·stride), y0 + stride, ... and y1 (the next
            # multiple, or the image's last row), the same across
            y = y0
            while True:
                x = x0
                while True:
                    i = y * width + x
                    want[i] = not traced[i]
                    if x == x1:
                        break
                    x = min(x + stride, x1)
                if y == y1:
                    break
                y = min(y + stride, y1)
    return want


@njit(cache=True, nogil=True)
def _leaves_to_trace(first, last, ys, xs, split, traced, rgb, depth, opacity, tolerance, depth_tolerance,
                     inside, want):
    """Set ``want`` (``(H·W,)`` bool, all False before) on the image rows ``first <= y < last`` at the leaves to trace
    in the split cells of the last split (``ys, xs`` the grid of spacing 2: cells of 2×2 pixels, or 2×1 at the
    image's last row or column, corners traced): those on the cells' edges (``inside`` False: the pixels between
    two corners), or those inside them (the cells' centres).

    A leaf whose two pixels across its cell on its row, or else on its column, are traced and agree is
    interpolated half way between them instead. Each leaf is judged once, as every split cell it belongs to would
    judge it, and reads only pixels of the round before: rows in parallel, the same result."""
    height, width = ys[-1] + 1, xs[-1] + 1
    rows, cols = split.shape
    rgb, depth, opacity = borrowed(rgb), borrowed(depth), borrowed(opacity)  # for the helpers: render/borrow.py
    traced, want = borrowed(traced), borrowed(want)
    for y in range(first, last):
        row = y * width
        on_grid = y % 2 == 0 or y == height - 1  # a row of corners: its leaves lie between two corners on it
        if on_grid and inside:
            continue
        g_row = y // 2 if y % 2 == 0 else rows  # a row of corners: its index in ys
        a = y // 2  # a middle row: the cell row it crosses (ys[a] = y - 1, ys[a + 1] = y + 1)
        for g in range(cols + 1):
            x = xs[g]
            # one call site for the three kinds of leaf: numba inlines _judge_leaf's code once (compile time)
            if on_grid:  # the pixel after corner x, in split cells
                if not (g < cols and x + 1 < xs[g + 1]
                        and ((g_row > 0 and split[g_row - 1, g]) or (g_row < rows and split[g_row, g]))):
                    continue
                i = row + x + 1
                left, right, up, down = i - 1, i + 1, -1, -1
            elif inside:  # a cell's centre
                if not (g < cols and x + 1 < xs[g + 1] and split[a, g]):
                    continue
                i = row + x + 1
                left, right, up, down = i - 1, i + 1, i - width, i + width
            else:  # the pixel between two corners on column x
                if not ((g > 0 and split[a, g - 1]) or (g < cols and split[a, g])):
                    continue
                i = row + x
                left, right, up, down = -1, -1, i - width, i + width
            _judge_leaf(i, left, right, up, down, traced, rgb, depth, opacity, tolerance, depth_tolerance, want)


@njit(cache=True, inline="always")
def _judge_leaf(i, left, right, up, down, traced, rgb, depth, opacity, tolerance, depth_tolerance, want):
    """Leaf ``i``: interpolated half way between ``left`` and ``right``, or else ``up`` and ``down``, where the two
    are traced and agree (``-1``: no such pair); else ``want[i]`` is set."""
    if traced[i]:
        return
    if left >= 0 and _between(i, left, right, 0.5, traced, rgb, depth, opacity, tolerance, depth_tolerance):
        return
    if up >= 0 and _between(i, up, down, 0.5, traced, rgb, depth, opacity, tolerance, depth_tolerance):
        return
    want[i] = True


def sample_adaptively(trace: Tracer, height: int, width: int, stride: int, tolerance: float,
                      depth_tolerance: float) -> tuple[np.ndarray, np.ndarray, np.ndarray, int]:
    """``(rgb (H·W, 3), depth (H·W,), opacity (H·W,), traced)``: an image traced at the pixels where it is not
    smooth and interpolated elsewhere (float32; ``traced`` counts the pixels traced). ``stride`` (a power of
    two) is the spacing of the coarsest grid, ``tolerance`` the largest spread of colour or opacity ([0, 1])
    over a cell's corners that is interpolated, ``depth_tolerance`` that of z-depth relative to its smallest."""
    if stride < 1 or stride & (stride - 1):
        raise ValueError(f"stride={stride}: expected a power of two")
    if min(height, width) < 2:
        stride = 1  # a single row or column has no cells: trace it all
    n = height * width
    rgb = np.zeros((n, 3), dtype=np.float32)
    depth = np.zeros(n, dtype=np.float32)
    opacity = np.zeros(n, dtype=np.float32)
    traced = np.zeros(n, dtype=np.bool_)

    def trace_into(want: np.ndarray) -> None:
        if want.any():
            trace(want, rgb, depth, opacity)
            np.logical_or(traced, want, out=traced)

    ys, xs = grid_axis(height, stride), grid_axis(width, stride)
    coarse = np.zeros((height, width), dtype=np.bool_)
    coarse[ys[:, None], xs[None, :]] = True
    trace_into(coarse.reshape(-1))
    active = np.ones((ys.size - 1, xs.size - 1), dtype=np.bool_)
    while stride > 1 and active.size:
        split = np.empty_like(active)
        run_parts(_judge_cells, ys.size - 1, ys, xs, active, width, rgb, depth, opacity, traced, tolerance,
                  depth_tolerance, split)
        if not split.any():
            break
        finer = stride // 2
        for inside in (False, True) if finer == 1 else (False,):  # leaves inside a cell: after those on its edges
            if finer > 1:
                want = _grid_to_trace(ys, xs, split, finer, traced)
            else:
                want = np.zeros(n, dtype=np.bool_)
                run_parts(_leaves_to_trace, height, ys, xs, split, traced, rgb, depth, opacity, tolerance,
                          depth_tolerance, inside, want)
            trace_into(want)
        if finer == 1:
            break  # every pixel is traced or interpolated
        fine_ys, fine_xs = grid_axis(height, finer), grid_axis(width, finer)
        active = split[(fine_ys[:-1] // stride)[:, None], (fine_xs[:-1] // stride)[None, :]]
        ys, xs, stride = fine_ys, fine_xs, finer
    trace_into((opacity == 0.0) & ~traced)  # a ray that sees nothing ends at its own far end
    return rgb, depth, opacity, int(np.count_nonzero(traced))
