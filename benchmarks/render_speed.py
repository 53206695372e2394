"""Render speed of a fitted scene, and run time against error for every render knob.

Run: ``python benchmarks/render_speed.py [SCENE]`` with ``SCENE`` a ``.n2r`` file (default: the fox scene that
``benchmarks/field_fit.py`` writes) or ``demo:NAME``, the fitted twin of demo scene ``NAME``, whose held-out
views are compared against the exact scene's renders instead of photos (a field not fitted on the fox).
``--sizes`` (default ``480x270,960x540,1920x1080``), ``--views`` (held-out views compared, default 3),
``--threads`` (default 2), ``--tables`` (which of the tables below, default all: ``speed,changes,psnr,sweep``)
and ``--smoke`` (one tiny size, one view, one timed render) change the run. Prints

1. ``speed``: at each size (portrait captures: the same pixel counts, turned), RGB only: seconds and frames/s (wall
   clock, best of 3 after a warm-up), CPU milliseconds a frame (all threads; the ratio that stays put on a
   shared machine) and the share of pixels traced, for the defaults, the defaults with every pixel traced
   (``adaptive=0``: the renderer before adaptive sampling, the same kernel), and the two fastest settings the
   sweep prices (half the size upsampled, ``scale=0.5``; and that with twice the sample spacing), and the
   defaults before 4 December (``t_stop=0.03``, ``min_weight=1e-2``). The defaults' row adds the frames/s over all
   the held-out views (their count over the sum of each one's best time): how fast the views render, where the
   other columns time the first one;
2. ``changes``: each change to the compiled renderer side by side with the one before, on ONE thread
   (``numba.set_num_threads(1)``: two threads give little more on a 2-core VM, so this is the ratio to read):
   CPU milliseconds a frame and PSNR against the truth (mean over the views) at each size;
3. ``psnr``: at each size, the PSNR of the defaults and of ``adaptive=0`` against the held-out photos (or the exact
   scene), mean over the views, and of the defaults against ``adaptive=0``;
4. ``sweep``: at the first size, a sweep of the knobs of :class:`pytest_n2r.render.RenderSettings` — sample spacing,
   the opacity below which cells are skipped, early ray termination, adaptive sampling's tolerance and
   render resolution — with frames/s and the PSNR of each variant against the best-quality render (finest
   spacing, no skipping, no termination, every pixel traced) and against the photos. The default is marked;
5. ``parts``: where a frame's wall time goes with the defaults, at each size on one thread and on ``--threads``:
   the colour bake (:func:`pytest_n2r.render.field_kernels.bake_logits`), the ray kernel (every pass of the
   adaptive sampler) and the rest (the sampler's judging, the rays, numpy and Python between the kernels); the
   mean over the held-out views of each one's fastest of 3 frames.

Results: docs/performance.md.
"""

from __future__ import annotations

import argparse
import functools
import sys
import time

import cv2
import numba
import numpy as np
import torch
from _timing import best_seconds

from pytest_n2r.metrics.image_quality import psnr
from pytest_n2r.render.field_render import RenderSettings
from pytest_n2r.scene import load_scene

DEFAULT = RenderSettings()
EVERY_PIXEL = DEFAULT.replace(adaptive=0.0)
BEST = RenderSettings(step_ratio=0.25, t_stop=0.0, min_alpha=0.0, adaptive=0.0)
#: The speed tricks that trade the most time for the least error (the sweep below prices them).
FAST = (DEFAULT.replace(scale=0.5), DEFAULT.replace(scale=0.5, step_ratio=1.0))
#: The defaults before 4 December's (``t_stop=0.03``, ``min_weight=1e-2``), the base of the changes below.
BEFORE_DEC4 = DEFAULT.replace(t_stop=0.03, min_weight=1e-2)
#: Those defaults without RENDER_VERSION 4's changes (colour baked per frame, min_weight) and 5's (the tail); the
#: adaptive sampler's last split (6 and 7) stays, so PREVIOUS is not the whole RENDER_VERSION 3 renderer.
PREVIOUS = BEFORE_DEC4.replace(colour_direction="ray", min_weight=0.0, tail=())
VERSION_4 = BEFORE_DEC4.replace(tail=())
#: The changes of RENDER_VERSION 4 and 5 and of 4 December's defaults, each on top of the one before
#: (docs/performance-log.md, "Rendering").
CHANGES = (("defaults less RENDER_VERSION 4 and 5", PREVIOUS),
           ("+ colour_direction='vertex'", PREVIOUS.replace(colour_direction="vertex")),
           ("+ min_weight=1e-2 (RENDER_VERSION 4)", VERSION_4),
           ("+ tail=(0.3, 0.1) (RENDER_VERSION 5)", BEFORE_DEC4),
           ("+ t_stop=0.04, min_weight=2e-2 (the defaults, 4 December)", DEFAULT),
           ("+ tail=(0.5, 0.1) (not adopted)", DEFAULT.replace(tail=(0.5, 0.1))))
