"""How far a ray may jump through empty space: for every empty 8³-cell block, the box of empty blocks around it.

The compiled renderer skips an empty block in one jump, to where the ray leaves it. Around the fox most blocks
are empty (93 % of the 224³ field's), and a ray crossed about 25 of them one jump at a time, each jump a few
divisions (docs/performance-log.md, "Rendering"). With the reach of a block the ray jumps to where it leaves the
whole box of empty blocks around it instead.

Convention: ``reach[bi, bj, bk]`` (int16, block indices as :func:`pytest_n2r.field.kernels.block_occupancy`'s
grid) is -1 for a block with an occupied cell, else the largest ``r`` such that every block within ``r`` blocks
of it (Chebyshev distance, the box of ``(2r + 1)³`` blocks centred on it) is empty; blocks beyond the grid count
as empty, and ``r`` is at most the grid's side in blocks.
"""

from __future__ import annotations

import numpy as np

__all__ = ["block_reach"]


def block_reach(blocks: np.ndarray) -> np.ndarray:
    """The reach of every block of ``blocks`` (``uint8`` ``(B, B, B)``, 1 where a block has an occupied cell).

    >>> blocks = np.zeros((5, 5, 5), dtype=np.uint8)
    >>> blocks[0, 0, 0] = 1
    >>> block_reach(blocks)[:, 0, 0].tolist()  # the occupied block, then 1, 2, 3, 4 blocks away from it
    [-1, 0, 1, 2, 3]
    """
    side = blocks.shape[0]
    box = blocks == 0  # the blocks whose box of radius r is empty, for r = 0, 1, ...
    reach = np.where(box, 0, -1).astype(np.int16)
    for r in range(1, side + 1):
        box = _eroded(box)
        if not box.any():
            break
        reach[box] = r
    return reach


def _eroded(box: np.ndarray) -> np.ndarray:
    """``box`` where each block's 3³ neighbourhood is all set (beyond the grid counts as set)."""
    for axis in range(3):
        padded = np.pad(box, [(1, 1) if a == axis else (0, 0) for a in range(3)], constant_values=True)
        n = box.shape[axis]
        box = (padded.take(range(n), axis) & padded.take(range(1, n + 1), axis)
               & padded.take(range(2, n + 2), axis))
    return box
