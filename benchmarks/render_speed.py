"""Render speed of a fitted scene, and run time against error for every render knob.

Run: ``python benchmarks/render_speed.py [SCENE.n2r]`` (default: the fox scene that
``benchmarks/field_fit.py`` writes). Prints

1. frames/s at 480×270, 960×540 and 1920×1080 pixels (portrait captures: the same pixel counts, turned),
   RGB only, RGB + depth + opacity, and RGB with the two fastest settings the sweep prices (half the size
   upsampled, ``scale=0.5``; and that with twice the sample spacing);
2. a sweep of the knobs of :class:`pytest_n2r.render.RenderSettings` — sample spacing, the opacity below which
   cells are skipped, early ray termination, and render resolution — with frames/s at 480×270 and the PSNR
   of each variant against the best-quality render (finest spacing, no skipping, no termination) and against
   the real held-out photos. The default is marked.

Times are the best of 3 renders after a warm-up, torch/numba on 2 threads. Results: docs/performance.md.
"""

from __future__ import annotations

import functools
import sys

import cv2
import numpy as np
import torch
from _timing import best_seconds

from pytest_n2r.metrics.image_quality import psnr
from pytest_n2r.render.field_render import RenderSettings
from pytest_n2r.scene import load_scene

DEFAULT = RenderSettings()
BEST = RenderSettings(step_ratio=0.25, t_stop=0.0, min_alpha=0.0)
#: The speed tricks that trade the most time for the least error (the sweep below prices them).
FAST = (DEFAULT.replace(scale=0.5), DEFAULT.replace(scale=0.5, step_ratio=1.0))


def sized(camera, pixels: int):
    """``camera`` resized to about ``pixels`` pixels, same aspect ratio."""
    scale = (pixels / (camera.width * camera.height)) ** 0.5
    return camera.resized(round(camera.width * scale), round(camera.height * scale))


def main(argv: list[str]) -> int:
    path = argv[0] if argv else "/tmp/n2r-bench-fox.n2r"
    torch.set_num_threads(2)
    scene = load_scene(path, device="cpu")
    views = [v for v in scene.views if v.split == "heldout" and v.image is not None][:3]
    if not views:
        print(f"{path}: no held-out view with a stored photo; nothing to compare against")
        return 1
    print(f"scene {path}: field {scene.report.get('field')}, fit PSNR {scene.report.get('psnr')} dB\n")

    variants = ((scene, "default", ("rgb",)), (scene, "default", ("rgb", "depth", "opacity")),
                (scene.with_settings(FAST[0]), "scale=0.5", ("rgb",)),
                (scene.with_settings(FAST[1]), "scale=0.5, step_ratio=1", ("rgb",)))
    print(f"{'size':>12} {'outputs':>18} {'settings':>24} {'s/frame':>8} {'frames/s':>9}")
    for w, h in ((480, 270), (960, 540), (1920, 1080)):
        camera = sized(views[0].camera, w * h)
        for variant, label, outputs in variants:
            s = best_seconds(functools.partial(variant.render, views[0].c2w, camera, outputs))
            print(f"{camera.width:>5}×{camera.height:<6} {'+'.join(outputs):>18} {label:>24} {s:>8.3f} "
                  f"{1 / s:>9.2f}")

    small = sized(views[0].camera, 480 * 270)
    reference = [scene.with_settings(BEST).render(v.c2w, small, ("rgb",)).rgb for v in views]
    photos = [cv2.resize(v.image, (small.width, small.height), interpolation=cv2.INTER_AREA) for v in views]

    def row(label: str, settings: RenderSettings) -> None:
        variant = scene.with_settings(settings)
        images = [variant.render(v.c2w, small, ("rgb",)).rgb for v in views]
        s = best_seconds(lambda: variant.render(views[0].c2w, small, ("rgb",)))
        to_best = np.mean([psnr(r, i) if not np.array_equal(r, i) else np.inf for r, i in zip(reference, images)])
        to_photo = np.mean([psnr(p, i) for p, i in zip(photos, images)])
        mark = "  <- default" if settings == DEFAULT else ""
        print(f"{label:>38} {1 / s:>9.2f} {to_best:>12.2f} {to_photo:>12.2f}{mark}")

    print(f"\nat {small.width}×{small.height}, mean over {len(views)} held-out views")
    print(f"{'variant':>38} {'frames/s':>9} {'PSNR→best':>12} {'PSNR→photo':>12}")
    row("best quality (reference)", BEST)
    for step in (0.5, 1.0, 2.0):
        row(f"step_ratio={step}", DEFAULT.replace(step_ratio=step))
    for min_alpha in (0.0, 1e-3, 1e-2, 5e-2):
        row(f"min_alpha={min_alpha:g}", DEFAULT.replace(min_alpha=min_alpha))
    for t_stop in (0.0, 1e-3, 1e-2, 3e-2, 1e-1):
        row(f"t_stop={t_stop:g}", DEFAULT.replace(t_stop=t_stop))
    row("scale=0.75 (render smaller, upsample)", DEFAULT.replace(scale=0.75))
    row("scale=0.5", FAST[0])
    row("scale=0.5, step_ratio=1.0", FAST[1])
    return 0


if __name__ == "__main__":
    sys.exit(main(sys.argv[1:]))
