"""Compiled CPU kernels (numba) of the splat rasterizer: projection, depth sort, tile binning.

The stages (driven by :class:`pytest_n2r.render.splat_render.SplatRenderer`):

1. :func:`project` (parallel over Gaussians): EWA projection of each 3-D covariance to a 2-D one with the
   3DGS low-pass dilation (from the covariance's factor, so that a needle's stays exact), its conic
   (inverse), the pixel rectangle where it can reach ``ALPHA_MIN``, its tile count and its SH colour for this
   view, as one record per Gaussian (:data:`RECORD`); the pixel and tile rectangles (int32) and the depth key
   (float32) go to small arrays of their own, which the next two stages read.
2. :func:`depth_order`: the visible Gaussians sorted by camera z-depth rounded to float32 (a stable LSD
   radix sort; equal keys keep index order), and :func:`gather` (parallel): their records, rectangles and
   tile counts in that order, so that binning reads memory in order and compositing reads each tile's
   records from ascending addresses.
3. :func:`bin_tiles` (parallel over fixed chunks of the depth order: a count pass, a prefix sum, a fill
   pass): a depth-ordered run of Gaussians into per-tile lists, each a sequential copy of its Gaussians'
   records and pixel rectangles in depth order.
4. compositing, in :mod:`pytest_n2r.render.splat_composite`.

Each pixel's result depends only on the depth-ordered Gaussians that reach it, never on the tile size, the
run boundaries, the binning chunks, the order tiles are composited in or the thread count, so renders are
deterministic to the bit.
"""

from __future__ import annotations

import math

import numpy as np
from numba import njit, prange

from ..splats.sh import colour_of

__all__ = [
    "ALPHA_MAX",
    "ALPHA_MIN",
    "DILATION",
    "RECORD",
    "RECT",
    "bin_tiles",
    "depth_order",
    "gather",
    "project",
    "reach",
]

#: Opacity of one Gaussian at one pixel is capped here (3DGS reference), so transmittance never hits 0.
ALPHA_MAX = 0.99
#: Contributions below this opacity are skipped (3DGS reference: 1/255).
ALPHA_MIN = 1.0 / 255.0
#: Added to the 2-D covariance's diagonal (pixels²): the reference's low-pass filter, so every Gaussian
#: covers at least about a pixel.
DILATION = 0.3
#: How far beyond the image edges (as a fraction of the image width or height, on each side) the
#: projection's Jacobian is evaluated at most (3DGS reference: 1.3 × the half field of view).
_GUARD = 0.15
#: Fields of a projected Gaussian's record (float64): pixel position, conic, peak opacity, colour, z-depth
#: and the squared Mahalanobis radius inside which it can reach ``ALPHA_MIN`` (widened by a margin, see
#: :func:`~pytest_n2r.render.splat_composite.composite_tiles`).
RECORD = ("u", "v", "conic_a", "conic_b", "conic_c", "opacity", "r", "g", "b", "z", "r2")
#: Fields of a projected Gaussian's rectangle (int32): the pixels ``x0 <= x < x1, y0 <= y < y1`` where it can
#: reach ``ALPHA_MIN``, and the tiles ``tx0 <= tx < tx1, ty0 <= ty < ty1`` they touch (divided once, here:
#: an integer division by a run-time tile size is slow, and binning would repeat it in each of its passes).
RECT = ("x0", "x1", "y0", "y1", "tx0", "tx1", "ty0", "ty1")
#: Depth-ordered Gaussians per chunk of :func:`bin_tiles` (at least; at most :data:`_BIN_CHUNKS` chunks):
#: a function of the count alone, never of the thread count.
_BIN_CHUNK = 4096
_BIN_CHUNKS = 64
_U, _V, _CA, _CB, _CC, _O, _R, _G, _B, _Z, _R2 = range(len(RECORD))
@njit(cache=True)
def reach(opacity, out):
    """``out[i]``: the squared Mahalanobis radius inside which Gaussian ``i`` of peak ``opacity[i]`` reaches
    ``ALPHA_MIN``, widened by a relative 1e-6 (0 for an opacity below ``ALPHA_MIN``): a property of the
    Gaussian alone, computed once per scene."""
    for i in range(opacity.shape[0]):
        o = opacity[i]
        out[i] = 2.0 * math.log(o / ALPHA_MIN) + 1e-6 if o >= ALPHA_MIN else 0.0


