"""The cells a render samples (pytest_n2r/render/cell_bits.py), found in one compiled pass, against the field's own
selection; their bits, block by block, read back as the renderer reads them; the renderer's check of the corners its
kernel reads unchecked."""

from __future__ import annotations

import numpy as np
import pytest
import torch
from hypothesis import given, settings
from hypothesis import strategies as st

from pytest_n2r.demo import load_demo
from pytest_n2r.errors import InvalidArgument
from pytest_n2r.field.kernels import BLOCK
from pytest_n2r.render.cell_bits import cell_occupied, kept_cells
from pytest_n2r.render.field_render import FieldRenderer, RenderSettings

from ..field.fields import random_field


def unpacked(bits: np.ndarray, side: int) -> np.ndarray:
    """The ``(side,) * 3`` bool grid ``bits`` holds (the module's *Convention*: ``bits[bi, bj, bk, li]``, bit
    ``8·lj + lk``), and whether its padding beyond ``side`` holds no bit."""
    nb = bits.shape[0]
    assert bits.shape == (nb, nb, nb, BLOCK) and bits.dtype == np.int64 and nb == -(-side // BLOCK), (
        f"bits of a {side}³ grid: shape {bits.shape} {bits.dtype}, expected ({-(-side // BLOCK)},) * 3 + ({BLOCK},) "
        "int64")
    flat = np.unpackbits(bits.astype("<i8").view(np.uint8), bitorder="little").reshape((nb,) * 3 + (BLOCK,) * 3)
    grid = flat.transpose(0, 3, 1, 4, 2, 5).reshape((nb * BLOCK,) * 3).astype(bool)
    assert int(grid.sum()) == int(grid[:side, :side, :side].sum()), "the padding beyond the grid has occupied bits"
    return grid[:side, :side, :side]


@settings(max_examples=40, deadline=None)
@given(side=st.integers(3, 20), occupied=st.floats(0.0, 1.0), seed=st.integers(0, 2 ** 16))
def test_every_cell_reads_back_as_the_grid_has_it(side, occupied, seed):
    """Without a threshold every occupied cell is sampled; the renderer's reader (``cell_occupied``) finds each
    cell's bit where the layout puts it."""
    field = random_field(resolution=side + 1, occupied=occupied, seed=seed)
    cells, bits = kept_cells(field, 0.5, 0.0)
    grid = field.occupancy.numpy()
    assert np.array_equal(cells.astype(bool), grid), "min_alpha=0: the cells sampled are not the occupied ones"
    read = np.array([[[cell_occupied(bits, i // BLOCK, j // BLOCK, k // BLOCK, i, j, k) for k in range(side)]
                      for j in range(side)] for i in range(side)])
    wrong = np.argwhere(read != grid)
    assert wrong.size == 0, (f"{len(wrong)} of {grid.size} cells read back wrong, e.g. cell {wrong[0].tolist()}: "
                             f"{bool(read[tuple(wrong[0])])} instead of {bool(grid[tuple(wrong[0])])}")
    assert np.array_equal(unpacked(bits, side), grid), "the bits are not laid out as the module's Convention says"


def selected_cells(field, step_ratio: float, min_alpha: float) -> np.ndarray:
    """The cells a render samples as the torch backend selects them: occupied, and (``min_alpha > 0``) with the
    opacity of the densest corner at least ``min_alpha``."""
    occupancy = field.occupancy.clone()
    if min_alpha > 0:
        with torch.no_grad():
            occupancy[field.occupancy] = field.occupied_cell_alpha(step_ratio) >= min_alpha
    return occupancy.numpy()


def assert_same_cells(field, step_ratio: float, min_alpha: float, what: str) -> None:
    cells, bits = kept_cells(field, step_ratio, min_alpha)
    expected = selected_cells(field, step_ratio, min_alpha)
    wrong = np.argwhere(cells.astype(bool) != expected)
    assert wrong.size == 0, (f"{what}, step_ratio={step_ratio}, min_alpha={min_alpha}: {len(wrong)} of "
                             f"{expected.sum()} selected cells differ, e.g. {wrong[0].tolist()} kept="
                             f"{bool(cells[tuple(wrong[0])])}, expected {bool(expected[tuple(wrong[0])])}")
    assert np.array_equal(unpacked(bits, expected.shape[0]), expected), f"{what}: the bits do not hold those cells"


@settings(max_examples=40, deadline=None)
@given(resolution=st.integers(4, 20), occupied=st.floats(0.0, 1.0), seed=st.integers(0, 2 ** 16),
       sparse=st.booleans(), step_ratio=st.sampled_from([0.25, 0.5, 1.0]),
       min_alpha=st.sampled_from([0.0, 1e-4, 1e-2, 0.3]), density_scale=st.floats(0.5, 8.0))
def test_kept_cells_are_the_cells_the_field_selects(resolution, occupied, seed, sparse, step_ratio, min_alpha,
                                                    density_scale):
    field = random_field(resolution=resolution, occupied=occupied, seed=seed, density_scale=density_scale)
    field = field.compact() if sparse else field
    assert_same_cells(field, step_ratio, min_alpha, f"{'sparse' if sparse else 'dense'} {resolution}³ field")


@pytest.mark.parametrize("min_alpha", [0.0, 1e-4])
def test_a_cell_with_a_nan_corner_is_kept_only_without_a_threshold(min_alpha):
    """As the torch selection: the densest corner of a cell with a NaN is NaN, whose opacity is below any
    threshold."""
    field = random_field(resolution=10, occupied=1.0, seed=5)
    field.values[0, 0] = float("nan")  # vertex (0, 0, 0): a corner of cell (0, 0, 0) alone
    cells, _ = kept_cells(field, 0.5, min_alpha)
    assert bool(cells[0, 0, 0]) == (min_alpha == 0), f"min_alpha={min_alpha}: cell (0, 0, 0) kept={cells[0, 0, 0]}"
    assert_same_cells(field, 0.5, min_alpha, "a field with a NaN corner")


def test_kept_cells_are_the_cells_the_field_selects_on_a_shipped_twin():
    """The demo wall's fitted twin (384³, a real fit's densities), at the default settings."""
    assert_same_cells(load_demo("wall-field", device="cpu").field, 0.5, 1e-4, "the wall's fitted twin")


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
