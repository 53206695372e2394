"""Pixels traced tile by tile: a permutation that groups tiles, and renders the same to the bit."""

from __future__ import annotations

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from pytest_n2r.geometry import Camera
from pytest_n2r.render import field_render
from pytest_n2r.render.field_render import FieldRenderer, RenderSettings
from pytest_n2r.render.ray_order import TILE, tile_order

from ..field.fields import named_pose, random_field


@settings(max_examples=60, deadline=None)
@given(width=st.integers(1, 70), height=st.integers(1, 40), seed=st.integers(0, 99))
def test_tile_order_is_a_permutation_that_takes_each_tile_whole_and_in_row_order(width, height, seed):
    rng = np.random.default_rng(seed)
    index = np.flatnonzero(rng.random(width * height) < 0.6)  # a pass's ascending pixels
    order = tile_order(index, width)
    assert np.array_equal(np.sort(order), np.arange(index.size)), f"{order} is not a permutation of the pixels"
    y, x = np.divmod(index[order], width)
    tile = (y // TILE) * width + x // TILE
    starts = np.flatnonzero(np.diff(tile)) + 1
    assert np.unique(tile).size == starts.size + (index.size > 0), (
        f"{width}×{height}: a tile's pixels are not traced one after the other: tiles {tile.tolist()}")
    inside = y * TILE + x % TILE  # row-major inside a tile
    for part in np.split(inside, starts):
        assert np.all(np.diff(part) > 0), f"{width}×{height}: pixels inside a tile out of row order: {part.tolist()}"


@pytest.mark.parametrize("adaptive", [0.0, 0.04])
def test_tracing_tile_by_tile_gives_the_images_of_tracing_row_by_row(monkeypatch, adaptive):
    field = random_field(sh_degree=1, seed=4)
    camera = Camera(83, 41, 60.0, 60.0, 41.0, 20.0)  # not a multiple of the tile: partial tiles at the right and bottom
    settings_ = RenderSettings(adaptive=adaptive, adaptive_stride=2)
    outputs = ("rgb", "depth", "opacity")
    tiled = FieldRenderer(field, settings_).render(named_pose("outside"), camera, outputs)
    monkeypatch.setattr(field_render, "tile_order", lambda index, width: np.arange(index.size))
    rows = FieldRenderer(field, settings_).render(named_pose("outside"), camera, outputs)
    for name in outputs:
        assert tiled[name].tobytes() == rows[name].tobytes(), (
            f"{name} differs between tracing tile by tile and row by row (adaptive={adaptive})")
    assert tiled["opacity"].max() > 0.5, "the pose sees almost nothing: the comparison would test little"
