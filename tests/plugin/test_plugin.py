"""The pytest plugin end to end, with pytester and the fake plane scenes (tiny renders, fast)."""

from __future__ import annotations

import json
import re
from types import SimpleNamespace

import pytest

PLANE = "tests.plugin.fakescene:plane"
RAMP = "tests.plugin.fakescene:ramp"


def test_a_relation_that_holds_passes(n2r_project):
    n2r_project.write("""
@metamorphic(AbsDifference(), eps=60, transform=transforms(yaw=4, x=0.05), examples=20)
def test_mean_colour(n2r_scene):
    return mean_colour
""")
    result = n2r_project.run("--n2r-scene", PLANE)
    result.assert_outcomes(passed=1)
    line = n2r_project.summary(result, "test_mean_colour[plane]")
    assert "20 examples" in line and "0 inconsistent" in line, line
    assert re.search(r"time render [\d.]+ s / SUT [\d.]+ s / metric [\d.]+ s", line), line


def test_a_sut_breaking_beyond_5_degrees_is_reported_near_5_degrees(n2r_project):
    n2r_project.write("""
@metamorphic(SameLabel(), eps=0.5, transform=transforms(yaw=20), examples=60)
def test_heading(n2r_scene):
    return heading_class
""")
    result = n2r_project.run("--n2r-scene", RAMP)
    result.assert_outcomes(failed=1)
    text = result.stdout.str()
    yaw = float(re.search(r"transform:\s+yaw=([+-][\d.]+)°", text).group(1))
    assert 5.0 < abs(yaw) <= 5.5, f"shrunk to yaw={yaw}, expected within 0.5° of 5°:\n{text}"
    for words in ("scene:      ramp", "source:     view", "score 0, deviation 1 > eps 0.5", "images:"):
        assert words in text, f"{words!r} missing from the failure:\n{text}"
    pictures = re.findall(r"(?:source|follow)\s+(\S+\.png)", text)
    assert len(pictures) == 2 and all((n2r_project.pytester.path / p).is_file() for p in pictures), pictures
    assert all(p.startswith("n2r-artifacts/") for p in pictures), f"paths not relative to where pytest ran: {pictures}"


def test_the_database_replays_the_last_failure_first(n2r_project):
    n2r_project.write("""
@metamorphic(SameLabel(), eps=0.5, transform=transforms(yaw=20), examples=60)
def test_heading(n2r_scene):
    return heading_class
""")
    first = n2r_project.run("--n2r-scene", RAMP, "--n2r-json", "first.json")
    second = n2r_project.run("--n2r-scene", RAMP, "--n2r-json", "second.json")
    second.assert_outcomes(failed=1)
    (before,) = json.loads((n2r_project.pytester.path / "first.json").read_text())["relations"]
    (after,) = json.loads((n2r_project.pytester.path / "second.json").read_text())["relations"]
    replayed = after["examples"][0]  # the second run's first draw is the saved failure
    assert replayed["transform"] == before["minimal"]["transform"] and not replayed["passed"], replayed
    minimal = re.compile(r"transform:\s+(.*)\(minimal")
    assert minimal.search(first.stdout.str()).group(1) == minimal.search(second.stdout.str()).group(1)
    # the SUT fixed: the run that passes drops the saved failure, so the run after it does not replay it first
    n2r_project.write("""
@metamorphic(SameLabel(), eps=0.5, transform=transforms(yaw=20), examples=60)
def test_heading(n2r_scene):
    return lambda rgb: 0
""")
    n2r_project.run("--n2r-scene", RAMP).assert_outcomes(passed=1)
    n2r_project.run("--n2r-scene", RAMP, "--n2r-json", "fourth.json").assert_outcomes(passed=1)
    (fourth,) = json.loads((n2r_project.pytester.path / "fourth.json").read_text())["relations"]
    assert fourth["examples"][0]["transform"] != before["minimal"]["transform"], (
        f"the fixed failure {before['minimal']['transform']} was still replayed first")


@pytest.mark.parametrize(
    ("decorator", "message"),
    [
        ("@metamorphic(AbsDifference(), eps=-0.1, transform=transforms(yaw=5))",
         "eps=-0.1 must be a finite number >= 0"),
        ("@metamorphic(AbsDifference(), eps=float('nan'), transform=transforms(yaw=5))", "eps=nan must be a finite"),
        ("@metamorphic('no_such_metric', eps=0.1, transform=transforms(yaw=5))",
         "unknown metric 'no_such_metric'; known: class_invariance"),
        ("@metamorphic(AbsDifference(), eps=0.1, transform='tau9')", "transform='tau9' is not a preset"),
        ("@metamorphic(AbsDifference(), eps=0.1, transform=transforms(yaw=5), search='hard')", "search='hard'"),
        ("@metamorphic(AbsDifference(), eps=0.1, transform=transforms(yaw=5), size='big')",
         "size='big' is not a render size"),
    ],
)
def test_bad_relation_arguments_are_collection_errors_naming_the_test(n2r_project, decorator, message):
    n2r_project.write(f"""
{decorator}
def test_bad(n2r_scene):
    return mean_colour
""")
    result = n2r_project.run("--n2r-scene", PLANE)
    result.assert_outcomes(errors=1)
    result.stdout.fnmatch_lines([f"*test_relations.py::test_bad: @metamorphic(...): *{message}*"])


def test_an_async_relation_test_is_a_collection_error(n2r_project):
    """An ``async def`` test returned a coroutine: the run failed with "it returned <coroutine ...>" and Python
    warned that it was never awaited."""
    n2r_project.write("""
@metamorphic(AbsDifference(), eps=0.1, transform=transforms(yaw=5))
async def test_bad(n2r_scene):
    return mean_colour
""")
    result = n2r_project.run("--n2r-scene", PLANE)
    result.assert_outcomes(errors=1)
    result.stdout.fnmatch_lines(["*test_relations.py::test_bad: @metamorphic(...): test_bad is async; *plain def*"])


def test_two_relations_on_one_test_are_a_collection_error(n2r_project):
    """The outer @metamorphic replaced the inner one: a strict relation the SUT breaks passed unchecked."""
    n2r_project.write("""
@metamorphic(AbsDifference(), eps=1000, transform=transforms(yaw=5))
@metamorphic(AbsDifference(), eps=0.0, transform=transforms(yaw=5))
def test_two(n2r_scene):
    return mean_colour
""")
    result = n2r_project.run("--n2r-scene", PLANE)
    result.assert_outcomes(errors=1)
    result.stdout.fnmatch_lines([("*test_relations.py::test_two: @metamorphic(...): test_two was given two "
                                  "relations (two @metamorphic decorators*write a test for each*")])


