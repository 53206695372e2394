"""House rules the whole repository keeps: ``ruff check .`` is clean (rules pinned in pyproject.toml), ``mypy``
finds the package's annotations true (it ships py.typed), the imports follow the layers of docs/architecture.md
(import-linter contracts in pyproject.toml) and no module grows into a 500-line room."""

from __future__ import annotations

import importlib.util
import os
import shutil
import subprocess
import sys

import pytest

from .conftest import REPO_ROOT


def _ruff() -> list[str] | None:
    """The command that runs ruff: this interpreter's ruff module, else the ``ruff`` on PATH; None if neither."""
    if importlib.util.find_spec("ruff") is not None:
        return [sys.executable, "-m", "ruff"]
    found = shutil.which("ruff")
    return [found] if found else None


def test_ruff_check_is_clean():
    ruff = _ruff()
    if ruff is None:
        pytest.skip("ruff is not installed (pip install -e '.[dev]' installs the pinned version)")
    version = subprocess.run([*ruff, "--version"], capture_output=True, text=True, check=True).stdout.strip()
    result = subprocess.run([*ruff, "check", ".", "--no-cache", "--output-format", "concise"],
                            cwd=REPO_ROOT, capture_output=True, text=True, check=False)
    assert result.returncode == 0, (
        f"`ruff check .` ({version}; pyproject.toml pins the version in the dev extra) found problems:\n"
        f"{result.stdout}{result.stderr}"
    )


def test_mypy_finds_the_annotations_true():
    """The package ships ``py.typed``: users' type checkers read its annotations, so ``mypy`` (the version pinned in
    the dev extra, configured in pyproject.toml) must find none of them false."""
    if importlib.util.find_spec("mypy") is None:
        pytest.skip("mypy is not installed (pip install -e '.[dev]' installs the pinned version)")
    result = subprocess.run([sys.executable, "-m", "mypy", "--cache-dir", os.devnull], cwd=REPO_ROOT,
                            capture_output=True, text=True, check=False)  # pyproject.toml names the files
    assert result.returncode == 0, f"`mypy` found annotations the code does not keep:\n{result.stdout}{result.stderr}"


def test_imports_follow_the_architecture():
    """``lint-imports`` with the contracts of pyproject.toml: the layers, no cycles, pytest only in the plugin."""
    if importlib.util.find_spec("importlinter") is None:
        pytest.skip("import-linter is not installed (pip install -e '.[dev]' installs the pinned version)")
    env = {**os.environ, "PYTHONPATH": os.pathsep.join(p for p in (str(REPO_ROOT), os.environ.get("PYTHONPATH")) if p)}
    result = subprocess.run(  # the package of this checkout, whatever is installed
        [sys.executable, "-c", "from importlinter.cli import lint_imports_command; lint_imports_command()",
         "--no-cache", "--no-logo"], cwd=REPO_ROOT, env=env, capture_output=True, text=True, check=False)
    assert result.returncode == 0, (
        "`lint-imports` found imports that break the architecture (docs/architecture.md says where code goes; "
        f"the contracts are in pyproject.toml):\n{result.stdout}{result.stderr}"
    )

# -- modest rooms ------------------------------------------------------------------------------------------

#: The most lines a module of pytest_n2r may have: one concept per module keeps every room small enough to
#: read in one sitting.
LINE_BUDGET = 400
#: Modules over the budget: path -> (the most lines it may have, why it is not split). The cap keeps them from
#: growing unnoticed; a module that shrinks under the budget must leave this table.
OVER_BUDGET: dict[str, tuple[int, str]] = {
    "pytest_n2r/demo/raycast.py": (
        650, ("the compiled ray caster of the exact demo scenes: the scene compiler, the surfaces and the numba "
              "kernel with its inlined helpers (the row cast is row_cast.py), still being tuned (issue 16); to be "
              "split into the compile step and the kernel")),
}


def _module_lines() -> dict[str, int]:
    return {path.relative_to(REPO_ROOT).as_posix(): len(path.read_text(encoding="utf-8").splitlines())
            for path in sorted((REPO_ROOT / "pytest_n2r").rglob("*.py"))}


def test_no_module_exceeds_the_line_budget():
    sizes = _module_lines()
    over = {path: n for path, n in sizes.items() if n > OVER_BUDGET.get(path, (LINE_BUDGET, ""))[0]}
    assert not over, (f"modules over the budget of {LINE_BUDGET} lines (or over their cap in OVER_BUDGET): {over}; "
                      "split them one concept per module (docs/architecture.md)")
    back = sorted(path for path in OVER_BUDGET if sizes.get(path, 0) <= LINE_BUDGET)
    assert not back, f"{back} are within the budget now (or gone): remove them from OVER_BUDGET"


# -- the architecture page ---------------------------------------------------------------------------------


def test_the_architecture_page_is_in_the_nav_and_linked_from_the_front_pages():
    assert ": architecture.md" in (REPO_ROOT / "mkdocs.yml").read_text(encoding="utf-8"), \
        "docs/architecture.md is not in the mkdocs nav"
    for page, link in (("docs/index.md", "(architecture.md)"), ("README.md", "(docs/architecture.md)")):
        assert link in (REPO_ROOT / page).read_text(encoding="utf-8"), f"{page} does not link to the architecture page"
