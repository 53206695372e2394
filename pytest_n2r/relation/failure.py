"""A relation's verdicts in words: the :class:`RelationFailure` a broken relation raises and its message
(scene, source view, the minimal follow-up, score and deviation against ``eps``, the search's counts, where
the failure pictures are), and the messages of a relation that tested nothing or drew mostly invalid views.
"""

from __future__ import annotations

import os
from pathlib import Path
from typing import Any

from ..metrics.base import MetricResult
from ..scene.base import Scene, SceneView
from ..strategies.follow_up import FollowUp
from .record import ExampleRecord, RelationRecord, plural
from .spec import Relation

__all__ = ["RelationFailure", "MAX_UNDEFINED", "SAME_PIXELS", "failure_message", "how_to_reproduce", "nothing_to_test",
           "too_many_invalid"]

#: A relation fails as "the SUT produced nothing to test" when more than this share of the draws it could
#: evaluate (valid follow-up views) had an undefined metric (no keypoints, empty or all-NaN outputs, ...).
MAX_UNDEFINED = 0.5

#: Why a follow-up whose pixels equal its source's, byte for byte, is undefined rather than passed: a pose change
#: that moves the picture by less than its last bits (a sky, a blank wall), a mutation that lands on pixels it
#: leaves as they were (black patches on black). The SUT sees one image twice, so the pair tests nothing.
SAME_PIXELS = ("the follow-up's pixels equal the source's, byte for byte: the change altered nothing in the picture, "
               "so the pair tests nothing")


class RelationFailure(AssertionError):
    """The SUT's outputs on a source view and its follow-up deviate by more than ``eps`` (or the SUT gave
    nothing to test); ``record`` is the run's :class:`~pytest_n2r.relation.record.RelationRecord`."""

    def __init__(self, message: str, record: RelationRecord | None = None):
        super().__init__(message)
        self.record = record


def failure_message(scene: Scene, relation: Relation, run: RelationRecord, view: SceneView,
                    tau: FollowUp, result: MetricResult, record: ExampleRecord, *, note: str = "",
                    images_error: str | None = None, reproduce: str = "") -> str:
    """The message of a failing example of ``run``: ``record`` (with the saved ``images`` if any) of source
    ``view`` and follow-up ``tau`` whose metric ``result`` broke ``relation`` on ``scene``; ``reproduce`` says
    how a rerun finds it again (:func:`how_to_reproduce`)."""
    metric = relation.metric
    camera = record.camera
    lines = [
        (f"metamorphic relation violated: {metric!r} deviates {result.deviation:.4g} from its ideal "
         f"{metric.ideal:g}, more than eps={relation.eps:g}"),
        f"  scene:      {scene.name} (content {scene.content_hash[:12]})",
        f"  source:     view {view.name!r} ({view.split}), rendered at {camera['width']}x{camera['height']}",
    ]
    lines.extend(tau.explain(scene, note))
    details = ", ".join(f"{k}={v}" for k, v in result.details.items())
    lines.append(f"  metric:     score {result.score:.4g}, deviation {result.deviation:.4g} > eps "
                 f"{relation.eps:g}" + (f" ({details})" if details else ""))
    lines.append(f"  search:     {plural(len(run.valid_examples), 'example')}, {run.inconsistencies} inconsistent, "
                 f"{run.rejected} rejected as invalid, {run.undefined} undefined, "
                 f"{plural(run.shrink_examples, 'shrink step')}")
    if record.images:
        images = record.images
        lines.append(f"  images:     source   {_shown_path(images['source'])}")
        lines.append(f"              follow   {_shown_path(images['follow'])}")
        lines.append(f"              (the renders the SUT saw: {Path(images['source_raw']).name}, "
                     f"{Path(images['follow_raw']).name})")
    elif images_error:
        lines.append(f"  images:     {images_error}")
    if reproduce:
        lines.append(f"  reproduce:  {reproduce}")
    return "\n".join(lines)


