"""Baselines: save every example of a run, replay exactly those examples later and compare them in pairs.

A baseline is JSON with stable ordering (sorted keys, relations by test id) so it diffs well in review. It
holds, per relation, one record per drawn example with all a replay needs (see
:class:`~pytest_n2r.relation.record.ExampleRecord`). ``--n2r-compare`` replays the baseline's accepted
examples on the current code, pairs each with its baseline record and judges the per-example changes of
the **deviation** (0 = ideal, larger = worse, whatever the metric's direction): the relation regressed when
a one-sided Student t lower confidence bound of the mean increase exceeds the margin the user sets
(:func:`compare_paired`). Unchanged code gives identical deviations (renders and SUTs are deterministic),
so its bound is exactly 0.

Every number of a baseline is checked on load (:func:`load_baseline`): a baseline that could silently pass
a regression (no relations, a NaN deviation, a malformed example) is a :class:`BaselineError` naming the
file, the relation, the example and the field.
"""

from __future__ import annotations

import json
import math
import os
import re
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np

from .. import defaults
from ..data.atomic import atomic_write_text
from ..errors import InvalidArgument, N2RError
from ..relation.record import ExampleRecord, RelationRecord
from .validate import BadField, DuplicateKey, check_version, meta_from_json, relation_from_json, unique_keys

__all__ = ["FORMAT", "VERSION", "BaselineError", "Baseline", "save_baseline", "load_baseline", "OUTCOMES",
           "DEFAULT_FAIL_ON", "PairedComparison", "parse_margin", "parse_outcomes", "compare_paired", "paired_bound",
           "check_confidence", "percent",
           "format_comparison_table", "replay_candidates"]

FORMAT = "pytest-n2r-baseline"
VERSION = 2

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


class BaselineError(N2RError):
    """A baseline file that cannot be used: missing, unreadable, from another version, or malformed."""


class Baseline(dict):
    """A loaded baseline: its relation records by test id, and :attr:`not_recorded`, the relation test ids the
    session that saved it collected but recorded nothing for (deselected with ``-k`` / ``-m`` / ``--deselect``,
    skipped, or not run): a comparison reports those as ``missing``, not ``new``."""

    not_recorded: frozenset[str] = frozenset()


# -- writing --------------------------------------------------------------------------------------------


def _plain_number(value: float) -> float | None:
    """JSON has no NaN: a non-finite number (the score of a rejected or undefined example) is written null."""
    return value if isinstance(value, (int, float)) and math.isfinite(value) else None


def save_baseline(path: str | os.PathLike, relations: list[RelationRecord], meta: dict | None = None) -> Path:
    """Write every relation's drawn examples (all statuses, replay data included) to ``path`` atomically:
    strict JSON, relations sorted by test id, one line per example (so a review diff shows which changed)."""
    def line(value: Any) -> str:
        return json.dumps(value, sort_keys=True, allow_nan=False)

    parts = []
    for r in sorted(relations, key=lambda r: r.nodeid):
        head = {"metric": r.metric, "eps": r.eps, "scene": r.scene, "scene_hash": r.scene_hash, "outcome": r.outcome}
        examples = ",\n".join(
            "    " + line({**{k: v for k, v in e.to_dict().items() if k != "images"},
                          "score": _plain_number(e.score), "deviation": _plain_number(e.deviation)})
            for e in r.examples)
        fields = ",\n".join(f"   {json.dumps(k)}: {line(v)}" for k, v in sorted(head.items()))
        parts.append(f"  {json.dumps(r.nodeid)}: {{\n{fields},\n   \"examples\": [\n{examples}\n   ]\n  }}")
    text = (f'{{\n "format": "{FORMAT}",\n "meta": {line(meta or {})},\n "relations": {{\n' + ",\n".join(parts)
            + f"\n }},\n \"version\": {VERSION}\n}}\n")
    json.loads(text)  # what is written must read back
    return atomic_write_text(path, text)


# -- reading and validating -----------------------------------------------------------------------------


