"""Comparing a run with its baseline: the replayed examples paired with the baseline's, judged per relation.

Each relation's outcome is one of :data:`OUTCOMES`: the relation regressed (``worse``) when a one-sided Student t
lower confidence bound of the mean increase of the deviation over its paired examples exceeds the margin the user
sets (:func:`compare_paired`); a relation that is in the baseline but did not run (``missing``) says whether it
was deselected, its scene is not in this run's scene set, or no test of that id was collected (renamed or deleted).
"""

from __future__ import annotations

import math
import re
from collections.abc import Collection
from dataclasses import dataclass, field

import numpy as np

from .. import defaults
from ..errors import InvalidArgument
from ..relation.record import ExampleRecord, RelationRecord

__all__ = ["OUTCOMES", "DEFAULT_FAIL_ON", "MAX_LOST", "PairedComparison", "parse_margin", "parse_outcomes",
           "compare_paired", "paired_bound", "check_confidence", "percent", "format_comparison_table",
           "replay_candidates"]

#: What comparing one relation with its baseline can give, and what each means.
OUTCOMES = {
    "ok": "paired examples replayed; the mean increase of the deviation is within the margin",
    "worse": "the lower confidence bound of the mean increase of the deviation exceeds the margin",
    "lost": "more than 10% of the baseline's examples are no longer tests (undefined or rejected now)",
    "no-pairs": "nothing could be paired (the relation errored, or no example was replayed)",
    "changed-scene": "the baseline was recorded on different scene content (content hash)",
    "changed-metric": "the relation's metric changed, so deviations cannot be compared",
    "changed-eps": "paired examples are within the margin, but the relation's eps changed",
    "missing": "in the baseline but not run (deselected, renamed or deleted)",
    "new": "run but not in the baseline (nothing to compare with)",
}
#: Outcomes that fail the run unless ``--n2r-compare-fail-on`` says otherwise.
DEFAULT_FAIL_ON = defaults.COMPARE_FAIL_ON
#: Share of a baseline's accepted examples that may become undefined before a relation is "lost".
MAX_LOST = 0.1

# -- comparing ------------------------------------------------------------------------------------------


def replay_candidates(baseline: RelationRecord) -> list[ExampleRecord]:
    """The baseline examples a comparison replays: the accepted ones (the others tested nothing)."""
    return [e for e in baseline.examples if e.valid and e.replayable]


def paired_bound(changes: list[float], confidence: float = defaults.COMPARE_CONFIDENCE) -> float:
    """One-sided lower confidence bound of the mean of paired ``changes``: Student's ``mean - t(confidence, n - 1)
    s / sqrt(n)`` (``s`` the sample standard deviation). NaN for no changes (or a non-finite one); ``-inf`` for a
    single change, which bounds nothing; the mean itself when every change is the same (``s = 0``).

    A percentile bootstrap gave bounds too high with few pairs (with 2 pairs, the smaller change: at a true mean
    equal to the margin it called a quarter of comparisons worse, where 5 % were asked for); the t bound keeps
    3-7 % at 2 to 20 pairs (``tests/report/test_baseline.py``, 2 000 draws of normal changes each).

    >>> paired_bound([0.0] * 20)
    0.0
    >>> round(paired_bound([0.1] * 10 + [0.0] * 10), 4)
    0.0302
    >>> paired_bound([0.5])
    -inf
    """
    check_confidence(confidence)
    x = np.asarray(changes, dtype=np.float64)
    if x.size == 0 or not np.isfinite(x).all():
        return math.nan
    if x.size == 1:
        return -math.inf
    if np.all(x == x[0]):
        return float(x[0])
    mean = math.fsum(x.tolist()) / x.size
    from scipy.stats import t

    spread = float(np.std(x, ddof=1)) / math.sqrt(x.size)
    return mean - float(t.ppf(confidence, x.size - 1)) * spread


def check_confidence(confidence: float) -> float:
    """``confidence`` as a float in (0.5, 1), or :class:`InvalidArgument` naming it.

    >>> check_confidence(1.5)
    Traceback (most recent call last):
    ...
    pytest_n2r.errors.InvalidArgument: confidence=1.5 is not a probability in (0.5, 1), e.g. 0.95
    """
    number = isinstance(confidence, (int, float, np.floating)) and not isinstance(confidence, bool)
    if not number or not 0.5 < confidence < 1:
        raise InvalidArgument(f"confidence={confidence!r} is not a probability in (0.5, 1), e.g. 0.95")
    return float(confidence)