@njit(cache=True, parallel=True)
def project(means, factors, opacity, r2s, sh, degree, w2c, campos, fx, fy, cx, cy, width, height, near, tile,
            records, rects, keys, tiles):
    """Project every Gaussian for the camera ``w2c`` (world → camera 4×4, OpenCV axes) into ``records``
    (:data:`RECORD`), ``rects`` (its pixel and tile rectangles, :data:`RECT`), ``keys`` (its z-depth as float32)
    and ``tiles`` (tiles its rectangle touches; 0: culled). ``factors`` are the Gaussians' ``R S`` (rotation
    times scales, N × 3 × 3: the 3-D covariance is ``F Fᵀ``); ``r2s`` is :func:`reach` of ``opacity``.

    The 2-D covariance is ``A Aᵀ`` plus the dilation, ``A = J W F`` (2 × 3), and its determinant is summed from
    the squares of ``A``'s 2 × 2 minors (Cauchy–Binet) plus the dilation's terms: never a difference of two
    large products. ``a c - b²`` lost every digit for a needle or a disc seen edge-on with a scale of e⁹ or
    more (measured: the conic off by 0.2 % against an exact computation, opacity by 1e-3, at log-scales like
    (−85, 9.4, −56)); so did a covariance ``F Fᵀ`` formed in float64 first, whose rounding in the long axes'
    entries is larger than the short axes.

    Culled: peak opacity below ``ALPHA_MIN``, mean at or in front of the ``near`` plane, a non-finite or
    singular 2-D covariance, or a rectangle outside the image.
    """
    lim_x0 = (-0.5 - cx) / fx - _GUARD * width / fx
    lim_x1 = (width - 0.5 - cx) / fx + _GUARD * width / fx
    lim_y0 = (-0.5 - cy) / fy - _GUARD * height / fy
    lim_y1 = (height - 0.5 - cy) / fy + _GUARD * height / fy
    for i in prange(means.shape[0]):
        tiles[i] = 0
        o = opacity[i]
        if not o >= ALPHA_MIN:
            continue
        mx, my, mz = means[i, 0], means[i, 1], means[i, 2]
        x = w2c[0, 0] * mx + w2c[0, 1] * my + w2c[0, 2] * mz + w2c[0, 3]
        y = w2c[1, 0] * mx + w2c[1, 1] * my + w2c[1, 2] * mz + w2c[1, 3]
        z = w2c[2, 0] * mx + w2c[2, 1] * my + w2c[2, 2] * mz + w2c[2, 3]
        if not z > near:
            continue
        u = fx * x / z + cx
        v = fy * y / z + cy
        # Jacobian of the projection at the mean (clamped to a guard band, as the reference does)
        tx = min(max(x / z, lim_x0), lim_x1)
        ty = min(max(y / z, lim_y0), lim_y1)
        j00, j02 = fx / z, -fx * tx / z
        j11, j12 = fy / z, -fy * ty / z
        # M = J · W (2×3), W the world → camera rotation; then the 2-D covariance M Σ Mᵀ
        m00 = j00 * w2c[0, 0] + j02 * w2c[2, 0]
        m01 = j00 * w2c[0, 1] + j02 * w2c[2, 1]
        m02 = j00 * w2c[0, 2] + j02 * w2c[2, 2]
        m10 = j11 * w2c[1, 0] + j12 * w2c[2, 0]
        m11 = j11 * w2c[1, 1] + j12 * w2c[2, 1]
        m12 = j11 * w2c[1, 2] + j12 * w2c[2, 2]
        f = factors[i]
        a0 = m00 * f[0, 0] + m01 * f[1, 0] + m02 * f[2, 0]
        a1 = m00 * f[0, 1] + m01 * f[1, 1] + m02 * f[2, 1]
        a2 = m00 * f[0, 2] + m01 * f[1, 2] + m02 * f[2, 2]
        b0 = m10 * f[0, 0] + m11 * f[1, 0] + m12 * f[2, 0]
        b1 = m10 * f[0, 1] + m11 * f[1, 1] + m12 * f[2, 1]
        b2 = m10 * f[0, 2] + m11 * f[1, 2] + m12 * f[2, 2]
        aa = a0 * a0 + a1 * a1 + a2 * a2
        cc = b0 * b0 + b1 * b1 + b2 * b2
        d01, d02, d12 = a0 * b1 - a1 * b0, a0 * b2 - a2 * b0, a1 * b2 - a2 * b1
        a = aa + DILATION
        b = a0 * b0 + a1 * b1 + a2 * b2
        c = cc + DILATION
        det = (d01 * d01 + d02 * d02 + d12 * d12) + DILATION * (aa + cc) + DILATION * DILATION
        if not (det > 0.0 and math.isfinite(det) and math.isfinite(u) and math.isfinite(v)):
            continue
        # opacity reaches ALPHA_MIN where the Mahalanobis distance² is at most r2; its bounding box, widened
        # a little so that rounding never drops a pixel the per-pixel test would keep
        r2 = r2s[i]
        ex = math.sqrt(r2 * a) * (1.0 + 1e-6) + 1e-4
        ey = math.sqrt(r2 * c) * (1.0 + 1e-6) + 1e-4
        x0 = max(math.ceil(u - ex), 0.0)
        x1 = min(math.floor(u + ex) + 1.0, float(width))
        y0 = max(math.ceil(v - ey), 0.0)
        y1 = min(math.floor(v + ey) + 1.0, float(height))
        if not (x0 < x1 and y0 < y1):
            continue
        rect = rects[i]
        rect[0], rect[1], rect[2], rect[3] = int(x0), int(x1), int(y0), int(y1)
        rect[4], rect[5] = rect[0] // tile, (rect[1] - 1) // tile + 1
        rect[6], rect[7] = rect[2] // tile, (rect[3] - 1) // tile + 1
        tiles[i] = (rect[5] - rect[4]) * (rect[7] - rect[6])
        rec = records[i]
        rec[_U], rec[_V], rec[_CA], rec[_CB], rec[_CC], rec[_O], rec[_Z] = u, v, c / det, -b / det, a / det, o, z
        keys[i] = np.float32(z)
        rec[_R2] = r2 * (1.0 + 1e-6)
        dx, dy, dz = mx - campos[0], my - campos[1], mz - campos[2]
        n = math.sqrt(dx * dx + dy * dy + dz * dz)
        if n > 0.0:
            dx, dy, dz = dx / n, dy / n, dz / n
        for ch in range(3):
            rec[_R + ch] = colour_of(sh, i, degree, dx, dy, dz, ch)