def test_a_relation_above_staticmethod_runs(n2r_project):
    """@metamorphic above @staticmethod set its relation on the staticmethod object: the test ran unchecked and
    passed (with pytest's "returned not None" warning), bad arguments included."""
    n2r_project.write("""
class TestStatic:
    @metamorphic(AbsDifference(), eps=0.0, transform=transforms(yaw=(2, 5)), examples=3)
    @staticmethod
    def test_breaks(n2r_scene):
        return mean_colour


class TestBad:
    @metamorphic(AbsDifference(), eps=-1, transform=transforms(yaw=5))
    @staticmethod
    def test_bad_eps(n2r_scene):
        return mean_colour
""")
    result = n2r_project.run("--n2r-scene", PLANE, "--continue-on-collection-errors")
    result.assert_outcomes(failed=1, errors=1)
    result.stdout.fnmatch_lines(["*TestBad::test_bad_eps: @metamorphic(...): eps=-1*"])
    assert "metamorphic relation violated" in result.stdout.str(), result.stdout.str()


@pytest.mark.parametrize("decorator", ["@settings(max_examples=3)", "@example(view=None, tau=None)"])
@pytest.mark.parametrize("above", [True, False], ids=["above", "below"])
def test_hypothesis_decorators_on_a_relation_test_say_what_to_use_instead(n2r_project, decorator, above):
    """Hypothesis said only "Using `@settings` on a test without `@given` is completely pointless"."""
    relation = "@metamorphic(AbsDifference(), eps=0.1, transform=transforms(yaw=5))"
    stack = "\n".join([decorator, relation] if above else [relation, decorator])
    n2r_project.write(f"""
from hypothesis import example, settings


{stack}
def test_bad(n2r_scene):
    return mean_colour
""")
    result = n2r_project.run("--n2r-scene", PLANE)
    result.assert_outcomes(errors=1)
    expected = (f"*test_bad: {decorator.split('(')[0]} does not apply to a @metamorphic test*"
                "@metamorphic(examples=...) or --n2r-examples*")
    result.stdout.fnmatch_lines([expected])


def test_parametrizing_n2r_scene_by_hand_says_to_pin_scenes_with_the_marker(n2r_project):
    """pytest said only "duplicate parametrization of 'n2r_scene'"."""
    n2r_project.write("""
import pytest


@pytest.mark.parametrize("n2r_scene", ["plane"], indirect=True)
def test_scene(n2r_scene):
    pass
""")
    result = n2r_project.run("--n2r-scene", PLANE)
    result.assert_outcomes(errors=1)
    result.stdout.fnmatch_lines(["*n2r_scene is parametrized by pytest-n2r*@pytest.mark.n2r_scene(...)*"])


def test_bad_bounds_fail_collection_with_the_bound_named(n2r_project):
    n2r_project.write("""
@metamorphic(AbsDifference(), eps=0.1, transform=transforms(yaw=(10, -10)))
def test_bad(n2r_scene):
    return mean_colour
""")
    result = n2r_project.run("--n2r-scene", PLANE)
    result.assert_outcomes(errors=1)
    result.stdout.fnmatch_lines(["*InvalidArgument: yaw=(10, -10) has lo > hi; write yaw=(-10, 10)*"])


@pytest.mark.parametrize(
    ("args", "message"),
    [
        (["--n2r-scene", "missing.n2r"], "--n2r-scene 'missing.n2r': no such file"),
        (["--n2r-scene", "notascene.txt"], "is not a scene file"),
        (["--n2r-scene", RAMP, "--n2r-size", "huge"],
         "--n2r-size / ini n2r_size: n2r_size='huge' is not a render size"),
        (["--n2r-scene", RAMP, "--n2r-examples", "0"], "--n2r-examples / ini n2r_examples: '0' is not a whole number"),
        (["--n2r-scene", RAMP, "--n2r-timeout", "-1"], "--n2r-timeout / ini n2r_timeout"),
        (["--n2r-scene", RAMP, "--n2r-cache-size", "lots"], "n2r_cache_size='lots' is not a size"),
        (["--n2r-scene", RAMP, "--n2r-render-scale", "2"],
         "--n2r-render-scale / ini n2r_render_scale: '2' is not a fraction in [0.1, 1]"),
    ],
)
def test_bad_options_are_usage_errors(n2r_project, args, message):
    (n2r_project.pytester.path / "notascene.txt").write_text("hello")
    n2r_project.write("""
def test_nothing():
    pass
""")
    result = n2r_project.run(*args)
    assert result.ret == pytest.ExitCode.USAGE_ERROR, result.stderr.str()
    assert message in result.stderr.str(), result.stderr.str()


def test_an_ini_glob_that_matches_nothing_is_a_usage_error(n2r_project):
    n2r_project.pytester.makeini("[pytest]\nn2r_scenes = scenes/*.n2r\n")
    n2r_project.write("def test_nothing():\n    pass\n")
    result = n2r_project.run()
    assert result.ret == pytest.ExitCode.USAGE_ERROR
    assert "ini n2r_scenes 'scenes/*.n2r' matched no file" in result.stderr.str()


@pytest.mark.parametrize(
    ("ini", "cli", "kwarg", "expected"),
    [
        (None, None, None, 50),  # the default
        (7, None, None, 7),  # ini
        (7, 5, None, 5),  # CLI beats ini
        (7, 5, 3, 3),  # marker keyword beats both
        (None, None, 4, 4),
    ],
)
def test_examples_precedence_marker_over_cli_over_ini(n2r_project, ini, cli, kwarg, expected):
    if ini is not None:
        n2r_project.pytester.makeini(f"[pytest]\nn2r_examples = {ini}\n")
    examples = "" if kwarg is None else f", examples={kwarg}"
    n2r_project.write(f"""
@metamorphic(AbsDifference(), eps=255, transform=transforms(yaw=3){examples})
def test_count(n2r_scene):
    return mean_colour
""")
    args = ["--n2r-scene", PLANE] + ([] if cli is None else ["--n2r-examples", str(cli)])
    result = n2r_project.run(*args)
    result.assert_outcomes(passed=1)
    line = n2r_project.summary(result, "test_count[plane]")
    assert f": {expected} example" in line, f"expected {expected} examples: {line}"


def test_scene_precedence_marker_over_cli_over_ini(n2r_project):
    n2r_project.pytester.makeini(f"[pytest]\nn2r_scenes = {PLANE}\n")
    n2r_project.write(f"""
def test_configured(n2r_scene):
    pass


@pytest.mark.n2r_scene({PLANE!r})
def test_pinned(n2r_scene):
    assert n2r_scene.name == "plane"
""")
    from_ini = n2r_project.run("-v")
    from_ini.stdout.fnmatch_lines(["*test_configured[[]plane[]] PASSED*", "*test_pinned[[]plane[]] PASSED*"])
    from_cli = n2r_project.run("-v", "--n2r-scene", RAMP)
    from_cli.stdout.fnmatch_lines(["*test_configured[[]ramp[]] PASSED*", "*test_pinned[[]plane[]] PASSED*"])


def test_every_configured_scene_parametrizes_the_fixture_and_a_pin_selects_one(n2r_project):
    n2r_project.write("""
def test_all(n2r_scene):
    pass


@pytest.mark.n2r_scene("ramp")
def test_ramp_only(n2r_scene):
    assert n2r_scene.name == "ramp"
""", name="test_scenes")
    result = n2r_project.run("-v", "--n2r-scene", PLANE, "--n2r-scene", RAMP)
    result.assert_outcomes(passed=3)
    for test in ("test_all[plane]", "test_all[ramp]", "test_ramp_only[ramp]"):
        assert f"test_scenes.py::{test} PASSED" in result.stdout.str(), test


