"""What the plugin shows beside a relation's result: the field floor, whether ``eps`` is below it, and on a
fitted demo scene the exact-vs-fitted replay; as plain JSON-ready data and as terminal lines."""

from __future__ import annotations

from collections.abc import Callable
from pathlib import Path
from typing import Any

import numpy as np

from ...render.size import RenderSize
from ...scene.base import Scene
from ...scene.render_cache import RenderCache
from ..record import ExampleRecord
from ..timeout import CallTimeout, time_limit
from .exact import compare_exact
from .measure import FieldFloor, FloorStore, measure_floor, sut_name

__all__ = ["annotate_relation", "annotation_lines"]

_STORES: dict[Path | None, FloorStore] = {}


def annotate_relation(scene: Scene, sut: Callable[[np.ndarray], Any], relation: Any, records: list[ExampleRecord],
                      *, size: RenderSize | None, cache: RenderCache | None, cache_dir: Path | None,
                      timeout: float | None = None) -> dict[str, Any] | None:
    """What the plugin shows beside a relation's result on ``scene`` (``None`` on an exact scene): the field
    floor of the relation's SUT, metric and render size, whether ``eps`` is below it, and on a fitted demo
    scene the relation's examples replayed on exact renders. Plain JSON-ready data; a floor that cannot be
    measured (the SUT raises on a photo, runs longer than ``timeout`` seconds, ...) is reported with the
    reason, never raised; after a time-out the exact replay is skipped (a hung SUT would hang there too)."""
    if getattr(scene, "is_exact", False):
        return None
    directory = None if cache_dir is None else Path(cache_dir) / "floors"
    store = _STORES.setdefault(directory, FloorStore(directory))
    eps = float(relation.eps)
    timed, timed_out = _timed(sut, timeout), False
    try:
        floor = measure_floor(scene, timed, relation.metric, size=size, cache=cache, store=store, name=sut_name(sut))
    except Exception as exc:  # noqa: BLE001 -- an annotation: what went wrong is said, the verdict stands
        timed_out = isinstance(exc, CallTimeout)
        floor = FieldFloor(scene.name, sut_name(sut), repr(relation.metric), str(size), "none",
                           reason=f"measuring it failed: {type(exc).__name__}: {exc}")
    out: dict[str, Any] = {"floor": floor.to_dict(), "line": floor.describe(eps), "below_floor": floor.above(eps)}
    if timed_out:  # a SUT that hung on the floor's images would hang again on the exact renders
        return out
    try:
        comparison = compare_exact(scene, timed, relation.metric, records,
                                   lambda v: v.camera if size is None else size.apply(v.camera), cache=cache)
    except Exception as exc:  # noqa: BLE001 -- as above
        out["exact_line"] = f"exact vs fitted: replay failed: {type(exc).__name__}: {exc}"
    else:
        if comparison is not None:
            out["exact"], out["exact_line"] = comparison.to_dict(), comparison.describe()
    return out


def _timed(sut: Callable[[np.ndarray], Any], timeout: float | None) -> Callable[[np.ndarray], Any]:
    """``sut`` with each call under the run's time limit (``None`` or 0: ``sut`` itself)."""
    if not timeout:
        return sut

    def timed(rgb: np.ndarray) -> Any:
        with time_limit(timeout, "the system under test, measuring the field floor"):
            return sut(rgb)

    return timed


def annotation_lines(annotation: dict[str, Any] | None) -> list[tuple[str, bool]]:
    """``(line, is_warning)`` pairs to print under a relation's summary line."""
    if not annotation:
        return []
    lines = [(annotation["line"], bool(annotation["below_floor"]))]
    if annotation.get("exact_line"):
        lines.append((annotation["exact_line"], False))
    return lines