TABLES = ("speed", "changes", "psnr", "sweep", "parts")


def sized(camera, pixels: int):
    """``camera`` resized to about ``pixels`` pixels, same aspect ratio."""
    scale = (pixels / (camera.width * camera.height)) ** 0.5
    return camera.resized(round(camera.width * scale), round(camera.height * scale))


def load(spec: str, n_views: int):
    """``(scene, views, truth)``: the fitted scene, its held-out views, and ``truth(view, camera)`` → the
    reference RGB (the photo resized, or the exact demo scene's render)."""
    if spec.startswith("demo:"):
        from pytest_n2r.demo import load_demo

        name = spec.removeprefix("demo:").removesuffix("-field")
        scene, exact = load_demo(name + "-field", device="cpu"), load_demo(name)
        views = [v for v in scene.views if v.split == "heldout"][:n_views]
        return scene, views, lambda view, camera: exact.render(view.c2w, camera, ("rgb",)).rgb
    scene = load_scene(spec, device="cpu")
    views = [v for v in scene.views if v.split == "heldout" and v.image is not None][:n_views]
    return scene, views, lambda view, camera: cv2.resize(view.image, (camera.width, camera.height),
                                                         interpolation=cv2.INTER_AREA)


def cpu_ms(fn, repeats: int) -> float:
    """The least CPU time (all threads) of ``repeats`` calls of ``fn``, in milliseconds."""
    best = float("inf")
    for _ in range(repeats):
        t0 = time.process_time()
        fn()
        best = min(best, time.process_time() - t0)
    return best * 1e3


def changes_table(scene, views, truth, sizes, repeats: int) -> None:
    """Table 2: each change side by side with the one before, one thread."""
    threads = numba.get_num_threads()
    numba.set_num_threads(1)
    variants = [(label, scene.with_settings(settings)) for label, settings in CHANGES]
    print(f"\neach change on top of the one before, ONE thread, CPU ms / frame (RGB) and PSNR against the truth "
          f"(mean over {len(views)} held-out views; in brackets: against the row above)\n| change | "
          + " | ".join(f"{w}×{h} CPU ms | PSNR → truth" for w, h in sizes) + " |\n|" + " --- |" * (2 * len(sizes) + 1))
    ms = {label: [] for label, _ in variants}
    db = {label: [] for label, _ in variants}
    for w, h in sizes:
        camera = sized(views[0].camera, w * h)
        refs = [truth(v, camera) for v in views]
        for label, variant in variants:
            render = functools.partial(variant.render, views[0].c2w, camera, ("rgb",))
            render()
            ms[label].append(cpu_ms(render, repeats))
            db[label].append(float(np.mean([psnr(r, variant.render(v.c2w, camera, ("rgb",)).rgb)
                                            for r, v in zip(refs, views)])))
    above = variants[0][0]
    for label, _ in variants:
        print(f"| {label} | " + " | ".join(
            f"{m:.0f} ({ms[above][i] / m:.2f}×) | {p:.3f} dB ({p - db[above][i]:+.3f})"
            for i, (m, p) in enumerate(zip(ms[label], db[label]))) + " |")
        above = label
    numba.set_num_threads(threads)