def test_the_closest_pin_decides_and_a_scene_pinned_twice_runs_once(n2r_project):
    """Pins of every level were added up: a function pinned to "ramp" in a module pinned to "plane" ran on both, and
    a method pinned to "plane" in a class and module pinned to it ran three times, as test_dup[plane0..2] (its id
    changing when a pin was added elsewhere, so a baseline called it missing)."""
    n2r_project.write(f"""
pytestmark = pytest.mark.n2r_scene("plane")


@pytest.mark.n2r_scene("ramp")
def test_only_ramp(n2r_scene):
    assert n2r_scene.name == "ramp"


def test_module_pin(n2r_scene):
    assert n2r_scene.name == "plane"


@pytest.mark.n2r_scene("plane")
class TestPinned:
    @pytest.mark.n2r_scene("plane", {PLANE!r})
    def test_dup(self, n2r_scene):
        pass


@pytest.mark.n2r_scene("plane")
@pytest.mark.n2r_scene("ramp")
def test_stacked(n2r_scene):
    pass
""", name="test_scenes")
    result = n2r_project.run("-v", "--n2r-scene", PLANE, "--n2r-scene", RAMP)
    result.assert_outcomes(passed=5)
    # two marks of one level both count (stacked here; a pytestmark list alike)
    for test in ("test_only_ramp[ramp]", "test_module_pin[plane]", "TestPinned::test_dup[plane]",
                 "test_stacked[plane]", "test_stacked[ramp]"):
        assert f"test_scenes.py::{test} PASSED" in result.stdout.str(), f"{test} did not run:\n{result.stdout.str()}"


#: An inner conftest's lines that log every scene load (process id and scene) to loads.txt in the project.
COUNT_LOADS = """
import os

import pytest_n2r.plugin.session as n2r_session_module

_load = n2r_session_module.load_scene_spec


def _counted(spec, *args, **kwargs):
    with open(os.path.join(os.path.dirname(__file__), "loads.txt"), "a") as log:
        log.write(f"{os.getpid()} {spec.name}\\n")
    return _load(spec, *args, **kwargs)


n2r_session_module.load_scene_spec = _counted


def pytest_unconfigure(config):
    n2r_session_module.load_scene_spec = _load
"""


def _loads(n2r_project) -> list[str]:
    return (n2r_project.pytester.path / "loads.txt").read_text().splitlines()


def test_a_scene_is_kept_to_its_last_test_and_released_after_it(n2r_project):
    """Every scene a session loaded stayed in memory to its end: a fitted scene and its renderer hold some 450 MB.
    Then each scene was released whenever pytest switched scenes, which is not only after its last test: pytest
    groups a session fixture's tests by the index of their parameter, so a test pinned to the second scene ran among
    the first scene's tests, and each scene was loaded twice (a fitted scene's first render costs again 0.66 s, a
    module:function scene runs its function again). Now a scene is loaded once, kept while tests on other scenes
    come between, and released after its last test, while the next scene's tests run."""
    conftest = n2r_project.pytester.path / "conftest.py"
    conftest.write_text(conftest.read_text() + COUNT_LOADS + '''
import pytest

# the order pytest gives these tests (the pinned test has the first parameter index): kept whatever its version does
ORDER = ["test_first[plane]", "test_pinned[ramp]", "test_last[plane]", "test_first[ramp]", "test_last[ramp]"]


@pytest.hookimpl(trylast=True)
def pytest_collection_modifyitems(items):
    items.sort(key=lambda item: ORDER.index(item.name))
''')
    n2r_project.write("""
import weakref

SEEN = {}


def test_first(n2r_scene):
    SEEN.setdefault(n2r_scene.name, weakref.ref(n2r_scene))
    if n2r_scene.name == "ramp":
        assert SEEN["plane"]() is None, "the plane scene is still held after its last test"


@pytest.mark.n2r_scene("ramp")
def test_pinned(n2r_scene):
    SEEN["ramp"] = weakref.ref(n2r_scene)


@metamorphic(AbsDifference(), eps=60, transform=transforms(yaw=4, x=0.05), examples=5)
def test_last(n2r_scene):
    assert SEEN[n2r_scene.name]() is n2r_scene, f"the {n2r_scene.name} scene was loaded again"
    return mean_colour
""", name="test_scenes")
    result = n2r_project.run("-v", "--n2r-scene", PLANE, "--n2r-scene", RAMP)
    result.stdout.fnmatch_lines([f"*{name.replace('[', '[[]')} PASSED*" for name in (
        "test_first[plane]", "test_pinned[ramp]", "test_last[plane]", "test_first[ramp]", "test_last[ramp]")])
    result.assert_outcomes(passed=5)
    assert [line.split()[1] for line in _loads(n2r_project)] == ["plane", "ramp"]


def test_an_xdist_worker_running_the_tests_file_by_file_loads_each_scene_once(n2r_project):
    """Under ``-n 2 --dist loadfile`` a worker runs a file's tests on every scene, then the next file's: each
    switch of scene released the other one, and a worker loaded each scene once per file (16 loads for 8 files
    instead of 4). Released at the run's last test on it, a scene still came back: xdist hands out the largest
    file first, so the worker running the last file met the last tests early. It now keeps its scenes to its end."""
    conftest = n2r_project.pytester.path / "conftest.py"
    conftest.write_text(conftest.read_text() + COUNT_LOADS)
    for number in range(6):
        n2r_project.write("""
import time

def test_scene(n2r_scene):
    time.sleep(0.2)
""", name=f"test_file{number}")
    n2r_project.write("""
import pytest

@pytest.mark.parametrize("k", range(5))
def test_scene(n2r_scene, k):
    pass
""", name="test_last")  # the largest file and the last in the run's order
    result = n2r_project.run("--n2r-scene", PLANE, "--n2r-scene", RAMP, "-n", "2", "--dist", "loadfile",
                             "-p", "no:benchmark")
    result.assert_outcomes(passed=22)
    loads = _loads(n2r_project)
    assert len(loads) == len(set(loads)) >= 2, f"a worker loaded a scene again: {sorted(loads)}"


