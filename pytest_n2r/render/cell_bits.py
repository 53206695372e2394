"""The cells' occupancy for the compiled renderer: one bit a cell, an 8³-cell block's 512 bits in one cache line.

The renderer looks up the cell of every sample it does not jump over (on the 224³ fox fit, ~26 empty cells and
~16 occupied ones a ray). As a byte a cell in the grid's own order, a step of one cell along the first axis is
``R²`` bytes away (a new cache line at every cell a ray enters), and the grid (11 MB at 224³, 56 MB at the
demo twins' 384³) does not stay in cache: on ``demo:object`` that one load was the kernel's hottest
instruction (a profile with ``perf``, docs/performance-log.md, "Rendering"). Block by block, the cells a ray
crosses in an occupied block share one 64-byte line, and the whole grid is an eighth of the bytes.

Convention: ``bits[bi, bj, bk, li]`` (int64, block indices as :func:`pytest_n2r.field.kernels.block_occupancy`'s
grid) holds the cells ``(8·bi + li, 8·bj + lj, 8·bk + lk)`` of block ``(bi, bj, bk)``: bit ``8·lj + lk`` is set
where that cell is occupied. Cells beyond the grid (the last block's padding) are empty.

The cells a render samples are the field's occupied cells whose densest corner is not too thin
(``RenderSettings.min_alpha``): :func:`kept_cells` finds them and packs their bits in one compiled pass over the
grid (:meth:`~pytest_n2r.field.grid.SceneField.occupied_cell_alpha` and a packing of a dense copy of the grid took
1.2 s of a renderer's 1.4 s set-up on the demo twins' 384³ grids; docs/performance-log.md, "Rendering").

numba's cache checks a kernel's own file only (numba/numba#1833): after editing :func:`cell_occupied`, delete the
``__pycache__`` folder of ``pytest_n2r/render``, whose cached renderer inlines it.
"""

from __future__ import annotations

import math

import numpy as np
import torch
from numba import njit

from ..errors import InvalidArgument
from ..field.grid import SceneField, opacity
from ..field.kernels import BLOCK
from .threads import run_parts

__all__ = ["cell_occupied", "kept_cells"]


@njit(cache=True, inline="always")
def cell_occupied(bits, bi, bj, bk, ci, cj, ck):
    """Whether cell ``(ci, cj, ck)`` (of block ``(bi, bj, bk)``, its indices over ``BLOCK``) is occupied (``bits``
    from :func:`kept_cells`; indices >= 0)."""
    m = BLOCK - 1  # unsigned indices: no wraparound code (pytest_n2r.render.field_kernels._row)
    word = bits[np.uint64(bi), np.uint64(bj), np.uint64(bk), np.uint64(ci & m)]
    return (word >> ((cj & m) * BLOCK + (ck & m))) & 1 != 0


def kept_cells(field: SceneField, step_ratio: float, min_alpha: float) -> tuple[np.ndarray, np.ndarray]:
    """``(cells, bits)``: the cells a render of ``field`` samples, as a ``(C, C, C)`` uint8 grid (1: sampled) and
    as bits (the module's *Convention*). Those are the occupied cells whose densest corner gives at least
    ``min_alpha`` opacity over one sample of ``step_ratio`` voxels (every occupied cell for ``min_alpha=0``;
    a cell with a NaN corner only then), the cells ``field.occupied_cell_alpha(step_ratio) >= min_alpha`` selects.
    Each stored vertex's opacity is computed once (the same torch expression), and a cell takes that of its
    densest corner. :class:`InvalidArgument` if the field does not store every corner of its occupied cells
    (the renderer reads them unchecked). A CPU field.
    """
    occupancy = field.occupancy.numpy().view(np.uint8)  # bool → uint8, no copy
    side = occupancy.shape[0]
    with torch.no_grad():
        raw = field.values.detach()[:, 0]
        density = np.ascontiguousarray(raw.numpy())
        kept_row = (opacity(raw, field.density_shift, step_ratio) >= min_alpha).numpy() \
            if min_alpha > 0 else np.ones(0, dtype=np.bool_)
    nb = (side + BLOCK - 1) // BLOCK
    cells = np.empty_like(occupancy)
    bits = np.zeros((nb, nb, nb, BLOCK), dtype=np.int64)
    missing = np.zeros(side, dtype=np.bool_)
    run_parts(_kept_cells, side, occupancy, field.kernel_rows(), density, kept_row, cells, bits, missing)
    if missing.any():
        raise InvalidArgument("the field does not store every vertex of its occupied cells")
    return cells, bits


@njit(cache=True, nogil=True)
def _kept_cells(first, last, occupancy, rows, density, kept_row, cells, bits, missing):
    """:func:`kept_cells` for the cell slices ``first <= i < last`` (each slice writes only its own words of
    ``bits``: bit ``li = i % BLOCK``); ``rows`` empty for a dense field, ``kept_row`` empty to keep every occupied
    cell; ``missing[i]`` set where slice ``i`` has an occupied cell with a corner the field does not store."""
    side = occupancy.shape[0]
    res = side + 1
    rr = res * res
    dense, every = rows.shape[0] == 0, kept_row.shape[0] == 0
    for i in range(first, last):
        for j in range(side):
            for k in range(side):
                cells[i, j, k] = 0
                if occupancy[i, j, k] == 0:
                    continue
                v = (i * res + j) * res + k
                best, best_density, nan = -1, -math.inf, False
                for corner in range(8):
                    u = v + (corner >> 2) * rr + ((corner >> 1) & 1) * res + (corner & 1)
                    row = u if dense else rows[u]
                    if row < 0:
                        missing[i] = True
                        return
                    value = density[row]
                    nan = nan or math.isnan(value)
                    if best < 0 or value > best_density:
                        best, best_density = row, value
                if every or (not nan and kept_row[best]):
                    cells[i, j, k] = 1
                    bit = np.int64(1) << ((j % BLOCK) * BLOCK + k % BLOCK)
                    bits[i // BLOCK, j // BLOCK, k // BLOCK, i % BLOCK] |= bit