def how_to_reproduce(derandomize: bool, database: Any, forced_seed: object = None) -> str:
    """How a rerun of a failed relation draws its failing example again, for the failure message. ``forced_seed``:
    pytest's ``--hypothesis-seed``, under which Hypothesis keeps no example database.

    >>> how_to_reproduce(True, "default")
    'run the test again: a derandomized search draws the same examples every run'
    >>> how_to_reproduce(False, "default", forced_seed=7)
    'run the test again with --hypothesis-seed=7: the seed draws the same examples (and no database is kept)'
    """
    if derandomize:
        return "run the test again: a derandomized search draws the same examples every run"
    if forced_seed is not None:
        return (f"run the test again with --hypothesis-seed={forced_seed}: the seed draws the same examples (and no "
                "database is kept)")
    if database is None:
        return ("no example database is kept (database=None): run with --n2r-derandomize yes, or "
                "--hypothesis-seed=N, to draw the same examples again")
    return ("run the test again: Hypothesis's example database (.hypothesis/ by default) replays this example "
            "first; --n2r-derandomize yes draws the same examples every run")


def _shown_path(path: str | os.PathLike) -> str:
    """``path`` relative to the current directory when it lies inside it (shorter, and what a reader can
    open from where they ran pytest), else as it is."""
    try:
        return str(Path(path).resolve().relative_to(Path.cwd().resolve()))
    except ValueError:
        return str(path)


def nothing_to_test(run: RelationRecord, relation: Relation) -> str:
    """Why a relation whose draws were mostly undefined fails (more than :data:`MAX_UNDEFINED`)."""
    evaluated = len(run.valid_examples) + run.undefined
    reasons = "; ".join(f"{n}x {r}" for r, n in run.undefined_reasons.most_common(3))
    sizes = sorted({(e.camera["width"], e.camera["height"]) for e in run.examples if e.camera})
    at = f", rendered at {', '.join(f'{w}x{h}' for w, h in sizes)} pixels" if sizes else ""
    unchanged = run.undefined_reasons.most_common(1)[0][0] == SAME_PIXELS
    return (
        f"{'nothing was tested' if unchanged else 'the SUT produced nothing to test'}: {relation.metric!r} was "
        f"undefined on {run.undefined} of {evaluated} evaluated draws ({run.undefined / evaluated:.0%} > "
        f"{MAX_UNDEFINED:.0%}) on scene {run.scene!r}{at}: {reasons}. {_UNCHANGED_HINT if unchanged else _EMPTY_HINT}"
    )


_EMPTY_HINT = ("A SUT that returns nothing (no keypoints, an empty or all-NaN output) never passes a relation; a "
               "detector may find nothing in images this small (ORB keeps 31 pixels from each border): a larger size "
               "(size= or --n2r-size) gives it more")
_UNCHANGED_HINT = ("The changes drawn left the pictures as they were: the views show nothing a small change moves (a "
                   "blank or black region), or the bounds are too small to move a pixel at this size; widen the "
                   "bounds or choose views that show the scene")


def too_many_invalid(run: RelationRecord, relation: Relation) -> str:
    """Why a relation whose follow-up views were mostly invalid is a usage error."""
    drawn = len(run.examples)
    share = run.rejected / drawn if drawn else 1.0
    reasons = ", ".join(f"{r}: {n}" for r, n in run.rejected_reasons.most_common()) or "no valid example"
    nothing = "" if run.valid_examples or not drawn else ": no follow-up view was valid, so nothing was compared"
    moved = any(e.transform and any(e.transform.get(k) for k in ("x", "y", "z")) for e in run.examples)
    turned_back = "look_at=True" in repr(relation.transform)  # the repr is the transforms(...) call
    look_at = (" (or use look_at=True, which turns a moved camera back toward what it saw)"
               if moved and not turned_back else "")
    return (
        f"{relation.transform!r} leaves what the scene {run.scene!r} can render faithfully in {share:.0%} of "
        f"{drawn} draws ({reasons}){nothing}; narrow the bounds{look_at} so most follow-up views stay in the "
        "captured region. If even small motions leave it, the scene covers little beyond its own views (a short "
        "fit, or few photos): `n2r info SCENE` shows what it holds"
    )
