"""Render sizes: 'WxH', the longer side, or a pair."""

from __future__ import annotations

import pytest

from pytest_n2r.render.size import RenderSize
from tests.plugin.fakescene import PlaneScene


@pytest.mark.parametrize(("text", "size"), [("480x270", (480, 270)), ("96", (96, 72)), ((40, 30), (40, 30))])
def test_render_size(text, size):
    camera = PlaneScene().views[0].camera
    resized = RenderSize.parse(text).apply(camera)
    assert (resized.width, resized.height) == size
