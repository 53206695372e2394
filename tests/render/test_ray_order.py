"""Pixels traced tile by tile: a permutation that groups tiles, and renders the same to the bit."""

from __future__ import annotations

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from pytest_n2r.geometry import Camera
from pytest_n2r.render import field_render
from pytest_n2r.render.field_render import FieldRenderer, RenderSettings
from pytest_n2r.render.ray_order import TILE, tiled_pixels

from ..field.fields import named_pose, random_field


@settings(max_examples=60, deadline=None)
@given(width=st.integers(1, 70), height=st.integers(1, 40), seed=st.integers(0, 99))
def test_tiled_pixels_are_the_wanted_pixels_each_tile_whole_and_in_row_order(width, height, seed):
    rng = np.random.default_rng(seed)
    want = rng.random(width * height) < 0.6  # a pass's pixels
    index = tiled_pixels(want, width)
    assert np.array_equal(np.sort(index), np.flatnonzero(want)), f"{index} are not the wanted pixels"
    y, x = np.divmod(index, width)
    tile = (y // TILE) * width + x // TILE
    starts = np.flatnonzero(np.diff(tile)) + 1
    assert np.all(np.diff(tile) >= 0), (
        f"{width}×{height}: tiles are not traced whole and row by row: tiles {tile.tolist()}")
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
    monkeypatch.setattr(field_render, "tiled_pixels", lambda want, width: np.flatnonzero(want))
    rows = FieldRenderer(field, settings_).render(named_pose("outside"), camera, outputs)
    for name in outputs:
        assert tiled[name].tobytes() == rows[name].tobytes(), (
            f"{name} differs between tracing tile by tile and row by row (adaptive={adaptive})")
    assert tiled["opacity"].max() > 0.5, "the pose sees almost nothing: the comparison would test little"