@njit(cache=True)
def depth_order(tiles, keys):
    """Indices of the Gaussians with ``tiles > 0`` sorted front to back by ``keys`` (z-depths as float32,
    > 0, so their bit patterns order them); equal keys keep index order (stable LSD radix sort, 16 bits a
    pass)."""
    all_bits = keys.view(np.uint32)
    n = 0
    for i in range(tiles.shape[0]):
        if tiles[i] > 0:
            n += 1
    ids = np.empty(n, np.int64)
    bits = np.empty(n, np.uint32)
    k = 0
    for i in range(tiles.shape[0]):
        if tiles[i] > 0:
            ids[k] = i
            bits[k] = all_bits[i]
            k += 1
    ids2 = np.empty(n, np.int64)
    bits2 = np.empty(n, np.uint32)
    count = np.empty(65537, np.int64)
    for shift in (0, 16):
        count[:] = 0
        for j in range(n):
            count[((bits[j] >> shift) & 0xFFFF) + 1] += 1
        if n == 0 or count.max() == n:
            continue  # every key has the same digit here: this pass changes nothing
        for d in range(65536):
            count[d + 1] += count[d]
        for j in range(n):
            d = (bits[j] >> shift) & 0xFFFF
            pos = count[d]
            count[d] = pos + 1
            ids2[pos] = ids[j]
            bits2[pos] = bits[j]
        ids, ids2 = ids2, ids
        bits, bits2 = bits2, bits
    return ids