def main(argv: list[str]) -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("scene", nargs="?", default="/tmp/n2r-bench-fox.n2r")
    parser.add_argument("--sizes", default="480x270,960x540,1920x1080")
    parser.add_argument("--views", type=int, default=3)
    parser.add_argument("--threads", type=int, default=2)
    parser.add_argument("--tables", default=",".join(TABLES), help=f"which tables, from {','.join(TABLES)}")
    parser.add_argument("--smoke", action="store_true", help="one tiny size, one view, one timed render")
    args = parser.parse_args(argv)
    tables = args.tables.split(",")
    if not set(tables) <= set(TABLES):
        parser.error(f"--tables {args.tables!r}: expected names from {','.join(TABLES)}")
    sizes = [tuple(int(v) for v in s.split("x")) for s in ("96x54" if args.smoke else args.sizes).split(",")]
    repeats = 1 if args.smoke else 3
    torch.set_num_threads(args.threads)
    numba.set_num_threads(min(args.threads, numba.config.NUMBA_NUM_THREADS))
    scene, views, truth = load(args.scene, 1 if args.smoke else args.views)
    if not views:
        print(f"{args.scene}: no held-out view with a stored photo; nothing to compare against")
        return 1
    print(f"scene {args.scene}: field {scene.field.resolution}³, fit PSNR {scene.report.get('psnr')} dB, "
          f"{args.threads} threads\n")
    variants = {"default": scene, "defaults before 4 December": scene.with_settings(BEFORE_DEC4),
                "adaptive=0": scene.with_settings(EVERY_PIXEL),
                "scale=0.5": scene.with_settings(FAST[0]), "scale=0.5, step_ratio=1": scene.with_settings(FAST[1])}
    if "speed" in tables:
        speed_table(variants, views, sizes, repeats)
    if "changes" in tables:
        changes_table(scene, views, truth, sizes, repeats)
    if "psnr" in tables:
        psnr_table(scene, variants, views, truth, sizes)
    if "sweep" in tables:
        sweep_table(scene, views, truth, sizes, repeats, args.smoke)
    if "parts" in tables:
        parts_table(scene, views, sizes, repeats)
    return 0


def speed_table(variants, views, sizes, repeats: int) -> None:
    """Table 1: frames/s and CPU ms of the defaults and the fast settings at each size (the first held-out view),
    and the defaults' frames/s over every held-out view."""
    print(f"| size | settings | s / frame | frames/s | CPU ms / frame | pixels traced | frames/s over the {len(views)} "
          f"held-out views |\n|{' --- |' * 7}")
    for w, h in sizes:
        camera = sized(views[0].camera, w * h)
        for label, variant in variants.items():
            render = functools.partial(variant.render, views[0].c2w, camera, ("rgb",))
            s = best_seconds(render, repeats)
            ms = cpu_ms(render, repeats)
            traced = variant._renderer.last_traced / (camera.width * camera.height)
            over = "—"
            if label == "default":
                seconds = [best_seconds(functools.partial(variant.render, v.c2w, camera, ("rgb",)), repeats)
                           for v in views]
                over = f"{len(seconds) / sum(seconds):.2f}"
            print(f"| {camera.width}×{camera.height} | {label} | {s:.3f} | {1 / s:.2f} | {ms:.0f} | {traced:.0%} | "
                  f"{over} |")



def psnr_table(scene, variants, views, truth, sizes) -> None:
    """Table 3: PSNR of the defaults and of adaptive=0 against the truth at each size."""
    print(f"\nmean over {len(views)} held-out views\n| size | PSNR → truth, default | PSNR → truth, adaptive=0 | "
          f"difference | PSNR default → adaptive=0 |\n|{' --- |' * 5}")
    for w, h in sizes:
        camera = sized(views[0].camera, w * h)
        refs = [truth(v, camera) for v in views]
        fast = [scene.render(v.c2w, camera, ("rgb",)).rgb for v in views]
        full = [variants["adaptive=0"].render(v.c2w, camera, ("rgb",)).rgb for v in views]
        p_fast = np.mean([psnr(r, i) for r, i in zip(refs, fast)])
        p_full = np.mean([psnr(r, i) for r, i in zip(refs, full)])
        to_full = np.mean([psnr(a, b) if not np.array_equal(a, b) else np.inf for a, b in zip(full, fast)])
        print(f"| {camera.width}×{camera.height} | {p_fast:.2f} dB | {p_full:.2f} dB | {p_fast - p_full:+.3f} dB | "
              f"{to_full:.1f} dB |")