def percent(confidence: float) -> str:
    """A confidence as a percentage, to its last digit (``0.975`` is ``97.5%``, not ``98%``).

    >>> percent(0.95), percent(0.975), percent(0.99999999)
    ('95%', '97.5%', '99.999999%')
    """
    return f"{round(confidence * 100, 10):.12g}%"


@dataclass
class PairedComparison:
    """One relation against its baseline: ``n`` paired examples, the mean change of the deviation
    (candidate − baseline; positive is worse), its lower confidence ``bound``, ``lost`` examples (a test
    in the baseline, undefined or rejected now), the ``outcome`` (a key of :data:`OUTCOMES`) with its
    ``message``, and whether it ``fails`` the run."""

    nodeid: str
    outcome: str
    n: int = 0
    mean_change: float = math.nan
    bound: float = math.nan
    lost: int = 0
    message: str = ""
    fails: bool = False
    notes: list[str] = field(default_factory=list)
    #: Other outcomes that apply too (a relation both ``lost`` and ``worse``): it fails when any is a failing one.
    also: tuple[str, ...] = ()

    @property
    def verdict(self) -> str:
        """Every outcome that applies, the first one first (``"lost+worse"``)."""
        return "+".join((self.outcome, *self.also))


_MARGIN = re.compile(r"^\s*mean\s*:\s*(?P<value>[0-9]*\.?[0-9]+(?:e-?[0-9]+)?)\s*$")


def parse_margin(spec: str | list[str] | None) -> float:
    """The margin of ``--n2r-compare-fail mean:MARGIN`` (absolute deviation units; default
    :data:`pytest_n2r.defaults.COMPARE_MARGIN`).

    >>> parse_margin("mean:0.05")
    0.05
    """
    parts = [p for chunk in ([spec] if isinstance(spec, str) else spec or []) for p in chunk.split(",") if p.strip()]
    if not parts:
        return defaults.COMPARE_MARGIN
    if len(parts) > 1:
        raise InvalidArgument(f"--n2r-compare-fail={','.join(parts)!r}: give one rule, mean:MARGIN")
    m = _MARGIN.match(parts[0])
    if not m:
        raise InvalidArgument(
            f"--n2r-compare-fail={parts[0]!r}: expected mean:MARGIN, the largest allowed mean increase of the "
            "deviation per paired example (e.g. mean:0.02); the gate compares the same examples in pairs"
        )
    return float(m["value"])


def parse_outcomes(spec: str | list[str] | None) -> tuple[str, ...]:
    """Outcomes that fail the run, from ``--n2r-compare-fail-on`` (comma-separated), default
    :data:`DEFAULT_FAIL_ON` (``None``); a value that names no outcome (``--n2r-compare-fail-on=``) is an error, not
    the default.

    >>> parse_outcomes("worse, lost")
    ('worse', 'lost')
    """
    if spec is None:
        return DEFAULT_FAIL_ON
    chunks = [spec] if isinstance(spec, str) else spec
    parts = [p.strip() for chunk in chunks for p in chunk.split(",") if p.strip()]
    if not parts:
        raise InvalidArgument(f"--n2r-compare-fail-on={','.join(chunks)!r} names no outcome; give one or more of "
                              f"{', '.join(o for o in OUTCOMES if o != 'ok')}, comma-separated (default: "
                              f"{', '.join(DEFAULT_FAIL_ON)})")
    unknown = [p for p in parts if p not in OUTCOMES or p == "ok"]
    if unknown:
        raise InvalidArgument(f"--n2r-compare-fail-on={','.join(parts)!r}: unknown outcome(s) {unknown}; expected "
                              f"some of {', '.join(o for o in OUTCOMES if o != 'ok')}")
    return tuple(parts)


