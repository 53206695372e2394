"""The compiled renderer and marcher against the torch reference (same lattice, same formulas).

With early termination and occupancy thresholds off (``t_stop=0, min_alpha=0``) both backends composite
exactly the same samples, so they may differ only by float32 rounding.
"""

from __future__ import annotations

import numpy as np
import pytest
import torch
from hypothesis import given, settings
from hypothesis import strategies as st

from pytest_n2r.field.grid import SceneField
from pytest_n2r.field.kernels import BLOCK, march_packed
from pytest_n2r.field.march import MarchGrid, march_compiled, march_dense
from pytest_n2r.geometry import Camera, camera_rays
from pytest_n2r.render.field_render import FieldRenderer, RenderSettings

from ..field.fields import CAMERA, POSES, camera_for, named_pose, pose, random_field
from .strategies import cameras, poses

OUTPUTS = ("rgb", "depth", "opacity")
#: One random field per SH degree for the Hypothesis test (built once).
FIELDS = {0: random_field(sh_degree=0, occupied=0.2, seed=3), 1: random_field(sh_degree=1),
          2: random_field(sh_degree=2, seed=5)}
EXACT = RenderSettings(t_stop=0.0, tail=(), min_alpha=0.0, colour_direction="ray", min_weight=0.0)


def render_both(field: SceneField, c2w: np.ndarray, camera: Camera = CAMERA,
                settings: RenderSettings = EXACT) -> tuple[dict, dict]:
    """``(compiled, torch)`` renders of every output."""
    compiled = FieldRenderer(field, settings.replace(backend="compiled")).render(c2w, camera, OUTPUTS)
    reference = FieldRenderer(field, settings.replace(backend="torch")).render(c2w, camera, OUTPUTS)
    return compiled, reference


def assert_same_render(compiled: dict, reference: dict, what: str, rtol: float = 1e-4) -> None:
    """rgb within one level; depth and opacity to ``rtol`` relative."""
    diff = np.abs(compiled["rgb"].astype(np.int16) - reference["rgb"].astype(np.int16))
    assert diff.max() <= 1, (f"{what}: compiled rgb differs from the torch reference by up to {diff.max()} levels "
                             f"at {int((diff > 1).sum())} of {diff.size} values")
    np.testing.assert_allclose(compiled["depth"], reference["depth"], rtol=rtol, atol=0,
                               err_msg=f"{what}: compiled depth differs from the torch reference")
    np.testing.assert_allclose(compiled["opacity"], reference["opacity"], rtol=rtol, atol=1e-6,
                               err_msg=f"{what}: compiled opacity differs from the torch reference")


#: Relative tolerance of depth and opacity per pose. From a thousand radii away the torch reference loses
#: precision: it forms sample positions ``o + t·d`` in float32 (``t`` comes from the marcher as float32), an
#: error of about ``|o|·2⁻²⁴`` ≈ 1e-4 voxel, while the compiled kernel works in float64. Measured: 1.1e-3
#: relative in opacity (rgb still within one level, depth within 1e-4).
RTOL = {name: 1e-4 for name in POSES} | {"far_away": 3e-3}


@pytest.mark.parametrize("sh_degree", [0, 1, 2])
@pytest.mark.parametrize("pose_name", list(POSES))
def test_compiled_renderer_matches_the_torch_reference(pose_name, sh_degree):
    field = random_field(sh_degree=sh_degree, seed=sh_degree)
    compiled, reference = render_both(field, named_pose(pose_name), camera_for(pose_name))
    assert_same_render(compiled, reference, f"pose {pose_name!r}, sh_degree={sh_degree}", RTOL[pose_name])
    if pose_name != "looking_away":
        assert reference["opacity"].max() > 0.5, (
            f"pose {pose_name!r} sees almost nothing (max opacity {reference['opacity'].max():.3g}): "
            "the comparison would test little")


