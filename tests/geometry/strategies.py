"""Hypothesis strategies shared by the geometry tests (angles in degrees, OpenCV camera frame)."""

from __future__ import annotations

import numpy as np
from hypothesis import strategies as st

from pytest_n2r.geometry import Camera, Transform

finite = st.floats(-10.0, 10.0, allow_nan=False, allow_infinity=False)
roll_yaw = st.floats(-179.999, 179.999, allow_nan=False)
pitch = st.floats(-90.0, 90.0, allow_nan=False)


@st.composite
def transforms(draw, max_pitch: float = 90.0) -> Transform:
    """Transforms with canonical angles (roll, yaw in (-180, 180), pitch in [-max_pitch, max_pitch])."""
    return Transform(
        roll=draw(roll_yaw), pitch=draw(st.floats(-max_pitch, max_pitch)), yaw=draw(roll_yaw),
        x=draw(finite), y=draw(finite), z=draw(finite),
    )


@st.composite
def poses(draw) -> np.ndarray:
    """Camera-to-world 4x4 poses (OpenCV axes) with any rotation and a centre within 10 units."""
    return draw(transforms()).matrix()


@st.composite
def cameras(draw) -> Camera:
    w = draw(st.integers(16, 2000))
    h = draw(st.integers(16, 2000))
    f = draw(st.floats(0.3, 3.0)) * max(w, h)
    return Camera(w, h, f * draw(st.floats(0.8, 1.25)), f, draw(st.floats(0.3, 0.7)) * w - 0.5,
                  draw(st.floats(0.3, 0.7)) * h - 0.5)


def angle_diff(a: float, b: float) -> float:
    """Smallest absolute difference of two angles in degrees."""
    return abs((a - b + 180.0) % 360.0 - 180.0)