def test_a_worker_releases_a_scene_once_past_its_last_test_of_the_run(monkeypatch):
    """A pytest-xdist worker runs some of the run's tests: under ``--dist load`` (and ``each``) in the run's order,
    so a scene whose last test another worker runs is released as soon as this worker is past it (not kept to the
    worker's end); under ``loadfile`` (whole files, the largest first) only at the worker's end. A released scene is not
    loaded again to compile its kernel pieces apart while a first render waits."""
    from pytest_n2r.plugin.precompile import compile_apart_meanwhile
    from pytest_n2r.plugin.session import N2RSession

    session = N2RSession()
    plane, ramp = session.scene_specs([PLANE, RAMP])
    run = [("a", plane), ("b", ramp), ("c", plane), ("d", None), ("e", ramp)]
    session.plan(run, dist="load")
    scene = session.load(plane)
    assert session.release_done("a", "b") == []  # its test c may be this worker's
    assert session.release_done("b", "d") == [scene] and session.released == {plane.source}  # c was another's
    assert session.release_done("d", None) == [] and session.released == {plane.source, ramp.source}

    session.plan(run, dist="loadfile")
    scene = session.load(plane)
    assert session.release_done("a", "e") == []  # c may come later, with its file
    assert session.release_done("c", "b") == []  # so may a, with another file
    assert session.release_done("b", None) == [scene]

    demo = N2RSession()
    wall, objects = demo.scene_specs(["demo:wall", "demo:object"])
    demo.plan([("a", wall), ("b", objects)])
    demo.release_done("a", "b")
    loaded = []
    monkeypatch.setattr(demo, "load", lambda spec: loaded.append(spec.name) or SimpleNamespace(compile_apart=list))
    compile_apart_meanwhile(demo, None)
    assert loaded == ["object"], "a released scene was loaded again for its kernel pieces"


def test_n2r_scene_where_it_cannot_be_parametrized_says_so(n2r_project):
    """A @metamorphic unittest.TestCase method and request.getfixturevalue("n2r_scene") were skipped with "no scene
    configured for pytest-n2r: pass --n2r-scene", though a scene was configured: the relation never ran."""
    n2r_project.write("""
import unittest


class T(unittest.TestCase):
    @metamorphic(AbsDifference(), eps=0.0, transform=transforms(yaw=5), examples=3)
    def test_ut(self):
        return mean_colour


def test_dynamic(request):
    request.getfixturevalue("n2r_scene")
""")
    result = n2r_project.run("--n2r-scene", PLANE)
    result.assert_outcomes(failed=1, errors=1)
    assert "no scene configured" not in result.stdout.str(), result.stdout.str()
    assert result.stdout.str().count("n2r_scene was requested where pytest-n2r cannot parametrize it") == 2, (
        result.stdout.str())


def test_a_users_own_n2r_scene_fixture_is_not_parametrized_over_the_configured_scenes(n2r_project):
    """An n2r_scene fixture of the user's replaced pytest-n2r's, yet the test was still parametrized over the
    configured scenes: it ran once per configured scene, each time on the user's scene, under ids and failure-picture
    folders named after scenes it never saw. A fixture that wraps pytest-n2r's (requests n2r_scene) keeps them."""
    n2r_project.write("""
from tests.plugin.fakescene import PlaneScene


@pytest.fixture(scope="session")
def n2r_scene():
    return PlaneScene(name="mine", texture="ramp")


@metamorphic(AbsDifference(), eps=1000, transform=transforms(yaw=5), examples=3)
def test_own(n2r_scene):
    assert n2r_scene.name == "mine"
    return mean_colour
""", name="test_own")
    n2r_project.write("""
@pytest.fixture(scope="session")
def n2r_scene(n2r_scene):
    return n2r_scene


@metamorphic(AbsDifference(), eps=1000, transform=transforms(yaw=5), examples=3)
def test_wrapped(n2r_scene):
    return mean_colour
""", name="test_wrapped")
    result = n2r_project.run("-v", "--n2r-scene", PLANE, "--n2r-scene", RAMP)
    result.assert_outcomes(passed=3)
    for test in ("test_own.py::test_own PASSED", "test_wrapped.py::test_wrapped[plane] PASSED",
                 "test_wrapped.py::test_wrapped[ramp] PASSED"):
        assert test in result.stdout.str(), f"{test!r} not in:\n{result.stdout.str()}"


def test_pinning_an_unconfigured_scene_is_a_collection_error_naming_the_test(n2r_project):
    n2r_project.write("""
@pytest.mark.n2r_scene("kitchen")
def test_unknown(n2r_scene):
    pass
""", name="test_scenes")
    result = n2r_project.run("--n2r-scene", PLANE, "--n2r-scene", RAMP)
    result.assert_outcomes(errors=1)
    result.stdout.fnmatch_lines([("test_scenes.py::test_unknown: n2r_scene marker names the scene 'kitchen', which "
                                  "is not configured (configured: plane, ramp)*")])


def test_a_sut_that_raises_shows_its_traceback_and_the_transform(n2r_project):
    n2r_project.write("""
def fragile(rgb):
    if heading_class(rgb) != 0:
        raise ValueError("lost track")
    return 0


@metamorphic(SameLabel(), eps=0.5, transform=transforms(yaw=20), examples=60)
def test_fragile(n2r_scene):
    return fragile
""")
    result = n2r_project.run("--n2r-scene", RAMP)
    result.assert_outcomes(failed=1)
    result.stdout.fnmatch_lines([
        "*raise ValueError(\"lost track\")*",
        ("*SUTError: the system under test raised ValueError: lost track -- on the follow-up view "
         "(scene 'ramp', source view 'view*', yaw=+5.010°)*"),
    ])


@pytest.mark.parametrize(
    ("sut", "message"),
    [
        ("lambda rgb: None", "the system under test returned None on the source view*expected a class label"),
        ("lambda rgb: float('nan')", "the system under test returned nan on the source view*"),
        ("lambda rgb: np.full(3, np.nan)", "*array of shape (3,) with 3 NaN/Inf value(s)*"),
        ("lambda rgb: [1, 2]", "*SUTOutputError: SameLabel() cannot use the SUT's output*compares class labels*"),
    ],
)
def test_bad_sut_outputs_name_what_was_expected(n2r_project, sut, message):
    n2r_project.write(f"""
@metamorphic(SameLabel(), eps=0.5, transform=transforms(yaw=2), examples=5)
def test_output(n2r_scene):
    return {sut}
""")
    result = n2r_project.run("--n2r-scene", RAMP)
    result.assert_outcomes(failed=1)
    result.stdout.fnmatch_lines([f"*{message}*"])


def test_a_test_that_returns_no_sut_fails_clearly(n2r_project):
    n2r_project.write("""
@metamorphic(SameLabel(), eps=0.5, transform=transforms(yaw=2))
def test_forgot(n2r_scene):
    heading_class
""")
    result = n2r_project.run("--n2r-scene", RAMP)
    result.assert_outcomes(failed=1)
    result.stdout.fnmatch_lines(["*test_forgot*a @metamorphic test must return the system under test*returned None*"])


def test_bounds_that_leave_the_captured_region_are_an_error_not_a_pass(n2r_project):
    n2r_project.write("""
@metamorphic(AbsDifference(), eps=255, transform=transforms(yaw=(60, 80)), examples=10)
def test_far(n2r_scene):
    return mean_colour
""")
    result = n2r_project.run("--n2r-scene", PLANE)
    result.assert_outcomes(failed=1)
    result.stdout.fnmatch_lines(
        ["*leaves what the scene 'plane' can render faithfully in 100% of * draws (empty view: *narrow the bounds*"])
    assert "rejected as invalid (" in n2r_project.summary(result, "test_far[plane]")
    assert "look_at=True" not in result.stdout.str(), "look_at changes nothing for a turn without a move"
    result.stdout.fnmatch_lines(["*If even small motions leave it, the scene covers little beyond its own views*"])


