"""The compiled renderer's shortcuts: colour logits baked per frame at the vertices (kept across frames where
they do not depend on the camera), and colour only where a sample carries weight (each within its stated bound)."""

from __future__ import annotations

import numpy as np
import pytest
import torch

from pytest_n2r.field.grid import SceneField
from pytest_n2r.field.lattice import contract
from pytest_n2r.field.march import march_dense
from pytest_n2r.field.query import sh_basis
from pytest_n2r.geometry import Camera
from pytest_n2r.render.field_kernels import bake_logits
from pytest_n2r.render.field_render import FieldRenderer, RenderSettings, render_rays_torch

from ..field.fields import CAMERA, SPACE, camera_for, named_pose, pose, random_field
from .test_agreement import rays_of

EXACT = RenderSettings(t_stop=0.0, tail=(), min_alpha=0.0, colour_direction="ray", min_weight=0.0, adaptive=0.0,
                       backend="compiled")


@pytest.mark.parametrize("min_weight", [1e-2, 5e-2])
@pytest.mark.parametrize("pose_name", ["inside", "outside"])
def test_colouring_only_weighty_samples_stays_within_the_light_samples_weight(pose_name, min_weight):
    """Each channel may move by at most the summed weight of the ray's samples lighter than ``min_weight``."""
    field = random_field(resolution=16, density_scale=1.5, seed=4)
    c2w = named_pose(pose_name)
    exact = FieldRenderer(field, EXACT).render(c2w, CAMERA, ("rgb",))["rgb"].astype(np.float64)
    fast = FieldRenderer(field, EXACT.replace(min_weight=min_weight)).render(c2w, CAMERA, ("rgb",))["rgb"]
    reference = FieldRenderer(field, EXACT.replace(backend="torch"))
    o, d = rays_of(field, c2w)
    marched = march_dense(o, d, reference.grid)
    ray_idx = marched[0]
    with torch.no_grad():
        weights = render_rays_torch(field, reference.grid, o, d, torch.zeros(3), False, marched)["weights"]
    light = torch.where(weights < min_weight, weights, torch.zeros_like(weights)).double()
    bound = torch.zeros(o.shape[0], dtype=torch.float64).index_add(0, ray_idx, light).numpy()
    error = np.abs(fast.astype(np.float64) - exact).reshape(-1, 3).max(axis=1)
    allowed = 255.0 * bound + 1.0  # one level of rounding on each side of the uint8 images
    assert (error <= allowed).all(), (
        f"min_weight={min_weight}: {int((error > allowed).sum())} pixels off by more than their bound; worst "
        f"{error.max():.0f} levels where {allowed[error.argmax()]:.1f} were allowed")
    assert error.max() >= 1 and bound.max() > 0.01, "no pixel changed: the bound was not put to the test"


@pytest.mark.parametrize("seed", range(4))
@pytest.mark.parametrize("sh_degree", [1, 2])
def test_baked_vertex_colours_match_ray_colours_where_a_cell_subtends_no_angle(sh_degree, seed):
    """From a thousand radii away (telephoto) the direction to a vertex is the ray's: within one level. Not in
    the contracted shell's outermost layer of cells, which reaches infinity and so subtends large angles from
    any camera outside the scene (its vertices take their direction from the scene's centre): with it, degree-1
    fields of seeds 0 and 5 differed by 28 and 48 levels (measured), so this field leaves it empty."""
    field = random_field(resolution=16, sh_degree=sh_degree, seed=seed)
    outermost = torch.zeros_like(field.occupancy)
    outermost[[0, -1]] = outermost[:, [0, -1]] = outermost[:, :, [0, -1]] = True
    field.occupancy &= ~outermost
    c2w, camera = named_pose("far_away"), camera_for("far_away")
    exact = FieldRenderer(field, EXACT).render(c2w, camera, ("rgb",))["rgb"].astype(np.int16)
    baked = FieldRenderer(field, EXACT.replace(colour_direction="vertex")).render(c2w, camera, ("rgb",))["rgb"]
    diff = np.abs(baked.astype(np.int16) - exact)
    assert diff.max() <= 1, (f"sh_degree={sh_degree}, seed {seed}: baked colours differ by up to {diff.max()} "
                             "levels from a thousand radii away")


