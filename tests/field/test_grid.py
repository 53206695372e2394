"""SceneField: density convention, refinement (upsampling) and the stored form (quantized tensors)."""

from __future__ import annotations

import numpy as np
import pytest
import torch
import torch.nn.functional as F

from pytest_n2r.errors import InvalidArgument, SceneFileError
from pytest_n2r.field.grid import SceneField, n_sh_coefficients
from pytest_n2r.geometry import Camera
from pytest_n2r.metrics.image_quality import psnr
from pytest_n2r.render.field_render import FieldRenderer, RenderSettings

from .fields import CAMERA, SPACE, named_pose, pose, random_field


def smooth_field(resolution: int = 16) -> SceneField:
    """A field whose density and colour coefficients are smooth functions of position (a few waves across
    the grid): refining it should change its renders only by quadrature error."""
    field = SceneField.empty(SPACE, resolution, sh_degree=1, alpha=0.05, step_ratio=0.5)
    q = torch.linspace(-SPACE.half_size, SPACE.half_size, resolution)
    x, y, z = (c.reshape(-1) for c in torch.meshgrid(q, q, q, indexing="ij"))
    field.values[:, 0] = 2.0 * torch.sin(2 * x) * torch.cos(1.5 * y) + z
    for c in range(1, field.values.shape[1]):
        field.values[:, c] = torch.sin(c + x * (1 + c % 3) - y * (c % 2) + 0.5 * z)
    return field


def test_an_empty_field_has_the_asked_opacity_per_sample_everywhere():
    field = SceneField.empty(SPACE, 12, sh_degree=0, alpha=0.03, step_ratio=0.7)
    alpha = field.cell_alpha(0.7)
    torch.testing.assert_close(alpha, torch.full_like(alpha, 0.03), rtol=1e-5, atol=0,
                               msg=lambda m: f"SceneField.empty(alpha=0.03): cell opacity per sample {m}")
    assert field.occupancy.all(), "an empty field must start with every cell occupied"


@pytest.mark.parametrize("resolution", [31, 24])
@pytest.mark.parametrize("pose_name", ["outside", "inside", "in_shell"])
def test_upsampling_a_smooth_field_keeps_its_render(pose_name, resolution):
    """Measured PSNR between the renders before and after: 41-62 dB (31: the old vertices are kept, 24: not)."""
    field = smooth_field()
    c2w = named_pose(pose_name)
    fine = RenderSettings(step_ratio=0.5)  # compare the fields, not two sample spacings
    before = FieldRenderer(field, fine).render(c2w, CAMERA, ("rgb", "opacity"))
    after = FieldRenderer(field.upsampled(resolution), fine).render(c2w, CAMERA, ("rgb", "opacity"))
    score = psnr(before["rgb"], after["rgb"])
    assert score > 35.0, f"pose {pose_name!r}: upsampling 16 → {resolution} changed the render ({score:.1f} dB)"
    change = float(np.abs(before["opacity"] - after["opacity"]).mean())
    assert change < 0.02, f"pose {pose_name!r}: upsampling 16 → {resolution} changed opacity by {change:.3f} on average"


def test_upsampling_keeps_opacity_per_unit_length():
    """At the vertices both grids share, the density per normalized length is unchanged; over one coarse
    voxel, a homogeneous field's opacity is unchanged."""
    field = smooth_field()
    fine = field.upsampled(31)  # vertex 2i of the fine grid is vertex i of the coarse one
    ratio = 2.0
    coarse_sigma = F.softplus(field.vertex_grid()[0] + field.density_shift)
    fine_sigma = F.softplus(fine.vertex_grid()[0, ::2, ::2, ::2] + fine.density_shift) * ratio
    torch.testing.assert_close(fine_sigma, coarse_sigma, rtol=1e-4, atol=1e-6,
                               msg=lambda m: f"density per unit length at shared vertices changed: {m}")
    flat = SceneField.empty(SPACE, 16, sh_degree=0, alpha=0.2, step_ratio=0.5)
    for resolution in (31, 24, 61):
        ratio = (resolution - 1) / 15
        alpha = flat.upsampled(resolution).cell_alpha(0.5 * ratio)  # the same length: one coarse half-voxel
        torch.testing.assert_close(alpha, torch.full_like(alpha, 0.2), rtol=1e-4, atol=0,
                                   msg=lambda m, r=resolution: f"16 → {r}: opacity over the same length changed: {m}")
    camera = Camera(3, 3, 1000.0, 1000.0, 1.0, 1.0)
    c2w = pose((0.0, 0.0, -3.0), (0.0, 0.0, 0.0))
    exact = RenderSettings(t_stop=0.0)
    opacity = [FieldRenderer(f, exact).render(c2w, camera, ("opacity",))["opacity"][1, 1]
               for f in (flat, flat.upsampled(31))]
    assert abs(opacity[0] - opacity[1]) < 1e-5, f"a ray through a homogeneous field: opacity {opacity[0]} → {opacity[1]}"


