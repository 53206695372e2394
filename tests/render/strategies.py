"""Hypothesis strategies for the render tests: poses anywhere (normalized units) and tiny cameras."""

from __future__ import annotations

import numpy as np
from hypothesis import strategies as st

from pytest_n2r.geometry import Camera

unit_vectors = st.tuples(*[st.floats(-1.0, 1.0)] * 3).filter(lambda v: np.linalg.norm(v) > 0.1)


@st.composite
def poses(draw, max_distance: float = 1e3) -> tuple[tuple[float, ...], tuple[float, ...]]:
    """``(eye, target)`` in normalized units: the eye anywhere from the centre to ``max_distance`` radii away
    (log-uniform distance from 1e-3), looking towards the centre, away from it or anywhere."""
    direction = np.asarray(draw(unit_vectors))
    distance = 10.0 ** draw(st.floats(-3.0, float(np.log10(max_distance))))
    eye = direction / np.linalg.norm(direction) * distance
    look = draw(st.sampled_from(["centre", "away", "anywhere"]))
    if look == "centre":
        forward = -eye
    elif look == "away":
        forward = eye
    else:
        forward = np.asarray(draw(unit_vectors))
    target = eye + forward / np.linalg.norm(forward)
    return tuple(float(v) for v in eye), tuple(float(v) for v in target)


@st.composite
def cameras(draw, max_side: int = 6) -> Camera:
    """Tiny cameras (1..max_side pixels a side) with fields of view from ~1° to ~170°."""
    w, h = draw(st.integers(1, max_side)), draw(st.integers(1, max_side))
    f = max(w, h) * 10.0 ** draw(st.floats(-1.1, 1.7))
    return Camera(w, h, f, f * draw(st.floats(0.8, 1.25)), (w - 1) / 2, (h - 1) / 2)
