"""SceneField: density convention, refinement (upsampling) and the stored form (quantized tensors)."""

from __future__ import annotations

import numpy as np
import pytest
import torch
import torch.nn.functional as F
from hypothesis import given, settings
from hypothesis import strategies as st

from pytest_n2r.errors import InvalidArgument, SceneFileError
from pytest_n2r.field.grid import SceneField, _cell_corners, n_sh_coefficients, used_vertex_index, used_vertex_mask
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
    coarse_sigma = F.softplus(field.density_grid() + field.density_shift)
    fine_sigma = F.softplus(fine.density_grid()[::2, ::2, ::2] + fine.density_shift) * ratio
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
    assert abs(opacity[0] - opacity[1]) < 1e-5, \
        f"a ray through a homogeneous field: opacity {opacity[0]} → {opacity[1]}"


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


@given(cells=st.integers(1, 9), fraction=st.sampled_from([0.0, 0.02, 0.3, 1.0]), seed=st.integers(0, 2**31 - 1))
def test_used_vertices_are_exactly_the_corners_of_occupied_cells(cells, fraction, seed):
    """The dilation that finds the used vertices gives the sorted unique corners of the occupied cells."""
    occupancy = torch.rand((cells,) * 3, generator=torch.Generator().manual_seed(seed)) < fraction
    expected = torch.unique(_cell_corners(occupancy))
    got = used_vertex_index(occupancy)
    assert got.dtype == torch.int64 and torch.equal(got, expected), (
        f"{cells}³ cells, {int(occupancy.sum())} occupied: used vertices {got.tolist()} != corners "
        f"{expected.tolist()}")


@pytest.mark.parametrize("sparse", [False, True], ids=["dense", "sparse"])
def test_row_vertices_inverts_vertex_rows(sparse):
    field = random_field(resolution=10, sh_degree=0, occupied=0.3, seed=4)
    if sparse:
        field = SceneField.from_tensors(field.metadata(), field.tensors())
    flat = field.row_vertices()
    assert flat.shape == (field.values.shape[0],) and flat.dtype == torch.int64, (
        f"row_vertices() is {tuple(flat.shape)} {flat.dtype}; expected ({field.values.shape[0]},) int64")
    rows = field.vertex_rows(flat)
    assert torch.equal(rows, torch.arange(field.values.shape[0])), (
        f"vertex_rows(row_vertices()) is not each row itself: first mismatch at row "
        f"{int((rows != torch.arange(rows.numel())).nonzero()[0])}")


@pytest.mark.parametrize("sh_degree", [0, 1, 2])
def test_tensors_round_trip_to_the_quantized_field(sh_degree):
    field = random_field(resolution=12, sh_degree=sh_degree, occupied=0.3, seed=9)
    quantized = field.quantized()
    back = SceneField.from_tensors(field.metadata(), field.tensors())
    assert back.values.numpy().tobytes() == quantized.values.numpy().tobytes(), \
        "from_tensors(tensors()) values differ from quantized()"
    assert torch.equal(back.occupancy, field.occupancy), "occupancy changed through tensors()"
    assert back.metadata() == field.metadata(), f"metadata {back.metadata()} != {field.metadata()}"
    used = field.used_vertex_index()
    assert back.is_sparse and back.values.shape[0] == used.numel() < 12 ** 3, (
        f"the reloaded field stores {back.values.shape[0]} rows; expected one per used vertex "
        f"({used.numel()})")
    assert torch.equal(back.rows >= 0, field.used_vertices()), "the stored vertices are not the used ones"
    err = float((field.values[used] - back.values[back.vertex_rows(used)]).abs().max())
    assert err <= 1e-3 * float(field.values.abs().max()), f"float16 storage changed used values by {err}"
    c2w = named_pose("outside")
    for name in ("rgb", "depth", "opacity"):
        a = FieldRenderer(back).render(c2w, CAMERA, (name,))[name]
        b = FieldRenderer(quantized).render(c2w, CAMERA, (name,))[name]
        assert a.tobytes() == b.tobytes(), f"the reloaded field renders {name} differently from quantized()"