@pytest.mark.parametrize("pose_name", ["inside", "outside", "far_away"])
def test_the_compiled_renderer_skips_empty_blocks_without_losing_samples(pose_name):
    field = random_field(resolution=33, occupied=0.004, seed=5, density_scale=6.0)
    field.values[:, 0] += 6.0  # the few occupied cells are dense enough to see
    compiled, reference = render_both(field, named_pose(pose_name), camera_for(pose_name))
    assert_same_render(compiled, reference, f"pose {pose_name!r}, 0.4% of cells occupied", RTOL[pose_name])
    assert (reference["opacity"] > 0.1).sum() >= 10, f"pose {pose_name!r} sees fewer than 10 occupied pixels"


@settings(max_examples=30, deadline=None)
@given(eye_target=poses(max_distance=30.0), camera=cameras(max_side=8), sh_degree=st.sampled_from([0, 1, 2]))
def test_the_backends_agree_from_any_pose_within_30_radii(eye_target, camera, sh_degree):
    field = FIELDS[sh_degree]
    compiled, reference = render_both(field, pose(*eye_target), camera)
    assert_same_render(compiled, reference, f"eye {eye_target[0]} towards {eye_target[1]} (normalized), {camera}, "
                                            f"sh_degree={sh_degree}")


def test_agreement_holds_with_a_background_and_a_coarse_shell():
    field = random_field(resolution=20, occupied=0.3, seed=7, density_scale=1.0)
    settings = EXACT.replace(background=(0.2, 0.9, 0.5), shell_samples=3, step_ratio=1.3, far=5.0)
    compiled, reference = render_both(field, named_pose("inside"), settings=settings)
    assert_same_render(compiled, reference, "background (0.2, 0.9, 0.5), shell_samples=3, step_ratio=1.3, far=5")


def rays_of(field: SceneField, c2w: np.ndarray, camera: Camera = CAMERA) -> tuple[torch.Tensor, torch.Tensor]:
    """The camera's rays in the field's normalized space (float32, flattened)."""
    o, d = field.space.normalize_rays(*camera_rays(camera, c2w))
    return torch.from_numpy(o.reshape(-1, 3)), torch.from_numpy(d.reshape(-1, 3))


def random_rays(n: int, seed: int) -> tuple[torch.Tensor, torch.Tensor]:
    """``n`` rays from anywhere within 3 radii in random directions of random length (normalized space)."""
    rng = np.random.default_rng(seed)
    o = rng.uniform(-3.0, 3.0, (n, 3))
    d = rng.normal(size=(n, 3)) * rng.uniform(0.05, 20.0, (n, 1))
    return torch.from_numpy(o.astype(np.float32)), torch.from_numpy(d.astype(np.float32))


def assert_same_samples(o: torch.Tensor, d: torch.Tensor, grid: MarchGrid, what: str) -> int:
    """``march_compiled`` and ``march_dense`` give the same packed samples; returns how many."""
    ray_c, t_c, off_c = march_compiled(o, d, grid)
    ray_d, t_d, off_d = march_dense(o, d, grid)
    counts_c, counts_d = torch.diff(off_c), torch.diff(off_d)
    bad = torch.nonzero(counts_c != counts_d).reshape(-1)
    assert bad.numel() == 0, (
        f"{what}: {bad.numel()} of {len(counts_c)} rays get a different number of samples from the compiled "
        f"marcher; first ray {int(bad[0])}: compiled {int(counts_c[bad[0]])}, dense {int(counts_d[bad[0]])} "
        f"(o={o[bad[0]].tolist()}, d={d[bad[0]].tolist()})" if bad.numel() else "")
    assert torch.equal(ray_c, ray_d), f"{what}: the samples' ray indices differ"
    np.testing.assert_allclose(t_c.numpy(), t_d.numpy(), rtol=1e-5, atol=0,
                               err_msg=f"{what}: sample t differs between march_compiled and march_dense")
    return int(off_c[-1])


