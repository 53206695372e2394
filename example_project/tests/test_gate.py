"""The regression gate: every shipped detector replays the examples of the committed baseline
(``tests/gate-baseline.json``, recorded from ``tests/test_detectors.py`` on the demo scenes) and is judged
per example against its own recorded deviations.

No environment variable is needed: the shipped configuration in ``perception/detectors.py`` is what runs,
so a pull request that edits it (or OpenCV, or the image pipeline) is judged here. ``PERCEPTION_ORB=<name>``
puts a candidate (or one of ``perception/regressions.py``) in the place of ORB.

The judgement is pytest-n2r's paired comparison (the same as ``--n2r-compare``): for each relation, the
per-example increase of the deviation over its baseline examples, and a one-sided 95 % Student t lower bound
of its mean; a relation fails when that bound exceeds ``MARGIN``, when examples stop being tests (the
detector finds nothing), or when the baseline no longer matches the scene or the metric. An unchanged
detector replays bit for bit (bound exactly 0). Re-record the baseline after an intended change with the
command in README.md ("The regression gate").

That the gate catches each realistic regression of ``perception/regressions.py`` is a test of pytest-n2r's
gate, not of this project's perception code: it lives in pytest-n2r's own suite
(``tests/example/test_regression_gate.py``), so this suite replays only the shipped detectors.
"""

from __future__ import annotations

import functools
from pathlib import Path
from typing import Any

import pytest
from perception.detectors import detector

from pytest_n2r import RenderCache, Transform
from pytest_n2r.relation import Relation, RunSettings, replay_relation
from pytest_n2r.relation.sut_outputs import SUTOutputs
from pytest_n2r.report import (
    PairedComparison,
    RelationRecord,
    compare_paired,
    load_baseline,
    replay_candidates,
)
from pytest_n2r.report.compare import format_comparison_table

from .test_detectors import REPEATABILITY, SPREAD  # the metrics the baseline's relations used

BASELINE = Path(__file__).with_name("gate-baseline.json")
#: The largest mean increase of the deviation per paired example the gate accepts (deviations are
#: 1 - repeatability and 1 - spread). An unchanged detector gives exactly 0; README.md gives the measured
#: increases of the regressions it must catch.
MARGIN = 0.02
#: Which detector each baseline relation tested (by test function name prefix); None: the ORB under test.
DETECTOR_OF = {"test_orb_": None, "test_sift_": "sift", "test_akaze_": "akaze"}
METRICS = {repr(m): m for m in (REPEATABILITY, SPREAD)}

pytestmark = pytest.mark.gate


@functools.cache
def baseline() -> dict[str, RelationRecord]:
    return load_baseline(BASELINE)


def relations_of(prefix: str, scene_name: str) -> list[RelationRecord]:
    """The baseline relations of the tests named ``prefix*`` on ``scene_name``."""
    return [r for nodeid, r in sorted(baseline().items())
            if nodeid.split("::")[-1].startswith(prefix) and r.scene == scene_name]


def replay(scene: Any, sut: Any, base: RelationRecord, cache: RenderCache,
           sut_outputs: SUTOutputs | None = None) -> RelationRecord:
    """``sut`` on exactly the baseline's examples of one relation (nothing replayed when the scene's content
    or the metric changed: the comparison says so). ``sut_outputs``: ``sut``'s outputs on renders to reuse
    (those of this run's relations, which ran the same detector object on the same renders)."""
    metric = METRICS.get(base.metric)
    if metric is None or base.scene_hash != scene.content_hash:
        # a metric this suite no longer uses (its parameters or its count changed) is named by the suite's metric
        # of the same kind, so the comparison reads "changed-metric" rather than "nothing replayed"
        now = metric or next((m for m in METRICS.values() if base.metric.startswith(f"{m.name}(")), None)
        return RelationRecord(base.nodeid, base.metric if now is None else repr(now), base.eps,
                              scene=scene.name, scene_hash=scene.content_hash)
    relation = Relation.build(metric, base.eps, Transform())
    return replay_relation(scene, sut, relation, replay_candidates(base), settings=RunSettings(timeout=None),
                           cache=cache, test_id=base.nodeid, sut_outputs=sut_outputs)


def gate(scene: Any, sut: Any, prefix: str, cache: RenderCache, margin: float = MARGIN,
         sut_outputs: SUTOutputs | None = None) -> list[PairedComparison]:
    """Replay every baseline relation of ``prefix`` on ``scene`` for ``sut`` and compare in pairs."""
    bases = relations_of(prefix, scene.name)
    records = [replay(scene, sut, base, cache, sut_outputs) for base in bases]
    return compare_paired({b.nodeid: b for b in bases}, records, margin=margin)


def _skip_unknown_scene(scene: Any) -> None:
    if not any(r.scene == scene.name for r in baseline().values()):
        pytest.skip(f"the committed baseline has no relation on scene {scene.name!r} (it covers the demo scenes)")


@pytest.mark.parametrize("prefix", DETECTOR_OF)
def test_shipped_detector_is_not_worse_than_its_baseline(n2r_scene, prefix, n2r_session):
    """``n2r_session``: pytest-n2r's render cache (the relations' renders, already in memory) and the outputs
    of the detectors on them: the replay renders nothing and runs a detector only where no relation did."""
    _skip_unknown_scene(n2r_scene)
    name = DETECTOR_OF[prefix]
    sut = detector(name)
    comparisons = gate(n2r_scene, sut, prefix, n2r_session.cache, sut_outputs=n2r_session.sut_outputs)
    assert comparisons, f"no baseline relation of {prefix}* on {n2r_scene.name}"
    table = format_comparison_table(comparisons)
    print(f"{sut!r} on {n2r_scene.name} against {BASELINE.name}:\n{table}")
    failed = [c for c in comparisons if c.fails]
    assert not failed, f"{sut!r} regressed against the committed baseline on {n2r_scene.name}:\n{table}\n" + \
        "\n".join(f"{c.nodeid}: {c.outcome}: {c.message}" for c in failed)
