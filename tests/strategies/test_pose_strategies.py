"""Pose-transform strategies: bounds, validation messages, repr, shrinking to the boundary, look-at, presets."""

from __future__ import annotations

import math

import numpy as np
import pytest
from hypothesis import assume, find, given, settings
from hypothesis import strategies as st

from pytest_n2r import InvalidArgument, InvalidType, Transform
from pytest_n2r import strategies as n2r
from pytest_n2r.geometry import Units
from pytest_n2r.strategies.grid import check_bound, grid_step

BOUNDS = st.tuples(st.floats(-170, 170), st.floats(-170, 170)).map(sorted).map(tuple)


@given(bound=BOUNDS, data=st.data())
def test_drawn_values_stay_within_their_bounds(bound, data):
    assume(bound != (0.0, 0.0))  # every bound 0 is refused (the identity only)
    tau = data.draw(n2r.transforms(yaw=bound, x=(bound[0] / 100, bound[1] / 100)))
    assert bound[0] <= tau.yaw <= bound[1], f"yaw={tau.yaw} outside {bound}"
    assert bound[0] / 100 <= tau.x <= bound[1] / 100, f"x={tau.x} outside {bound} / 100"
    assert (tau.roll, tau.pitch, tau.y, tau.z) == (0.0, 0.0, 0.0, 0.0)


@given(data=st.data())
def test_a_bound_a_few_subnormals_wide_draws_inside_it(data):
    """Hypothesis found transforms(yaw=(0.0, 5e-324)) failing with 'math domain error': the grid step
    underflowed to 0."""
    tau = data.draw(n2r.transforms(yaw=(0.0, 5e-324)))
    assert 0.0 <= tau.yaw <= 5e-324, f"yaw={tau.yaw} outside (0, 5e-324)"


@given(data=st.data())
def test_a_bound_near_the_largest_float_draws_inside_it(data):
    """A bound whose span a float holds is drawn from (a wider one is refused, below)."""
    tau = data.draw(n2r.transforms(x=(0.0, 1.7e308), y=(-8e307, 8e307)))
    assert 0.0 <= tau.x <= 1.7e308 and -8e307 <= tau.y <= 8e307, f"{tau!r} outside its bounds"


@pytest.mark.parametrize(
    ("kwargs", "error", "words"),
    [
        ({"yaw": (10, -10)}, InvalidArgument, "yaw=(10, -10) has lo > hi; write yaw=(-10, 10)"),
        ({"x": float("nan")}, InvalidArgument, "x=nan must be finite"),
        ({"pitch": (0, float("inf"))}, InvalidArgument, "pitch[1]=inf must be finite"),
        ({"roll": "5"}, InvalidType, "roll='5' must be a number b (meaning -b..b) or a pair (lo, hi)"),
        ({"yaw": (1, 2, 3)}, InvalidArgument, "yaw=(1, 2, 3) must be a number"),
        ({"yaw": 200}, InvalidArgument, "angles are degrees in [-180, 180]"),
        ({"x": 0.1, "units": "furlongs"}, InvalidArgument, "units='furlongs' is not a unit"),
        ({"x": 0.1, "units": "scene", "look_at": True}, InvalidArgument, "look_at=True needs units='reference'"),
        ({"z": 0.95, "look_at": True}, InvalidArgument, "keep z below 0.9"),
        ({"x": 1.7e308}, InvalidArgument, "x=1.7e+308 spans inf (hi - lo overflows a float)"),
        ({"y": (-1e308, 1e308)}, InvalidArgument, "y=(-1e+308, 1e+308) spans inf"),
        ({}, InvalidArgument, "roll, pitch, yaw, x, y and z are all 0: every pose change would be the identity"),
        ({"yaw": 0, "x": (0, 0), "look_at": True}, InvalidArgument, "are all 0"),
    ],
)
def test_bad_bounds_are_rejected_eagerly_naming_the_argument(kwargs, error, words):
    with pytest.raises(error) as info:
        n2r.transforms(**kwargs)
    assert words in str(info.value)


def test_repr_rebuilds_the_call():
    strategy = n2r.transforms(yaw=10, x=(-0.1, 0.2), look_at=True)
    assert repr(strategy) == "transforms(look_at=True, x=(-0.1, 0.2), yaw=(-10.0, 10.0))"
    assert repr(n2r.transforms(x=0.5, units="scene")) == "transforms(units='scene', x=(-0.5, 0.5))"