def test_a_relation_with_no_valid_example_fails_even_when_any_share_of_rejections_is_allowed(n2r_project):
    n2r_project.write("""
from pytest_n2r import Validity


@metamorphic(AbsDifference(), eps=255, transform=transforms(yaw=(80, 89)), examples=5,
             validity=Validity(max_rejected=1.0))
def test_tolerant(n2r_scene):
    return mean_colour
""")
    result = n2r_project.run("--n2r-scene", PLANE)
    assert result.parseoutcomes().get("passed", 0) == 0, "a relation that compared nothing must not pass"
    result.assert_outcomes(failed=1)
    result.stdout.fnmatch_lines([("*in 100% of * draws (empty view: *): no follow-up view was valid, so nothing was "
                                  "compared*")])


def test_a_second_run_renders_nothing(n2r_project):
    n2r_project.write("""
@metamorphic(AbsDifference(), eps=60, transform=transforms(yaw=4, x=0.05), examples=15)
def test_a(n2r_scene):
    return mean_colour


@pytest.mark.n2r_scene("ramp")
@metamorphic(SameLabel(), eps=0.5, transform=transforms(yaw=3), examples=15)
def test_b(n2r_scene):
    return heading_class
""")
    n2r_project.run("--n2r-scene", PLANE, "--n2r-scene", RAMP, "--n2r-derandomize", "yes").assert_outcomes(passed=3)
    cold = n2r_project.renders()
    assert cold > 0
    result = n2r_project.run("--n2r-scene", PLANE, "--n2r-scene", RAMP, "--n2r-derandomize", "yes")
    result.assert_outcomes(passed=3)
    assert n2r_project.renders() == cold, f"the warm run rendered {n2r_project.renders() - cold} views"
    result.stdout.fnmatch_lines(["*3 relations: * 0 renders (the rest from the cache)*"])
    n2r_project.run("--n2r-scene", PLANE, "--n2r-scene", RAMP, "--n2r-derandomize", "yes", "--n2r-cache-clear")
    assert n2r_project.renders() == 2 * cold, "--n2r-cache-clear should have forced every render again"


def test_hypothesis_seed_reproduces_the_draws_of_a_run(n2r_project, monkeypatch, tmp_path):
    from hypothesis import core

    # the inner runs are in this process: Hypothesis's pytest plugin sets its global seed and never unsets it
    monkeypatch.setattr(core, "global_force_seed", None)
    n2r_project.write("""
@metamorphic(AbsDifference(), eps=255, transform=transforms(yaw=4, x=0.05), examples=8)
def test_a(n2r_scene):
    return mean_colour
""")

    def drawn(*args: str) -> list:
        out = tmp_path / "run.json"
        # --n2r-json=PATH in one argument: pytest takes an existing path argument into its choice of rootdir
        n2r_project.run("--n2r-scene", PLANE, "--n2r-cache-dir", "none", f"--n2r-json={out}",
                        *args).assert_outcomes(passed=1)
        [record] = json.loads(out.read_text())["relations"]
        return [(e["view"], e["transform"]) for e in record["examples"]]

    first, again, other = drawn("--hypothesis-seed=1"), drawn("--hypothesis-seed=1"), drawn("--hypothesis-seed=2")
    assert first == again, f"the same --hypothesis-seed drew other examples:\n{first}\n{again}"
    assert first != other, f"--hypothesis-seed=1 and 2 drew the same examples: {first}"


def test_ci_derandomizes(n2r_project, monkeypatch):
    n2r_project.write("""
@metamorphic(AbsDifference(), eps=60, transform=transforms(yaw=4), examples=10)
def test_a(n2r_scene):
    return mean_colour
""")
    monkeypatch.setenv("CI", "true")
    n2r_project.run("--n2r-scene", PLANE, "--n2r-cache-dir", "none")
    first = n2r_project.renders()
    n2r_project.run("--n2r-scene", PLANE, "--n2r-cache-dir", "none")
    assert n2r_project.renders() == 2 * first
    log = n2r_project.render_log.read_text().splitlines()
    assert len(log) == 2 * first  # same number of renders each run: the same examples


def test_xdist_gives_the_serial_verdicts_and_shares_the_cache(n2r_project):
    pytest.importorskip("xdist")
    n2r_project.write("""
@metamorphic(AbsDifference(), eps=60, transform=transforms(yaw=4), examples=10)
def test_holds(n2r_scene):
    return mean_colour


@metamorphic(SameLabel(), eps=0.5, transform=transforms(yaw=20), examples=30)
def test_breaks(n2r_scene):
    return heading_class
""")
    args = ["--n2r-scene", RAMP, "--n2r-derandomize", "yes", "-rA", "-p", "no:benchmark"]
    serial = n2r_project.run(*args)
    serial.assert_outcomes(passed=1, failed=1)
    cold = n2r_project.renders()
    parallel = n2r_project.run(*args, "-n", "2")
    parallel.assert_outcomes(passed=1, failed=1)
    verdicts = re.compile(r"^(PASSED|FAILED) (\S+)")
    assert sorted(m.groups() for m in map(verdicts.match, serial.outlines) if m) == \
        sorted(m.groups() for m in map(verdicts.match, parallel.outlines) if m)
    assert n2r_project.renders() == cold, "the xdist workers should have found every render in the shared cache"
    parallel.stdout.fnmatch_lines(["*transform:  yaw=+5.010°*"])


def test_header_lists_scenes_device_threads_and_cache(n2r_project):
    """Run in this process, where torch is loaded: "auto" is shown with the device it chooses."""
    import torch

    n2r_project.write("def test_nothing():\n    pass\n")
    result = n2r_project.run("--n2r-scene", PLANE, "--n2r-cache-dir", "mycache")
    chosen = "cuda" if torch.cuda.is_available() else "cpu"
    result.stdout.fnmatch_lines([f"n2r: scenes plane; device auto ({chosen}); torch threads *; cache */mycache"])


def test_header_does_not_load_torch_to_name_the_device(n2r_project):
    n2r_project.write("def test_nothing():\n    pass\n")
    result = n2r_project.pytester.runpytest_subprocess("-p", "no:cacheprovider", "--n2r-scene", PLANE)
    result.stdout.fnmatch_lines(["n2r: scenes plane; device auto; torch not loaded; cache *"])


