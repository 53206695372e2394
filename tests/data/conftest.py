"""Fixtures for the ingestion tests: small synthetic captures rendered once per session."""

from __future__ import annotations

import shutil

import pytest

from .synthetic import SyntheticCapture, make_capture


@pytest.fixture(scope="session")
def _corner_master(tmp_path_factory) -> SyntheticCapture:
    return make_capture(tmp_path_factory.mktemp("corner"), n=6)


@pytest.fixture
def corner(_corner_master, tmp_path) -> SyntheticCapture:
    """Six 160x120 renders of the textured corner in ``tmp_path/images`` (a fresh copy per test)."""
    shutil.copytree(_corner_master.images_dir, tmp_path / "images")
    return SyntheticCapture(tmp_path, tmp_path / "images", list(_corner_master.names), _corner_master.camera,
                            list(_corner_master.c2ws), list(_corner_master.depths))
