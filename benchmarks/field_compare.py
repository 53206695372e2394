"""Fitted-field render speed and error of several git revisions side by side, in one run (ratios survive a
shared machine).

Run: ``python benchmarks/field_compare.py SCENE main HEAD`` (``SCENE`` a ``.n2r`` file or ``demo:NAME``, the
fitted twin of demo scene ``NAME``; any revisions, the first is the base of the ratios; ``--sizes``, default
``480x270,960x540,1920x1080``; ``--views`` held-out views compared, default 3; ``--rounds R``, default 3;
``--smoke`` for a seconds-long run on tiny input). Each revision's ``pytest_n2r`` is exported with ``git archive``
(as ``benchmarks/splat_compare.py`` does) and renders the scene with its default settings (RGB) in its own
process, the revisions taking turns ``R`` times, so a change in the machine's load hits every revision alike. Per
process and size: CPU ms per frame, the least thread CPU time of 3 renders of the first held-out view on one
numba thread after a warm-up (what an idle core takes, whatever the load); frames/s, 1 / the best wall time of 3
renders on ``--threads`` numba threads (default 2: read it only from a quiet or locked run); idle ms a frame, the
time the render threads wait for each other in those renders (for each run of a kernel on the threads,
:func:`pytest_n2r.render.threads._run`: its wall time less each thread's time in the kernel, summed over threads and
runs; so a frame's wall time is about (its threads' work + idle) / threads); and the PSNR against the truth — the
held-out photos resized (``INTER_AREA``), or the exact demo scene's render — mean over the views. The table gives the
medians over rounds, their ratios to the first revision (> 1: faster), the PSNR and its difference to the first
revision's, and how many RGB values differ from the first revision's render. A second table gives each revision's
renderer set-up: the least time of 3 to build the scene's :class:`~pytest_n2r.render.field_render.FieldRenderer`
once its kernels are loaded (what a process pays on its first render of a field, besides decoding it).
"""

from __future__ import annotations

import argparse
import os
import statistics
import sys
import tempfile
from pathlib import Path

import numpy as np
from splat_compare import export, run_in_export

