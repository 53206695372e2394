"""Render speed and accuracy of splat scenes on the CPU, next to the fitted field of the same demo scene.

Run: ``python benchmarks/splat_speed.py`` (``--gaussians N`` for the speed table's count, default 300 000;
``--smoke`` for a seconds-long run on tiny input). Builds Gaussians on the exact ``object`` demo scene's
surfaces (:func:`pytest_n2r.demo.splats.sample_splats`, deterministic) and prints

1. frames/s of its six held-out views at 480×270 and 1920×1080 (RGB + depth + opacity; best of 3 renders
   per view after a warm-up, the median over views), on 2 numba threads and on 1, the CPU time of a frame
   on 1 thread (what an idle core takes, even on a loaded machine), and the fitted demo field
   ``demo:object-field`` at 480×270 on the same views in the same run;
2. the held-out PSNR against the exact renders (480×270, over the exact scene's background) for 4 000,
   50 000 and 300 000 Gaussians, and for the fitted field on the same views.

Results: docs/performance.md and docs/splat-scenes.md.
"""

from __future__ import annotations

import argparse
import statistics
import time
import timeit

import numba
import numpy as np

from pytest_n2r.demo import fitted_scene, ground_truth
from pytest_n2r.demo.splats import sample_splats
from pytest_n2r.metrics.image_quality import psnr
from pytest_n2r.render.splat_render import SplatSettings
from pytest_n2r.scene import SplatScene

OUTPUTS = ("rgb", "depth", "opacity")


def frames_per_second(scene, views, size: tuple[int, int], repeats: int) -> float:
    """The median over ``views`` of 1 / (best of ``repeats`` render times after a warm-up) at ``size``."""
    rates = []
    for view in views:
        render = lambda v=view: scene.render(v.c2w, v.camera.resized(*size), OUTPUTS)
        render()
        rates.append(1.0 / min(timeit.repeat(render, number=1, repeat=repeats)))
    return statistics.median(rates)


def cpu_seconds(scene, views, size: tuple[int, int], repeats: int) -> float:
    """The median over ``views`` of the least CPU time of the calling thread for a render at ``size``: with
    numba on one thread (all work in the calling thread), what an idle core would take, however loaded the
    machine is (process time would also count the idle OpenMP worker spinning)."""
    spent = []
    for view in views:
        camera = view.camera.resized(*size)
        scene.render(view.c2w, camera, OUTPUTS)
        best = np.inf
        for _ in range(repeats):
            start = time.thread_time()
            scene.render(view.c2w, camera, OUTPUTS)
            best = min(best, time.thread_time() - start)
        spent.append(best)
    return statistics.median(spent)


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--gaussians", type=int, default=300_000)
    parser.add_argument("--smoke", action="store_true", help="tiny input, to check that the script runs")
    args = parser.parse_args(argv)
    exact = ground_truth("object")
    views = [v for v in exact.views if v.split == "heldout"]
    background = tuple(float(c) for c in exact.background)
    settings = SplatSettings(background=background)
    sizes, counts, repeats = ((480, 270), (1920, 1080)), (4_000, 50_000, args.gaussians), 3
    if args.smoke:
        views, sizes, counts, repeats = views[:1], ((64, 36),), (2_000,), 1
    threads = numba.get_num_threads()
    print(f"numba threads available: {threads}; views: {len(views)} held out of demo:object\n")

    start = time.perf_counter()
    scene = SplatScene(sample_splats(exact, counts[-1]), exact.views, settings=settings,
                       reference_length=exact.reference_length)
    print(f"## speed: {len(scene.gaussians)} Gaussians (sampled in {time.perf_counter() - start:.1f} s)\n")
    print(f"| size | frames/s, {threads} threads | frames/s, 1 thread | CPU ms per frame, 1 thread |")
    print("|---|---|---|---|")
    rates = {size: frames_per_second(scene, views, size, repeats) for size in sizes}
    field_rate = None if args.smoke else frames_per_second(fitted_scene("object", device="cpu"), views, sizes[0],
                                                           repeats)
    numba.set_num_threads(1)  # last: with OpenMP, going back to more threads makes every parallel region slow
    for size in sizes:
        one = frames_per_second(scene, views, size, repeats)
        cpu = 1e3 * cpu_seconds(scene, views, size, repeats)
        print(f"| {size[0]}×{size[1]} | {rates[size]:.1f} | {one:.1f} | {cpu:.0f} |")
    stages = []
    for view in views:  # where a frame's time goes, on one thread
        scene.render(view.c2w, view.camera.resized(*sizes[0]), OUTPUTS)
        stages.append(scene.renderer.stage_seconds)
    numba.set_num_threads(threads)
    if field_rate is not None:
        print(f"| 480×270, fitted field demo:object-field (same views, same run) | {field_rate:.1f} | | |")
    print(f"\nstages at {sizes[0][0]}×{sizes[0][1]}, 1 thread, ms (median over views): " + ", ".join(
        f"{name} {1e3 * statistics.median(s[name] for s in stages):.1f}" for name in stages[0]))
    print("\n## accuracy against the exact renders (held out, 480×270)\n")
    print("| Gaussians | PSNR dB (mean) | per view |")
    print("|---|---|---|")
    size = sizes[0]
    truth = [exact.render(v.c2w, v.camera.resized(*size), "rgb").rgb for v in views]
    for count in counts:
        splats = scene if count == counts[-1] else SplatScene(sample_splats(exact, count), exact.views,
                                                              settings=settings,
                                                              reference_length=exact.reference_length)
        scores = [psnr(t, splats.render(v.c2w, v.camera.resized(*size), "rgb").rgb) for v, t in zip(views, truth)]
        print(f"| {count} | {np.mean(scores):.2f} | {', '.join(f'{s:.2f}' for s in scores)} |")
    if not args.smoke:
        field = fitted_scene("object", device="cpu")
        scores = [psnr(t, field.render(v.c2w, v.camera.resized(*size), "rgb").rgb) for v, t in zip(views, truth)]
        print(f"| fitted field demo:object-field | {np.mean(scores):.2f} | {', '.join(f'{s:.2f}' for s in scores)} |")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
