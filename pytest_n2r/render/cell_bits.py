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

numba's cache checks a kernel's own file only (numba/numba#1833): after editing :func:`cell_occupied`, delete the
``__pycache__`` folder of ``pytest_n2r/render``, whose cached renderer inlines it.
"""

from __future__ import annotations

import numpy as np
from numba import njit

from ..field.kernels import BLOCK

__all__ = ["cell_bits", "cell_occupied"]


def cell_bits(cells: np.ndarray) -> np.ndarray:
    """The occupancy bits of ``cells`` (``(C, C, C)``, nonzero where a cell is occupied), block by block.

    >>> cells = np.zeros((10, 10, 10), dtype=np.uint8)
    >>> cells[9, 2, 3] = 1  # block (1, 0, 0), li 1, bit 8·2 + 3
    >>> bits = cell_bits(cells)
    >>> bits.shape, int(bits[1, 0, 0, 1]) == 1 << 19, int(np.count_nonzero(bits))
    ((2, 2, 2, 8), True, 1)
    """
    side = cells.shape[0]
    nb = (side + BLOCK - 1) // BLOCK
    padded = np.zeros((nb * BLOCK,) * 3, dtype=bool)
    padded[:side, :side, :side] = cells != 0
    by_block = padded.reshape(nb, BLOCK, nb, BLOCK, nb, BLOCK).transpose(0, 2, 4, 1, 3, 5)
    packed = np.packbits(by_block.reshape(nb, nb, nb, BLOCK, BLOCK * BLOCK), axis=-1, bitorder="little")
    return np.ascontiguousarray(packed).view("<i8").reshape(nb, nb, nb, BLOCK).astype(np.int64, copy=False)


@njit(cache=True, inline="always")
def cell_occupied(bits, bi, bj, bk, ci, cj, ck):
    """Whether cell ``(ci, cj, ck)`` (of block ``(bi, bj, bk)``, its indices over ``BLOCK``) is occupied (``bits``
    from :func:`cell_bits`; indices >= 0)."""
    m = BLOCK - 1  # unsigned indices: no wraparound code (pytest_n2r.render.field_kernels._row)
    word = bits[np.uint64(bi), np.uint64(bj), np.uint64(bk), np.uint64(ci & m)]
    return (word >> ((cj & m) * BLOCK + (ck & m))) & 1 != 0