def compare_paired(baseline: dict[str, RelationRecord], current: list[RelationRecord], *,
                   margin: float = defaults.COMPARE_MARGIN, confidence: float = defaults.COMPARE_CONFIDENCE,
                   fail_on: tuple[str, ...] = DEFAULT_FAIL_ON, collected: Collection[str] | None = None,
                   scenes: Collection[str] | None = None) -> list[PairedComparison]:
    """Compare every current relation with the same test id's baseline on the replayed examples, in pairs (of
    several records of one test id, the last); baseline relations that did not run are ``missing``. ``collected``
    (the relation test ids this session collected) and ``scenes`` (this run's scene names as its relation records
    carry them, :attr:`RelationRecord.scene`), where given, tell why one is missing or new: deselected, a scene set
    that differs from the baseline's (the scenes its relations were recorded on), or renamed or deleted."""
    check_confidence(confidence)
    current = list({rel.nodeid: rel for rel in current}.values())  # a test run again under its id: its last record
    out = [_compare_one(baseline.get(rel.nodeid), rel, margin, confidence)
           for rel in sorted(current, key=lambda r: r.nodeid)]
    ran = {rel.nodeid for rel in current}
    out += [PairedComparison(nodeid, "missing", message=_why_missing(baseline[nodeid], collected, scenes))
            for nodeid in sorted(set(baseline) - ran)]
    not_recorded: Collection[str] = getattr(baseline, "not_recorded", frozenset())  # a loaded Baseline's
    # like with like: the scene names relation records carry (a loaded scene's name), never ``meta.scenes`` (the
    # configured names the test ids carry: 'make' for the scene ``myscenes:make`` named 'plane')
    base_scenes = {r.scene for r in baseline.values() if r.scene}
    scene_of = {rel.nodeid: rel.scene for rel in current}
    for c in out:
        if c.outcome == "new" and c.nodeid in not_recorded:
            c.outcome = "missing"
            c.message = ("not in the baseline: the session that saved it collected this relation but did not run it "
                         "(deselected with -k / -m / --deselect, or skipped), so nothing gates it; save the baseline "
                         "from a session that runs it, or pass --n2r-compare-fail-on without 'missing'")
        elif c.outcome == "new" and base_scenes and scene_of.get(c.nodeid) and scene_of[c.nodeid] not in base_scenes:
            c.message = (f"not in the baseline: it runs on scene {scene_of[c.nodeid]!r}, which the baseline's scenes "
                         f"({', '.join(sorted(base_scenes))}) lack: the scene set differs from the baseline's, so "
                         "nothing to compare with (save a new baseline on this scene set to include it)")
    for c in out:
        c.fails = c.outcome in fail_on or any(o in fail_on for o in c.also)
    return out


_WITHOUT_MISSING = "or pass --n2r-compare-fail-on without 'missing'"


def _why_missing(base: RelationRecord, collected: Collection[str] | None, scenes: Collection[str] | None) -> str:
    """Why a baseline relation did not run, as far as the session can tell."""
    if collected is not None and base.nodeid in collected:
        return ("in the baseline but not run in this session: collected, then deselected (-k / -m / --deselect) or "
                f"skipped; run it, {_WITHOUT_MISSING}")
    if scenes is not None and base.scene and base.scene not in scenes:
        return (f"in the baseline but not run: it was recorded on scene {base.scene!r}, which is not among this run's "
                f"scenes ({', '.join(sorted(scenes)) or 'none'}): the scene set differs from the baseline's; run "
                f"with the baseline's scenes, save a new baseline on this scene set, {_WITHOUT_MISSING}")
    if collected is not None:
        return ("in the baseline but no test of this id was collected in this session: the relation was renamed or "
                "deleted (or its file was not among the paths given to pytest); on a pull request that renames or "
                f"removes a relation, refresh the baseline when it merges, {_WITHOUT_MISSING} for that pull request "
                "(docs/reporting.md)")
    return ("in the baseline but not run in this session (deselected, renamed or deleted); run it, "
            f"{_WITHOUT_MISSING}")