@pytest.mark.parametrize("backend", ["compiled", "torch"])
@pytest.mark.parametrize("pose_name", ["outside", "inside"])
def test_a_sparse_field_renders_exactly_like_the_dense_one(backend, pose_name):
    """``compact()`` keeps the vertices of occupied cells, the only ones a render reads: same bytes."""
    dense = random_field(resolution=14, occupied=0.05, seed=3)
    sparse = dense.compact()
    assert sparse.is_sparse and sparse.values.shape[0] < dense.values.shape[0] / 2, (
        f"compact() kept {sparse.values.shape[0]} of {dense.values.shape[0]} rows at 5 % occupancy")
    c2w = named_pose(pose_name)
    settings = RenderSettings(backend=backend)
    a = FieldRenderer(dense, settings).render(c2w, CAMERA, ("rgb", "depth", "opacity"))
    b = FieldRenderer(sparse, settings).render(c2w, CAMERA, ("rgb", "depth", "opacity"))
    for name in a:
        assert a[name].tobytes() == b[name].tobytes(), (
            f"{backend}, {pose_name}: sparse {name} differs from dense")
    expected = dense.cell_alpha(0.5)[dense.occupancy]
    for name, got in (("sparse cell_alpha", sparse.cell_alpha(0.5)[dense.occupancy]),
                      ("dense occupied_cell_alpha", dense.occupied_cell_alpha(0.5)),
                      ("sparse occupied_cell_alpha", sparse.occupied_cell_alpha(0.5))):
        assert torch.equal(got, expected), f"{name} differs from the dense cell_alpha of the occupied cells"


@settings(max_examples=40, deadline=None)
@given(coarse=st.integers(4, 14), finer=st.integers(0, 40), fraction=st.sampled_from([0.0, 0.03, 0.3, 1.0]),
       seed=st.integers(0, 2**16))
def test_the_upsampled_occupancy_is_the_nearest_cell_dilated_as_torch_defines_them(coarse, finer, fraction, seed):
    """In bools, index by index: the same cells as ``F.interpolate(nearest)`` then a 3³ ``max_pool3d``, which
    took 17 bytes a fine cell (1 GB at 384³) to size a grid that might not fit."""
    field = random_field(resolution=coarse, occupied=fraction, seed=seed)
    fine = coarse + finer
    occ = F.interpolate(field.occupancy[None, None].float(), size=(fine - 1,) * 3, mode="nearest")
    expected = F.max_pool3d(occ, kernel_size=3, stride=1, padding=1)[0, 0] > 0
    got = field.upsampled_occupancy(fine)
    assert torch.equal(got, expected), f"{coarse}³ → {fine}³: {int((got != expected).sum())} cells differ"


@settings(max_examples=25, deadline=None)
@given(resolution=st.integers(4, 10), finer=st.integers(11, 24), chunk=st.integers(1, 300),
       seed=st.integers(0, 2**16), sh_degree=st.sampled_from([0, 1, 2]))
def test_upsampling_a_chunk_at_a_time_gives_the_same_field_to_the_bit(resolution, finer, chunk, seed, sh_degree):
    field = random_field(resolution=resolution, sh_degree=sh_degree, occupied=0.3, seed=seed).compact()
    whole = field.upsampled(finer, chunk=10**9)
    parts = field.upsampled(finer, chunk=chunk)
    assert torch.equal(whole.occupancy, parts.occupancy) and torch.equal(whole.rows, parts.rows)
    assert torch.equal(whole.values, parts.values), f"values differ when upsampled {chunk} vertices at a time"
    assert torch.equal(whole.rows >= 0, used_vertex_mask(field.upsampled_occupancy(finer)).reshape(-1)), \
        "the vertices counted to size a grid are not those upsampling stores"