def sweep_table(scene, views, truth, sizes, repeats: int, smoke: bool) -> None:
    """Table 4: every knob at the first size, frames/s and PSNR against the best render and the truth."""
    small = sized(views[0].camera, sizes[0][0] * sizes[0][1])
    reference = [scene.with_settings(BEST).render(v.c2w, small, ("rgb",)).rgb for v in views]
    photos = [truth(v, small) for v in views]

    def row(label: str, settings: RenderSettings) -> None:
        variant = scene.with_settings(settings)
        images = [variant.render(v.c2w, small, ("rgb",)).rgb for v in views]
        s = best_seconds(lambda: variant.render(views[0].c2w, small, ("rgb",)), repeats)
        to_best = np.mean([psnr(r, i) if not np.array_equal(r, i) else np.inf for r, i in zip(reference, images)])
        to_photo = np.mean([psnr(p, i) for p, i in zip(photos, images)])
        mark = " ← default" if settings == DEFAULT else ""
        print(f"| {label}{mark} | {1 / s:.2f} | {to_best:.1f} dB | {to_photo:.2f} dB |")

    print(f"\nat {small.width}×{small.height}, mean over {len(views)} held-out views\n"
          f"| variant | frames/s | PSNR → best | PSNR → truth |\n|{' --- |' * 4}")
    row("best quality (reference)", BEST)
    row("defaults", DEFAULT)
    if not smoke:
        for step in (1.0, 2.0):
            row(f"step_ratio={step}", DEFAULT.replace(step_ratio=step))
        for min_alpha in (0.0, 1e-2, 5e-2):
            row(f"min_alpha={min_alpha:g}", DEFAULT.replace(min_alpha=min_alpha))
        for t_stop in (0.0, 1e-2, 1e-1):
            row(f"t_stop={t_stop:g}", DEFAULT.replace(t_stop=t_stop))
        for tolerance in (0.0, 0.02, 0.08, 0.16):
            row(f"adaptive={tolerance:g}", DEFAULT.replace(adaptive=tolerance))
        row("adaptive_stride=4", DEFAULT.replace(adaptive_stride=4))
        row("scale=0.75 (render smaller, upsample)", DEFAULT.replace(scale=0.75))
        row("scale=0.5", FAST[0])
        row("scale=0.5, step_ratio=1.0", FAST[1])
        for min_weight in (0.0, 3e-2):
            row(f"min_weight={min_weight:g}", DEFAULT.replace(min_weight=min_weight))
        row("colour_direction='ray'", DEFAULT.replace(colour_direction="ray"))


def parts_table(scene, views, sizes, repeats: int) -> None:
    """Table 5: a frame's wall time at the defaults split into the colour bake, the ray kernel and the rest."""
    renderer = scene._renderer  # built on first use
    spent = {"bake": 0.0, "rays": 0.0}

    def timed(name: str, method):
        def run(*args):
            t0 = time.perf_counter()
            try:
                return method(*args)
            finally:
                spent[name] += time.perf_counter() - t0
        return run

    # instance attributes shadow the renderer's methods for this table only (deleted below)
    renderer._bake_logits = timed("bake", renderer._bake_logits)
    renderer._trace_pixels = timed("rays", renderer._trace_pixels)
    threads = numba.get_num_threads()
    print(f"\nwhere a frame's wall time goes, defaults, mean over {len(views)} held-out views (each one's fastest of "
          f"{repeats})\n| size | threads | ms a frame | colour bake | ray kernel | the rest |\n|{' --- |' * 6}")
    try:
        for n in sorted({1, threads}):
            numba.set_num_threads(n)
            for w, h in sizes:
                rows = []
                for view in views:
                    camera = sized(view.camera, w * h)
                    scene.render(view.c2w, camera, ("rgb",))  # warm
                    best = None
                    for _ in range(repeats):
                        spent.update(bake=0.0, rays=0.0)
                        t0 = time.perf_counter()
                        scene.render(view.c2w, camera, ("rgb",))
                        total = time.perf_counter() - t0
                        if best is None or total < best[0]:
                            best = (total, spent["bake"], spent["rays"])
                    rows.append(best)
                total, bake, rays = (float(np.mean(column)) * 1e3 for column in zip(*rows))
                rest = total - bake - rays
                print(f"| {camera.width}×{camera.height} | {n} | {total:.1f} | {bake:.1f} ({bake / total:.0%}) | "
                      f"{rays:.1f} ({rays / total:.0%}) | {rest:.1f} ({rest / total:.0%}) |")
    finally:
        del renderer._bake_logits, renderer._trace_pixels
        numba.set_num_threads(threads)


if __name__ == "__main__":
    sys.exit(main(sys.argv[1:]))