def test_the_plugin_does_nothing_when_unused(n2r_project):
    n2r_project.pytester.makepyfile(test_plain="""
import sys

def test_plain():
    loaded = sorted(m for m in sys.modules if m.startswith("pytest_n2r."))
    # the plugin, its option registry and its path parsers, the two leaf modules that registry reads, the plugin's
    # two hook modules (its reports; the test order under xdist), its terminal summary and its garbage collector's
    # cleanup (gc and pytest alone), and the package's check that numba can cache its kernels: nothing of the engine
    assert loaded == ["pytest_n2r.defaults", "pytest_n2r.errors", "pytest_n2r.kernel_cache", "pytest_n2r.plugin",
                      "pytest_n2r.plugin.garbage_collector", "pytest_n2r.plugin.options",
                      "pytest_n2r.plugin.path_options", "pytest_n2r.plugin.report",
                      "pytest_n2r.plugin.schedule", "pytest_n2r.plugin.summary"], loaded
""")
    result = n2r_project.pytester.runpytest_subprocess("-p", "no:cacheprovider")
    result.assert_outcomes(passed=1)
    assert "n2r:" not in result.stdout.str() and "pytest-n2r" not in result.stdout.str()
    ours = [p.name for p in n2r_project.pytester.path.rglob("*") if "n2r" in p.name.lower()]
    assert not ours, f"an unused plugin left files behind: {ours}"


def test_p_no_n2r_disables_the_plugin(n2r_project):
    n2r_project.pytester.makepyfile(test_plain="def test_plain():\n    pass\n")
    n2r_project.pytester.runpytest("-p", "no:n2r").assert_outcomes(passed=1)
    result = n2r_project.pytester.runpytest("-p", "no:n2r", "--n2r-scene", PLANE)
    assert result.ret == pytest.ExitCode.USAGE_ERROR and "unrecognized arguments: --n2r-scene" in result.stderr.str()


#: A mutation of a test module's own, for inner test files (a relation's transform draws it).
DARKEN = """
from dataclasses import dataclass
from typing import ClassVar

from hypothesis import strategies as st
from pytest_n2r.strategies import Mutation


@dataclass(frozen=True, repr=False)
class Darken(Mutation):
    amount: float = 0.0
    name: ClassVar[str] = "darken"

    @property
    def is_identity(self):
        return self.amount == 0

    def _apply(self, rgb):
        return (rgb * (1 - self.amount)).astype(np.uint8)

    def describe(self):
        return f"darken(amount={self.amount})"
"""


def test_a_mutation_strategy_as_transform(n2r_project):
    n2r_project.write(DARKEN + """

@metamorphic(AbsDifference(), eps=20, transform=st.integers(0, 100).map(lambda k: Darken(k / 100)), examples=30)
def test_darkening(n2r_scene):
    return mean_colour
""")
    result = n2r_project.run("--n2r-scene", PLANE)
    result.assert_outcomes(failed=1)
    text = result.stdout.str()
    amount = float(re.search(r"mutated by darken\(amount=([\d.]+)\)", text).group(1))
    assert 0.05 < amount < 0.3, f"shrunk to darken(amount={amount}):\n{text}"


def test_targeted_search_runs_and_reports(n2r_project):
    n2r_project.write("""
@metamorphic(AbsDifference(), eps=60, transform=transforms(yaw=4), examples=15, search="targeted")
def test_targeted(n2r_scene):
    return mean_colour
""")
    result = n2r_project.run("--n2r-scene", PLANE)
    result.assert_outcomes(passed=1)
    assert "15 examples" in n2r_project.summary(result, "test_targeted[plane]")


def test_a_hanging_sut_is_stopped_by_the_time_limit(n2r_project):
    n2r_project.write("""
import time


def hangs(rgb):
    time.sleep(30)


@metamorphic(AbsDifference(), eps=60, transform=transforms(yaw=4), examples=3)
def test_hang(n2r_scene):
    return hangs
""")
    result = n2r_project.run("--n2r-scene", PLANE, "--n2r-timeout", "0.2")
    result.assert_outcomes(failed=1)
    result.stdout.fnmatch_lines([("*the system under test on the source view (*) did not finish within 0.2 s "
                                  "(--n2r-timeout / ini n2r_timeout)*")])
    assert result.duration < 20, f"the hang was not interrupted ({result.duration:.1f} s)"


def test_no_scene_configured_and_no_demo_scene_skips_with_instructions(n2r_project, monkeypatch):
    import pytest_n2r.demo

    monkeypatch.setattr(pytest_n2r.demo, "demo_scene_names", list)
    n2r_project.write("def test_uses_scene(n2r_scene):\n    pass\n")
    result = n2r_project.run("-rs")
    result.assert_outcomes(skipped=1)
    result.stdout.fnmatch_lines(["*no scene configured for pytest-n2r: pass --n2r-scene PATH*n2r_scenes*"])


def test_a_metric_by_name_from_the_registry_with_a_corner_detector(n2r_project):
    n2r_project.write("""
import cv2


def corners(rgb):
    gray = cv2.cvtColor(rgb, cv2.COLOR_RGB2GRAY)
    found = cv2.goodFeaturesToTrack(gray, 50, 0.05, 4)
    return np.zeros((0, 2), np.float32) if found is None else found.reshape(-1, 2)


@metamorphic("repeatability", eps=0.6, transform=transforms(yaw=2), examples=8)
def test_corners(n2r_scene):
    return corners
""")
    result = n2r_project.run("--n2r-scene", PLANE, "--n2r-size", "160x120")
    result.assert_outcomes(passed=1)
    line = n2r_project.summary(result, "test_corners[plane]")
    assert "8 examples" in line and "0 inconsistent" in line, line


def test_relation_records_reach_the_controller_as_plain_data(n2r_project):
    n2r_project.pytester.makeconftest(n2r_project.pytester.path.joinpath("conftest.py").read_text() + """
import json

def pytest_sessionfinish(session):
    from pytest_n2r.plugin import relation_records

    records = relation_records(session.config)
    with open("records.json", "w") as f:
        json.dump([r.to_dict() for r in records], f, default=str)
""")
    n2r_project.write("""
@metamorphic(AbsDifference(), eps=60, transform=transforms(yaw=4), examples=6)
def test_a(n2r_scene):
    return mean_colour
""")
    n2r_project.run("--n2r-scene", PLANE).assert_outcomes(passed=1)
    import json

    (record,) = json.loads((n2r_project.pytester.path / "records.json").read_text())
    assert record["nodeid"].endswith("test_a[plane]") and record["outcome"] == "passed"
    accepted = [e for e in record["examples"] if e["status"] == "accepted"]  # rejected draws are recorded too
    assert len(accepted) == 6 and record["examples"][0]["scene"] == "plane"


