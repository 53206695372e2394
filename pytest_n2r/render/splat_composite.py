"""Compiled CPU compositing (numba) of the splat rasterizer, its last stage (the others:
:mod:`pytest_n2r.render.splat_kernels`).

:func:`composite_tiles` (tiles dealt over the render threads, the busiest first): front-to-back alpha compositing
with early termination, a Gaussian at a time over blocks of :data:`LANES` pixels, branch-free inside a block so
that LLVM compiles a block to SIMD instructions (a block's 4 float64 per quantity: one AVX2 vector); each pixel's
arithmetic is the same as one pixel at a time, so are its bits. Each pixel's state (transmittance, colour,
depth) carries over between runs, so compositing a long list in several runs gives the same bits as in one.
:func:`finish` turns the pixel state into the outputs.
"""

from __future__ import annotations

import numpy as np
from numba import njit, prange

from .borrow import borrowed
from .splat_kernels import _B, _CA, _CB, _CC, _G, _O, _R, _R2, _U, _V, _Z, ALPHA_MAX, ALPHA_MIN

__all__ = ["BATCH", "COLS", "LANES", "ROWS", "composite_tiles", "exp_of_power", "finish"]

#: Gaussians a tile composites between two updates of its rows' spans of pixels not yet done.
BATCH = 32
#: A block: ``COLS`` pixels of ``ROWS`` tile rows, composited together. A tile holds its pixel state in blocks,
#: transmittance, R, G, B and depth each ``LANES`` values in a row (lane ``(y % ROWS) · COLS + x % COLS``).
#: Two rows of 2: a block's 4 float64 fill one AVX2 vector, and a Gaussian's rectangle in a tile, about 5 × 4
#: pixels at 480×270, leaves fewer of a block's lanes idle than with the 4 × 2 blocks (one AVX-512 vector) that
#: came before. On an AVX2 CPU a frame took 0.72-0.85 of their CPU; on the AVX-512 CPU they were chosen on, blocks
#: of 4 lanes had measured the same as 4 × 2 (docs/performance-log.md, "Splat scenes").
COLS = 2
ROWS = 2
LANES = COLS * ROWS
_T, _AR, _AG, _AB, _AD = range(5)
_FIELDS = 5
#: :func:`exp_of_power`'s table: ``exp(-j / _EXP_STEPS)`` for ``0 <= j <= _POWER_MIN_EXP · _EXP_STEPS``.
_EXP_STEPS = 64
_POWER_MIN_EXP = 6.0
_EXP_TABLE = np.exp(-np.arange(int(_POWER_MIN_EXP * _EXP_STEPS) + 1) / _EXP_STEPS)
_INDEX_MAX = float(_EXP_TABLE.shape[0] - 1)


@njit(inline="always")
def exp_of_power(power):
    """``exp(power)`` for ``-6 <= power <= 1/128`` (what compositing needs: ``alpha >= ALPHA_MIN`` implies
    ``power >= ln(ALPHA_MIN) > -5.6``) within 1e-15 relative (a few ulps; measured 6.7e-16): a table of
    ``exp(-j / 64)`` times a degree-5 Taylor polynomial on the remainder (``|r| <= 1/128``, truncation error
    below ``1e-16``). Inlined and free of calls, so the compositing loop keeps its values in registers (libm's
    ``exp`` is a call that spills them)."""
    x = -power * _EXP_STEPS
    # the index clamped as a float and converted to int32: AVX2 converts a vector of float64 to int32, not int64
    # (the same index as int(x + 0.5) clamped to the table; a rounding's tiny positive power: j = 0)
    j = np.int32(min(max(x, 0.0), _INDEX_MAX) + 0.5)
    r = (j - x) * (1.0 / _EXP_STEPS)
    return _EXP_TABLE[j] * (1.0 + r * (1.0 + r * (0.5 + r * (1.0 / 6.0 + r * (1.0 / 24.0 + r * (1.0 / 120.0))))))


