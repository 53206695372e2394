"""A fitted field turned into splats: one Gaussian per occupied voxel, where the voxel is, as large and as
opaque as the knobs say, with the field's colour."""

from __future__ import annotations

import math

import numpy as np
import pytest
import torch
from hypothesis import given, settings
from hypothesis import strategies as st

from pytest_n2r.errors import InvalidArgument
from pytest_n2r.field.grid import SceneField
from pytest_n2r.field.query import sh_basis
from pytest_n2r.field.space import SceneSpace
from pytest_n2r.scene.splat_from_field import field_to_gaussians, uncontract
from pytest_n2r.splats.sh import view_colours

from ..render.splat_reference import sh_basis as splat_sh_basis

SPACE = SceneSpace((1.0, -2.0, 0.5), 3.0, shell=0.25)
RES = 6  # 5³ cells of 2.5 / 5 = 0.5 normalized units; cell i spans [-1.25 + 0.5 i, -0.75 + 0.5 i]


def one_cell_field(cell: tuple[int, int, int], raw_density: float, coeff: np.ndarray, shift: float = -2.0
                   ) -> SceneField:
    """A dense field whose only occupied cell is ``cell``; every vertex holds ``raw_density`` and the SH
    colour coefficients ``coeff`` (n_sh, 3)."""
    occupancy = torch.zeros((RES - 1,) * 3, dtype=torch.bool)
    occupancy[cell] = True
    row = np.concatenate([[raw_density], np.asarray(coeff, dtype=np.float64).reshape(-1)])  # [l·3 + channel]
    values = torch.tensor(np.tile(row, (RES ** 3, 1)), dtype=torch.float32)
    return SceneField(SPACE, values, occupancy, shift, sh_degree={1: 0, 4: 1, 9: 2}[len(coeff)])


@settings(max_examples=50, deadline=None)
@given(st.lists(st.floats(-50.0, 50.0), min_size=3, max_size=3))
def test_uncontract_inverts_the_contraction(p):
    p = np.array([p])
    np.testing.assert_allclose(uncontract(SPACE, SPACE.contract(p)), p, rtol=1e-9, atol=1e-12)


def test_uncontract_refuses_the_points_at_infinity():
    with pytest.raises(InvalidArgument, match="1 \\+ shell = 1.25 lie at infinity"):
        uncontract(SPACE, np.array([[1.25, 0.0, 0.0]]))


def test_a_cell_inside_the_cube_becomes_a_round_gaussian_of_its_density_and_colour():
    coeff = np.array([[0.8, -0.4, 1.5]])  # degree 0
    shift = -2.0
    field = one_cell_field((2, 2, 1), 1.0, coeff, shift)
    g = field_to_gaussians(field, size=0.4, path=0.8)
    assert len(g) == 1, f"{len(g)} Gaussians for one occupied cell"
    centre = np.array([0.0, 0.0, -0.5])  # normalized
    np.testing.assert_allclose(g.means[0], np.array(SPACE.center) + SPACE.radius * centre, rtol=1e-6, atol=1e-6)
    np.testing.assert_allclose(np.exp(g.log_scales[0]), [0.4 * 0.5 * SPACE.radius] * 3, rtol=1e-5)
    sigma = math.log1p(math.exp(1.0 + shift))
    assert g.opacities[0] == pytest.approx(1 - math.exp(-sigma * 0.8), rel=1e-5), "opacity of 0.8 voxels"
    colour = view_colours(g.sh.astype(np.float64), np.array([[0.3, -0.2, 0.9]]))[0]
    np.testing.assert_allclose(colour, 1 / (1 + np.exp(-0.28209479177387814 * coeff[0])), rtol=1e-6)


@pytest.mark.parametrize("degree", [0, 1, 2])
def test_the_fields_sh_basis_is_the_splats(degree):
    """A field and a splat scene evaluate one basis (the 3DGS reference code's constants and signs), so a field's
    coefficients carry over to splats unchanged but for the colour's sigmoid."""
    d = np.random.default_rng(degree).normal(size=(50, 3))
    d /= np.linalg.norm(d, axis=1, keepdims=True)
    field_basis = sh_basis(torch.from_numpy(d), degree).numpy()
    np.testing.assert_allclose(field_basis, splat_sh_basis(d, degree), rtol=0, atol=1e-15,
                               err_msg=f"the field's SH basis of degree {degree} is not the splats'")


@pytest.mark.parametrize("degree", [1, 2])
def test_view_dependent_colour_is_the_fields_to_first_order(degree):
    """The field's colour is sigmoid(Σ Y_l k_l); the splat's is linear in the same basis: they agree at every
    direction to the square of the view-dependent terms."""
    coeff = np.array([[0.5, -1.0, 0.2], [0.02, -0.03, 0.01], [0.01, 0.02, -0.02], [-0.03, 0.01, 0.02],
                      [0.01, -0.02, 0.03], [-0.02, 0.01, 0.01], [0.03, 0.02, -0.01], [0.01, 0.01, 0.02],
                      [-0.01, 0.03, -0.02]])[:(degree + 1) ** 2]
    g = field_to_gaussians(one_cell_field((2, 2, 2), 3.0, coeff))
    d = np.random.default_rng(0).normal(size=(20, 3))
    d /= np.linalg.norm(d, axis=1, keepdims=True)
    field_colour = 1 / (1 + np.exp(-(splat_sh_basis(d, degree) @ coeff)))
    splat_colour = view_colours(np.repeat(g.sh.astype(np.float64), 20, axis=0), d)
    assert np.abs(splat_colour - field_colour).max() < 2e-3, (
        f"degree-{degree} colour is not the first-order expansion: off by {np.abs(splat_colour - field_colour).max()}")


