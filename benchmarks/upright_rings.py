"""The up check on camera rings whose truth is known: how often a right photo reads as upside down, how often a turned
one is found, and how far the other photos' up axes spread in each case (what ``JUDGED_SPREAD_DEG`` rests on).

Run: ``python benchmarks/upright_rings.py [--draws 300] [--photos 3 4 5 6 7 8 9 10 11 12 16 24 48]``

For each photo count and draw, two rings around a subject (``tests/data/synthetic.py``'s ``ring_poses``, each photo
rolled up to 8° as a hand does, in a random world frame):

- **steep**: right photos looking down ``[lowest, lowest + 10°]``, ``lowest`` uniform in 0–75°. A photo 120° or more
  from the consensus there is a false alarm, which the check holds back where the others spread past
  ``JUDGED_SPREAD_DEG``; printed: how many draws had one (before that gate), and the others' spread in them.
- **turned**: photos looking down 0–20°, a fifth of them (at least one) turned half a turn about their viewing
  direction; printed: the draws where exactly the turned photos were found, and the others' largest spread.

Results: docs/scene-field-log.md, and the comment at ``JUDGED_SPREAD_DEG`` in ``pytest_n2r/data/upright.py``.
"""

from __future__ import annotations

import argparse
import sys
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))

from pytest_n2r.data.upright import JUDGED_SPREAD_DEG, UPSIDE_DOWN_DEG, check_upright
from tests.data.synthetic import HALF_TURN, in_a_random_frame, ring_poses


def _rest_spread(angles: np.ndarray) -> float:
    """The largest angle of the photos not past :data:`UPSIDE_DOWN_DEG` (degrees; 0 where none is)."""
    rest = angles[angles < UPSIDE_DOWN_DEG]
    return float(rest.max()) if rest.size else 0.0


def row(photos: int, draws: int) -> dict:
    """One photo count: false alarms on steep rings and detections on turned ones, with the spreads behind them."""
    names = [f"p{k:03d}" for k in range(photos)]
    alarms, alarm_spreads, found, turned_spreads = 0, [], 0, []
    for draw in range(draws):
        rng = np.random.default_rng(draw)
        lowest = rng.uniform(0.0, 75.0)
        check = check_upright(names, in_a_random_frame(ring_poses(photos, rng, (lowest, lowest + 10.0)), rng))
        if np.any(check.angles_deg >= UPSIDE_DOWN_DEG):  # what the check would say without the spread's gate
            alarms += 1
            alarm_spreads.append(_rest_spread(check.angles_deg))
        rng = np.random.default_rng(draws + draw)
        picked = set(rng.choice(photos, size=max(1, photos // 5), replace=False).tolist())
        poses = ring_poses(photos, rng, (0.0, 20.0))
        check = check_upright(names, in_a_random_frame(
            [p @ HALF_TURN if k in picked else p for k, p in enumerate(poses)], rng))
        found += set(check.upside_down) == {names[k] for k in picked}
        turned_spreads.append(_rest_spread(check.angles_deg))
    return {"photos": photos, "draws": draws, "alarms": alarms,
            "alarm_spread_min": min(alarm_spreads) if alarm_spreads else None,
            "found": found, "turned_spread_max": max(turned_spreads)}


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--draws", type=int, default=300, help="draws of each ring per photo count")
    parser.add_argument("--photos", type=int, nargs="+", default=[3, 4, 5, 6, 7, 8, 9, 10, 11, 12, 16, 24, 48])
    args = parser.parse_args(argv)
    if args.draws < 1 or min(args.photos) < 3:
        parser.error(f"--draws {args.draws} and --photos {min(args.photos)}: expected at least 1 draw and 3 photos")
    rows = [row(n, args.draws) for n in args.photos]
    print(f"the up check on rings (threshold {UPSIDE_DOWN_DEG:g}°, judged where the others spread at most "
          f"{JUDGED_SPREAD_DEG:g}°)\n")
    print("| photos | draws | steep rings: a right photo 120° off (before the gate) | the others' spread there, "
          "smallest ° | turned rings: exactly the turned found | the others' spread, largest ° |")
    print("|---|---|---|---|---|---|")
    for r in rows:
        spread = "—" if r["alarm_spread_min"] is None else f"{r['alarm_spread_min']:.1f}"
        print(f"| {r['photos']} | {r['draws']} | {r['alarms']} | {spread} | {r['found']} | "
              f"{r['turned_spread_max']:.1f} |")
    alarms = [r["alarm_spread_min"] for r in rows if r["alarm_spread_min"] is not None]
    print(f"\nall: {sum(r['alarms'] for r in rows)} false alarms before the gate (the others spread "
          f"{min(alarms):.1f}° or more)" if alarms else "\nall: no false alarm before the gate", end="")
    print(f"; turned photos found in {sum(r['found'] for r in rows)} of {sum(r['draws'] for r in rows)} draws, the "
          f"others within {max(r['turned_spread_max'] for r in rows):.1f}°")
    return 0


if __name__ == "__main__":
    sys.exit(main())
