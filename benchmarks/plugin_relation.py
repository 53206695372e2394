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

``--reference`` renders an exact demo scene by its numpy reference instead (the renderer before the compiled
kernel), for a side-by-side comparison; ``--runs`` picks some of the four runs. Scenes are loaded and their
renderer compiled before the runs start (printed apart).

Columns: wall time, time spent rendering (cache lookups included), in the SUT, in the metric and in the
validity checks (seconds), renders done, calls of the SUT (once per render: a follow-up pose drawn twice runs
it once), valid and rejected examples.
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

from pytest_n2r.metrics import repeatability
from pytest_n2r.plugin.scenes import default_scene_specs, load_scene_spec, parse_scene_specs
from pytest_n2r.relation import Relation, RunSettings, check_relation
from pytest_n2r.render.size import RenderSize
from pytest_n2r.scene.base import Scene
from pytest_n2r.scene.render_cache import RenderCache
from pytest_n2r.strategies import transforms

ORB = cv2.ORB_create(500)


def orb(rgb: np.ndarray) -> np.ndarray:
    """The SUT: ORB keypoints (N, 2) in pixels of an RGB image."""
    gray = cv2.cvtColor(rgb, cv2.COLOR_RGB2GRAY)
    return np.array([k.pt for k in ORB.detect(gray, None)], dtype=np.float32).reshape(-1, 2)


class ReferenceRendered(Scene):
    """An exact demo scene rendered by its vectorized numpy reference (what the plugin used before the
    compiled kernel), for a side-by-side run."""

    is_exact = True

    def __init__(self, scene) -> None:
        self.scene, self.name, self.views = scene, scene.name, scene.views
        self.reference_length, self.metres_per_unit = scene.reference_length, scene.metres_per_unit

    @property
    def content_hash(self) -> str:
        return self.scene.content_hash + "/reference"

    def _render(self, c2w, camera, outputs):
        return self.scene.render_reference(c2w, camera, outputs)


def scene_spec(text: str | None):
    if text:
        return parse_scene_specs([text], Path.cwd(), "--scene")[0]
    specs = default_scene_specs()
    return specs[0] if specs else parse_scene_specs(["tests.plugin.fakescene:plane"], ROOT, "--scene")[0]


def run(scene, relation, settings, cache, label: str) -> list[str]:
    start = time.perf_counter()
    record = check_relation(scene, orb, relation, settings=settings, cache=cache, test_id="benchmark")
    wall = time.perf_counter() - start
    return [label, f"{wall:.2f}", *(f"{record.timings[k]:.2f}" for k in ("render", "sut", "metric", "validity")),
            str(record.renders), str(record.sut_calls), str(len(record.valid_examples)), str(record.rejected)]


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--scene", help="scene spec (default: the first demo scene)")
    parser.add_argument("--examples", type=int, default=100)
    parser.add_argument("--size", default="480x270")
    parser.add_argument("--reference", action="store_true",
                        help="render an exact demo scene by its numpy reference (the renderer before the compiled one)")
    parser.add_argument("--runs", default="cold,warm-disk,warm-memory,no-cache",
                        help="which of the four runs to do (comma-separated; default all)")
    args = parser.parse_args(argv)

    spec = scene_spec(args.scene)
    t0 = time.perf_counter()
    scene = load_scene_spec(spec, "auto")
    if args.reference:
        scene = ReferenceRendered(scene)
    view = scene.views[0]
    scene.render(view.c2w, view.camera.resized(4, 2), ("rgb", "depth", "opacity"))  # compiles, if it compiles
    load_s = time.perf_counter() - t0
    relation = Relation.build(repeatability(px=2), 1.0, transforms(yaw=10, x=0.1), examples=args.examples)
    settings = RunSettings(examples=args.examples, size=RenderSize.parse(args.size), derandomize=True,
                           database=None, timeout=None)
    print(f"scene {spec.source} ({type(scene).__name__}, loaded and compiled in {load_s:.2f} s), {args.examples} "
          f"examples of "
          f"{relation.describe()} at {args.size}, ORB(500), derandomized")
    rows = [["run", "wall s", "render s", "SUT s", "metric s", "validity s", "renders", "SUT calls", "examples",
             "rejected"]]
    with tempfile.TemporaryDirectory() as tmp:
        cold_cache = RenderCache(tmp)
        runs = {"cold": cold_cache, "warm-disk": RenderCache(tmp), "warm-memory": cold_cache,
                "no-cache": RenderCache(None)}
        for name in args.runs.split(","):
            rows.append(run(scene, relation, settings, runs[name], name))
        disk = cold_cache.disk_usage()
    widths = [max(len(r[i]) for r in rows) for i in range(len(rows[0]))]
    for row in rows:
        print("  ".join(c.rjust(w) if i else c.ljust(w) for i, (c, w) in enumerate(zip(row, widths))))
    wall = {row[0]: float(row[1]) for row in rows[1:]}
    if "cold" in wall and "warm-disk" in wall:
        print(f"warm (disk) / cold = {wall['warm-disk'] / wall['cold']:.3f}; cache on disk {disk / 2**20:.1f} MiB")
    return 0


if __name__ == "__main__":
    sys.exit(main())
