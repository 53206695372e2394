"""Baselines: save a run's examples and scores, compare a later run against them.

A baseline is JSON with stable ordering (sorted keys, relations by test id) so it diffs well in review.
Comparison works on **deviations** (0 = ideal, larger = worse), whatever the metric's direction, so one
rule means the same for repeatability and for an L2 distance.
"""

from __future__ import annotations

import json
import math
import os
import re
from dataclasses import dataclass
from pathlib import Path

from ..data.atomic import atomic_write_text
from ..errors import InvalidArgument, N2RError
from .records import STATS, RelationRecord

__all__ = ["FORMAT", "save_baseline", "load_baseline", "CompareRule", "parse_compare_rules", "Comparison",
           "compare_runs", "format_comparison_table"]

FORMAT = "pytest-n2r-baseline"
VERSION = 1


def save_baseline(path: str | os.PathLike, relations: list[RelationRecord], meta: dict | None = None) -> Path:
    """Write every relation's examples (scene, view, transform, score, deviation) to ``path`` atomically."""
    data = {
        "format": FORMAT,
        "version": VERSION,
        "meta": meta or {},
        "relations": {
            r.nodeid: {
                "metric": r.metric,
                "eps": r.eps,
                "stats": r.stats(),
                "examples": [
                    {k: getattr(e, k) for k in ("scene", "view", "transform", "score", "deviation", "passed", "valid")}
                    for e in r.examples
                ],
            }
            for r in sorted(relations, key=lambda r: r.nodeid)
        },
    }
    return atomic_write_text(path, json.dumps(data, indent=1, sort_keys=True, allow_nan=True) + "\n")


def load_baseline(path: str | os.PathLike) -> dict[str, RelationRecord]:
    """Read a baseline written by :func:`save_baseline`; raise :class:`N2RError` naming what is wrong."""
    path = Path(path)
    if not path.is_file():
        raise N2RError(f"baseline {path} does not exist; create it with --n2r-save-baseline {path}")
    try:
        data = json.loads(path.read_text(encoding="utf-8"))
    except (OSError, UnicodeDecodeError, json.JSONDecodeError) as exc:
        raise N2RError(f"baseline {path} is not readable JSON: {exc}") from None
    if not isinstance(data, dict) or data.get("format") != FORMAT:
        raise N2RError(f"baseline {path} is not a pytest-n2r baseline (missing \"format\": \"{FORMAT}\")")
    if data.get("version") != VERSION:
        raise N2RError(
            f"baseline {path} has format version {data.get('version')!r}; this pytest-n2r reads version "
            f"{VERSION}. Regenerate it with --n2r-save-baseline"
        )
    out = {}
    for nodeid, rel in data.get("relations", {}).items():
        try:
            out[nodeid] = RelationRecord.from_dict({"nodeid": nodeid, **rel})
        except (KeyError, TypeError, ValueError) as exc:
            raise N2RError(f"baseline {path}: relation {nodeid!r} is malformed ({exc!r})") from None
    return out


@dataclass(frozen=True)
class CompareRule:
    """Fail when statistic ``stat`` of the deviations grows by more than ``limit`` (absolute), or by more
    than ``limit`` percent of the baseline value when ``percent`` is set."""

    stat: str
    limit: float
    percent: bool = False

    def __str__(self) -> str:
        return f"{self.stat}:{self.limit:g}{'%' if self.percent else ''}"

    def worse_by(self, baseline: float, candidate: float) -> float:
        """How much worse ``candidate`` is, in the rule's unit (absolute or percent)."""
        diff = candidate - baseline
        if not self.percent:
            return diff
        return math.inf if baseline == 0 and diff > 0 else (0.0 if baseline == 0 else 100.0 * diff / abs(baseline))

    def fails(self, baseline: float, candidate: float) -> bool:
        if math.isnan(baseline) or math.isnan(candidate):
            return False
        return self.worse_by(baseline, candidate) > self.limit


_RULE = re.compile(r"^\s*(?P<stat>[a-z0-9]+)\s*:\s*(?P<value>[0-9]*\.?[0-9]+(?:e-?[0-9]+)?)\s*(?P<pct>%?)\s*$")


def parse_compare_rules(spec: str | list[str]) -> list[CompareRule]:
    """Parse ``"mean:0.05"``, ``"p90:0.1,rate:10%"`` (or a list of such) into rules.

    >>> parse_compare_rules("mean:0.05,p90:10%")
    [CompareRule(stat='mean', limit=0.05, percent=False), CompareRule(stat='p90', limit=10.0, percent=True)]
    """
    parts = [spec] if isinstance(spec, str) else list(spec)
    rules = []
    for part in (p for chunk in parts for p in chunk.split(",") if p.strip()):
        m = _RULE.match(part)
        if not m or m["stat"] not in STATS:
            raise InvalidArgument(
                f"--n2r-compare-fail={part!r}: expected STAT:LIMIT or STAT:LIMIT% with STAT one of "
                f"{', '.join(STATS)} (e.g. mean:0.05 or p90:10%)"
            )
        rules.append(CompareRule(m["stat"], float(m["value"]), bool(m["pct"])))
    return rules


@dataclass
class Comparison:
    """A relation compared with its baseline: the statistics side by side and the rules it broke."""

    nodeid: str
    baseline: dict[str, float]
    candidate: dict[str, float]
    failed_rules: list[str]
    status: str  # "ok", "worse", "new" (no baseline), "stale" (metric or eps changed)

    @property
    def failed(self) -> bool:
        return self.status == "worse"


def compare_runs(
    baseline: dict[str, RelationRecord], current: list[RelationRecord], rules: list[CompareRule]
) -> list[Comparison]:
    """Compare each current relation with the baseline relation of the same test id."""
    out = []
    for rel in sorted(current, key=lambda r: r.nodeid):
        cand = rel.stats()
        base_rel = baseline.get(rel.nodeid)
        if base_rel is None:
            out.append(Comparison(rel.nodeid, {}, cand, [], "new"))
            continue
        base = base_rel.stats()
        if base_rel.metric != rel.metric or base_rel.eps != rel.eps:
            out.append(Comparison(rel.nodeid, base, cand, [], "stale"))
            continue
        broken = [
            f"{r} (baseline {base[r.stat]:.4f} -> {cand[r.stat]:.4f})" for r in rules if r.fails(base[r.stat], cand[r.stat])
        ]
        out.append(Comparison(rel.nodeid, base, cand, broken, "worse" if broken else "ok"))
    return out


def format_comparison_table(comparisons: list[Comparison], stats: tuple[str, ...] = ("mean", "p90", "rate")) -> str:
    """A plain-text table of baseline vs candidate per relation, for the terminal summary."""
    header = ["relation", *[f"{s} base→cand" for s in stats], "status"]
    rows = [header]
    for c in comparisons:
        cells = [c.nodeid]
        for s in stats:
            b, k = c.baseline.get(s, math.nan), c.candidate.get(s, math.nan)
            cells.append("—" if math.isnan(b) else f"{b:.3f}→{k:.3f}")
        cells.append(c.status + (": " + "; ".join(c.failed_rules) if c.failed_rules else ""))
        rows.append(cells)
    widths = [max(len(r[i]) for r in rows) for i in range(len(header))]
    return "\n".join("  ".join(cell.ljust(w) for cell, w in zip(r, widths)).rstrip() for r in rows)
