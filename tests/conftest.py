"""Shared test helpers."""

from __future__ import annotations

import os
import re
from dataclasses import dataclass
from pathlib import Path

import numba.core.boxing  # noqa: F401  (see below)
import pytest
from hypothesis import settings
from numba.core.registry import cpu_target

pytest_plugins = ["pytester"]

# numba imports numba.core.boxing on its first compile of a function with a Python wrapper. When that first
# compile happens inside an in-process pytester run (a plugin test rendering a demo scene), pytester's module
# snapshot drops the module afterwards, and the next compile imports it again: numba's global registry then
# raises "duplicate registration for <class 'numba.core.types.scalars.Boolean'>" (seen in a -n 2 run whose
# workers got the tests in another order). Imported here, before any inner run, it stays. The same holds for the
# implementations numba's CPU target imports on its first compile or cache load (numba.np.polynomial's among
# them: "duplicate registration for <class 'numba.core.types.npytypes.PolynomialType'>", seen on 3 December when
# a demo scene's kernels were first loaded from numba's cache inside an inner run): loaded here (~0.6 s a process).
cpu_target.target_context.refresh()

# Our own property tests: "dev" draws new examples on every run (how most of our edge cases were found);
# "ci" draws the same examples on every run, so a red CI run is a change in the code, never the luck of a
# draw. CI selects "ci" (the CI variable is set); HYPOTHESIS_PROFILE=dev brings the random search to CI.
settings.register_profile("dev", print_blob=True)
settings.register_profile("ci", derandomize=True, print_blob=True)
settings.load_profile(os.environ.get("HYPOTHESIS_PROFILE") or ("ci" if os.environ.get("CI") else "dev"))

REPO_ROOT = Path(__file__).resolve().parent.parent
SHARED_SCENES = REPO_ROOT.parent / "shared" / "scenes"


def shared_scene(name: str) -> Path:
    """Path of ``../shared/scenes/<name>`` beside the checkout; skips the test when it is absent."""
    path = SHARED_SCENES / name
    if not path.is_dir():
        pytest.skip(f"shared scene {name!r} not found at {path} (research data lives beside the checkout)")
    return path


@dataclass(frozen=True)
class DocBlock:
    """A fenced code block of a docs page: its language, its ``title="..."`` (a file name, or ``""``),
    the line of the page it starts on (1-based) and its text."""

    lang: str
    title: str
    line: int
    code: str


_FENCE = re.compile(r'^```(\w*)(?:[ \t]+title="([^"]*)")?[ \t]*\n(.*?)^```[ \t]*$', flags=re.DOTALL | re.MULTILINE)


def doc_blocks(page: str) -> list[DocBlock]:
    """The fenced code blocks of ``docs/<page>``, in page order."""
    text = (REPO_ROOT / "docs" / page).read_text(encoding="utf-8")
    return [DocBlock(m[1], m[2] or "", text.count("\n", 0, m.start()) + 1, m[3]) for m in _FENCE.finditer(text)]


@pytest.fixture
def umask():
    """``umask(mask)``: the process's umask set to ``mask`` for the rest of the test (as a conftest may set it after
    pytest-n2r was imported), the test's own restored after it."""
    before = os.umask(0o022)
    os.umask(before)
    yield os.umask
    os.umask(before)