def test_a_bad_upsampling_chunk_is_named():
    with pytest.raises(InvalidArgument, match="chunk=0: expected a number of vertices >= 1"):
        random_field(resolution=8).upsampled(12, chunk=0)


def test_upsampling_a_sparse_field_keeps_its_stored_values():
    """A sparse field refines like a dense one: at the vertices the grids share, every vertex the coarse field
    stores is stored by the fine one with the same density per unit length and the same colour."""
    field = smooth_field()
    field.occupancy[:, :, 8:] = False  # half the cube empty: the refined fields store only the other half
    once = field.upsampled(31)
    twice = once.upsampled(61)  # vertex 2i of `twice` is vertex i of `once`
    assert twice.is_sparse and twice.values.shape[0] < 0.6 * 61 ** 3, (
        f"the refined field stores {twice.values.shape[0]} of {61 ** 3} vertices; expected about half")
    coarse, fine = once.density_grid(), twice.density_grid()[::2, ::2, ::2]
    stored = torch.isfinite(coarse)
    assert stored.any() and torch.isfinite(fine[stored]).all(), (
        "a vertex stored by the coarse field was dropped")
    torch.testing.assert_close(F.softplus(fine[stored] + twice.density_shift) * 2.0,
                               F.softplus(coarse[stored] + once.density_shift), rtol=1e-4, atol=1e-6,
                               msg=lambda m: f"density per unit length at shared vertices changed: {m}")
    i, j, k = (c.reshape(-1) for c in torch.meshgrid(*(torch.arange(31),) * 3, indexing="ij"))
    coarse_flat = (i * 31 + j) * 31 + k
    fine_flat = (2 * i * 61 + 2 * j) * 61 + 2 * k
    keep = once.vertex_rows(coarse_flat) >= 0
    torch.testing.assert_close(twice.values[twice.vertex_rows(fine_flat[keep]), 1:],
                               once.values[once.vertex_rows(coarse_flat[keep]), 1:],
                               msg=lambda m: f"colour at shared stored vertices changed: {m}")


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
    ("sh_degree", r"field\.sh_degree=3; expected 0, 1 or 2"),
    ("metadata", r"field metadata is incomplete or invalid \('density_shift'\)"),
    ("background", r"field\.background=\[0.5, 2.0, 0.5\]; expected three values in \[0, 1\]"),
    ("no background", r"field metadata is incomplete or invalid \('background'\)"),
])
def test_bad_field_tensors_are_scene_file_errors_naming_the_problem(change, message):
    meta, tensors = _broken(change)
    with pytest.raises(SceneFileError, match=r"^bad\.n2r: " + message):
        SceneField.from_tensors(meta, tensors, source="bad.n2r")


@pytest.mark.parametrize("rows, width, occupancy, message", [
    (100, 4, (3, 3, 3), r"values has 100 rows; a dense field of occupancy \(3, 3, 3\) has resolution³ = 64"),
    (64, 13, (3, 3, 3), r"values has shape \(64, 13\); expected \(64, 4\) for sh_degree=0"),
    (64, 4, (4, 4, 3), r"occupancy has shape \(4, 4, 3\); expected \(R-1, R-1, R-1\)"),
])
def test_inconsistent_field_arrays_are_named(rows, width, occupancy, message):
    with pytest.raises(InvalidArgument, match=message):
        SceneField(SPACE, torch.zeros(rows, width), torch.ones(occupancy, dtype=torch.bool), 0.0, 0)
    with pytest.raises(InvalidArgument, match=r"rows is torch.int64 \(64,\); expected int32 \(64,\)"):
        SceneField(SPACE, torch.zeros(10, 4), torch.ones((3, 3, 3), dtype=torch.bool), 0.0, 0,
                   rows=torch.zeros(64, dtype=torch.int64))
    with pytest.raises(InvalidArgument, match=r"sh_degree=3: expected 0"):
        n_sh_coefficients(3)


