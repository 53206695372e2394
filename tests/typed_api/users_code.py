"""Code as a user of pytest-n2r types it, checked by mypy with the package (``tests/test_house.py``): the package
ships ``py.typed``, so what a user's type checker reads is part of the API. Not a test module: mypy reads it, pytest
does not collect it.

Each annotated assignment states the type a user expects; a misspelt name carries an ignore that mypy's
``warn_unused_ignores`` turns into an error if the name were ever read as ``Any`` instead of refused.
"""

from __future__ import annotations

from typing import TYPE_CHECKING

import numpy as np
from hypothesis import strategies as st

import pytest_n2r
import pytest_n2r.scene
from pytest_n2r import Camera, RenderedView, Scene, SceneView, Transform, Units, load_scene, metamorphic
from pytest_n2r import strategies as n2r
from pytest_n2r.metrics import Metric, repeatability
from pytest_n2r.strategies import ViewPick
from pytest_n2r.strategies.pose_change import PoseChange

if TYPE_CHECKING:  # read by mypy only: at run time these fail, as they should (pytest imports this file for doctests)
    misspelt = pytest_n2r.Tranform  # type: ignore[attr-defined]  # an error, not Any: the lazy __getattr__ is hidden
    also_misspelt = pytest_n2r.scene.FieldScen  # type: ignore[attr-defined]  # the lazy subpackage's too

tau: PoseChange = PoseChange(yaw=5.0, x=0.1, units="scene")  # units by name, as the docs write them
units: Units = tau.units  # read back as the enumeration
moved: Transform = Transform(yaw=10.0).then(Transform(x=0.1))
changes: st.SearchStrategy[PoseChange] = n2r.transforms(yaw=10, x=(-0.1, 0.1), units=Units.REFERENCE)
metric: Metric = repeatability(px=2)
picks: st.SearchStrategy[ViewPick] = n2r.views(split="all", interpolate=True)  # resolved by the scene at hand


def orb(rgb: np.ndarray) -> np.ndarray:
    return np.zeros((0, 2), np.float32) + rgb.mean()


@metamorphic(metric, eps=0.3, transform=changes)
def test_orb_repeatability(n2r_scene: Scene) -> object:
    return orb


def render_first_view(path: str) -> np.ndarray:
    scene: Scene = load_scene(path)
    view = scene.views[0]
    camera: Camera = view.camera.fit_within(320)
    rendered: RenderedView = scene.render(view.c2w, camera, ("rgb", "depth"))
    return rendered.output("rgb")


def held_out_views(scene: Scene) -> st.SearchStrategy[SceneView]:
    return n2r.views(scene, interpolate=True)