@pytest.mark.parametrize("pose_name", ["inside", "in_shell"])
def test_baked_colours_of_a_degree_0_field_are_exact_and_degree_1_moves_them(pose_name):
    """A degree-0 colour has no direction. A degree-1 colour moves by the angle a cell subtends: on this 16³
    field of unit-normal SH coefficients, seen from inside, cells subtend up to tens of degrees and the
    renders differ by up to 9 (inside) and 8 (in the shell) levels, measured; the test allows 16. A fitted
    field at 160³ seen from its capture poses differs far less (fox: 65.8 dB, docs/performance-log.md)."""
    c2w = named_pose(pose_name)
    flat = random_field(resolution=16, sh_degree=0, seed=6)
    exact = FieldRenderer(flat, EXACT).render(c2w, CAMERA, ("rgb",))["rgb"].astype(np.int16)
    baked = FieldRenderer(flat, EXACT.replace(colour_direction="vertex")).render(c2w, CAMERA, ("rgb",))["rgb"]
    assert np.abs(baked - exact).max() <= 1, "a degree-0 field's baked colours differ from its exact ones"
    shiny = random_field(resolution=16, sh_degree=1, seed=6)
    exact = FieldRenderer(shiny, EXACT).render(c2w, CAMERA, ("rgb",))["rgb"].astype(np.int16)
    baked = FieldRenderer(shiny, EXACT.replace(colour_direction="vertex")).render(c2w, CAMERA, ("rgb",))["rgb"]
    diff = np.abs(baked - exact)
    assert 1 < diff.max() <= 16, (f"pose {pose_name!r}: baked colours of a degree-1 field differ by up to "
                                  f"{diff.max()} levels from exact ones; expected a visible change of at most 16")


@pytest.mark.parametrize("sparse", [False, True])
def test_a_frame_bakes_each_vertex_from_its_uncontracted_position(sparse):
    """``vertex_positions``: contracting the position a vertex's colour direction is taken from gives the vertex's
    own lattice position back, and exactly the vertices on the shell's outer face (which stand for infinity) are
    flagged, their position that face point (a direction, not a place)."""
    field = random_field(resolution=12, sh_degree=1, occupied=0.3, seed=5)
    field = field.compact() if sparse else field
    renderer = FieldRenderer(field, RenderSettings(backend="compiled"))
    res, shell = renderer.grid.resolution, renderer.grid.shell
    rows = field.kernel_rows()
    vertex = np.flatnonzero(rows >= 0) if rows.shape[0] else np.arange(res ** 3)
    row = rows[vertex] if rows.shape[0] else vertex
    assert (rows.shape[0] > 0) == sparse and row.size == renderer._position.shape[1], "not the field asked for"
    half = 1.0 + shell
    lattice = np.stack(np.unravel_index(vertex, (res,) * 3), axis=1) * (2.0 * half / (res - 1)) - half
    position, outer = renderer._position[:, row].T, renderer._outer[row]
    on_face = np.abs(lattice).max(axis=1) >= half - 1e-9
    assert np.array_equal(outer, on_face), f"{int((outer != on_face).sum())} vertices flagged wrongly as at infinity"
    back = contract(torch.from_numpy(position[~outer]), shell).numpy()
    np.testing.assert_allclose(back, lattice[~outer], rtol=0, atol=1e-12,
                               err_msg="a vertex's position does not contract to its lattice position")
    np.testing.assert_array_equal(position[outer], lattice[outer], err_msg="an outer vertex's direction moved")