def test_n2r_session_lets_a_test_replay_with_the_relations_renders_and_outputs(n2r_project):
    """The ``n2r_session`` fixture (what the example's regression gate uses): its render cache holds the renders
    of the relations that ran before, and a replay passed its SUT outputs calls the SUT on none of them but one."""
    n2r_project.write("""
from pytest_n2r import Relation
from pytest_n2r.relation import replay_relation

calls = []
def counted(rgb):
    calls.append(1)
    return mean_colour(rgb)

RUNS = {}

@metamorphic(AbsDifference(), eps=255, transform=transforms(yaw=4), examples=10)
def test_a_relation(n2r_scene, n2r_session):
    RUNS["relation"] = n2r_session
    return counted

def test_replay_it(n2r_scene, n2r_session):
    (record,) = n2r_session.records
    assert n2r_session is RUNS["relation"], "one session object per pytest session"
    renders, before = n2r_session.cache.stats.renders, len(calls)
    relation = Relation.build(AbsDifference(), 255, transforms(yaw=4))
    replayed = replay_relation(n2r_scene, counted, relation, record.valid_examples, cache=n2r_session.cache,
                               sut_outputs=n2r_session.sut_outputs)
    assert len(replayed.replayed) == len(record.valid_examples) > 0
    assert n2r_session.cache.stats.renders == renders, "the replay rendered again"
    # one call: the check that the SUT object still gives the first output the relation left
    assert len(calls) == before + 1 and replayed.sut_calls == 1, "the replay ran the SUT on renders it had run on"
""")
    result = n2r_project.run("--n2r-scene", PLANE)
    result.assert_outcomes(passed=2)


def test_the_start_up_runs_without_the_cyclic_collector_which_the_first_setup_turns_on_again(n2r_project):
    """The collector is off from the plugin's configuration to the end of the first test's setup (the start-up's
    imports make few cycles), on again after it, and on again after a session that ran no test."""
    import gc

    n2r_project.write("""
import gc

AT_IMPORT = gc.isenabled()


def test_first(n2r_scene):
    assert not AT_IMPORT, "the collector was on while the test modules were imported"
    assert gc.isenabled(), "the collector is still off after the first setup"
""")
    assert gc.isenabled(), "the outer session runs with the collector on"
    n2r_project.run("--n2r-scene", PLANE).assert_outcomes(passed=1)
    assert gc.isenabled(), "the collector is off after the session"
    n2r_project.run("--n2r-scene", PLANE, "--collect-only")
    assert gc.isenabled(), "the collector is off after a session that ran no test"


def test_what_a_session_loaded_is_frozen_out_of_the_garbage_collectors_way(n2r_project):
    """The heap is frozen after the first setup on a scene, but garbage is collected first: an unreachable
    cycle that was frozen would never be freed."""
    n2r_project.write("""
import gc
import weakref

gc.unfreeze()  # at collection: an earlier run in this process may have frozen objects already
gc.disable()  # so that nothing but the plugin collects the cycle below


class Node:
    pass


def _garbage():
    node = Node()
    node.me = node
    return weakref.ref(node)


GARBAGE = _garbage()


def test_setup_froze_the_heap_and_no_garbage(n2r_scene):
    gc.enable()
    assert gc.get_freeze_count() > 0, "nothing frozen after the setup of a test on n2r_scene"
    assert GARBAGE() is None, "an unreachable cycle was frozen instead of collected"
""")
    result = n2r_project.run("--n2r-scene", PLANE)
    result.assert_outcomes(passed=1)


def test_a_sut_output_the_metric_cannot_use_is_a_short_failure_naming_the_example(n2r_project):
    """An output of the wrong type failed with a 40-line traceback through pytest-n2r's engine."""
    n2r_project.write("""
from pytest_n2r import metamorphic, transforms
from pytest_n2r.metrics import class_invariance


@metamorphic(class_invariance(), eps=0.5, transform=transforms(yaw=5), examples=3)
def test_label(n2r_scene):
    return lambda rgb: int(rgb.mean() > 100)
""")
    result = n2r_project.run("--n2r-scene", PLANE)
    out = result.stdout.str()
    result.assert_outcomes(failed=1)
    assert "source output has shape (); expected a 1-D vector of class scores" in out, out
    assert "Falsifying example" in out and "pytest_n2r/relation" not in out, out


def test_a_relation_marked_xfail_is_summarized_as_expected_not_as_a_failure(n2r_project):
    """The summary said FAILED for a relation pytest reported XFAIL, in a green run."""
    n2r_project.write("""
import pytest
from pytest_n2r import metamorphic, transforms
from tests.plugin.fakemetrics import AbsDifference


@pytest.mark.xfail(strict=True, reason="a known weakness")
@metamorphic(AbsDifference(), eps=0.0, transform=transforms(yaw=5), examples=3)
def test_weak(n2r_scene):
    return lambda rgb: float(rgb.mean())
""")
    result = n2r_project.run("--n2r-scene", PLANE, "-n", "2", "--n2r-json=out.json")
    result.assert_outcomes(xfailed=1)
    lines = [line for line in result.stdout.lines if "test_weak" in line and "examples" in line]
    assert lines and lines[0].startswith("XFAIL  "), result.stdout.str()
    # an expected failure is not shrunk: the shrink would only cost time (in the example project 1.5 s a run)
    (record,) = json.loads((n2r_project.pytester.path / "out.json").read_text())["relations"]
    assert record["shrink_examples"] == 0 and "not shrunk: shrinking is off" in record["message"], record["message"]


@pytest.mark.parametrize("mark, args", [('@pytest.mark.xfail(condition=False, reason="only on windows")', ()),
                                        ('@pytest.mark.xfail(sys.platform == "win32", reason="on windows")', ()),
                                        ('@pytest.mark.xfail(reason="a known weakness")', ("--runxfail",)),
                                        ('@pytest.mark.xfail(raises=ValueError, reason="a loader bug")', ())],
                         ids=["condition-keyword", "condition-positional", "runxfail", "raises-another-error"])
def test_a_relation_not_expected_to_fail_is_shrunk(n2r_project, mark, args):
    """``xfail(condition=False)`` as a keyword (and ``--runxfail``) was read as expected to fail: a real failure was
    reported unshrunk, "shrinking is off (the test is expected to fail)"."""
    n2r_project.write(f"""
import sys
import pytest
from pytest_n2r import metamorphic, transforms
from tests.plugin.fakemetrics import AbsDifference


{mark}
@metamorphic(AbsDifference(), eps=0.0, transform=transforms(yaw=5), examples=3)
def test_weak(n2r_scene):
    return lambda rgb: float(rgb.mean())
""")
    result = n2r_project.run("--n2r-scene", PLANE, *args)
    result.assert_outcomes(failed=1)
    assert "(minimal after shrinking)" in result.stdout.str() and "shrinking is off" not in result.stdout.str(), (
        result.stdout.str())


@pytest.mark.parametrize("workers", [[], ["-n", "2"]], ids=["serial", "xdist"])
def test_a_relation_failure_is_located_at_its_test_not_in_pluggy(n2r_project, workers):
    """The failure was raised from the plugin's hook, every frame hidden: ``--tb=line`` (what IDEs and CI
    annotations read) pointed into pluggy, and every failure ended in "All traceback entries are hidden"."""
    n2r_project.write("""
from pytest_n2r import metamorphic, transforms
from tests.plugin.fakemetrics import AbsDifference


@metamorphic(AbsDifference(), eps=0.0, transform=transforms(yaw=5), examples=3)
def test_changes(n2r_scene):
    return lambda rgb: float(rgb.mean())
""")
    result = n2r_project.run("--n2r-scene", PLANE, "--tb=line", *workers)
    result.assert_outcomes(failed=1)
    out = result.stdout.str()
    assert "pluggy/" not in out and "All traceback entries are hidden" not in out, out
    assert re.search(r"test_\w+\.py:\d+: Failed: metamorphic relation violated", out), out