@pytest.mark.parametrize("occupied", [0.5, 0.001])
@pytest.mark.parametrize("pose_name", list(POSES))
def test_march_compiled_gives_the_dense_samples(pose_name, occupied):
    field = random_field(resolution=33, occupied=occupied, seed=3)
    grid = MarchGrid(field.occupancy, field.space.shell, 0.5, None, 100.0)
    o, d = rays_of(field, named_pose(pose_name), camera_for(pose_name))
    assert_same_samples(o, d, grid, f"pose {pose_name!r}, {occupied:.1%} of cells occupied")


@pytest.mark.parametrize("occupied", [0.5, 0.0005])
def test_block_skipping_drops_no_occupied_sample_on_random_rays(occupied):
    field = random_field(resolution=41, occupied=occupied, seed=11)
    grid = MarchGrid(field.occupancy, field.space.shell, 0.7, 5, 20.0)
    _, blocks = grid.numpy()
    if occupied < 0.01:
        assert 0.05 < blocks.mean() < 0.5, (f"{blocks.mean():.0%} of the 8³ blocks are occupied; this test needs "
                                            "empty blocks between occupied ones")
    o, d = random_rays(4000, seed=int(occupied * 1000))
    n = assert_same_samples(o, d, grid, f"4000 random rays, {occupied:.1%} of cells occupied")
    assert n > 0, "no ray took a sample: the comparison tested nothing"



@pytest.mark.parametrize("groups", [1, 3, 4000])
def test_the_march_packs_the_same_samples_however_its_rays_are_shared_out(groups):
    # each thread marches its range of rays into its own part of a scratch buffer; the joined result must
    # not depend on how many parts there were
    field = random_field(resolution=41, occupied=0.05, seed=2)
    grid = MarchGrid(field.occupancy, field.space.shell, 0.5, 4, 20.0)
    cells, blocks = grid.numpy()
    o, d = (x.numpy() for x in random_rays(4000, seed=groups))
    args = (o, d, cells, blocks, grid.resolution, grid.shell, grid.step, grid.shell_samples, grid.far)
    counts_1, t_1 = march_packed(*args, np.array([0, 4000]))
    counts, t = march_packed(*args, np.linspace(0, 4000, groups + 1).round().astype(np.int64))
    assert t_1.size > 0, "no ray took a sample: the comparison tested nothing"
    np.testing.assert_array_equal(counts, counts_1, err_msg=f"sample counts change when {groups} parts march")
    np.testing.assert_array_equal(t, t_1, err_msg=f"packed t change when {groups} parts march")

def test_a_single_occupied_cell_is_found_behind_empty_blocks():
    """Rays through the middle of one occupied cell far from others must sample it, from every side."""
    field = random_field(resolution=41, occupied=0.0)
    cell = (13, 27, 9)  # in a block of its own, the rest empty
    field.occupancy[cell] = True
    grid = MarchGrid(field.occupancy, field.space.shell, 0.5, 4, 20.0)
    voxel = field.space.voxel_size(41)
    centre = -field.space.half_size + (np.asarray(cell) + 0.5) * voxel
    rng = np.random.default_rng(5)
    dirs = rng.normal(size=(500, 3))
    dirs /= np.linalg.norm(dirs, axis=1, keepdims=True)
    jitter = rng.uniform(-0.2, 0.2, (500, 3)) * voxel
    o = torch.from_numpy((centre + jitter - 2.5 * dirs).astype(np.float32))
    d = torch.from_numpy(dirs.astype(np.float32))
    ray_c, _, _ = march_compiled(o, d, grid)
    hit = torch.bincount(ray_c, minlength=500)
    assert (hit > 0).all(), f"{int((hit == 0).sum())} of 500 rays through the only occupied cell took no sample in it"
    assert_same_samples(o, d, grid, "rays through a lone occupied cell")
    _, blocks = grid.numpy()
    assert int(blocks.sum()) == 1, f"{int(blocks.sum())} occupied {BLOCK}³ blocks; expected only the lone cell's"
