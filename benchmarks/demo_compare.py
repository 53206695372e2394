"""Render speed of the exact demo scenes at several git revisions side by side, in one run (ratios survive a
shared machine).

Run: ``python benchmarks/demo_compare.py main HEAD`` (any revisions; the first is the base of the ratios;
``--size WxH``, default 480x270; ``--rounds R``, default 3; ``--view I``, default 5; ``--poses N``, default 0;
``--smoke`` for a seconds-long run on tiny input). Each revision's ``pytest_n2r`` is exported with ``git archive`` (as
``benchmarks/splat_compare.py`` does) and renders view ``I`` of ``demo:wall`` and ``demo:object`` (RGB + depth +
opacity) in its own process, the revisions taking turns ``R`` times, so a change in the machine's load hits every
revision alike. Per process and scene: CPU ms per frame, the least thread CPU time of 3 renders on one numba
thread (what an idle core takes, whatever the load), and frames/s, 1 / the best wall time of 3 renders on all
numba threads, each after a warm-up. Each revision has its own numba cache folder, empty in the first round: that
round's first render of each scene (process CPU seconds) is the cold compile a fresh clone pays; later rounds'
first renders load the kernels from the cache (and compile the blend masks, which are not cached). The table
gives the median over rounds, the ratio to the first revision, and how far its images are from the first
revision's (RGB pixels that differ and by how many grey levels at most, the largest relative z-depth difference,
opacity pixels that differ), over view ``I`` and, with ``--poses N``, every other captured view and ``N`` random
poses (the captured views moved as in ``demo_render_speed.py``, seeded), rendered in the first round.
"""

from __future__ import annotations

import argparse
import os
import statistics
import tempfile
from pathlib import Path

import numpy as np
from splat_compare import export, run_in_export

#: Run in a child process whose PYTHONPATH holds one revision's package: argv = size, view, repeats, out folder,
#: random poses for the images (0: the view alone).
CHILD = r"""
import json, sys, time
import numba, numpy as np
from pytest_n2r.demo import ground_truth
from pytest_n2r.geometry import Transform
w, h = (int(v) for v in sys.argv[1].split("x"))
view, repeats, out, poses = int(sys.argv[2]), int(sys.argv[3]), sys.argv[4], int(sys.argv[5])
outputs = ("rgb", "depth", "opacity")
result = {}
for name in ("wall", "object"):
    scene = ground_truth(name)
    c2w, camera = scene.views[view].c2w, scene.views[view].camera.resized(w, h)
    c0 = time.process_time()
    frame = scene.render(c2w, camera, outputs)
    first = time.process_time() - c0
    frames = [frame]
    if poses:
        rng = np.random.default_rng(1)
        moved = []
        for _ in range(poses):
            base = scene.views[rng.integers(len(scene.views))]
            tau = Transform(roll=rng.uniform(-20, 20), pitch=rng.uniform(-20, 20), yaw=rng.uniform(-30, 30),
                            x=rng.uniform(-0.5, 0.5), y=rng.uniform(-0.5, 0.5), z=rng.uniform(-0.5, 0.5))
            moved.append(tau.apply(base.c2w, scene.reference_length))
        frames += [scene.render(p, camera, outputs) for p in [v.c2w for v in scene.views[::2]] + moved]
    np.savez(f"{out}/{name}.npz", **{o: np.stack([getattr(f, o) for f in frames]) for o in outputs})
    all_threads = numba.get_num_threads()
    numba.set_num_threads(1)  # the render then runs in this thread: its thread time is the frame's CPU time
    cpu = []
    for _ in range(repeats):
        c0 = time.thread_time()
        scene.render(c2w, camera, outputs)
        cpu.append(time.thread_time() - c0)
    numba.set_num_threads(all_threads)
    scene.render(c2w, camera, outputs)
    wall = []
    for _ in range(repeats):
        t0 = time.perf_counter()
        scene.render(c2w, camera, outputs)
        wall.append(time.perf_counter() - t0)
    result[name] = {"cpu_ms": 1e3 * min(cpu), "fps": 1.0 / min(wall), "first_s": first}
import pytest_n2r
result["package"] = pytest_n2r.__file__
print(json.dumps(result))
"""

