"""The example project's regression gate has power: each realistic regression of
``example_project/perception/regressions.py`` clears every ``eps`` of the example's relations but fails the
gate of ``example_project/tests/test_gate.py`` on the committed baseline ``tests/gate-baseline.json``.

This tests pytest-n2r's paired comparison on a real suite, not the example's perception code, so it lives
here rather than in the example's own suite (which a user's pull-request job runs; it replays only the
shipped detectors). It uses the example's gate functions unchanged, and the render cache of this checkout
(``.n2r-cache/``, as the plugin would), so a second run renders nothing.
"""

from __future__ import annotations

import importlib
import importlib.util
import sys
import warnings
from dataclasses import replace
from pathlib import Path
from types import ModuleType

import pytest

from pytest_n2r import RenderCache

from ..conftest import REPO_ROOT

EXAMPLE = REPO_ROOT / "example_project"
#: The example's test package under a name of its own: pytest-n2r's tests are the package ``tests`` too.
PACKAGE = "perception_example_tests"
#: The regressions of example_project/perception/regressions.py (test_the_list_is_complete keeps it so).
REGRESSION_NAMES = ("orb-candidate", "orb-half-resolution", "orb-half-the-points", "orb-dead-right-quarter",
                    "orb-fast-threshold-25", "orb-3px-grid")

pytestmark = pytest.mark.slow


def _example_gate() -> ModuleType:
    """``example_project/tests/test_gate.py``, imported with ``perception`` importable."""
    if PACKAGE not in sys.modules:
        spec = importlib.util.spec_from_file_location(PACKAGE, EXAMPLE / "tests" / "__init__.py",
                                                      submodule_search_locations=[str(EXAMPLE / "tests")])
        package = importlib.util.module_from_spec(spec)
        sys.modules[PACKAGE] = package
        spec.loader.exec_module(package)
    sys.path.insert(0, str(EXAMPLE))
    try:
        with warnings.catch_warnings():  # its marker ``gate`` is registered in the example's pyproject.toml
            warnings.simplefilter("ignore", pytest.PytestUnknownMarkWarning)
            return importlib.import_module(f"{PACKAGE}.test_gate")
    finally:
        sys.path.remove(str(EXAMPLE))


@pytest.fixture(scope="module")
def example_gate() -> ModuleType:
    return _example_gate()


def test_the_list_is_complete(example_gate):
    from perception.regressions import REGRESSIONS

    assert sorted(REGRESSION_NAMES) == sorted(REGRESSIONS), \
        f"REGRESSION_NAMES {sorted(REGRESSION_NAMES)} differ from perception.regressions {sorted(REGRESSIONS)}"


@pytest.mark.parametrize("name", REGRESSION_NAMES)
def test_the_gate_catches_a_realistic_regression(name, example_gate, request):
    """On the demo scenes the committed baseline covers, at least one ORB relation is worse (the example's
    README.md gives which, and with how many examples), and every relation the gate fails is worse or lost."""
    from perception.regressions import REGRESSIONS

    from pytest_n2r.demo import load_demo

    cache = RenderCache(Path(request.config.rootpath) / ".n2r-cache")
    tables, caught = [], []
    for scene_name in sorted({r.scene for r in example_gate.baseline().values()}):
        comparisons = example_gate.gate(load_demo(scene_name), REGRESSIONS[name], "test_orb_", cache)
        tables.append(f"{scene_name}:\n{example_gate.format_comparison_table(comparisons)}")
        caught += [c for c in comparisons if c.fails]
    report = "\n".join(tables)
    assert caught, f"{name} passed the gate:\n{report}"
    assert all(c.outcome in ("worse", "lost") for c in caught), f"{name}: a failure that is not a regression:\n{report}"


def test_a_baseline_of_another_metric_reads_as_a_changed_metric(example_gate):
    """A baseline recorded with a metric the suite no longer uses (repeatability before it named its matching)
    fails the gate as ``changed-metric``, saying to save a new baseline, not as "nothing replayed"."""
    from pytest_n2r.demo import load_demo

    base = next(r for r in example_gate.baseline().values() if r.metric.startswith("repeatability("))
    old = replace(base, metric="repeatability(px=3.0, mapping='depth')")
    current = example_gate.replay(load_demo(base.scene), None, old, cache=None)
    (comparison,) = example_gate.compare_paired({old.nodeid: old}, [current], margin=example_gate.MARGIN)
    assert comparison.outcome == "changed-metric" and comparison.fails, comparison
    assert "save a new baseline" in comparison.message, comparison.message
