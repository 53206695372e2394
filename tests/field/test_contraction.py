"""The contraction and the grid lookup exist once per backend — NumPy (:class:`SceneSpace`), torch
(:mod:`pytest_n2r.field.lattice`) and numba (:mod:`pytest_n2r.field.kernels`) — and the three are the same
map: on random points, at the contraction's boundary ``‖p‖∞ = 1`` (and one ulp either side of it), on the
cube's faces, edges and corners, and far out."""

from __future__ import annotations

import numpy as np
import pytest
import torch
from hypothesis import example, given, settings
from hypothesis import strategies as st
from numba import njit

from pytest_n2r.field.kernels import contract_xyz, grid_coords_xyz, sample_alpha
from pytest_n2r.field.lattice import contract, grid_coords
from pytest_n2r.field.space import SceneSpace

SHELLS = (0.05, 0.25, 1.0, 4.0)
#: NumPy and torch compute ``(a·p)/r``, numba ``p·(a/r)`` (``a = 1 + shell·(1 - 1/r)``): two roundings each
#: of 2⁻⁵³, so they may differ by four, relative.
ROUNDING = 4 * 2.0 ** -53
#: Below the smallest normal float (2.2e-308) a rounding error is absolute, up to one subnormal step (4.9e-324),
#: not relative: a coordinate of 2.2e-313 beside one of 2.0 came out 1.12750000003e-313 in numba and
#: 1.1275e-313 in NumPy (a relative 2.7e-11; Hypothesis found it). Two roundings each: four steps.
SUBNORMAL_ROUNDING = 4 * np.finfo(np.float64).smallest_subnormal


@njit(cache=True)
def _contract_numba(p, shell):
    out = np.empty_like(p)
    for i in range(p.shape[0]):
        out[i, 0], out[i, 1], out[i, 2] = contract_xyz(p[i, 0], p[i, 1], p[i, 2], shell)
    return out


@njit(cache=True)
def _grid_numba(p, shell, res):
    out = np.empty_like(p)
    for i in range(p.shape[0]):
        out[i, 0], out[i, 1], out[i, 2] = grid_coords_xyz(p[i, 0], p[i, 1], p[i, 2], shell, res)
    return out


def _boundary_points() -> np.ndarray:
    """Points on and one ulp either side of the unit cube's faces, edges and corners, and the origin."""
    below, above = np.nextafter(1.0, 0.0), np.nextafter(1.0, 2.0)
    rng = np.random.default_rng(7)
    points = [np.zeros(3)]
    for r in (below, 1.0, above):
        for sign in (-1.0, 1.0):
            for axis in range(3):
                face = rng.uniform(-1.0, 1.0, (4, 3))  # on a face
                face[:, axis] = sign * r
                points.extend(face)
            points.append(np.full(3, sign * r))  # a corner
            points.append(np.array([sign * r, -sign * r, 0.3]))  # an edge
    return np.asarray(points)


def _check_backends_agree(p: np.ndarray, shell: float) -> None:
    q = SceneSpace((0.0, 0.0, 0.0), 1.0, shell).contract(p)
    q_torch = contract(torch.from_numpy(p), shell).numpy()
    q_numba = _contract_numba(p, shell)
    inside = np.abs(p).max(axis=1) <= 1.0
    assert np.array_equal(q_torch, q), (
        f"shell={shell}: torch's contraction differs from NumPy's at {p[(q_torch != q).any(axis=1)][:3].tolist()}")
    assert np.array_equal(q_numba[inside], p[inside]) and np.array_equal(q[inside], p[inside]), (
        f"shell={shell}: a point inside the unit cube moved")
    np.testing.assert_allclose(q_numba, q, rtol=ROUNDING, atol=SUBNORMAL_ROUNDING,
                               err_msg=f"shell={shell}: numba's contraction is not NumPy's to rounding")
    for res in (2, 17, 384):
        g_torch = grid_coords(torch.from_numpy(p), shell, res).numpy()
        g_numba = _grid_numba(p, shell, res)
        assert ((g_torch >= 0) & (g_torch <= res - 1)).all(), f"torch grid coordinates leave [0, {res - 1}]"
        np.testing.assert_allclose(g_numba, g_torch, rtol=0.0, atol=4 * res * 2.0 ** -52,
                                   err_msg=f"shell={shell}, res={res}: the grid lookups disagree")


@pytest.mark.parametrize("shell", SHELLS)
def test_the_backends_agree_on_the_boundary_of_the_contraction(shell):
    _check_backends_agree(_boundary_points(), shell)


@pytest.mark.parametrize("shell", SHELLS)
def test_the_backends_agree_on_random_points_near_and_far(shell):
    rng = np.random.default_rng(int(shell * 100))
    p = rng.normal(size=(20000, 3)) * np.exp(rng.uniform(-4.0, 30.0, (20000, 1)))
    _check_backends_agree(p, shell)


coordinates = st.one_of(st.floats(-1.0, 1.0), st.floats(-1e300, 1e300), st.sampled_from([-1.0, 1.0]))


@settings(max_examples=300, deadline=None)
@given(p=st.lists(st.tuples(coordinates, coordinates, coordinates), min_size=1, max_size=8),
       shell=st.sampled_from(SHELLS))
@example(p=[(2.0, 2.2e-313, 0.0)], shell=0.05)
@example(p=[(1.5, 1e-300, 4e-309)], shell=0.25)
def test_the_backends_agree_on_any_point(p, shell):
    _check_backends_agree(np.asarray(p, dtype=np.float64), shell)


@settings(max_examples=200, deadline=None)
@given(x=st.floats(-800.0, 1e6), sigma_step=st.sampled_from([0.5, 0.25, 1.0, 1.3]))
def test_sample_opacity_is_in_0_1_and_the_half_voxel_fast_path_is_the_formula(x, sigma_step):
    """The compiled kernel's ``1 - (1 + eˣ)^-½`` at half-voxel spacing equals ``1 - exp(-softplus(x)·s)``."""
    alpha = sample_alpha(x, sigma_step)
    assert 0.0 <= alpha <= 1.0, f"opacity {alpha} of raw density {x} at spacing {sigma_step}"
    expected = -np.expm1(-float(torch.nn.functional.softplus(torch.tensor(x, dtype=torch.float64))) * sigma_step)
    assert abs(alpha - expected) <= 1e-12, f"opacity {alpha} of raw density {x}, expected {expected}"


def test_the_fields_sh_basis_is_the_3dgs_basis_the_splats_use():
    """The field's colour basis (constants of :mod:`pytest_n2r.field.kernels`, shared by the torch and compiled
    paths, so their agreement cannot see a wrong sign) is the 3DGS reference's, as a field converted to splats needs."""
    from pytest_n2r.field.query import sh_basis

    from ..render.splat_reference import sh_basis as reference_basis

    rng = np.random.default_rng(3)
    d = rng.normal(size=(200, 3))
    d /= np.linalg.norm(d, axis=1, keepdims=True)
    for degree in (0, 1, 2):
        np.testing.assert_allclose(sh_basis(torch.from_numpy(d), degree).numpy(), reference_basis(d, degree), rtol=0,
                                   atol=1e-12, err_msg=f"the field's SH basis of degree {degree} is not the 3DGS one")