@pytest.mark.parametrize("sh_degree", [1, 2])
def test_a_frames_bake_is_the_sh_colour_from_the_camera_to_each_vertex(sh_degree):
    """``bake_logits`` (column by column, branch-free) gives each stored vertex the SH colour logits of the direction
    from the camera to it (:func:`~pytest_n2r.field.query.sh_basis`, float64), and a vertex at the camera centre,
    which has no direction, its direction-free colour."""
    field = random_field(resolution=12, sh_degree=sh_degree, occupied=0.3, seed=6).compact()
    renderer = FieldRenderer(field, RenderSettings(backend="compiled"))
    position, outer = renderer._position, renderer._outer
    inner = np.flatnonzero(~outer)
    origin = position[:, inner[inner.size // 2]].copy()  # the camera stands on this vertex
    logits = np.empty((outer.size, 3), dtype=np.float32)
    bake_logits(0, outer.size, renderer._colour, position, outer, origin, sh_degree, logits)
    direction = position.T - np.where(outer[:, None], 0.0, origin)
    norm = np.linalg.norm(direction, axis=1, keepdims=True)
    unit = torch.from_numpy(np.divide(direction, norm, out=np.zeros_like(direction), where=norm > 0))
    basis = sh_basis(unit, sh_degree).numpy()
    basis[norm[:, 0] == 0, 1:] = 0.0
    values = field.values.detach().double().numpy()
    expected = np.einsum("nl,nlc->nc", basis, values[:, 1:].reshape(values.shape[0], -1, 3))
    assert (norm == 0).sum() == 1 and np.isfinite(logits).all(), "the vertex at the camera centre got no finite colour"
    np.testing.assert_allclose(logits.astype(np.float64), expected, rtol=1e-5, atol=1e-5,
                               err_msg="a baked logit is not the SH colour seen from the camera")


@pytest.mark.parametrize("sh_degree", [0, 1, 2])
def test_a_renderer_kept_across_frames_renders_what_a_fresh_one_does(sh_degree):
    """A degree-0 field's logits are baked on the first frame and kept (they do not depend on the camera); a
    view-dependent field's are baked for each frame. Either way frame after frame from one renderer matches, to the bit,
    a fresh renderer for each pose."""
    field = random_field(resolution=16, sh_degree=sh_degree, seed=8)
    settings = RenderSettings(backend="compiled")
    kept = FieldRenderer(field, settings)
    for name in ("outside", "inside", "in_shell"):
        c2w = named_pose(name)
        again = kept.render(c2w, CAMERA, ("rgb", "depth", "opacity"))
        fresh = FieldRenderer(field, settings).render(c2w, CAMERA, ("rgb", "depth", "opacity"))
        differ = [k for k in fresh if not np.array_equal(again[k], fresh[k])]
        assert not differ, f"SH degree {sh_degree}, pose {name!r}: {differ} differ from a fresh renderer's"
    assert (kept._fixed_logits is not None) == (sh_degree == 0), (
        f"SH degree {sh_degree}: logits kept across frames: {kept._fixed_logits is not None}")


@pytest.mark.parametrize("tail", [(0.3,), (0.3, 0.1), (0.5, 0.2, 0.05)])
@pytest.mark.parametrize("pose_name", ["inside", "outside"])
def test_coarser_tail_stays_within_the_transmittance_where_it_starts(pose_name, tail):
    """Behind the first threshold crossed a ray's samples get coarser; what lies there adds at most the ray's
    transmittance at that point to a channel (and to opacity) in either render, so that is each pixel's bound."""
    field = random_field(resolution=16, density_scale=1.5, seed=4)
    c2w = named_pose(pose_name)
    outputs = ("rgb", "opacity")
    exact = FieldRenderer(field, EXACT).render(c2w, CAMERA, outputs)
    fast = FieldRenderer(field, EXACT.replace(tail=tail)).render(c2w, CAMERA, outputs)
    reference = FieldRenderer(field, EXACT.replace(backend="torch"))
    o, d = rays_of(field, c2w)
    marched = march_dense(o, d, reference.grid)
    with torch.no_grad():
        weights = render_rays_torch(field, reference.grid, o, d, torch.zeros(3), False, marched)["weights"].double()
    ray_idx, offsets = marched[0], marched[2]
    # transmittance after each sample (1 - the ray's weight so far); the bound: the first (largest) below tail[0]
    cumulative = torch.cumsum(weights, 0)
    start = torch.cat([torch.zeros(1, dtype=torch.float64), cumulative])[offsets[:-1]]
    after = 1.0 - (cumulative - start[ray_idx])
    below = torch.where(after < tail[0], after, torch.full_like(after, -1.0))
    bound = np.zeros(o.shape[0])
    np.maximum.at(bound, ray_idx.numpy(), below.numpy())
    error = np.abs(fast["rgb"].astype(np.float64) - exact["rgb"]).reshape(-1, 3).max(axis=1)
    allowed = 255.0 * bound + 1.0  # one level of rounding on each side of the uint8 images
    assert (error <= allowed).all(), (
        f"tail={tail}: {int((error > allowed).sum())} pixels off by more than their bound; worst "
        f"{error.max():.0f} levels where {allowed[error.argmax()]:.1f} were allowed")
    opacity_error = np.abs(fast["opacity"].astype(np.float64) - exact["opacity"]).ravel()
    assert (opacity_error <= bound + 1e-6).all(), f"tail={tail}: opacity moved by up to {opacity_error.max():.4f}"
    assert error.max() >= 1 and bound.max() > 0.05, "no pixel changed: the bound was not put to the test"


def test_coarser_tail_is_exact_in_a_homogeneous_field():
    """In a field of constant density a sample standing for n lattice steps absorbs exactly what the n steps do,
    inside the cube and in the shell, up to the lattice's end: the opacity of a ray through the whole field."""
    flat = SceneField.empty(SPACE, 16, sh_degree=0, alpha=0.12, step_ratio=0.5)
    camera = Camera(3, 3, 1000.0, 1000.0, 1.0, 1.0)
    c2w = pose((0.0, 0.0, -3.0), (0.0, 0.0, 0.0))
    exact = FieldRenderer(flat, EXACT).render(c2w, camera, ("opacity",))["opacity"]
    fast = FieldRenderer(flat, EXACT.replace(tail=(0.5, 0.3, 0.1))).render(c2w, camera, ("opacity",))["opacity"]
    assert exact.min() > 0.9, f"opacity {exact.min():.3f}: the ray never crossed the thresholds"
    np.testing.assert_allclose(fast, exact, rtol=0, atol=1e-6,
                               err_msg="a coarser tail changed the opacity of a homogeneous field")
