"""pytester helpers for plugin tests: an isolated project that can import the fake scene and metrics."""

from __future__ import annotations

import re
from dataclasses import dataclass
from pathlib import Path

import pytest
import torch  # noqa: F401  (see below: torch's C extension cannot be imported a second time in one process)
from hypothesis import settings

# pytester drops the modules an inner run imported first; importing these here keeps one copy of each, so
# an inner test's metric is an instance of the same Metric class the (cached) @metamorphic checks against,
# and a test that patches the demo scenes patches the module the inner run reads. torch is imported above for
# the same reason: an inner run that imports it first (a scene file naming a classifier) and drops it left
# a half-initialised extension ("SystemError: ... bad call flags" when tests/plugin ran on its own).
import pytest_n2r.demo
import pytest_n2r.metrics
import pytest_n2r.plugin.marker
import pytest_n2r.strategies  # noqa: F401

from . import fakemetrics  # noqa: F401
from .fakescene import RENDER_LOG_ENV

REPO_ROOT = Path(__file__).resolve().parents[2]

#: The inner project's conftest: its own Hypothesis database in its own folder.
INNER_CONFTEST = """
from hypothesis import settings
from hypothesis.database import DirectoryBasedExampleDatabase
settings.register_profile("n2r-inner", database=DirectoryBasedExampleDatabase({db!r}))
settings.load_profile("n2r-inner")
"""

#: Imports and SUTs the inner test files share.
PRELUDE = """
import numpy as np
import pytest
from pytest_n2r import metamorphic, transforms
from tests.plugin.fakemetrics import AbsDifference, SameLabel
from tests.plugin.fakescene import decode_ramp_x


def heading_class(rgb):
    '''A SUT that classifies the heading in 10-degree classes: it breaks beyond 5 degrees of yaw.'''
    h, w = rgb.shape[:2]
    x = decode_ramp_x(rgb[(h - 1) // 2:h // 2 + 1, (w - 1) // 2:w // 2 + 1]).mean()
    return int(round(np.degrees(np.arctan2(x, 2.0)) / 10))


def mean_colour(rgb):
    return float(rgb.mean())
"""


@dataclass
class N2RProject:
    pytester: pytest.Pytester
    render_log: Path

    def write(self, body: str, name: str = "test_relations") -> None:
        self.pytester.makepyfile(**{name: PRELUDE + body})

    def run(self, *args: str) -> pytest.RunResult:
        """Run the inner project; renders are 96 pixels wide unless ``--n2r-size`` is given."""
        size = () if "--n2r-size" in args else ("--n2r-size", "96")
        return self.pytester.runpytest("-p", "no:cacheprovider", *size, *args)

    def renders(self) -> int:
        """Scene renders so far (every process, xdist workers included)."""
        return len(self.render_log.read_text().splitlines()) if self.render_log.exists() else 0

    def summary(self, result: pytest.RunResult, test: str) -> str:
        """The pytest-n2r summary line of ``test`` (a node id suffix)."""
        pattern = r"(PASSED|FAILED|ERROR)\s+\S*" + re.escape(test) + ": "
        lines = [line for line in result.outlines if re.match(pattern, line)]
        assert lines, f"no pytest-n2r summary line for {test!r} in:\n" + "\n".join(result.outlines)
        return lines[-1]


@pytest.fixture
def n2r_project(pytester: pytest.Pytester, monkeypatch: pytest.MonkeyPatch) -> N2RProject:
    monkeypatch.setenv("PYTHONPATH", str(REPO_ROOT))  # xdist workers import the fake scene from here
    monkeypatch.delenv("CI", raising=False)
    log = pytester.path / "renders.log"
    monkeypatch.setenv(RENDER_LOG_ENV, str(log))
    pytester.makeconftest(INNER_CONFTEST.format(db=str(pytester.path / ".hypothesis-db")))
    profile = settings.get_current_profile_name()
    yield N2RProject(pytester, log)
    settings.load_profile(profile)  # the inner conftest switched the process-wide profile
