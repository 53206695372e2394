"""Kernels of the splat rasterizer checked on their own: the exponential compositing uses, and the parallel
tile binning against a plain one."""

from __future__ import annotations

import numpy as np
from numba import njit

from pytest_n2r.render import splat_composite
from pytest_n2r.render import splat_kernels as k


@njit
def _exps(powers):
    out = np.empty_like(powers)
    for i in range(powers.shape[0]):
        out[i] = splat_composite.exp_of_power(powers[i])
    return out


def test_exp_of_power_is_exp_to_a_few_ulps_where_compositing_uses_it():
    powers = np.concatenate([-np.random.default_rng(0).uniform(0, 6, 200_000), np.linspace(-6, 0, 4097),
                             [0.0, -1e-300, -np.log(255.0), 1e-12, 1 / 128]])
    rel = np.abs(_exps(powers) / np.exp(powers) - 1)
    assert rel.max() < 1e-15, f"relative error up to {rel.max():.3g} at power {powers[np.argmax(rel)]}"


def _plain_bins(rects, start, tile, tiles_x, live):
    lists = [[] for _ in live]
    for j, (x0, x1, y0, y1) in enumerate(rects):
        for ty in range(y0 // tile, (y1 - 1) // tile + 1):
            for tx in range(x0 // tile, (x1 - 1) // tile + 1):
                if live[ty * tiles_x + tx] > 0:
                    lists[ty * tiles_x + tx].append(start + j)
    return lists


def with_tiles(rects, tile):
    """Pixel rectangles ``x0, x1, y0, y1`` with their tile rectangles appended (:data:`RECT`)."""
    x0, x1, y0, y1 = rects.T
    return np.stack([x0, x1, y0, y1, x0 // tile, (x1 - 1) // tile + 1, y0 // tile, (y1 - 1) // tile + 1],
                    axis=1).astype(np.int32)


def _bin(start, stop, rects, tile, tiles_x, live):
    """:func:`k.bin_tiles` of ``rects`` whose records hold their position in the depth order: each tile's list of
    positions, read back from the records it copied (and its rectangles, checked against ``rects``)."""
    n = len(rects)
    records = np.zeros((n, len(k.RECORD)))
    records[:, 0] = np.arange(n)
    pairs = int(sum((r[5] - r[4]) * (r[7] - r[6]) for r in with_tiles(rects[start:stop], tile)))
    tile_start = np.empty(len(live) + 1, np.int64)
    pair_records = np.full((pairs, len(k.RECORD)), -1.0)
    pair_rects = np.full((pairs, 4), -1, np.int32)
    k.bin_tiles(start, stop, records, with_tiles(rects, tile), tiles_x, live, tile_start, pair_records, pair_rects)
    used = tile_start[-1]
    positions = pair_records[:used, 0].astype(np.int64)
    assert (pair_records[:used, 1:] == 0).all(), "a tile's copy of a record differs from the record"
    assert (pair_rects[:used] == rects[positions]).all(), "a tile's copy of a rectangle differs from the rectangle"
    return [positions[tile_start[t]:tile_start[t + 1]].tolist() for t in range(len(live))]


def test_binning_in_parallel_chunks_gives_the_plain_depth_ordered_lists():
    """50 000 depth-ordered Gaussians (12 chunks) on a 100×60 image with 8-pixel tiles, some tiles already
    done: every tile's list of positions is the plain loop's, in depth order, whatever the chunks, and each
    tile holds copies of its Gaussians' records and rectangles."""
    rng = np.random.default_rng(1)
    n, width, height, tile = 50_000, 100, 60, 8
    tiles_x, tiles_y = -(-width // tile), -(-height // tile)
    x0, y0 = rng.integers(0, width, n), rng.integers(0, height, n)
    rects = np.stack([x0, np.minimum(x0 + rng.integers(1, 20, n), width), y0,
                      np.minimum(y0 + rng.integers(1, 20, n), height)], axis=1).astype(np.int32)
    live = rng.integers(0, 3, tiles_x * tiles_y).astype(np.int64)
    expected = _plain_bins(rects.tolist(), 0, tile, tiles_x, live)
    for t, (got, want) in enumerate(zip(_bin(0, n, rects, tile, tiles_x, live), expected)):
        assert got == want, (f"tile {t}: {len(got)} Gaussians binned, expected {len(want)}; first differences "
                             f"{[(a, b) for a, b in zip(got, want) if a != b][:3]}")
    # a run from the middle of the order bins that run alone
    expected = _plain_bins(rects[1000:9000].tolist(), 1000, tile, tiles_x, live)
    assert _bin(1000, 9000, rects, tile, tiles_x, live) == expected, \
        "binning the run 1000..9000 differs from the plain loop's"
