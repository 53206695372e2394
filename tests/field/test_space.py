"""SceneSpace: normalization, and the contraction that maps all of space into the grid's cube."""

from __future__ import annotations

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from pytest_n2r.errors import InvalidArgument
from pytest_n2r.field.space import SceneSpace

SPACE = SceneSpace((0.5, -1.0, 2.0), 3.0, shell=0.25)

coordinates = st.one_of(st.floats(-1.0, 1.0), st.floats(-1e300, 1e300))
points = st.tuples(coordinates, coordinates, coordinates)


# the outer branch, computed and discarded for tiny points, must not warn
@pytest.mark.filterwarnings("error::RuntimeWarning")
@settings(max_examples=300, deadline=None)
@given(p=points, shell=st.sampled_from([0.05, 0.25, 1.0, 4.0]))
def test_contract_maps_all_of_space_into_the_cube_and_is_the_identity_inside(p, shell):
    space = SceneSpace((0.0, 0.0, 0.0), 1.0, shell)
    p = np.asarray(p)
    q = space.contract(p)
    r = np.abs(p).max()
    # It may overshoot by an ulp (1.2500000000000002 for (0, 0, 1.49e16)); the grid lookups clamp.
    assert np.isfinite(q).all() and np.abs(q).max() <= space.half_size * (1 + 1e-15), (
        f"contract({p.tolist()}) = {q.tolist()} lies outside the cube of half size {space.half_size}")
    if r <= 1.0:
        assert np.array_equal(q, p), f"contract moved {p.tolist()} inside the unit cube to {q.tolist()}"
    else:
        expected = 1.0 + shell * (1.0 - 1.0 / r)  # the ∞-norm of the contracted point
        assert abs(np.abs(q).max() - expected) <= 1e-12 * expected, f"|contract({p.tolist()})|∞ = {np.abs(q).max()}"
        assert np.allclose(q / np.abs(q).max(), p / r, rtol=1e-12, atol=1e-300), "contract changed the direction"


def test_contract_is_continuous_and_radially_increasing():
    direction = np.array([0.3, -1.0, 0.6])
    radii = np.concatenate([np.linspace(0.0, 1.0, 50), 1.0 + np.geomspace(1e-12, 1e12, 200)])
    q = SPACE.contract(radii[:, None] * direction)
    norms = np.abs(q).max(axis=1)
    assert np.all(np.diff(norms) >= 0), "points farther out along a ray are contracted nearer the centre"
    assert np.abs(np.diff(q, axis=0)).max() < 0.05, "contract jumps between nearby points (at the cube's face?)"
    assert norms[-1] > SPACE.half_size - 1e-9 and norms[-1] <= SPACE.half_size


@pytest.mark.parametrize("kwargs, message", [
    ({"center": (0, 0), "radius": 1.0}, r"center=\(0, 0\): expected three finite numbers"),
    ({"center": (0, 0, float("nan")), "radius": 1.0}, r"expected three finite numbers"),
    ({"center": (0, 0, 0), "radius": 0.0}, r"radius=0\.0: expected a finite number > 0"),
    ({"center": (0, 0, 0), "radius": float("inf")}, r"radius=inf"),
    ({"center": (0, 0, 0), "radius": 1.0, "shell": 5.0}, r"shell=5\.0: expected a thickness in \(0, 4\]"),
])
def test_bad_spaces_are_named(kwargs, message):
    with pytest.raises(InvalidArgument, match=message):
        SceneSpace(**kwargs)


def test_around_puts_the_bounds_and_the_cameras_in_the_unit_cube():
    bounds = np.array([[-2.0, 0.0, 1.0], [3.0, 1.0, 2.0]])
    cameras = np.array([[0.0, 6.0, 1.5], [-4.0, 0.5, 1.0]])
    space = SceneSpace.around(bounds, cameras, padding=0.05)
    corners = np.array([[x, y, z] for x in bounds[:, 0] for y in bounds[:, 1] for z in bounds[:, 2]])
    for name, pts in (("bounds", corners), ("cameras", cameras)):
        p = (pts - np.asarray(space.center)) / space.radius
        assert np.abs(p).max() <= 1.0 / 1.05 + 1e-12, f"{name} reach {np.abs(p).max()} of the cube (padding lost)"
    with pytest.raises(InvalidArgument, match=r"bounds must be a finite \(2, 3\) box"):
        SceneSpace.around(bounds[::-1])


def test_normalized_rays_keep_t_as_scene_depth():
    rng = np.random.default_rng(0)
    o, d = rng.normal(size=(20, 3)) * 4, rng.normal(size=(20, 3))
    t = rng.uniform(0.1, 10.0, (20, 1))
    o_n, d_n = SPACE.normalize_rays(o, d)
    expected = (o + t * d - np.asarray(SPACE.center)) / SPACE.radius
    np.testing.assert_allclose(o_n + t * d_n, expected, rtol=1e-5, atol=1e-5,
                               err_msg="o + t·d in normalized units is not the normalized scene point")
    assert o_n.dtype == d_n.dtype == np.float32


def test_the_dict_form_round_trips_and_missing_keys_are_named():
    assert SceneSpace.from_dict(SPACE.to_dict()) == SPACE
    with pytest.raises(InvalidArgument, match=r"expected center, radius and shell"):
        SceneSpace.from_dict({"center": [0, 0, 0], "radius": 1.0})
