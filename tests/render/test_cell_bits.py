"""The cells' occupancy bits, block by block (pytest_n2r/render/cell_bits.py), against the grid they pack; the
renderer's check of the corners its kernel reads unchecked."""

from __future__ import annotations

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from pytest_n2r.errors import InvalidArgument
from pytest_n2r.field.kernels import BLOCK
from pytest_n2r.render.cell_bits import cell_bits, cell_occupied
from pytest_n2r.render.field_render import FieldRenderer, RenderSettings

from ..field.fields import random_field


@settings(max_examples=40, deadline=None)
@given(side=st.integers(1, 20), occupied=st.floats(0.0, 1.0), seed=st.integers(0, 2 ** 16))
def test_every_cell_reads_back_as_the_grid_has_it(side, occupied, seed):
    cells = (np.random.default_rng(seed).random((side,) * 3) < occupied).astype(np.uint8)
    bits = cell_bits(cells)
    blocks = -(-side // BLOCK)
    assert bits.shape == (blocks, blocks, blocks, BLOCK) and bits.dtype == np.int64, \
        f"bits of a {side}³ grid: shape {bits.shape} {bits.dtype}, expected ({blocks},) * 3 + ({BLOCK},) int64"
    read = np.array([[[cell_occupied(bits, i // BLOCK, j // BLOCK, k // BLOCK, i, j, k) for k in range(side)]
                      for j in range(side)] for i in range(side)])
    wrong = np.argwhere(read != cells.astype(bool))
    assert wrong.size == 0, (f"{len(wrong)} of {cells.size} cells read back wrong, e.g. cell {wrong[0].tolist()}: "
                             f"{bool(read[tuple(wrong[0])])} instead of {bool(cells[tuple(wrong[0])])}")
    assert sum((int(w) & (2 ** 64 - 1)).bit_count() for w in bits.ravel()) == int(cells.sum()), \
        "the padding beyond the grid has occupied bits"


@pytest.mark.parametrize("min_alpha", [0.0, 1e-4])
def test_a_renderer_refuses_a_field_missing_a_corner_of_an_occupied_cell(min_alpha):
    """The compiled kernel reads the corners of occupied cells with unsigned indices, unchecked
    (pytest_n2r.render.field_kernels._row): a field whose row map lacks one is refused before a render, whatever
    ``min_alpha`` (the check used to run only to skip thin cells)."""
    field = random_field(resolution=12, occupied=0.5, seed=3).compact()
    cell = field.occupancy.nonzero()[0].tolist()
    field.rows[(cell[0] * 12 + cell[1]) * 12 + cell[2]] = -1  # its first corner, no longer stored
    with pytest.raises(InvalidArgument, match="does not store every vertex of its occupied cells"):
        FieldRenderer(field, RenderSettings(min_alpha=min_alpha, backend="compiled"))
