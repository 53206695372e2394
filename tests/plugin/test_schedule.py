"""Under pytest-xdist the tests on fitted scenes run first and tests are handed out one at a time; a serial
run keeps pytest's order (pytest_n2r.plugin.schedule)."""

from __future__ import annotations

import pytest

#: Inner tests that log the order they ran in, per process; the last one is on a fitted demo twin.
ORDERED = """
import os
import pytest


def _log(request):
    with open({log!r}, "a") as f:
        f.write(os.environ.get("PYTEST_XDIST_WORKER", "serial") + " " + request.node.name + "\\n")


@pytest.mark.parametrize("k", range(6))
def test_exact(n2r_scene, k, request):
    _log(request)


@pytest.mark.n2r_scene("demo:wall-field")
def test_fitted(n2r_scene, request):
    _log(request)
"""


def _runs(log) -> dict[str, list[str]]:
    by_process: dict[str, list[str]] = {}
    for line in log.read_text().splitlines():
        process, name = line.split(" ", 1)
        by_process.setdefault(process, []).append(name)
    log.unlink()
    return by_process


def test_the_tests_on_fitted_scenes_run_first_under_xdist_only(pytester, monkeypatch):
    pytest.importorskip("xdist")
    # the serial run is in this process: where this suite itself runs under xdist, its worker's name is not the
    # inner run's (the inner tests log "serial" only without it)
    monkeypatch.delenv("PYTEST_XDIST_WORKER", raising=False)
    log = pytester.path / "order.log"
    pytester.makepyfile(test_order=ORDERED.format(log=str(log)))
    args = ("-p", "no:cacheprovider", "-p", "no:benchmark", "--n2r-scene", "demo:wall")
    pytester.runpytest(*args).assert_outcomes(passed=7)
    assert _runs(log)["serial"][-1] == "test_fitted[wall-field]", "a serial run must keep pytest's order"
    pytester.runpytest(*args, "-n", "2").assert_outcomes(passed=7)
    runs = _runs(log)
    first = [names[0] for names in runs.values()]
    assert "test_fitted[wall-field]" in first, f"the fitted-scene test did not run first in its worker: {runs}"


def test_xdist_hands_out_one_test_at_a_time_unless_told(pytester):
    pytest.importorskip("xdist")
    pytester.makeini("[pytest]\nn2r_scenes = demo:wall\n")
    # "--dist load" is what xdist's command line sets for "-n 2" before pytest_configure (parseconfigure skips it)
    assert pytester.parseconfigure("-n", "2", "--dist", "load").option.maxschedchunk == 1
    assert pytester.parseconfigure("-n", "2", "--dist", "load", "--maxschedchunk", "4").option.maxschedchunk == 4, \
        "a chunk size the user gave must stay"
    assert pytester.parseconfigure().option.maxschedchunk is None, "a serial run must not be touched"


def test_an_xdist_worker_of_a_suite_without_relations_does_not_load_the_engine(pytester):
    """Each worker of a suite that does not use pytest-n2r imported numba, numpy, scipy and Hypothesis through the
    scheduling hook (553 more modules, +78 MB a worker, 7.7 against 5.5 s for one trivial test on -n 2)."""
    pytest.importorskip("xdist")
    pytester.makepyfile(test_plain="""
import sys


def test_x():
    heavy = sorted(m for m in ("numba", "numpy", "scipy", "pytest_n2r.relation", "pytest_n2r.scene")
                   if m in sys.modules)
    assert not heavy, f"imported by a worker of a suite that uses no relation: {heavy}"
""")
    pytester.runpytest_subprocess("-p", "no:cacheprovider", "-n", "2").assert_outcomes(passed=1)


def test_a_suite_that_does_not_use_pytest_n2r_keeps_xdists_chunks(pytester):
    """--maxschedchunk 1 only for a session that uses pytest-n2r; other suites keep xdist's own scheduling."""
    pytest.importorskip("xdist")
    assert pytester.parseconfigure("-n", "2", "--dist", "load").option.maxschedchunk is None


@pytest.mark.parametrize(("source", "slow"), [("scenes/site.n2r", True), ("scenes/SITE.N2R", True),
                                               ("scenes/site.ply", False)])
def test_fitted_scene_files_are_scheduled_with_the_slow_scenes(source, slow):
    """A user's fitted ``.n2r`` renders as slowly as the demo's fitted twins: under xdist its tests go first too."""
    from pytest_n2r.plugin.precompile import family
    from pytest_n2r.plugin.scenes import SceneSpec
    from pytest_n2r.plugin.schedule import SLOW_FAMILIES

    assert (family(SceneSpec("site", "file", source)) in SLOW_FAMILIES) is slow
    assert family(SceneSpec("wall-field", "demo", "demo:wall-field")) in SLOW_FAMILIES
