"""The package as a user meets it: the console script, the lazy top-level API, the docs build."""

from __future__ import annotations

import os
import shutil
import subprocess
import sys

import pytest

import pytest_n2r
from pytest_n2r.cli.main import main

from .conftest import REPO_ROOT


def test_version_flag(capsys):
    with pytest.raises(SystemExit) as exc:
        main(["--version"])
    assert exc.value.code == 0
    assert capsys.readouterr().out.strip() == f"pytest-n2r {pytest_n2r.__version__}"


def test_help_lists_every_subcommand(capsys):
    from pytest_n2r.cli.main import COMMANDS

    with pytest.raises(SystemExit):
        main(["--help"])
    out = capsys.readouterr().out
    missing = [c for c in COMMANDS if c not in out]
    assert not missing, f"`n2r --help` does not list {missing}:\n{out}"


def test_top_level_import_is_lazy():
    """Importing the package (as the pytest plugin does at start-up) must not import torch or cv2."""
    code = "import sys, pytest_n2r, pytest_n2r.plugin; print(sorted({'torch', 'cv2', 'pycolmap'} & set(sys.modules)))"
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, check=True).stdout
    assert out.strip() == "[]", f"heavy modules imported eagerly: {out.strip()}"


def test_unknown_public_name_raises_attribute_error():
    with pytest.raises(AttributeError, match="no attribute 'nope'"):
        pytest_n2r.nope  # noqa: B018


@pytest.mark.skipif(shutil.which("mkdocs") is None, reason="mkdocs is not installed (pip install -e '.[dev]')")
def test_docs_build_without_warnings(tmp_path):
    result = subprocess.run(
        ["mkdocs", "build", "--strict", "--site-dir", str(tmp_path / "site")],
        cwd=REPO_ROOT, capture_output=True, text=True, env={**os.environ, "NO_MKDOCS_2_WARNING": "1"},
    )
    assert result.returncode == 0, f"mkdocs build --strict failed:\n{result.stdout}\n{result.stderr}"


@pytest.mark.parametrize("name", sorted(pytest_n2r._EXPORTS))
def test_every_public_name_resolves(name):
    value = getattr(pytest_n2r, name)
    assert getattr(value, "__name__", name) == name or not hasattr(value, "__name__"), \
        f"pytest_n2r.{name} resolves to {value!r}, whose name differs"
