"""Compiled CPU compositing (numba) of the splat rasterizer, its last stage (the others:
:mod:`pytest_n2r.render.splat_kernels`).

:func:`composite_tiles` (parallel over tiles, the busiest first): front-to-back alpha compositing, pixel by
pixel, with early termination; each pixel's state (transmittance, colour, depth) carries over between runs,
so compositing a long list in several runs gives the same bits as in one. A tile's records are copied in
batches of :data:`BATCH` into a contiguous block first: the copy's loads are independent of each other, so
their cache misses overlap, where the pixel loop would wait for each record in turn. :func:`finish` turns
the pixel state into the outputs.
"""

from __future__ import annotations

import numpy as np
from numba import njit, prange

from .splat_kernels import _B, _CA, _CB, _CC, _G, _O, _R, _R2, _U, _V, _Z, ALPHA_MAX, ALPHA_MIN

__all__ = ["BATCH", "LANES", "composite_tiles", "exp_of_power", "finish"]

#: Records a tile copies at a time before compositing them (see :func:`composite_tiles`).
BATCH = 32
#: Pixels of a tile row composited together (one AVX-512 vector of float64): a tile's pixel state is held in
#: blocks of ``LANES`` pixels of a row, transmittance, R, G, B and depth each ``LANES`` values in a row.
LANES = 8
_T, _AR, _AG, _AB, _AD = range(5)
_FIELDS = 5
#: :func:`exp_of_power`'s table: ``exp(-j / _EXP_STEPS)`` for ``0 <= j <= _POWER_MIN_EXP · _EXP_STEPS``.
_EXP_STEPS = 64
_POWER_MIN_EXP = 6.0
_EXP_TABLE = np.exp(-np.arange(int(_POWER_MIN_EXP * _EXP_STEPS) + 1) / _EXP_STEPS)


@njit(inline="always")
def exp_of_power(power):
    """``exp(power)`` for ``-6 <= power <= 1/128`` (what compositing needs: ``alpha >= ALPHA_MIN`` implies
    ``power >= ln(ALPHA_MIN) > -5.6``) within 1e-15 relative (a few ulps; measured 6.7e-16): a table of
    ``exp(-j / 64)`` times a degree-5 Taylor polynomial on the remainder (``|r| <= 1/128``, truncation error
    below ``1e-16``). Inlined and free of calls, so the compositing loop keeps its values in registers (libm's
    ``exp`` is a call that spills them)."""
    x = -power * _EXP_STEPS
    j = min(max(int(x + 0.5), 0), _EXP_TABLE.shape[0] - 1)  # a rounding's tiny positive power: j = 0
    r = (j - x) * (1.0 / _EXP_STEPS)
    return _EXP_TABLE[j] * (1.0 + r * (1.0 + r * (0.5 + r * (1.0 / 6.0 + r * (1.0 / 24.0 + r * (1.0 / 120.0))))))