def load_baseline(path: str | os.PathLike) -> Baseline:
    """Read and validate a baseline written by :func:`save_baseline`; :class:`BaselineError` names what
    is wrong (file, relation, example, field) and how to fix it."""
    path = Path(path)
    regenerate = f"regenerate it with --n2r-save-baseline {path}"
    if not path.is_file():
        raise BaselineError(f"baseline {path} does not exist; create it with --n2r-save-baseline {path}")
    try:
        data = json.loads(path.read_text(encoding="utf-8"), parse_constant=_reject_constant,
                          object_pairs_hook=unique_keys)
    except DuplicateKey as exc:
        raise BaselineError(f"baseline {path}: {exc}, or {regenerate}") from None
    except (OSError, UnicodeDecodeError, json.JSONDecodeError, ValueError) as exc:
        raise BaselineError(f"baseline {path} is not readable JSON: {exc}; {regenerate}") from None
    except RecursionError:
        raise BaselineError(f"baseline {path} is not readable JSON: nested too deeply for the JSON parser; "
                            f"{regenerate}") from None
    if not isinstance(data, dict) or data.get("format") != FORMAT:
        raise BaselineError(f"baseline {path} is not a pytest-n2r baseline (missing \"format\": \"{FORMAT}\")")
    wrong_version = check_version(data, VERSION)
    if wrong_version is not None:
        newer = isinstance(data.get("version"), int) and data["version"] > VERSION
        raise BaselineError(f"baseline {path} {wrong_version}" + ("" if newer else f"; {regenerate}"))
    relations = data.get("relations")
    if not isinstance(relations, dict) or not relations:
        raise BaselineError(
            f"baseline {path} has no relations: it would let every relation pass as new; {regenerate} "
            "on a run that has relation tests"
        )
    out = Baseline()
    for nodeid, rel in relations.items():
        try:
            out[nodeid] = relation_from_json(nodeid, rel)
        except BadField as exc:
            raise BaselineError(f"baseline {path}: relation {nodeid!r}: {exc}; {regenerate}") from None
    try:
        meta = meta_from_json(data.get("meta"))
    except BadField as exc:
        raise BaselineError(f"baseline {path}: {exc}; {regenerate}") from None
    out.not_recorded = frozenset(meta.get("not_recorded", ())) - set(out)
    return out


def _reject_constant(name: str) -> float:
    raise ValueError(f"{name} is not a number JSON allows (pytest-n2r writes null for 'no value')")


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
    :data:`DEFAULT_FAIL_ON`."""
    parts = [p.strip() for chunk in ([spec] if isinstance(spec, str) else spec or []) for p in chunk.split(",")
             if p.strip()]
    if not parts:
        return DEFAULT_FAIL_ON
    unknown = [p for p in parts if p not in OUTCOMES or p == "ok"]
    if unknown:
        raise InvalidArgument(f"--n2r-compare-fail-on={','.join(parts)!r}: unknown outcome(s) {unknown}; expected "
                              f"some of {', '.join(o for o in OUTCOMES if o != 'ok')}")
    return tuple(parts)


def compare_paired(baseline: dict[str, RelationRecord], current: list[RelationRecord], *,
                   margin: float = defaults.COMPARE_MARGIN, confidence: float = defaults.COMPARE_CONFIDENCE,
                   fail_on: tuple[str, ...] = DEFAULT_FAIL_ON) -> list[PairedComparison]:
    """Compare every current relation with the same test id's baseline on the replayed examples, in pairs;
    baseline relations that did not run are ``missing``."""
    check_confidence(confidence)
    out = [_compare_one(baseline.get(rel.nodeid), rel, margin, confidence)
           for rel in sorted(current, key=lambda r: r.nodeid)]
    ran = {rel.nodeid for rel in current}
    out += [PairedComparison(nodeid, "missing", message="in the baseline but not run in this session (deselected, "
                             "renamed or deleted); run it, or pass --n2r-compare-fail-on without 'missing'")
            for nodeid in sorted(set(baseline) - ran)]
    not_recorded = getattr(baseline, "not_recorded", frozenset())
    for c in out:
        if c.outcome == "new" and c.nodeid in not_recorded:
            c.outcome = "missing"
            c.message = ("not in the baseline: the session that saved it collected this relation but did not run it "
                         "(deselected with -k / -m / --deselect, or skipped), so nothing gates it; save the baseline "
                         "from a session that runs it, or pass --n2r-compare-fail-on without 'missing'")
    for c in out:
        c.fails = c.outcome in fail_on or any(o in fail_on for o in c.also)
    return out


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
            f"{cur.scene_hash[:12]} (the scene file, its render settings or pytest-n2r's renderer changed): the "
            "examples cannot be replayed as they were; save a new baseline on the new scene")
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
    if base.eps != cur.eps:
        result.notes.append(f"eps changed {base.eps:g} -> {cur.eps:g}")
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
        result.message += "".join(f"; also {o}: {m}" for o, m in rest if o != "changed-eps")
    if 0 < lost and result.outcome != "lost":  # a few lost examples: the mean is over the rest, which may flatter it
        result.notes.append(f"{lost} of {len(base_examples)} lost: undefined or rejected now, left out of the mean")
    if n == 1:
        result.notes.append("1 pair: no confidence bound, so it cannot be judged worse")
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