SCENES = ("wall", "object")


def measure(folder: Path, size: str, view: int, repeats: int, out: Path, cache: Path, poses: int) -> dict:
    """One round of one revision (see :data:`CHILD`) with its numba cache in ``cache``, its images (of ``poses``
    random poses too) saved under ``out``."""
    out.mkdir(parents=True, exist_ok=True)
    return run_in_export(folder, CHILD, [size, str(view), str(repeats), str(out), str(poses)],
                         {"NUMBA_CACHE_DIR": str(cache)})


def difference(images: Path, base: Path) -> str:
    """How far one revision's images are from the base revision's (see the module docstring)."""
    a, b = np.load(images), np.load(base)
    grey = np.abs(a["rgb"].astype(int) - b["rgb"].astype(int)).max(axis=-1)
    depth = float(np.max(np.abs(a["depth"].astype(float) - b["depth"]) / b["depth"]))
    return (f"{int(np.sum(grey > 0))} px (max {int(grey.max())}) | {depth:.1e} | "
            f"{int(np.sum(a['opacity'] != b['opacity']))} px")


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("revisions", nargs="+", help="git revisions; the first is the base of the ratios")
    parser.add_argument("--size", default="480x270", help="WxH (default 480x270)")
    parser.add_argument("--rounds", type=int, default=3)
    parser.add_argument("--view", type=int, default=5, help="the view of each scene that is rendered")
    parser.add_argument("--poses", type=int, default=0,
                        help="random poses whose images are compared too (with every other captured view)")
    parser.add_argument("--smoke", action="store_true", help="tiny input, to check that the script runs")
    args = parser.parse_args(argv)
    size, rounds, repeats, poses = args.size, args.rounds, 3, args.poses
    if args.smoke:
        size, rounds, repeats, poses = "24x14", 1, 1, 1
    with tempfile.TemporaryDirectory(prefix="n2r-demo-compare-") as tmp:
        folders = {rev: export(rev, Path(tmp)) for rev in args.revisions}
        runs: dict[str, list[dict]] = {rev: [] for rev in args.revisions}
        for r in range(rounds):
            for rev, folder in folders.items():
                runs[rev].append(measure(folder, size, args.view, repeats, Path(tmp) / "images" / f"{rev}-{r}",
                                         Path(tmp) / "numba" / rev, poses if r == 0 else 0))
        load = os.getloadavg()
        compared = f"; images compared over it, 24 captured views and {poses} random poses" if poses else ""
        print(f"view {args.view} at {size}, RGB + depth + opacity, {rounds} rounds; load average at the end "
              f"{load[0]:.1f} / {load[1]:.1f} / {load[2]:.1f} (1 / 5 / 15 min){compared}\n")
        print("| scene | revision | CPU ms per frame, 1 thread | ratio | frames/s, all threads | ratio | "
              "RGB differing from the first | z-depth rel. | opacity | first render, empty numba cache (CPU s) | "
              "first render, later rounds |")
        print("|---|---|---|---|---|---|---|---|---|---|---|")
        first = args.revisions[0]
        for name in SCENES:
            base = None
            for rev, folder in folders.items():
                cpu = statistics.median(run[name]["cpu_ms"] for run in runs[rev])
                fps = statistics.median(run[name]["fps"] for run in runs[rev])
                base = base or (cpu, fps)
                images = Path(tmp) / "images"
                diff = difference(images / f"{rev}-0" / f"{name}.npz", images / f"{first}-0" / f"{name}.npz")
                warm = [run[name]["first_s"] for run in runs[rev][1:]]
                later = f"{statistics.median(warm):.1f}" if warm else "(one round)"
                print(f"| {name} | {rev} ({folder.name[:10]}) | {cpu:.1f} | {cpu / base[0]:.2f} | {fps:.1f} | "
                      f"{fps / base[1]:.2f} | {diff} | {runs[rev][0][name]['first_s']:.1f} | {later} |")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