@njit(cache=True, parallel=True, fastmath={"contract"})
def composite_tiles(tile_start, pair_records, pair_rects, width, tile, tiles_x, tile_order, t_stop, live, trans,
                    acc_rgb, acc_depth, final, background, rgb_out, depth_out, opacity_out):
    """Composite each tile's Gaussians (``tile_ids`` into ``records`` and ``sorted_rects``, depth-ordered) front to
    back into the pixel state (``trans``: transmittance, negated once the pixel is done; ``acc_rgb`` /
    ``acc_depth``: weighted sums), updating ``live`` (pixels of the tile not yet done).

    Per pixel and Gaussian (3DGS reference): ``alpha = min(ALPHA_MAX, opacity · exp(-½ dᵀ conic d))``,
    skipped below ``ALPHA_MIN``; if the transmittance after it would fall below ``t_stop`` the pixel is done
    without it; else it adds ``alpha · T`` times its colour and depth and ``T *= 1 - alpha``. Every pixel of
    the Gaussian's rectangle inside the tile is visited, except those outside the span of each tile row's
    pixels not yet done (kept per row: done pixels gather at a row's ends as the surface fills in, and a
    third of the visits went to them); where the exponent is below ``-r2 / 2`` (``alpha`` below ``ALPHA_MIN``
    with a margin) the exponential is skipped, which is cheaper than bounding each row by the ellipse (a
    square root per row). Compiled with floating-point contraction (fused multiply-adds).

    With ``final`` (the last run), each tile's pixels are then finished into the outputs (:func:`finish`) in
    the same parallel region: one region fewer per frame. Tiles are taken in ``tile_order`` (every tile
    once; the busiest first, so that no thread is left with a long tile at the end).
    """
    n_tiles = live.shape[0]
    height = trans.shape[0] // width
    blocks_x = (tile + LANES - 1) // LANES
    for i in prange(n_tiles):
        t = tile_order[i]
        s, e = tile_start[t], tile_start[t + 1]
        tx0 = (t % tiles_x) * tile
        ty0 = (t // tiles_x) * tile
        tx1 = min(tx0 + tile, width)
        ty1 = min(ty0 + tile, height)
        if live[t] == 0:
            e = s
        state = np.empty(((ty1 - ty0) * blocks_x, _FIELDS, LANES))
        _load_tile(state, trans, acc_rgb, acc_depth, width, tx0, tx1, ty0, ty1, blocks_x)
        # per row of the tile, the pixels lo <= x < hi hold every pixel not yet done
        lo = np.empty(ty1 - ty0, np.int64)
        hi = np.empty(ty1 - ty0, np.int64)
        lo[:], hi[:] = tx0, tx1
        for k in range(s, e):
            if (k - s) % BATCH == 0:
                # the spans move past the pixels done since the last batch (here, not as pixels finish: a branch
                # on a pixel just composited waits for its whole computation, and a mispredicted one discards it)
                rows_left = 0
                for r in range(ty1 - ty0):
                    _shrink_span(state, r * blocks_x, tx0, r, lo, hi)
                    rows_left += lo[r] < hi[r]
                if rows_left == 0:
                    break
            rec, span = pair_records[k], pair_rects[k]
            gx0, gx1 = max(span[0], tx0), min(span[1], tx1)
            gy0, gy1 = max(span[2], ty0), min(span[3], ty1)
            u, v, ca, cb, cc, o = rec[_U], rec[_V], rec[_CA], rec[_CB], rec[_CC], rec[_O]
            cr, cg, cbl, z = rec[_R], rec[_G], rec[_B], rec[_Z]
            power_min = -0.5 * rec[_R2]
            for py in range(gy0, gy1):
                r = py - ty0
                xa, xe = max(gx0, lo[r]), min(gx1, hi[r])
                if xa >= xe:
                    continue
                dy = v - py
                for bx in range((xa - tx0) // LANES, (xe - tx0 - 1) // LANES + 1):
                    blk = state[r * blocks_x + bx]
                    x0 = tx0 + bx * LANES
                    for lane in range(LANES):
                        px = x0 + lane
                        tp = blk[_T, lane]
                        dx = u - px
                        power = -0.5 * (ca * dx * dx + cc * dy * dy) - cb * dx * dy
                        alpha = min(ALPHA_MAX, o * exp_of_power(max(power, power_min)))
                        after = tp * (1.0 - alpha)
                        ok = (px >= xa) & (px < xe) & (tp >= 0.0) & (power >= power_min) & (alpha >= ALPHA_MIN)
                        stop = ok & (after < t_stop)
                        add = ok & (after >= t_stop)
                        w = alpha * tp
                        blk[_AR, lane] = blk[_AR, lane] + w * cr if add else blk[_AR, lane]
                        blk[_AG, lane] = blk[_AG, lane] + w * cg if add else blk[_AG, lane]
                        blk[_AB, lane] = blk[_AB, lane] + w * cbl if add else blk[_AB, lane]
                        blk[_AD, lane] = blk[_AD, lane] + w * z if add else blk[_AD, lane]
                        blk[_T, lane] = after if add else (-tp if stop else tp)
        live[t] = _live_pixels(state, tx1 - tx0, ty1 - ty0, blocks_x)
        if final:
            for r in range(ty1 - ty0):
                for x in range(tx1 - tx0):
                    blk, lane = state[r * blocks_x + x // LANES], x % LANES
                    _finish_values((ty0 + r) * width + tx0 + x, blk[_T, lane], blk[_AR, lane], blk[_AG, lane],
                                   blk[_AB, lane], blk[_AD, lane], background, rgb_out, depth_out, opacity_out)
        else:
            _store_tile(state, trans, acc_rgb, acc_depth, width, tx0, tx1, ty0, ty1, blocks_x)


@njit(inline="always")
def _load_tile(state, trans, acc_rgb, acc_depth, width, tx0, tx1, ty0, ty1, blocks_x):
    """Copy the pixel state of the tile ``tx0 <= x < tx1, ty0 <= y < ty1`` into its blocks in ``state`` (see
    :func:`composite_tiles`); the lanes beyond the tile's right edge are marked done."""
    for r in range(ty1 - ty0):
        for x in range(blocks_x * LANES):
            blk, lane = state[r * blocks_x + x // LANES], x % LANES
            if x < tx1 - tx0:
                p = (ty0 + r) * width + tx0 + x
                blk[_T, lane], blk[_AR, lane], blk[_AG, lane] = trans[p], acc_rgb[p, 0], acc_rgb[p, 1]
                blk[_AB, lane], blk[_AD, lane] = acc_rgb[p, 2], acc_depth[p]
            else:
                blk[:, lane] = 0.0
                blk[_T, lane] = -1.0


@njit(inline="always")
def _store_tile(state, trans, acc_rgb, acc_depth, width, tx0, tx1, ty0, ty1, blocks_x):
    """Copy a tile's blocks in ``state`` back into the pixel state (the inverse of :func:`_load_tile`)."""
    for r in range(ty1 - ty0):
        for x in range(tx1 - tx0):
            blk, lane = state[r * blocks_x + x // LANES], x % LANES
            p = (ty0 + r) * width + tx0 + x
            trans[p], acc_rgb[p, 0], acc_rgb[p, 1] = blk[_T, lane], blk[_AR, lane], blk[_AG, lane]
            acc_rgb[p, 2], acc_depth[p] = blk[_AB, lane], blk[_AD, lane]


@njit(inline="always")
def _shrink_span(state, row_block, tx0, r, lo, hi):
    """Move the ends of tile row ``r``'s span ``lo[r] <= x < hi[r]`` past the done pixels there (negative
    transmittance; the row's blocks start at block ``row_block`` of ``state``, its first pixel is ``tx0``)."""
    x0, x1 = lo[r], hi[r]
    while x0 < x1 and _trans_at(state, row_block, tx0, x0) < 0.0:
        x0 += 1
    while x1 > x0 and _trans_at(state, row_block, tx0, x1 - 1) < 0.0:
        x1 -= 1
    lo[r], hi[r] = x0, x1


@njit(inline="always")
def _trans_at(state, row_block, tx0, x):
    """The transmittance of pixel ``x`` of the tile row whose blocks start at ``row_block`` (first pixel ``tx0``)."""
    return state[row_block + (x - tx0) // LANES, _T, (x - tx0) % LANES]


@njit(inline="always")
def _live_pixels(state, width, height, blocks_x):
    """Pixels not yet done (transmittance >= 0) of a ``width`` × ``height`` tile's blocks."""
    n = 0
    for r in range(height):
        for x in range(width):
            n += state[r * blocks_x + x // LANES, _T, x % LANES] >= 0.0
    return n


@njit(cache=True, parallel=True)
def finish(trans, acc_rgb, acc_depth, background, rgb_out, depth_out, opacity_out):
    """Pixel state (``trans`` negated where done) → ``rgb`` uint8 (over ``background``, rounded half to even
    like ``np.rint``), ``depth`` (the weighted mean z-depth; 0 where nothing contributed) and ``opacity``
    (``1 - T``), flat over pixels."""
    for p in prange(trans.shape[0]):
        _finish_values(p, trans[p], acc_rgb[p, 0], acc_rgb[p, 1], acc_rgb[p, 2], acc_depth[p], background, rgb_out,
                       depth_out, opacity_out)


@njit(inline="always")
def _finish_values(p, trans, red, green, blue, depth, background, rgb_out, depth_out, opacity_out):
    """:func:`finish` of pixel ``p`` with the state ``trans``, ``red``, ``green``, ``blue``, ``depth``."""
    tp = abs(trans)
    for ch, acc in enumerate((red, green, blue)):
        value = acc + tp * background[ch]
        rgb_out[p, ch] = np.uint8(min(max(np.rint(value * 255.0), 0.0), 255.0))
    weight = 1.0 - tp
    depth_out[p] = depth / weight if weight > 0.0 else 0.0
    opacity_out[p] = weight