@njit(cache=True, nogil=True, fastmath={"contract"})
def composite_tiles(part, parts, tile_start, pair_records, pair_rects, width, tile, tiles_x, tile_order, t_stop, live,
                    trans, acc_rgb, acc_depth, final, background, rgb_out, depth_out, opacity_out):
    """Composite each tile's Gaussians (rows ``tile_start[t]`` to ``tile_start[t + 1]`` of ``pair_records`` and
    ``pair_rects``, depth-ordered) front to back into the pixel state (``trans``: transmittance, negated once
    the pixel is done; ``acc_rgb`` / ``acc_depth``: weighted sums), updating ``live`` (pixels of the tile not
    yet done).

    Per pixel and Gaussian (3DGS reference): ``alpha = min(ALPHA_MAX, opacity · exp(-½ dᵀ conic d))``,
    skipped below ``ALPHA_MIN``; if the transmittance after it would fall below ``t_stop`` the pixel is done
    without it; else it adds ``alpha · T`` times its colour and depth and ``T *= 1 - alpha``. Every block
    that meets the Gaussian's rectangle inside the tile is visited, except those outside the span of the
    pixels not yet done of its block row (done pixels gather at a row's ends as the surface fills in; the
    spans are updated every :data:`BATCH` Gaussians, not as pixels finish: a branch on a pixel just
    composited would wait for its whole computation, and a mispredicted one discards it). In a block, every
    lane is computed and a mask keeps the result of those inside the rectangle and the span, not done, with
    the exponent at least ``-r2 / 2`` (``alpha`` below ``ALPHA_MIN`` with a margin) and ``alpha`` at least
    ``ALPHA_MIN``: the others keep their state. Compiled with floating-point contraction (fused
    multiply-adds).

    With ``final`` (the last run), each tile's pixels are then finished into the outputs (:func:`finish`) in
    the same call: one pass fewer per frame. This call composites the tiles ``tile_order[part::parts]``
    (:func:`~pytest_n2r.render.threads.run_dealt` runs the ``parts`` on the render threads; ``tile_order`` lists
    every tile once, the busiest first, so that dealt in turn they share out evenly). A plain ``nogil`` loop on
    the render threads rather than numba's parallel loop: with the same tiles in the same order, compositing took
    0.77-0.83 of the parallel loop's time on two threads (docs/performance-log.md, "Splat scenes").
    """
    n_tiles = live.shape[0]
    height = trans.shape[0] // width
    pair_records, pair_rects = borrowed(pair_records), borrowed(pair_rects)  # rows taken per pair: render/borrow.py
    blocks_x = (tile + COLS - 1) // COLS
    for i in range(part, n_tiles, parts):
        t = tile_order[i]
        s, e = tile_start[t], tile_start[t + 1]
        tx0 = (t % tiles_x) * tile
        ty0 = (t // tiles_x) * tile
        tx1 = min(tx0 + tile, width)
        ty1 = min(ty0 + tile, height)
        if live[t] == 0:
            e = s
        block_rows = (ty1 - ty0 + ROWS - 1) // ROWS
        state = np.empty((block_rows * blocks_x, _FIELDS, LANES))
        view = borrowed(state)  # for the helpers and the blocks: state itself is read to the tile's end, below
        _load_tile(view, trans, acc_rgb, acc_depth, width, tx0, tx1, ty0, ty1, blocks_x)
        # per block row of the tile, the pixels lo <= x < hi hold every pixel not yet done
        lo = np.full(block_rows, tx0)
        hi = np.full(block_rows, tx1)
        for k in range(s, e):
            if (k - s) % BATCH == 0:
                rows_left = 0
                for br in range(block_rows):
                    _shrink_span(view, br, blocks_x, tx0, lo, hi)
                    rows_left += lo[br] < hi[br]
                if rows_left == 0:
                    break
            rec, span = pair_records[k], pair_rects[k]
            gx0, gx1 = max(span[0], tx0), min(span[1], tx1)
            gy0, gy1 = max(span[2], ty0), min(span[3], ty1)
            u, v, ca, cb, cc, o = rec[_U], rec[_V], rec[_CA], rec[_CB], rec[_CC], rec[_O]
            cr, cg, cbl, z = rec[_R], rec[_G], rec[_B], rec[_Z]
            power_min = -0.5 * rec[_R2]
            for br in range((gy0 - ty0) // ROWS, (gy1 - 1 - ty0) // ROWS + 1):
                xa, xe = max(gx0, lo[br]), min(gx1, hi[br])
                if xa >= xe:
                    continue
                y0 = ty0 + br * ROWS
                for bx in range((xa - tx0) // COLS, (xe - tx0 - 1) // COLS + 1):
                    blk = view[br * blocks_x + bx]
                    x0 = tx0 + bx * COLS
                    for lane in range(LANES):
                        px = x0 + lane % COLS
                        py = y0 + lane // COLS
                        tp = blk[_T, lane]
                        dx = u - px
                        dy = v - py
                        power = -0.5 * (ca * dx * dx + cc * dy * dy) - cb * dx * dy
                        alpha = min(ALPHA_MAX, o * exp_of_power(max(power, power_min)))
                        after = tp * (1.0 - alpha)
                        ok = ((px >= xa) & (px < xe) & (py >= gy0) & (py < gy1) & (tp >= 0.0) & (power >= power_min)
                              & (alpha >= ALPHA_MIN))
                        stop = ok & (after < t_stop)
                        add = ok & (after >= t_stop)
                        w = alpha * tp
                        blk[_AR, lane] = blk[_AR, lane] + w * cr if add else blk[_AR, lane]
                        blk[_AG, lane] = blk[_AG, lane] + w * cg if add else blk[_AG, lane]
                        blk[_AB, lane] = blk[_AB, lane] + w * cbl if add else blk[_AB, lane]
                        blk[_AD, lane] = blk[_AD, lane] + w * z if add else blk[_AD, lane]
                        blk[_T, lane] = after if add else (-tp if stop else tp)
        live[t] = 0
        for y in range(ty1 - ty0):
            for x in range(tx1 - tx0):
                b, lane = _block_of(x, y, blocks_x)
                if final:
                    _finish_values((ty0 + y) * width + tx0 + x, state[b, _T, lane], state[b, _AR, lane],
                                   state[b, _AG, lane], state[b, _AB, lane], state[b, _AD, lane], background, rgb_out,
                                   depth_out, opacity_out)
                else:
                    p = (ty0 + y) * width + tx0 + x
                    trans[p], acc_depth[p] = state[b, _T, lane], state[b, _AD, lane]
                    for ch in range(3):
                        acc_rgb[p, ch] = state[b, _AR + ch, lane]
                live[t] += state[b, _T, lane] >= 0.0


@njit(inline="always")
def _block_of(x, y, blocks_x):
    """The block and lane of pixel ``x, y`` of a tile (counted from its top left pixel) with ``blocks_x`` blocks
    in a row."""
    return (y // ROWS) * blocks_x + x // COLS, (y % ROWS) * COLS + x % COLS


@njit(inline="always")
def _load_tile(state, trans, acc_rgb, acc_depth, width, tx0, tx1, ty0, ty1, blocks_x):
    """Copy the pixel state of the tile ``tx0 <= x < tx1, ty0 <= y < ty1`` into its blocks in ``state``; the
    lanes beyond the tile's edges are marked done."""
    state[:, _T, :] = -1.0
    state[:, _AR:, :] = 0.0
    for y in range(ty1 - ty0):
        for x in range(tx1 - tx0):
            b, lane = _block_of(x, y, blocks_x)
            p = (ty0 + y) * width + tx0 + x
            state[b, _T, lane], state[b, _AR, lane], state[b, _AG, lane] = trans[p], acc_rgb[p, 0], acc_rgb[p, 1]
            state[b, _AB, lane], state[b, _AD, lane] = acc_rgb[p, 2], acc_depth[p]


@njit(inline="always")
def _shrink_span(state, br, blocks_x, tx0, lo, hi):
    """Move the ends of block row ``br``'s span ``lo[br] <= x < hi[br]`` past the columns whose pixels are all
    done there (negative transmittance; ``tx0`` is the tile's first column)."""
    x0, x1 = lo[br], hi[br]
    while x0 < x1 and _column_done(state, br, blocks_x, x0 - tx0):
        x0 += 1
    while x1 > x0 and _column_done(state, br, blocks_x, x1 - 1 - tx0):
        x1 -= 1
    lo[br], hi[br] = x0, x1


@njit(inline="always")
def _column_done(state, br, blocks_x, x):
    """Whether the pixels of column ``x`` of the tile in block row ``br`` are all done."""
    for row in range(ROWS):
        if state[br * blocks_x + x // COLS, _T, row * COLS + x % COLS] >= 0.0:
            return False
    return True


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
