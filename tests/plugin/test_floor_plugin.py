"""The field floor beside every relation's result, in the terminal summary, failures and JSON records."""

from __future__ import annotations

import json
import re

import pytest

BLURRED = "tests.plugin.fakefield:blurred_plane"
SHARP = "tests.plugin.fakefield:sharp_plane_field"

# a brightness change of a grey level or two: the corners stay where they are, so both relations pass (a fixed
# Transform() would render the source again, a pair that tests nothing)
BODY = """
from pytest_n2r.metrics import repeatability
from pytest_n2r.strategies import brightness
from tests.plugin.fakefield import corners


@metamorphic(repeatability(px=2), eps=0.05, transform=brightness(max_levels=2), examples=2)
def test_tight(n2r_scene):
    return corners


@metamorphic(repeatability(px=2), eps=1.0, transform=brightness(max_levels=2), examples=2)
def test_loose(n2r_scene):
    return corners
"""


def test_the_floor_is_shown_beside_each_relation_and_eps_below_it_warns(n2r_project, tmp_path):
    n2r_project.write(BODY)
    out = tmp_path / "run.json"
    result = n2r_project.run("--n2r-scene", BLURRED, "--n2r-json", str(out))
    result.assert_outcomes(passed=2)
    text = result.stdout.str()
    tight = text.split(n2r_project.summary(result, "test_tight[blurred_plane]"))[1].splitlines()[1]
    loose = text.split(n2r_project.summary(result, "test_loose[blurred_plane]"))[1].splitlines()[1]
    assert "field floor" in tight and "photo vs field render" in tight, tight
    assert "WARNING: eps 0.05 is below the field floor: this relation tests the scene field, not the SUT" in tight
    assert "field floor" in loose and "WARNING" not in loose, loose
    records = {r["nodeid"].rsplit("::", 1)[1]: r for r in json.loads(out.read_text())["relations"]}
    floor = records["test_tight[blurred_plane]"]["floor"]
    assert floor["below_floor"] is True and floor["floor"]["value"] > 0.05 and floor["floor"]["n"] == 2
    assert records["test_loose[blurred_plane]"]["floor"]["below_floor"] is False


def test_a_render_equal_to_the_photo_has_a_zero_floor_and_no_warning(n2r_project):
    n2r_project.write(BODY)
    result = n2r_project.run("--n2r-scene", SHARP, "--n2r-size", "160x120")  # the photos' own size
    result.assert_outcomes(passed=2)
    assert "field floor 0 (photo vs field render" in result.stdout.str()
    assert "WARNING" not in result.stdout.str()


def test_a_failure_below_the_floor_says_so(n2r_project):
    n2r_project.write("""
from pytest_n2r.metrics import repeatability
from tests.plugin.fakefield import corners


@metamorphic(repeatability(px=2), eps=0.01, transform=transforms(x=(0.1, 0.2)), examples=3)
def test_turn(n2r_scene):
    return corners
""")
    result = n2r_project.run("--n2r-scene", BLURRED)
    result.assert_outcomes(failed=1)
    result.stdout.fnmatch_lines(["*metamorphic relation violated*",
                                 "*floor:      field floor * WARNING: eps 0.01 is below the field floor*"])


def test_a_scene_without_photos_says_why_it_has_no_floor(n2r_project):
    n2r_project.write(BODY)
    result = n2r_project.run("--n2r-scene", "tests.plugin.fakescene:plane")
    result.stdout.fnmatch_lines(["*field floor n/a: scene 'plane' stores no photos of its held-out views*"])


def test_exact_scenes_show_no_floor_and_fitted_demo_scenes_replay_on_exact_renders(n2r_project):
    n2r_project.write("""
from pytest_n2r.metrics import repeatability
from pytest_n2r.study import resolve_sut

orb = resolve_sut("orb", None).fn


@metamorphic(repeatability(px=2), eps=1.0, transform=transforms(yaw=(-2, 2)), examples=3)
def test_orb(n2r_scene):
    return orb
""")
    # 160 px: at 96 ORB finds no keypoint (31-px borders), and nothing to compare is not a pass
    result = n2r_project.run("--n2r-scene", "demo:wall", "--n2r-scene", "demo:wall-field", "--n2r-size", "160",
                             "--n2r-device", "cpu")
    result.assert_outcomes(passed=2)
    text = result.stdout.str()
    exact_part = text.split(n2r_project.summary(result, "test_orb[wall]"))[1].splitlines()[1]
    assert "field floor" not in exact_part, "an exact scene has no field, so no floor line"
    field_part = text.split(n2r_project.summary(result, "test_orb[wall-field]"))[1].splitlines()[1:3]
    assert "exact render vs field render" in field_part[0], field_part
    assert "same poses on exact renders: mean deviation" in field_part[1] and "3 examples" in field_part[1]