def test_upsampling_keeps_occupied_cells_and_dilates_by_one_cell():
    field = random_field(resolution=9, occupied=0.1, seed=4)
    fine = field.upsampled(17)  # fine cell (2i + a) lies in coarse cell i
    coarse_of_fine = field.occupancy.repeat_interleave(2, 0).repeat_interleave(2, 1).repeat_interleave(2, 2)
    lost = coarse_of_fine & ~fine.occupancy
    assert not lost.any(), f"{int(lost.sum())} fine cells inside occupied coarse cells are not occupied"
    dilated = F.max_pool3d(coarse_of_fine[None, None].float(), 3, 1, 1)[0, 0] > 0
    assert torch.equal(fine.occupancy, dilated), (
        f"occupancy after upsampling is not the coarse one dilated by one fine cell "
        f"({int((fine.occupancy != dilated).sum())} cells differ)")


@pytest.mark.parametrize("sh_degree", [0, 1])
def test_tensors_round_trip_to_the_quantized_field(sh_degree):
    field = random_field(resolution=12, sh_degree=sh_degree, occupied=0.3, seed=9)
    quantized = field.quantized()
    back = SceneField.from_tensors(field.metadata(), field.tensors())
    assert back.values.numpy().tobytes() == quantized.values.numpy().tobytes(), \
        "from_tensors(tensors()) values differ from quantized()"
    assert torch.equal(back.occupancy, field.occupancy), "occupancy changed through tensors()"
    assert back.metadata() == field.metadata(), f"metadata {back.metadata()} != {field.metadata()}"
    unused = ~field.used_vertices()
    assert unused.any() and not back.values[unused].any(), "vertices of no occupied cell must be stored as zeros"
    used = ~unused
    err = float((field.values[used] - back.values[used]).abs().max())
    assert err <= 1e-3 * float(field.values.abs().max()), f"float16 storage changed used values by {err}"
    c2w = named_pose("outside")
    for name in ("rgb", "depth", "opacity"):
        a = FieldRenderer(back).render(c2w, CAMERA, (name,))[name]
        b = FieldRenderer(quantized).render(c2w, CAMERA, (name,))[name]
        assert a.tobytes() == b.tobytes(), f"the reloaded field renders {name} differently from quantized()"


def _broken(change: str) -> tuple[dict, dict]:
    field = random_field(resolution=8, occupied=0.5, seed=1)
    meta, tensors = field.metadata(), field.tensors()
    if change == "nan":
        tensors["vertex_values"][3, 1] = float("nan")
    elif change == "index outside":
        tensors["vertex_index"][-1] = 8 ** 3
    elif change == "index not the used vertices":
        tensors["vertex_index"] = tensors["vertex_index"].flip(0)
    elif change == "sh_degree":
        meta["sh_degree"] = 3
    elif change == "metadata":
        del meta["density_shift"]
    elif change == "background":
        meta["background"] = [0.5, 2.0, 0.5]
    elif change == "no background":
        del meta["background"]
    return meta, tensors


@pytest.mark.parametrize("change, message", [
    ("nan", r"tensor 'vertex_values' holds NaN or Inf"),
    ("index outside", r"tensor 'vertex_index' points outside the 8³ grid"),
    ("index not the used vertices", r"'vertex_index' does not list exactly the vertices of occupied cells"),
    ("sh_degree", r"sh_degree=3: expected 0 \(view-independent colour\) or 1"),
    ("metadata", r"field metadata is incomplete or invalid \('density_shift'\)"),
    ("background", r"field background \[0.5, 2.0, 0.5\] is not three values in \[0, 1\]"),
    ("no background", r"field metadata is incomplete or invalid \('background'\)"),
])
def test_bad_field_tensors_are_scene_file_errors_naming_the_problem(change, message):
    meta, tensors = _broken(change)
    with pytest.raises(SceneFileError, match=r"^bad\.n2r: " + message):
        SceneField.from_tensors(meta, tensors, source="bad.n2r")


@pytest.mark.parametrize("rows, width, occupancy, message", [
    (100, 13, (3, 3, 3), r"values has 100 rows; expected resolution³ rows"),
    (64, 13, (3, 3, 3), r"values has shape \(64, 13\); expected \(64, 4\) for sh_degree=0"),
    (64, 4, (4, 4, 4), r"occupancy has shape \(4, 4, 4\); expected \(3, 3, 3\)"),
])
def test_inconsistent_field_arrays_are_named(rows, width, occupancy, message):
    with pytest.raises(InvalidArgument, match=message):
        SceneField(SPACE, torch.zeros(rows, width), torch.ones(occupancy, dtype=torch.bool), 0.0, 0)
    with pytest.raises(InvalidArgument, match=r"sh_degree=2: expected 0"):
        n_sh_coefficients(2)