def _compare_one(
    base: RelationRecord | None, cur: RelationRecord, margin: float, confidence: float
) -> PairedComparison:
    nodeid = cur.nodeid
    if base is None:
        return PairedComparison(nodeid, "new", message="not in the baseline: nothing to compare with (save a new "
                                "baseline to include it)")
    if base.metric != cur.metric:
        return PairedComparison(nodeid, "changed-metric", message=f"metric changed from {base.metric} to "
                                f"{cur.metric}: deviations are not comparable; save a new baseline")
    if base.scene_hash != cur.scene_hash:
        return PairedComparison(
            nodeid, "changed-scene", message=f"recorded on scene content {base.scene_hash[:12]}, run on "
            f"{cur.scene_hash[:12]} (the scene file, its render settings or pytest-n2r's renderer changed, or a "
            "fitted scene rendered on another device: its content names the CPU's compiled renderer or torch's "
            "device and GPU, so a baseline saved on CPU CI differs on a GPU machine; pin --n2r-device cpu where "
            "baselines are gated): the examples cannot be replayed as they were; save a new baseline on the new "
            "scene")
    base_examples = replay_candidates(base)
    replayed = cur.replayed or []
    if not replayed or len(replayed) != len(base_examples):
        why = f"the relation ended in {cur.outcome}" if cur.outcome == "error" else "no example was replayed"
        return PairedComparison(nodeid, "no-pairs", message=f"{why}: nothing to pair with the baseline's "
                                f"{len(base_examples)} examples")
    if [b.key() for b in base_examples] != [c.key() for c in replayed]:
        return PairedComparison(nodeid, "no-pairs", message="the replayed examples are not the baseline's (scene "
                                "content, pose, camera or follow-up differ); save a new baseline")
    changes, lost = [], 0
    for b, c in zip(base_examples, replayed):
        if c.valid:
            changes.append(c.deviation - b.deviation)
        else:
            lost += 1
    n = len(changes)
    mean = math.fsum(changes) / n if n else math.nan
    bound = paired_bound(changes, confidence)
    result = PairedComparison(nodeid, "ok", n, mean, bound, lost)
    if math.isnan(bound):
        result.outcome = "no-pairs"
        result.message = f"no paired example is a test now ({lost} of {len(base_examples)} undefined or rejected)"
        return result
    applies = []  # every outcome that applies, most telling first: the relation fails when any is a failing one
    if lost > MAX_LOST * len(base_examples):
        applies.append(("lost", (f"{lost} of {len(base_examples)} baseline examples are no longer tests (undefined "
                        "now: the SUT produced nothing to compare; or rejected now: the relation's validity "
                        "thresholds changed)")))
    if bound > margin:
        applies.append(("worse", (f"the deviation grew by {mean:+.4f} on average over {n} paired examples; its "
                        f"{percent(confidence)} lower bound {bound:+.4f} exceeds the margin {margin:g}")))
    if base.eps != cur.eps:
        applies.append(("changed-eps", f"eps changed from {base.eps:g} to {cur.eps:g}"
                        + ("" if applies else " (within the margin)")))
    if applies:
        (result.outcome, result.message), rest = applies[0], applies[1:]
        result.also = tuple(o for o, _ in rest)
        result.message += "".join(f"; also {o}: {m}" for o, m in rest)
    if 0 < lost and result.outcome != "lost":  # a few lost examples: the mean is over the rest, which may flatter it
        result.notes.append(f"{lost} of {len(base_examples)} lost: undefined or rejected now, left out of the mean")
    if n == 1:
        result.notes.append("1 pair: no confidence bound, so it cannot be judged worse")
    elif result.outcome == "ok" and -paired_bound([-c for c in changes], confidence) < -margin:
        result.notes.append(f"better: the deviation fell by more than the margin ({percent(confidence)} upper "
                            "bound); save a new baseline once this change is merged, to gate against it")
    return result


def format_comparison_table(comparisons: list[PairedComparison],
                            confidence: float = defaults.COMPARE_CONFIDENCE) -> str:
    """A plain-text table per relation: n, mean change, its lower confidence bound, verdict."""
    header = ["relation", "n", "mean change", f"{percent(confidence)} lower bound", "verdict"]
    rows = [header]
    for c in comparisons:
        verdict = c.verdict + (" (fails)" if c.fails else "") + (f" [{'; '.join(c.notes)}]" if c.notes else "")
        rows.append([c.nodeid, str(c.n) if c.n or c.outcome in ("ok", "worse", "lost") else "—",
                     "—" if math.isnan(c.mean_change) else f"{c.mean_change:+.4f}",
                     "—" if math.isnan(c.bound) else f"{c.bound:+.4f}", verdict])
    widths = [max(len(r[i]) for r in rows) for i in range(len(header))]
    return "\n".join("  ".join(cell.ljust(w) for cell, w in zip(r, widths)).rstrip() for r in rows)
