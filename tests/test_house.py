"""House rules the whole repository keeps: ``ruff check .`` is clean (rules pinned in pyproject.toml)."""

from __future__ import annotations

import importlib.util
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