def test_a_scene_that_cannot_be_loaded_is_named_once(n2r_project):
    """``pytest.fail`` inside the ``except`` block printed the loader's error, "During handling of the above exception,
    another exception occurred:", then the message again."""
    n2r_project.write("def test_scene(n2r_scene):\n    pass\n")
    result = n2r_project.run("--n2r-scene=nosuchmodule:scene")
    out = result.stdout.str()
    assert "During handling" not in out, out
    assert out.count("cannot import it (No module named 'nosuchmodule')") == 1, out


def test_the_session_unfreezes_what_it_froze_at_its_end(n2r_project):
    """The freeze was never undone: a process running pytest again (``pytest.main``, pytester, a notebook) kept every
    earlier session's objects, its config among them, out of the collector's reach for good."""
    import gc

    n2r_project.write("def test_scene(n2r_scene):\n    pass\n")
    gc.unfreeze()
    n2r_project.pytester.inline_run("-p", "no:cacheprovider", "--n2r-scene", PLANE).assertoutcome(passed=1)
    assert gc.get_freeze_count() == 0, f"{gc.get_freeze_count()} objects still frozen after the session"


def test_pytests_last_collections_walk_only_what_the_session_did_not_freeze(n2r_project, monkeypatch):
    """pytest's last cleanups collect five times over (``_pytest.unraisableexception``): with the heap unfrozen
    before them each walked everything the session loaded, 0.95 s at the end of a warm main job."""
    import gc

    from _pytest import unraisableexception

    if not hasattr(unraisableexception, "gc_collect_harder"):  # pytest < 8.4 collects no garbage at its end
        pytest.skip("this pytest collects no garbage in its last cleanups")
    frozen_then = []
    collect = unraisableexception.gc_collect_harder
    monkeypatch.setattr(unraisableexception, "gc_collect_harder",
                        lambda iterations: (frozen_then.append(gc.get_freeze_count()), collect(iterations)))
    n2r_project.write("def test_scene(n2r_scene):\n    pass\n")
    gc.unfreeze()
    n2r_project.pytester.inline_run("-p", "no:cacheprovider", "--n2r-scene", PLANE).assertoutcome(passed=1)
    assert frozen_then and frozen_then[-1] > 0, f"objects frozen when pytest collected at its end: {frozen_then}"
    assert gc.get_freeze_count() == 0, f"{gc.get_freeze_count()} objects still frozen after the session"


def test_the_collector_paused_for_the_start_up_resumes_after_the_freeze(n2r_project):
    """The start-up runs with the collector off; the first setup collects and freezes before turning it back on,
    so no young collection walks everything the start-up made just before the full one."""
    n2r_project.write("""
import gc

COLLECTIONS = []
gc.callbacks.append(lambda phase, info: phase == "start" and COLLECTIONS.append(info["generation"]))
PAUSED_AT_COLLECTION = not gc.isenabled()
ALLOCATED = [[] for _ in range(100_000)]  # far past the young generation's threshold


def test_collected_once_then_on(n2r_scene):
    assert PAUSED_AT_COLLECTION, "the start-up did not run with the collector off"
    assert gc.isenabled(), "the collector is still off after the first setup"
    assert COLLECTIONS[:1] == [2], f"collections before the freeze: {COLLECTIONS}"
""")
    result = n2r_project.run("--n2r-scene", PLANE)
    result.assert_outcomes(passed=1)


CLEAR_LOG_PLUGIN = """

import os

import pytest

from pytest_n2r.scene.render_cache import RenderCache

ROLE = []
_clear = RenderCache.clear


@pytest.hookimpl(tryfirst=True)
def pytest_configure(config):
    ROLE.append(config.workerinput["workerid"] if hasattr(config, "workerinput") else "controller")


def clear(self):
    with open(os.environ["N2R_TEST_CLEAR_LOG"], "a") as log:
        log.write(ROLE[-1] + "\\n")
    return _clear(self)


RenderCache.clear = clear
"""


def test_cache_clear_under_xdist_is_done_once_by_the_controller(n2r_project, monkeypatch):
    """``--n2r-cache-clear -n 2``: the controller clears the shared cache before the workers start; a worker that
    cleared it too would delete what the other had just rendered."""
    pytest.importorskip("xdist")
    conftest = n2r_project.pytester.path / "conftest.py"  # loaded by the controller and by every worker
    conftest.write_text(conftest.read_text() + CLEAR_LOG_PLUGIN)
    log = n2r_project.pytester.path / "clears.log"
    monkeypatch.setenv("N2R_TEST_CLEAR_LOG", str(log))
    n2r_project.write("""
@metamorphic(AbsDifference(), eps=1000, transform=transforms(yaw=4), examples=3)
def test_a(n2r_scene):
    return mean_colour


@metamorphic(AbsDifference(), eps=1000, transform=transforms(yaw=3), examples=3)
def test_b(n2r_scene):
    return mean_colour
""")
    n2r_project.run("--n2r-scene", PLANE, "-n", "2", "--n2r-cache-clear").assert_outcomes(passed=2)
    assert log.read_text().split() == ["controller"], f"RenderCache.clear was called by: {log.read_text().split()}"


def test_every_metamorphic_argument_reaches_the_relation():
    """``views=``, ``interpolate=`` and ``validity=`` of ``@metamorphic`` must reach the Relation the plugin runs: a
    call that dropped one ran every test on the held-out views, on captured poses only, with default thresholds."""
    from pytest_n2r import Validity, metamorphic, transforms
    from pytest_n2r.plugin import RELATION_ATTR
    from tests.plugin.fakemetrics import AbsDifference

    strict = Validity(max_rejected=0.25)

    @metamorphic(AbsDifference(), eps=1, transform=transforms(yaw=5), views="train", interpolate=True,
                 validity=strict, search="targeted")
    def test_all(n2r_scene):
        return float

    relation = getattr(test_all, RELATION_ATTR)
    assert (relation.views, relation.interpolate, relation.search) == ("train", True, "targeted"), relation
    assert relation.validity == strict, relation.validity


def test_a_pin_of_the_default_scene_collects_without_a_configured_scene(n2r_project):
    """With no scene configured, the default demo scene is the configured one: pinning it by name must select it,
    not fail collection as an unknown scene."""
    from pytest_n2r.plugin.scenes import default_scene_specs

    default = default_scene_specs()[0].name
    n2r_project.write(f"""
@pytest.mark.n2r_scene({default!r})
@metamorphic(AbsDifference(), eps=255, transform=transforms(yaw=2), examples=2)
def test_pinned(n2r_scene):
    return mean_colour
""")
    result = n2r_project.run("--collect-only", "-q", "--n2r-examples", "2")
    assert result.ret == pytest.ExitCode.OK, result.stdout.str()
    result.stdout.fnmatch_lines([f"*test_pinned[[]{default}[]]*"])
