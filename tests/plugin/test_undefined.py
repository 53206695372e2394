"""Nothing to compare is never a pass, through the plugin: an empty detector fails its ``@metamorphic`` test
and the summary counts the undefined draws (issue 15, point 1; the engine's side is in
tests/relation/test_undefined.py)."""

from __future__ import annotations

from .test_plugin import PLANE


def test_an_empty_detector_fails_metamorphic(n2r_project):
    n2r_project.write("""
from pytest_n2r.metrics import repeatability


@metamorphic(repeatability(px=2), eps=0.9, transform=transforms(yaw=3), examples=10)
def test_empty(n2r_scene):
    return lambda rgb: np.zeros((0, 2))
""")
    result = n2r_project.run("--n2r-scene", PLANE)
    result.assert_outcomes(failed=1)
    result.stdout.fnmatch_lines(["*the SUT produced nothing to test*the SUT found no keypoint in either view*"])
    assert "undefined (" in n2r_project.summary(result, "test_empty[plane]")
