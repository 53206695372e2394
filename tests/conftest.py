"""Shared test helpers."""

from __future__ import annotations

from pathlib import Path

import pytest

pytest_plugins = ["pytester"]

REPO_ROOT = Path(__file__).resolve().parent.parent
SHARED_SCENES = REPO_ROOT.parent / "shared" / "scenes"


def shared_scene(name: str) -> Path:
    """Path of ``../shared/scenes/<name>`` beside the checkout; skips the test when it is absent."""
    path = SHARED_SCENES / name
    if not path.is_dir():
        pytest.skip(f"shared scene {name!r} not found at {path} (research data lives beside the checkout)")
    return path
