"""How many examples the regression gate needs to catch each regression of ``perception/regressions.py``.

For every ORB relation of the committed baseline (``tests/gate-baseline.json``) on both demo scenes, the
regressed detector replays the baseline's examples; the gate's paired bound is then computed on the first
k pairs, k = 1 .. n. A regression is caught by a relation at the smallest k whose bound exceeds the margin.
Printed per regression: how many relations catch it with all their pairs, the mean increase of the
deviation (its range over the relations), and the smallest k over the catching relations (the gate fails as
soon as one relation does) with the median k; and how many of the relations' own eps tests the regression
fails on the same examples (the eps tests draw exactly the baseline's examples: derandomized).
Run from the repository root (about 20 s on a 2-core CPU once the suite has filled the render cache):

    python example_project/gate_power.py
"""

from __future__ import annotations

import sys
from dataclasses import replace
from pathlib import Path

HERE = Path(__file__).resolve().parent
sys.path.insert(0, str(HERE))

from perception.detectors import detector
from perception.regressions import REGRESSIONS
from tests.test_gate import MARGIN, relations_of, replay

from pytest_n2r import RenderCache
from pytest_n2r.demo import load_demo
from pytest_n2r.report import RelationRecord, compare_paired, replay_candidates


def examples_needed(base: RelationRecord, current: RelationRecord) -> int | None:
    """The smallest k for which the gate fails the relation on its first k baseline examples (None: never)."""
    bases, replayed = replay_candidates(base), current.replayed or []
    for k in range(1, len(bases) + 1):
        first_base = replace(base, examples=bases[:k])
        (c,) = compare_paired({base.nodeid: first_base}, [replace(current, replayed=replayed[:k])], margin=MARGIN)
        if c.fails:
            return k
    return None


def main() -> None:
    cache = RenderCache(HERE / ".n2r-cache")
    scenes = [load_demo(name) for name in ("wall", "object")]
    suts = {"orb (unchanged)": detector("orb"), **REGRESSIONS}
    print(f"margin {MARGIN}, 95% paired t bound; ORB relations of the committed baseline on "
          f"{', '.join(s.name for s in scenes)}")
    print(f"{'detector':24s} {'relations caught':>17s} {'mean change min..max':>22s} {'examples needed':>22s} "
          f"{'eps tests failed':>17s}")
    for name, sut in suts.items():
        needed, means, total, by, eps_failed = [], [], 0, [], 0
        for scene in scenes:
            for base in relations_of("test_orb_", scene.name):
                total += 1
                current = replay(scene, sut, base, cache)
                (c,) = compare_paired({base.nodeid: base}, [current], margin=MARGIN)
                means.append(c.mean_change)
                # the eps test draws the same examples (derandomized): it fails when one of them exceeds eps
                eps_failed += any(e.valid and e.deviation > base.eps for e in current.replayed or [])
                if c.fails:
                    needed.append(examples_needed(base, current))
                    by.append(f"{base.nodeid.split('::')[-1].removeprefix('test_orb_')} ({needed[-1]})")
        first = "never" if not needed else f"{min(needed)} (median {sorted(needed)[len(needed) // 2]})"
        print(f"{name:24s} {len(needed):>8d} of {total:<7d} {f'{min(means):+.3f}..{max(means):+.3f}':>22s} "
              f"{first:>22s} {eps_failed:>8d} of {total}")
        if by:
            print(f"{'':24s} caught by: {', '.join(by)}")


if __name__ == "__main__":
    main()