def test_a_density_shift_that_is_not_a_number_is_refused_on_loading():
    """JSON reads ``NaN``: a scene file whose density shift is NaN would load, and every sample would render NaN."""
    field = random_field(resolution=6, occupied=0.5, seed=2)
    meta = field.metadata() | {"density_shift": float("nan")}
    with pytest.raises(SceneFileError, match=r"^bad\.n2r: field\.density_shift=nan; expected a finite number"):
        SceneField.from_tensors(meta, field.tensors(), source="bad.n2r")


def test_refining_a_field_emptier_than_float32_holds_keeps_its_values_finite():
    """A raw density so low that its softplus underflows to 0 in float32 refines to a finite (very low) one: an
    infinite raw density would make the saved scene file unreadable ("holds NaN or Inf")."""
    field = SceneField.empty(SPACE, 6, sh_degree=0, alpha=0.05, step_ratio=0.5)
    field.values[:, 0] = -200.0
    fine = field.upsampled(11)
    assert torch.isfinite(fine.values).all(), (
        f"upsampling raw density -200 gave {int((~torch.isfinite(fine.values)).sum())} non-finite values")
    back = SceneField.from_tensors(fine.metadata(), fine.tensors())
    assert float(back.cell_alpha(0.5).max()) < 1e-9, "the refined empty field is no longer empty"


def test_describe_reports_the_fraction_of_cells_occupied_and_the_vertices_stored():
    field = SceneField.empty(SPACE, 9, sh_degree=0, alpha=0.05, step_ratio=0.5)
    field.occupancy[:, :, 4:] = False  # 8³ cells, the half with k < 4 occupied: vertices k = 0..4 used
    info = field.describe()
    assert info["occupied_fraction"] == 0.5, f"half the cells occupied, describe() says {info['occupied_fraction']}"
    assert info["stored_vertices"] == 9 * 9 * 5, f"describe() counts {info['stored_vertices']} used vertices; 405"
    assert (info["resolution"], info["sh_degree"]) == (9, 0), info


def test_a_sparse_field_without_the_vertices_of_an_occupied_cell_is_refused_not_read_from_another_row():
    """Row -1 (not stored) would index the last row of ``values``: the cell's opacity and a compacted field's
    values would come silently from another vertex."""
    field = random_field(resolution=8, occupied=0.3, seed=5).compact()
    field.occupancy[:] = True  # now cells whose corners the field does not store are occupied
    for name, call in (("occupied_cell_alpha", lambda: field.occupied_cell_alpha(0.5)), ("compact", field.compact)):
        with pytest.raises(InvalidArgument, match="does not store every vertex of its occupied cells"):
            call()


def test_refining_a_sparse_field_counts_a_vertex_it_does_not_store_as_zeros():
    """A fine vertex halfway between a stored coarse vertex and one not stored takes half the stored value: the
    unstored corner adds nothing (it used to be able to read row 0, another vertex's values)."""
    field = SceneField.empty(SPACE, 5, sh_degree=0, alpha=0.05, step_ratio=0.5)
    field.values[:, 1:] = 1.0
    field.occupancy[:] = False
    field.occupancy[0, 0, 0] = True
    sparse = field.compact()  # stores the 8 corners of cell (0, 0, 0) only; row 0 is vertex (0, 0, 0)
    fine = sparse.upsampled(9)  # fine vertex (3, 0, 0) lies halfway between coarse vertices 1 (stored) and 2 (not)
    for ijk in ((3, 0, 0), (0, 3, 0), (0, 0, 3)):
        flat = torch.tensor([(ijk[0] * 9 + ijk[1]) * 9 + ijk[2]])
        row = fine.vertex_rows(flat)
        assert int(row) >= 0, f"fine vertex {ijk} of the dilated occupancy is not stored"
        colour = fine.values[row, 1:].reshape(-1).tolist()
        assert colour == [0.5, 0.5, 0.5], (
            f"fine vertex {ijk}, halfway to a coarse vertex not stored: colour coefficients {colour}, expected "
            f"half the stored 1.0 (the unstored vertex counts as 0)")