@njit(cache=True, parallel=True)
def gather(order, records, rects, tiles, ordered, sorted_rects, sorted_tiles):
    """``ordered[j] = records[order[j]]``, ``sorted_rects[j] = rects[order[j]]`` and ``sorted_tiles[j] =
    tiles[order[j]]``: binning reads the rectangles in order, and compositing reads a tile's records from
    ascending addresses (its list is in depth order)."""
    for j in prange(order.shape[0]):
        i = order[j]
        for f in range(records.shape[1]):
            ordered[j, f] = records[i, f]
        for f in range(rects.shape[1]):
            sorted_rects[j, f] = rects[i, f]
        sorted_tiles[j] = tiles[i]


@njit(cache=True, parallel=True)
def bin_tiles(start, stop, ordered, sorted_rects, tiles_x, live, tile_start, pair_records, pair_rects):
    """Bin the depth-ordered Gaussians ``start <= j < stop`` (``ordered``: their :data:`RECORD`,
    ``sorted_rects``: their :data:`RECT`) into the tiles whose pixels are not all done (``live > 0``): rows
    ``tile_start[t]`` to ``tile_start[t + 1]`` of ``pair_records`` and ``pair_rects`` are copies of tile ``t``'s
    Gaussians' records and pixel rectangles (the first four fields of :data:`RECT`), in depth order.

    Compositing then reads each tile's records one after another in memory; read from ``ordered``, a tile's
    records were one in about as many as there are tiles, each a cache miss, which cost compositing a third
    of its time (measured: 18 of 46 ms at 480×270). Here they are read in order and written to one
    sequential stream per tile.

    Fixed chunks of the run (their number depends on its length alone) are counted per tile in parallel,
    each chunk's slots within a tile follow the previous chunk's (a prefix sum over tiles, then chunks),
    and the chunks fill their slots in parallel: the same lists whatever the thread count.
    """
    n_tiles = live.shape[0]
    n = stop - start
    chunks = min(max(n // _BIN_CHUNK, 1), _BIN_CHUNKS)
    slots = np.zeros((chunks, n_tiles), np.int64)
    for c in prange(chunks):
        _bin_chunk(start + n * c // chunks, start + n * (c + 1) // chunks, ordered, sorted_rects, tiles_x, live,
                   slots, c, pair_records, pair_rects, False)
    pos = 0
    for t in range(n_tiles):
        tile_start[t] = pos
        for c in range(chunks):
            count = slots[c, t]
            slots[c, t] = pos
            pos += count
    tile_start[n_tiles] = pos
    for c in prange(chunks):
        _bin_chunk(start + n * c // chunks, start + n * (c + 1) // chunks, ordered, sorted_rects, tiles_x, live,
                   slots, c, pair_records, pair_rects, True)


@njit(inline="always")
def _bin_chunk(j0, j1, ordered, sorted_rects, tiles_x, live, slots, c, pair_records, pair_rects, fill):
    """One chunk's pass of :func:`bin_tiles`: count its Gaussians per live tile into ``slots[c]``, or (``fill``)
    copy their records and pixel rectangles to row ``slots[c]`` and advance it."""
    for j in range(j0, j1):
        rect = sorted_rects[j]
        tx0, tx1, ty0, ty1 = rect[4], rect[5], rect[6], rect[7]
        for ty in range(ty0, ty1):
            for t in range(ty * tiles_x + tx0, ty * tiles_x + tx1):
                if live[t] > 0:
                    if fill:
                        slot = slots[c, t]
                        for f in range(ordered.shape[1]):
                            pair_records[slot, f] = ordered[j, f]
                        for f in range(4):
                            pair_rects[slot, f] = rect[f]
                    slots[c, t] += 1
