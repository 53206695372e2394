"""Hypothesis strategies for the demo-scene tests: a demo scene's captured view moved by a transform."""

from __future__ import annotations

from hypothesis import strategies as st

from pytest_n2r.demo import demo_scene_names
from pytest_n2r.geometry import Transform


def moved_views(shift: float) -> st.SearchStrategy[tuple[str, int, Transform]]:
    """``(scene name, view index, transform)``: rotations up to 20° (roll, pitch) and 30° (yaw), translations
    up to ``shift`` reference lengths along each axis."""
    return st.tuples(
        st.sampled_from(demo_scene_names()), st.integers(0, 47),
        st.builds(Transform, roll=st.floats(-20, 20), pitch=st.floats(-20, 20), yaw=st.floats(-30, 30),
                  x=st.floats(-shift, shift), y=st.floats(-shift, shift), z=st.floats(-shift, shift)),
    )
