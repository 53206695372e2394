"""numba's cache folder for a read-only installation (pytest_n2r/kernel_cache.py)."""

from __future__ import annotations

import os
from pathlib import Path

import numba.core.config
import pytest

from pytest_n2r import kernel_cache


@pytest.fixture
def numba_dir(monkeypatch):
    """NUMBA_CACHE_DIR unset, and numba's own setting restored after the test."""
    monkeypatch.delenv("NUMBA_CACHE_DIR", raising=False)
    monkeypatch.setattr(numba.core.config, "CACHE_DIR", numba.core.config.CACHE_DIR)


def test_a_read_only_installation_without_a_home_gets_a_temporary_kernel_cache(numba_dir, monkeypatch, tmp_path):
    """Run by a container's --user with HOME=/ over a root-owned site-packages, numba refused every cache=True kernel
    at import (`cannot cache function '_smoothstep': no locator available`): an INTERNALERROR for the whole run."""
    package = tmp_path / "site-packages" / "pytest_n2r"
    package.mkdir(parents=True)
    monkeypatch.setattr(kernel_cache.os, "access", lambda path, mode: False)  # as a user who may write nothing
    monkeypatch.setattr("tempfile.tempdir", str(tmp_path))
    folder = kernel_cache.ensure_kernel_cache(package)
    assert folder is not None and folder.parent == tmp_path, f"no writable kernel cache named: {folder}"
    assert os.environ["NUMBA_CACHE_DIR"] == str(folder) == numba.core.config.CACHE_DIR, (
        "numba's cache folder was not set for this process and its children")


@pytest.mark.parametrize("writable", ["package", "user cache", "set"])
def test_numba_is_left_alone_where_it_has_a_place_to_write(numba_dir, monkeypatch, tmp_path, writable):
    package = tmp_path / "pytest_n2r"
    package.mkdir()
    if writable == "set":
        monkeypatch.setenv("NUMBA_CACHE_DIR", str(tmp_path / "mine"))
    monkeypatch.setenv("XDG_CACHE_HOME", str(tmp_path / "xdg"))
    can_write = {"package": package, "user cache": tmp_path}.get(writable)  # tmp_path: where XDG_CACHE_HOME/numba
    monkeypatch.setattr(kernel_cache.os, "access", lambda path, mode: Path(path) == can_write)  # would be made
    before = numba.core.config.CACHE_DIR
    assert kernel_cache.ensure_kernel_cache(package) is None, f"changed numba's cache with the {writable} writable"
    assert numba.core.config.CACHE_DIR == before