def test_a_cell_in_the_shell_is_stretched_to_its_world_extent():
    """The outermost layer of cells covers the world far away: its Gaussian is as wide as the cell is, along
    each world axis (by the contraction's derivative)."""
    field = one_cell_field((4, 2, 2), 2.0, np.array([[0.0, 0.0, 0.0]]))
    g = field_to_gaussians(field, size=1.0)
    q = np.array([[1.0, 0.0, 0.0]])  # the cell's centre: x in [0.75, 1.25], contracted
    np.testing.assert_allclose(g.means[0], np.array(SPACE.center) + SPACE.radius * uncontract(SPACE, q)[0],
                               rtol=1e-6)
    scales = np.exp(g.log_scales[0])
    assert scales[0] > 2 * scales[1], f"the shell cell's Gaussian is not stretched outwards: scales {scales}"
    h = 0.125
    ends = uncontract(SPACE, np.array([[1.0 - h, 0.0, 0.0], [1.0 + h, 0.0, 0.0]]))
    assert scales[0] == pytest.approx(SPACE.radius * (ends[1, 0] - ends[0, 0]) * 2, rel=1e-5)


def test_cells_too_thin_to_draw_are_dropped():
    field = one_cell_field((1, 1, 1), -30.0, np.array([[0.0, 0.0, 0.0]]))
    assert len(field_to_gaussians(field)) == 0, "a cell of opacity below 1/255 became a Gaussian"


@pytest.mark.parametrize("knob", ["size", "path"])
@pytest.mark.parametrize("value", [0.0, -1.0, math.nan, math.inf])
def test_bad_knobs_are_named(knob, value):
    with pytest.raises(InvalidArgument, match=f"{knob}={value!r}; expected a finite number > 0"):
        field_to_gaussians(one_cell_field((1, 1, 1), 0.0, np.zeros((1, 3))), **{knob: value})


def test_n2r_import_turns_a_fitted_scene_file_into_a_splat_scene_file(tmp_path, capsys):
    from pytest_n2r.cli.main import main
    from pytest_n2r.field.config import FieldConfig
    from pytest_n2r.scene import SplatScene, load_scene, save_scene

    from .conftest import random_field, tiny_views

    fitted = save_scene(tmp_path / "fitted.n2r", random_field(), FieldConfig(), tiny_views(), {"train_seconds": 1.0},
                        reference_length=3.0)
    out = tmp_path / "splats.n2r"
    assert main(["import", str(fitted), "-o", str(out), "--size", "0.3"]) == 0, capsys.readouterr().err
    assert "Gaussians, SH degree 1" in capsys.readouterr().err
    field_scene, splats = load_scene(fitted, device="cpu"), load_scene(out)
    assert isinstance(splats, SplatScene)
    expected = field_to_gaussians(field_scene.field, size=0.3)
    assert len(splats.gaussians) == len(expected) > 0
    np.testing.assert_array_equal(splats.gaussians.means, expected.means)
    assert [(v.name, v.split) for v in splats.views] == [(v.name, v.split) for v in field_scene.views]
    assert splats.reference_length == field_scene.reference_length == 3.0
    assert splats.background == field_scene.field.background


@pytest.mark.parametrize("extra, expected", [
    (["--cameras", "x.json"], "--cameras: only for a .ply"),
    (["--background", "1,1,1"], "--background: only for a .ply"),
])
def test_n2r_import_of_a_fitted_file_refuses_the_ply_options(tmp_path, capsys, extra, expected):
    from pytest_n2r.cli.main import main
    from pytest_n2r.field.config import FieldConfig
    from pytest_n2r.scene import save_scene

    from .conftest import random_field, tiny_views

    fitted = save_scene(tmp_path / "fitted.n2r", random_field(), FieldConfig(), tiny_views(), {}, reference_length=3.0)
    assert main(["import", str(fitted), "-o", str(tmp_path / "out.n2r"), *extra]) == 2
    assert expected in capsys.readouterr().err and not (tmp_path / "out.n2r").exists()


def test_n2r_import_help_states_the_conversion_defaults(capsys):
    from pytest_n2r.cli.main import main
    from pytest_n2r.scene.splat_from_field import DEFAULT_PATH, DEFAULT_SIZE

    with pytest.raises(SystemExit):
        main(["import", "--help"])
    shown = " ".join(capsys.readouterr().out.split())
    assert f"(default {DEFAULT_SIZE})" in shown and f"(default {DEFAULT_PATH})" in shown, shown