@pytest.mark.parametrize("bounds", [
    {"roll": 5, "pitch": 5, "yaw": 30, "x": 0.2, "y": 0.2, "z": 0.2}, {"yaw": 20, "x": (-0.1, 0.3)}, {"pitch": 10},
])
def test_unconstrained_search_shrinks_to_one_grid_step_along_one_axis(bounds):
    """The identity is never drawn (a view compared with itself cannot fail): any motion failing shrinks to the
    smallest motion there is, one grid step along one component, every other component 0."""
    tau = find(n2r.transforms(**bounds), lambda t: True, settings=settings(database=None))
    moved = {name: value for name, value in tau.as_dict().items() if value}
    assert len(moved) == 1, f"shrunk to {tau!r}; expected one component off 0"
    (axis, value), = moved.items()
    step = grid_step(*check_bound(axis, bounds[axis]))
    assert abs(value) == step, f"shrunk to {tau!r}; expected {axis} one grid step ({step}) from 0"


@pytest.mark.parametrize("bounds", [
    {"yaw": 10, "x": 0.1}, {"x": 0.1}, {"roll": 5, "pitch": 5, "yaw": 30, "x": 0.2, "y": 0.2, "z": 0.2},
    {"yaw": (0, 20), "z": (-0.2, 0.0)}, {"y": 0.05, "pitch": 3.0, "look_at": True}, {"yaw": (0.0, 5e-324)},
])
def test_no_draw_is_the_identity(bounds):
    drawn = []

    @settings(max_examples=500, database=None)
    @given(n2r.transforms(**bounds))
    def collect(tau):
        drawn.append(tau)

    collect()
    identities = sum(tau.is_identity for tau in drawn)
    assert identities == 0, f"{identities} of {len(drawn)} draws of transforms(**{bounds}) are the identity"


@pytest.mark.parametrize("name", sorted(n2r.PRESETS))
def test_the_presets_never_draw_the_identity(name):
    @settings(max_examples=200, database=None)
    @given(n2r.PRESETS[name])
    def check(tau):
        assert not tau.is_identity, f"{name} drew the identity"

    check()


def test_a_one_axis_failure_shrinks_with_the_other_axes_at_0():
    tau = find(n2r.transforms(roll=5, yaw=20, x=0.1), lambda t: t.yaw > 5,
               settings=settings(max_examples=500, database=None))
    assert 5 < tau.yaw <= 5.01 and tau.roll == 0 and tau.x == 0, f"shrunk to {tau!r}; expected yaw just above 5"


@pytest.mark.parametrize("bound, nearest", [((2.3456, 20), 2.3456), ((-20, -2.3456), -2.3456),
                                            ((0.123456789, 0.5), 0.123456789)])
def test_a_bound_end_off_the_grid_is_the_smallest_draw(bound, nearest):
    """The end of a bound nearest 0 is where shrinking ends, also when it is not on the decimal grid (rounding
    it to the grid moved it to 2.346)."""
    tau = find(n2r.transforms(yaw=bound), lambda t: True, settings=settings(database=None))
    assert tau.yaw == nearest, f"shrunk to yaw={tau.yaw!r}; expected the bound's end {nearest}"


@pytest.mark.parametrize(
    ("bounds", "condition", "axis", "lo", "hi"),
    [
        ({"yaw": 20}, lambda t: abs(t.yaw) > 5, "yaw", 5.0, 5.01),
        ({"yaw": 20}, lambda t: t.yaw < -12.345, "yaw", -12.36, -12.345),
        ({"pitch": (-80, 80)}, lambda t: t.pitch > 33.3, "pitch", 33.3, 33.31),
        ({"x": 0.3}, lambda t: t.x > 0.0123, "x", 0.0123, 0.0124),
        ({"yaw": (2, 20)}, lambda t: True, "yaw", 2.0, 2.0),
        ({"yaw": (-20, -2)}, lambda t: True, "yaw", -2.0, -2.0),
    ],
)
def test_failures_shrink_to_the_boundary(bounds, condition, axis, lo, hi):
    tau = find(n2r.transforms(**bounds), condition, settings=settings(max_examples=500, database=None))
    assert lo <= getattr(tau, axis) <= hi, f"shrunk to {tau!r}; expected {axis} in [{lo}, {hi}]"


def test_a_failure_needing_two_axes_shrinks_both():
    tau = find(n2r.transforms(yaw=20, y=0.3), lambda t: t.yaw > 4 and t.y < -0.1,
               settings=settings(max_examples=1000, database=None))
    assert 4 < tau.yaw <= 4.01 and -0.1001 <= tau.y < -0.1, f"shrunk to {tau!r}"


def _moved_point(tau: Transform, point=(0.0, 0.0, 1.0)) -> np.ndarray:
    """``point`` (source camera frame, reference lengths) in the follow-up camera frame."""
    T = tau.matrix()
    return T[:3, :3].T @ (np.asarray(point) - T[:3, 3])


@given(tau=n2r.transforms(x=0.4, y=0.4, z=0.5, look_at=True))
def test_look_at_keeps_the_reference_point_on_the_optical_axis(tau):
    p = _moved_point(tau)
    assert p[2] > 0 and math.hypot(p[0], p[1]) < 1e-9 * p[2], f"{tau!r} puts the look-at point at {p}"