#: Run in a child process whose PYTHONPATH holds one revision's package: argv = scene, sizes, views, repeats, out.
CHILD = r"""
import json, sys, time
import cv2, numba, numpy as np
import pytest_n2r.render.threads as threads
from pytest_n2r.metrics.image_quality import psnr
from pytest_n2r.render.field_render import FieldRenderer
spec, sizes, n_views, repeats, out = sys.argv[1], sys.argv[2], int(sys.argv[3]), int(sys.argv[4]), sys.argv[5]
if spec.startswith("demo:"):
    from pytest_n2r.demo import load_demo
    name = spec.removeprefix("demo:").removesuffix("-field")
    scene, exact = load_demo(name + "-field", device="cpu"), load_demo(name)
    views = [v for v in scene.views if v.split == "heldout"][:n_views]
    truth = lambda view, camera: exact.render(view.c2w, camera, ("rgb",)).rgb
else:
    from pytest_n2r.scene import load_scene
    scene = load_scene(spec, device="cpu")
    views = [v for v in scene.views if v.split == "heldout" and v.image is not None][:n_views]
    truth = lambda view, camera: cv2.resize(view.image, (camera.width, camera.height), interpolation=cv2.INTER_AREA)
result = {}
for size in sizes.split(","):
    w, h = (int(v) for v in size.split("x"))
    base = views[0].camera
    s = (w * h / (base.width * base.height)) ** 0.5  # about w·h pixels, the capture's aspect ratio
    camera = base.resized(round(base.width * s), round(base.height * s))
    images = [scene.render(v.c2w, camera, ("rgb",)).rgb for v in views]
    np.save(f"{out}/{size}.npy", np.stack(images))
    all_threads = numba.get_num_threads()
    numba.set_num_threads(1)  # the render then runs in this thread: its thread time is the frame's CPU time
    cpu, wall = [], []
    for _ in range(repeats):
        c0 = time.thread_time()
        scene.render(views[0].c2w, camera, ("rgb",))
        cpu.append(time.thread_time() - c0)
    numba.set_num_threads(all_threads)
    scene.render(views[0].c2w, camera, ("rgb",))
    for _ in range(repeats):
        t0 = time.perf_counter()
        scene.render(views[0].c2w, camera, ("rgb",))
        wall.append(time.perf_counter() - t0)
    idle, run = [0.0], threads._run
    def timed_run(kernel, heads, args):  # the threads' wait: the run's wall time less each thread's busy time
        busy = []
        def timed(*a):
            t = time.perf_counter()
            try:
                kernel(*a)
            finally:
                busy.append(time.perf_counter() - t)
        t0 = time.perf_counter()
        run(timed, heads, args)
        idle[0] += sum(time.perf_counter() - t0 - b for b in busy)
    threads._run = timed_run
    for _ in range(repeats):
        scene.render(views[0].c2w, camera, ("rgb",))
    threads._run = run
    db = [psnr(truth(v, camera), image) for v, image in zip(views, images)]
    result[size] = {"cpu_ms": 1e3 * min(cpu), "fps": 1.0 / min(wall), "idle_ms": 1e3 * idle[0] / repeats,
                    "psnr": float(np.mean(db)), "shape": f"{camera.width}x{camera.height}"}
setup = []
for _ in range(3):
    t0 = time.perf_counter()
    FieldRenderer(scene.field, scene.settings)
    setup.append(time.perf_counter() - t0)
result["setup_s"] = min(setup)
import pytest_n2r
result["package"] = pytest_n2r.__file__
print(json.dumps(result))
"""


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("scene", help="a .n2r file or demo:NAME (the fitted twin of demo scene NAME)")
    parser.add_argument("revisions", nargs="+", help="git revisions; the first is the base of the ratios")
    parser.add_argument("--sizes", default="480x270,960x540,1920x1080")
    parser.add_argument("--views", type=int, default=3)
    parser.add_argument("--rounds", type=int, default=3)
    parser.add_argument("--threads", type=int, default=2, help="numba threads of the frames/s column")
    parser.add_argument("--smoke", action="store_true", help="tiny input, to check that the script runs")
    args = parser.parse_args(argv)
    if not args.scene.startswith("demo:") and not Path(args.scene).is_file():
        parser.error(f"scene {args.scene!r}: no such file; expected a .n2r scene file or demo:NAME")
    sizes, views, rounds, repeats = args.sizes, args.views, args.rounds, 3
    if args.smoke:
        sizes, views, rounds, repeats = "96x54", 1, 1, 1
    with tempfile.TemporaryDirectory(prefix="n2r-field-compare-") as tmp:
        folders = {rev: export(rev, Path(tmp)) for rev in args.revisions}
        runs: dict[str, list[dict]] = {rev: [] for rev in args.revisions}
        for r in range(rounds):
            for rev, folder in folders.items():
                out = Path(tmp) / "images" / f"{rev}-{r}"
                out.mkdir(parents=True, exist_ok=True)
                env = {"NUMBA_NUM_THREADS": str(args.threads), "NUMBA_CACHE_DIR": str(Path(tmp) / rev)}
                runs[rev].append(run_in_export(folder, CHILD, [args.scene, sizes, str(views), str(repeats), str(out)],
                                               env))
        load = os.getloadavg()
        print(f"{args.scene}, default settings, RGB, {rounds} rounds, {views} held-out views; load average at the end "
              f"{load[0]:.1f} / {load[1]:.1f} / {load[2]:.1f} (1 / 5 / 15 min)\n")
        print(f"| size | revision | CPU ms per frame, 1 thread | speed-up | frames/s, {args.threads} threads | ratio | "
              "idle ms a frame | PSNR → truth | difference | RGB values differing |")
        print("|---|---|---|---|---|---|---|---|---|---|")
        first = args.revisions[0]
        for size in sizes.split(","):
            base_ms = statistics.median(run[size]["cpu_ms"] for run in runs[first])
            base_fps = statistics.median(run[size]["fps"] for run in runs[first])
            base_db = runs[first][0][size]["psnr"]
            base_images = np.load(Path(tmp) / "images" / f"{first}-0" / f"{size}.npy")
            for rev, folder in folders.items():
                ms = statistics.median(run[size]["cpu_ms"] for run in runs[rev])
                fps = statistics.median(run[size]["fps"] for run in runs[rev])
                idle = statistics.median(run[size]["idle_ms"] for run in runs[rev])
                db = runs[rev][0][size]["psnr"]
                images = np.load(Path(tmp) / "images" / f"{rev}-0" / f"{size}.npy")
                differing = int(np.sum(images != base_images))
                print(f"| {runs[rev][0][size]['shape']} | {rev} ({folder.name[:10]}) | {ms:.0f} | "
                      f"{base_ms / ms:.2f}× | {fps:.2f} | {fps / base_fps:.2f}× | {idle:.1f} | {db:.3f} dB | "
                      f"{db - base_db:+.3f} dB | {differing} of {images.size} |")
        print("\n| revision | renderer set-up s (median over rounds of the least of 3) |\n|---|---|")
        for rev, folder in folders.items():
            print(f"| {rev} ({folder.name[:10]}) | {statistics.median(run['setup_s'] for run in runs[rev]):.3f} |")
    return 0


if __name__ == "__main__":
    sys.exit(main())
