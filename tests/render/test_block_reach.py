"""The reach of empty blocks (pytest_n2r/render/block_reach.py) and the renderer's jumps through them."""

from __future__ import annotations

import itertools

import numpy as np
import pytest
import torch
from hypothesis import given, settings
from hypothesis import strategies as st

from pytest_n2r.render.block_reach import block_reach
from pytest_n2r.render.field_render import FieldRenderer, RenderSettings

from ..field.fields import CAMERA, POSES, camera_for, named_pose, pose, random_field
from .strategies import cameras, poses


def brute_reach(blocks: np.ndarray) -> np.ndarray:
    """The reach by its definition: the largest empty box around each empty block, grown one block at a time."""
    side = blocks.shape[0]
    reach = np.full(blocks.shape, -1, dtype=np.int16)
    for i, j, k in itertools.product(range(side), repeat=3):
        r = -1
        while r < side:
            lo = [max(0, c - r - 1) for c in (i, j, k)]
            hi = [c + r + 2 for c in (i, j, k)]
            if blocks[lo[0]:hi[0], lo[1]:hi[1], lo[2]:hi[2]].any():
                break
            r += 1
        reach[i, j, k] = r
    return reach


@settings(max_examples=60, deadline=None)
@given(side=st.integers(1, 7), occupied=st.floats(0.0, 0.2), seed=st.integers(0, 2 ** 16))
def test_block_reach_is_the_largest_empty_box_around_each_block(side, occupied, seed):
    blocks = (np.random.default_rng(seed).random((side,) * 3) < occupied).astype(np.uint8)
    reach, expected = block_reach(blocks), brute_reach(blocks)
    wrong = np.argwhere(reach != expected)
    assert wrong.size == 0, (f"{len(wrong)} of {blocks.size} blocks have the wrong reach, e.g. block "
                             f"{wrong[0].tolist()}: {reach[tuple(wrong[0])]} instead of {expected[tuple(wrong[0])]}")


def blob_field(sh_degree: int):
    """A 64³ field (8³ blocks) whose occupied cells are a ball off the centre: most blocks empty, reaches up to 4."""
    field = random_field(resolution=64, sh_degree=sh_degree, occupied=0.6, seed=5 + sh_degree)
    i, j, k = torch.meshgrid(*(torch.arange(63, dtype=torch.float32),) * 3, indexing="ij")
    field.occupancy &= (i - 36.0) ** 2 + (j - 28.0) ** 2 + (k - 30.0) ** 2 < 12.0 ** 2
    return field


@pytest.mark.parametrize("sh_degree", [0, 1])
@pytest.mark.parametrize("tail", [(0.3, 0.1), ()])
def test_jumps_through_boxes_of_empty_blocks_change_no_bit(sh_degree, tail):
    """Jumping to the exit of the box of empty blocks around a block takes the same samples as jumping block by
    block: every output equal to the bit, from every named pose (with the tail's doubled samples and without)."""
    field = blob_field(sh_degree)
    renderer = FieldRenderer(field, RenderSettings(tail=tail, adaptive=0.0))
    assert renderer._reach.max() >= 2, "the test field should have boxes of empty blocks to jump through"
    block_by_block = FieldRenderer(field, RenderSettings(tail=tail, adaptive=0.0))
    block_by_block._reach = np.minimum(block_by_block._reach, 0)
    for name in POSES:
        camera = camera_for(name) if name == "far_away" else CAMERA.resized(64, 48)
        a = renderer.render(named_pose(name), camera, ("rgb", "depth", "opacity"))
        b = block_by_block.render(named_pose(name), camera, ("rgb", "depth", "opacity"))
        assert float(a["opacity"].max()) > 0.0 or name == "looking_away", f"pose {name}: the render saw nothing"
        for output in a:
            differing = int(np.sum(a[output] != b[output]))
            assert differing == 0, (f"pose {name}, {output}: {differing} of {a[output].size} values differ between "
                                    "jumps through boxes of empty blocks and jumps block by block")


BLOB = blob_field(1)


def no_jumps(renderer: FieldRenderer) -> FieldRenderer:
    """``renderer`` stepping through every lattice step of an empty block (every block marked occupied in its
    reach: the ray checks each empty cell's bit and takes nothing there)."""
    renderer._reach = np.full_like(renderer._reach, -1)
    return renderer


def assert_no_sample_lost(c2w: np.ndarray, camera, what: str) -> None:
    """Jumps through empty blocks give every output to the bit as stepping through them (one sample a step, so
    without the tail: with it a jump moves the doubled samples after it, the module docstring of the kernel)."""
    settings_ = RenderSettings(tail=(), adaptive=0.0)
    a = FieldRenderer(BLOB, settings_).render(c2w, camera, ("rgb", "depth", "opacity"))
    b = no_jumps(FieldRenderer(BLOB, settings_)).render(c2w, camera, ("rgb", "depth", "opacity"))
    for output in a:
        differing = int(np.sum(a[output] != b[output]))
        assert differing == 0, (f"{what}, {output}: {differing} of {a[output].size} values differ between jumping "
                                "through empty blocks and stepping through them: a jump skipped a sample")


@pytest.mark.parametrize("eye", [(2.0, 0.0, 0.0), (0.0, -2.0, 0.0), (0.0, 0.0, 2.5), (0.31, 0.0, 0.0)])
def test_jumps_along_an_axis_skip_no_sample(eye):
    """Rays along a grid axis (the other two direction components 0 at the centre pixel, tiny around it), from
    outside the cube and from inside it."""
    assert_no_sample_lost(pose(eye, (0.0, 0.0, 0.0)), CAMERA.resized(33, 33), f"eye {eye} towards the centre")


@settings(max_examples=40, deadline=None)
@given(eye_target=poses(max_distance=30.0), camera=cameras(max_side=12))
def test_jumps_skip_no_sample_from_any_pose(eye_target, camera):
    assert_no_sample_lost(pose(*eye_target), camera, f"eye {eye_target[0]} towards {eye_target[1]}, {camera}")