def test_look_at_tilts_down_when_the_camera_moves_up():
    tau = find(n2r.transforms(y=0.2, look_at=True), lambda t: t.y < -0.1)
    assert tau.pitch < 0, f"moving up (y={tau.y}) should pitch down, got pitch={tau.pitch}"
    tau = find(n2r.transforms(x=0.2, look_at=True), lambda t: t.x > 0.1)
    assert tau.yaw < 0, f"moving right (x={tau.x}) should yaw left, got yaw={tau.yaw}"


@pytest.mark.parametrize("name", sorted(n2r.PRESETS))
def test_presets_are_look_at_transforms_in_reference_units(name):
    strategy = n2r.PRESETS[name]
    assert "look_at=True" in repr(strategy)
    assert n2r.PRESET_FAMILIES[name].units is Units.REFERENCE and n2r.PRESET_FAMILIES[name].look_at
    assert find(strategy, lambda t: True).units is Units.REFERENCE


def test_draws_spread_over_the_whole_bound():
    drawn = []

    @settings(max_examples=300, database=None, derandomize=True)
    @given(n2r.transforms(yaw=80))
    def collect(tau):
        drawn.append(abs(tau.yaw))

    collect()
    far = np.mean(np.asarray(drawn) > 40)
    assert 0.4 < far < 0.65, f"{far:.0%} of draws had |yaw| > 40 for a bound of 80; expected about half"


def test_the_grid_draws_what_hypothesis_integers_draw():
    """The grid draws from ``st.integers`` built once and unwrapped (cheaper per draw, docs/performance-log.md):
    the same values as ``st.integers`` itself, seed for seed, so the drawn examples stay the same."""
    from pytest_n2r.strategies.grid import _integers

    def drawn(integers):
        values = []

        @settings(max_examples=50, derandomize=True, database=None)
        @given(st.data())
        def collect(data):
            values.append([data.draw(integers(lo, hi)) for lo, hi in ((0, 1), (0, 63), (17, 255), (1000, 4000))])

        collect()
        return values

    assert drawn(_integers) == drawn(st.integers), "the built-once strategies drew other values than st.integers"


@pytest.mark.parametrize("pitch, y, clamped", [(89.0, 0.5, 90.0), (-89.0, -0.5, -90.0)])
def test_a_look_at_pitch_is_clamped_after_the_compensation_is_added(pitch, y, clamped):
    """The look-at pitch is clamped to ±90° once the compensation is added: clamping the drawn pitch before adding
    it turned the camera past straight down (or up), a pitch of 89° plus 26.6° of compensation giving 115.6°."""
    from pytest_n2r.geometry.look_at import MAX_LOOK_AT_PITCH, look_at_transform

    tau = look_at_transform(pitch=pitch, y=y)
    assert tau.pitch == clamped, f"look_at_transform(pitch={pitch}, y={y}) has pitch {tau.pitch}, expected {clamped}"
    family = n2r.PoseChangeFamily.of(pitch=(80, 89), y=(0.4, 0.5), look_at=True)
    drawn = family.build({"pitch": abs(pitch), "y": abs(y)})
    assert drawn.pitch == MAX_LOOK_AT_PITCH, f"a look-at draw turned past straight down: pitch {drawn.pitch}"


@pytest.mark.parametrize("bound, expected", [(-10, (-10.0, 10.0)), (10, (-10.0, 10.0)), (-0.2, (-0.2, 0.2))])
def test_a_negative_number_bound_means_minus_b_to_b(bound, expected):
    """A number ``b`` means ``-|b|..|b|``: taken as ``-b..b``, ``yaw=-10`` became the bound (10, -10), lo above hi."""
    axis = "yaw" if abs(bound) > 1 else "x"
    assert check_bound(axis, bound) == expected, f"{axis}={bound} gave {check_bound(axis, bound)}, expected {expected}"
    tau = find(n2r.transforms(**{axis: bound}), lambda t: abs(getattr(t, axis)) > abs(bound) / 2,
               settings=settings(database=None))
    assert expected[0] <= getattr(tau, axis) <= expected[1], f"{tau!r} is outside {axis}={expected}"


def test_a_bound_that_excludes_0_is_never_forced_off_its_nearest_end():
    """When some bound excludes 0 no draw can be the identity, so no component is forced off 0: with one forced (the
    last bounded one, here x), shrinking stopped one grid step short of the smallest motion, at x=0.10001."""
    tau = find(n2r.transforms(yaw=5, x=(0.1, 0.2)), lambda t: True, settings=settings(database=None))
    assert (tau.yaw, tau.x) == (0.0, 0.1), f"shrunk to {tau!r}; expected yaw=0 and x=0.1, the end of its bound"
