"""The pytest-n2r terminal section at each verbosity: ``-qq`` keeps a CI log of many relations short."""

from __future__ import annotations

import re

PLANE = "tests.plugin.fakescene:plane"

RELATIONS = """
@metamorphic(AbsDifference(), eps=255, transform=transforms(yaw=5), examples=3)
def test_holds(n2r_scene):
    return mean_colour


@metamorphic(AbsDifference(), eps=0.0, transform=transforms(yaw=5), examples=3)
def test_breaks(n2r_scene):
    return lambda rgb: float(rgb.mean())


@pytest.mark.xfail(strict=True, reason="a known weakness")
@metamorphic(AbsDifference(), eps=0.0, transform=transforms(yaw=5), examples=3)
def test_known_weakness(n2r_scene):
    return lambda rgb: float(rgb.mean())


@pytest.mark.xfail(strict=True, reason="thought weak, holds")
@metamorphic(AbsDifference(), eps=255, transform=transforms(yaw=5), examples=3)
def test_strict_xpass(n2r_scene):
    return mean_colour


def crash(rgb):
    raise RuntimeError("the SUT crashed")


@metamorphic(AbsDifference(), eps=255, transform=transforms(yaw=5), examples=3)
def test_crashes(n2r_scene):
    return crash
"""


def _section(result) -> list[str]:
    lines = result.outlines
    start = next(i for i, line in enumerate(lines) if re.match(r"=+ pytest-n2r =+$", line))
    end = next((i for i in range(start + 1, len(lines)) if lines[i].startswith("=")), len(lines))
    return lines[start + 1:end]


def test_at_qq_only_the_relations_that_did_not_pass_and_the_totals_are_shown(n2r_project):
    """With ``-qq`` the section still printed one line per relation and three summary lines."""
    n2r_project.write(RELATIONS)
    result = n2r_project.run("--n2r-scene", PLANE, "-qq")
    assert result.ret == 1, result.stdout.str()  # -qq prints no line of outcomes for assert_outcomes to read
    section = _section(result)
    shown = [line.split(" ", 1)[0] + " " + re.search(r"::(test_\w+)", line).group(1)
             for line in section if "::test_" in line]
    assert sorted(shown) == ["ERROR test_crashes", "FAILED test_breaks", "XFAIL test_known_weakness",
                             "XPASS test_strict_xpass"], section  # a strict xpass fails the run: it is shown
    assert len(section) == 5 and section[-1].startswith("5 relations: "), (
        "the relations that did not pass, then the totals line, nothing else:\n" + "\n".join(section))


def test_at_q_every_relation_and_the_time_are_shown(n2r_project):
    n2r_project.write(RELATIONS)
    result = n2r_project.run("--n2r-scene", PLANE, "-q")
    result.assert_outcomes(passed=1, failed=3, xfailed=1)
    section = _section(result)
    assert any(line.startswith("PASSED ") and "test_holds" in line for line in section), section
    assert sum("::test_" in line for line in section) == 5, section
    assert any(line.startswith("XPASS  ") and "test_strict_xpass" in line for line in section), section
    assert any(line.startswith("5 relations: ") for line in section), section
    assert any(line.startswith("time ") and "since pytest loaded pytest-n2r" in line for line in section), section


def test_at_qq_a_failure_below_the_floor_keeps_its_floor_warning(n2r_project):
    """-qq drops the plain floor lines but keeps the warnings (eps below the floor) of relations shown."""
    n2r_project.write("""
from pytest_n2r.metrics import repeatability
from tests.plugin.fakefield import corners


@metamorphic(repeatability(px=2), eps=0.01, transform=transforms(x=(0.1, 0.2)), examples=3)
def test_turn(n2r_scene):
    return corners
""")
    result = n2r_project.run("--n2r-scene", "tests.plugin.fakefield:blurred_plane", "-qq")
    assert result.ret == 1
    assert any(line.startswith("       field floor") and "WARNING: eps 0.01 is below the field floor" in line
               for line in result.outlines), "\n".join(result.outlines)
