"""pytest-n2r: metamorphic tests for perception code on rendered views of real scenes.

The top-level names are imported lazily, so ``import pytest_n2r`` (and the pytest plugin) costs
nothing until a name is used; type checkers read the same names from the ``TYPE_CHECKING`` imports.
"""

from __future__ import annotations

import importlib
from typing import TYPE_CHECKING, Any

from .kernel_cache import ensure_kernel_cache

__version__ = "0.1.0"

ensure_kernel_cache()  # before any kernel module imports numba: a read-only installation still imports them

if TYPE_CHECKING:  # what type checkers and IDEs see; a test keeps it in step with _EXPORTS
    from .data import Capture, ingest
    from .demo import GroundTruthScene
    from .errors import (
        IngestError,
        InvalidArgument,
        InvalidType,
        MetricArgumentError,
        MetricUndefined,
        N2RError,
        SceneFileError,
        SUTError,
        SUTOutputError,
    )
    from .geometry import Camera, Transform, Units
    from .metrics import (
        Metric,
        MetricResult,
        class_invariance,
        cosine_similarity,
        interest_point_spread,
        l2_norm,
        repeatability,
        resolve_metric,
        ssim_metric,
    )
    from .plugin.marker import metamorphic
    from .relation import Relation, RelationFailure, Validity, check_relation
    from .render import RenderedView
    from .scene import FieldScene, Scene, SceneView, SplatScene, load_scene, save_scene
    from .scene.render_cache import RenderCache
    from .strategies import BlackPatches, Brightness, Mutation, NoisePatch, transforms, views

#: public name -> module that defines it
_EXPORTS: dict[str, str] = {
    "Camera": "pytest_n2r.geometry",
    "Transform": "pytest_n2r.geometry",
    "Units": "pytest_n2r.geometry",
    "Scene": "pytest_n2r.scene",
    "SceneView": "pytest_n2r.scene",
    "FieldScene": "pytest_n2r.scene",
    "SplatScene": "pytest_n2r.scene",
    "load_scene": "pytest_n2r.scene",
    "save_scene": "pytest_n2r.scene",
    "RenderedView": "pytest_n2r.render",
    "N2RError": "pytest_n2r.errors",
    "InvalidArgument": "pytest_n2r.errors",
    "InvalidType": "pytest_n2r.errors",
    "SceneFileError": "pytest_n2r.errors",
    "IngestError": "pytest_n2r.errors",
    "ingest": "pytest_n2r.data",
    "Capture": "pytest_n2r.data",
    "SUTOutputError": "pytest_n2r.errors",
    "MetricArgumentError": "pytest_n2r.errors",
    "MetricUndefined": "pytest_n2r.errors",
    "Metric": "pytest_n2r.metrics",
    "MetricResult": "pytest_n2r.metrics",
    "resolve_metric": "pytest_n2r.metrics",
    "cosine_similarity": "pytest_n2r.metrics",
    "l2_norm": "pytest_n2r.metrics",
    "class_invariance": "pytest_n2r.metrics",
    "repeatability": "pytest_n2r.metrics",
    "interest_point_spread": "pytest_n2r.metrics",
    "ssim_metric": "pytest_n2r.metrics",
    "Mutation": "pytest_n2r.strategies",
    "Brightness": "pytest_n2r.strategies",
    "NoisePatch": "pytest_n2r.strategies",
    "BlackPatches": "pytest_n2r.strategies",
    "GroundTruthScene": "pytest_n2r.demo",
    "metamorphic": "pytest_n2r.plugin.marker",
    "transforms": "pytest_n2r.strategies",
    "views": "pytest_n2r.strategies",
    "Relation": "pytest_n2r.relation",
    "RelationFailure": "pytest_n2r.relation",
    "SUTError": "pytest_n2r.errors",
    "check_relation": "pytest_n2r.relation",
    "RenderCache": "pytest_n2r.scene.render_cache",
    "Validity": "pytest_n2r.relation",
}

#: the lazily exported names and __version__, spelled out for type checkers and linters; a test
#: (tests/test_project.py) keeps it in step with _EXPORTS
__all__ = [
    "__version__", "Camera", "Transform", "Units", "Scene", "SceneView", "FieldScene", "SplatScene",
    "load_scene", "save_scene", "RenderedView", "N2RError", "InvalidArgument", "InvalidType", "SceneFileError",
    "IngestError", "ingest", "Capture", "SUTOutputError", "MetricArgumentError", "MetricUndefined", "Metric",
    "MetricResult",
    "resolve_metric", "cosine_similarity", "l2_norm", "class_invariance", "repeatability",
    "interest_point_spread", "ssim_metric", "Mutation", "Brightness", "NoisePatch", "BlackPatches", "GroundTruthScene",
    "metamorphic", "transforms", "views", "Relation", "RelationFailure", "SUTError", "check_relation",
    "RenderCache", "Validity",
]


if not TYPE_CHECKING:  # hidden from type checkers, which read the imports above: a misspelt name is an error, not Any
    def __getattr__(name: str) -> Any:
        module = _EXPORTS.get(name)
        if module is None:
            raise AttributeError(f"module 'pytest_n2r' has no attribute {name!r}")
        value = getattr(importlib.import_module(module), name)
        globals()[name] = value
        return value


def __dir__() -> list[str]:
    return sorted(__all__)
