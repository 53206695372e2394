"""Cost of one metamorphic relation as the plugin runs it: 100 examples of ORB repeatability at 480x270.

Run: ``python benchmarks/plugin_relation.py [--scene SPEC] [--examples N]``. ``SPEC`` is what
``--n2r-scene`` takes (``demo:object``, a ``.n2r`` file, ``module:function``); the default is the first
built-in demo scene, or the test suite's analytic plane when this build has no demo scenes.

Four runs of the same derandomized relation (``repeatability(px=2)``, ``eps=1`` so every example runs),
side by side in one process:

- **cold**: an empty render cache directory: every view is rendered;
- **warm, disk**: a new cache object on the same directory (what a second ``pytest`` run sees);
- **warm, memory**: the same cache object again (a second relation on the same views in one session);
- **no cache**: a memory-only cache that starts empty (the renders without disk writes).

Columns: wall time, time spent rendering (cache lookups included), in the SUT and in the metric (seconds),
renders done, valid and rejected examples. Targets: cold <= 30 s, warm <= 5 s, render <= SUT.
"""

from __future__ import annotations

import argparse
import sys
import tempfile
import time
from pathlib import Path

import cv2
import numpy as np

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))  # the repository's package and, as a fallback scene, its test scene

from pytest_n2r.cache import RenderCache  # noqa: E402
from pytest_n2r.metrics import repeatability  # noqa: E402
from pytest_n2r.relations import Relation, RunSettings, check_relation  # noqa: E402
from pytest_n2r.render.size import RenderSize  # noqa: E402
from pytest_n2r.session import default_scene_specs, load_scene_spec, parse_scene_specs  # noqa: E402
from pytest_n2r.strategies import transforms  # noqa: E402

ORB = cv2.ORB_create(500)


def orb(rgb: np.ndarray) -> np.ndarray:
    """The SUT: ORB keypoints (N, 2) in pixels of an RGB image."""
    gray = cv2.cvtColor(rgb, cv2.COLOR_RGB2GRAY)
    return np.array([k.pt for k in ORB.detect(gray, None)], dtype=np.float32).reshape(-1, 2)


def scene_spec(text: str | None):
    if text:
        return parse_scene_specs([text], Path.cwd(), "--scene")[0]
    specs = default_scene_specs()
    return specs[0] if specs else parse_scene_specs(["tests.plugin.fakescene:plane"], ROOT, "--scene")[0]


def run(scene, relation, settings, cache, label: str) -> list[str]:
    start = time.perf_counter()
    stats = check_relation(scene, orb, relation, settings=settings, cache=cache, test_id="benchmark")
    wall = time.perf_counter() - start
    return [label, f"{wall:.2f}", f"{stats.render_s:.2f}", f"{stats.sut_s:.2f}", f"{stats.metric_s:.2f}",
            str(stats.renders), str(stats.examples), str(stats.n_rejected)]


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--scene", help="scene spec (default: the first demo scene)")
    parser.add_argument("--examples", type=int, default=100)
    parser.add_argument("--size", default="480x270")
    args = parser.parse_args(argv)

    spec = scene_spec(args.scene)
    t0 = time.perf_counter()
    scene = load_scene_spec(spec, "auto")
    load_s = time.perf_counter() - t0
    relation = Relation.build(repeatability(px=2), 1.0, transforms(yaw=10, x=0.1), examples=args.examples)
    settings = RunSettings(examples=args.examples, size=RenderSize.parse(args.size), derandomize=True,
                           database=None, timeout=None)
    print(f"scene {spec.source} ({type(scene).__name__}, loaded in {load_s:.2f} s), {args.examples} examples of "
          f"{relation.describe()} at {args.size}, ORB(500), derandomized")
    rows = [["run", "wall s", "render s", "SUT s", "metric s", "renders", "examples", "rejected"]]
    with tempfile.TemporaryDirectory() as tmp:
        cold_cache = RenderCache(tmp)
        rows.append(run(scene, relation, settings, cold_cache, "cold"))
        rows.append(run(scene, relation, settings, RenderCache(tmp), "warm, disk"))
        rows.append(run(scene, relation, settings, cold_cache, "warm, memory"))
        rows.append(run(scene, relation, settings, RenderCache(None), "no cache"))
        disk = cold_cache.disk_usage()
    widths = [max(len(r[i]) for r in rows) for i in range(len(rows[0]))]
    for row in rows:
        print("  ".join(c.rjust(w) if i else c.ljust(w) for i, (c, w) in enumerate(zip(row, widths))))
    cold, warm = float(rows[1][1]), float(rows[2][1])
    print(f"warm (disk) / cold = {warm / cold:.3f}; cache on disk {disk / 2**20:.1f} MiB")
    return 0


if __name__ == "__main__":
    sys.exit(main())