COUNTED = """
import time
from pytest_n2r.metrics import repeatability
from pytest_n2r.strategies import brightness
from tests.plugin.fakefield import corners


def sut(rgb):
    {misbehave}
    return corners(rgb)


@metamorphic(repeatability(px=2), eps=1.0, transform=brightness(max_levels=2), examples=2)
def test_counted(n2r_scene):
    return sut
"""


@pytest.mark.parametrize(("misbehave", "exit_code"), [
    ("time.sleep(3)", pytest.ExitCode.TESTS_FAILED),  # a hang, ended by --n2r-timeout 1
    ('raise ValueError("boom")', pytest.ExitCode.TESTS_FAILED),
    ("raise KeyboardInterrupt", pytest.ExitCode.INTERRUPTED),
])
def test_no_floor_is_measured_after_an_error_a_time_out_or_an_interrupt(n2r_project, monkeypatch, misbehave,
                                                                         exit_code):
    import pytest_n2r.plugin

    measured = []
    floor = pytest_n2r.plugin._floor  # the inner run is in this process: it calls the plugin module's _floor
    monkeypatch.setattr(pytest_n2r.plugin, "_floor", lambda *args: measured.append(args) or floor(*args))
    n2r_project.write(COUNTED.format(misbehave=misbehave))
    result = n2r_project.pytester.runpytest("-p", "no:cacheprovider", "--n2r-scene", BLURRED, "--n2r-size", "96",
                                            "--n2r-timeout", "1", "--n2r-cache-dir", "none", no_reraise_ctrlc=True)
    assert result.ret == exit_code, f"expected exit code {exit_code!r}, not {result.ret!r}:\n{result.stdout.str()}"
    assert not measured, "the field floor ran the SUT again after the relation stopped without a verdict"
    assert not re.search(r"^\s+field floor", result.stdout.str(), re.MULTILINE), "a floor line without a verdict"


def test_the_floors_sut_calls_are_under_the_time_limit(n2r_project):
    # the SUT hangs on sharp images only: the blurred renders of the relation pass, the floor's photos hang
    n2r_project.write(COUNTED.format(misbehave="""if np.abs(np.diff(rgb.astype(int), axis=1)).max() > 100:
        time.sleep(30)"""))
    result = n2r_project.run("--n2r-scene", BLURRED, "--n2r-timeout", "1", "--n2r-cache-dir", "none",
                             "--n2r-size", "160x120")  # the photos' own size: not resized, so sharp
    result.assert_outcomes(passed=1)
    result.stdout.fnmatch_lines([("*field floor n/a: measuring it failed: CallTimeout: the system under test, "
                                  "measuring the field floor did not finish within 1 s*")])
    assert result.duration < 20, f"the 1 s limit did not stop the floor's 30 s hang: {result.duration:.1f} s"


def test_the_floor_is_measured_at_the_relations_own_render_size(n2r_project, tmp_path):
    """``@metamorphic(size=...)`` renders the relation at its size: its floor must be measured there too, not at
    ``--n2r-size``."""
    n2r_project.write(BODY.replace("examples=2)\ndef test_tight", "examples=2, size=64)\ndef test_tight"))
    out = tmp_path / "run.json"
    n2r_project.run("--n2r-scene", BLURRED, "--n2r-json", str(out)).assert_outcomes(passed=2)
    records = {r["nodeid"].rsplit("::", 1)[1]: r for r in json.loads(out.read_text())["relations"]}
    sizes = {name: records[f"{name}[blurred_plane]"]["floor"]["floor"]["size"] for name in ("test_tight", "test_loose")}
    assert sizes["test_tight"] != sizes["test_loose"] and "64" in sizes["test_tight"], sizes
