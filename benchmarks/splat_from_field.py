"""A fitted scene field against its conversion to splats: held-out PSNR against the photos, and render speed.

Run: ``python benchmarks/splat_from_field.py SCENE.n2r`` (a scene file written by ``n2r fit``, with its
photos; ``--size`` and ``--path`` set the conversion, default :func:`field_to_gaussians`'s; ``--long-side``
sets the render size, default 480: 480×270 for landscape views, 270×480 for portrait ones). Converts the
field to one Gaussian per occupied voxel (:mod:`pytest_n2r.scene.splat_from_field`), then renders each
held-out view (``--split train --every N``: every N-th training view, to choose the knobs) with both: PSNR
against the view's photo (the fit's own metric), and frames/s (RGB + depth + opacity; best of 3 renders per
view after a warm-up, the median over views, all numba threads). Both use the same fit: the splats cost the
field's fit time plus the conversion's. ``demo:NAME`` instead of a file takes the fitted demo field and
scores against the exact demo renders; ``--smoke`` does that for ``demo:object`` on one view at 48 px, to
check that the script runs.

The fox field (``benchmarks/field_fit.py --out /tmp/fox.n2r``) must never be copied into this repository.
Results: docs/splat-scenes.md.
"""

from __future__ import annotations

import argparse
import statistics
import time
import timeit

import numpy as np

from pytest_n2r.metrics.image_quality import psnr
from pytest_n2r.scene import load_scene
from pytest_n2r.scene.splat_from_field import splat_scene_from_field

OUTPUTS = ("rgb", "depth", "opacity")


def sized(camera, long_side: int):
    """``camera`` resized so that its longer side has ``long_side`` pixels (the aspect ratio kept)."""
    scale = long_side / max(camera.width, camera.height)
    return camera.resized(round(camera.width * scale), round(camera.height * scale))


def score(scene, views, long_side: int, repeats: int) -> tuple[list[float], float]:
    """PSNR per view against its photo (resized to the render size) and the median frames/s over views."""
    import cv2

    scores, rates = [], []
    for view in views:
        camera = sized(view.camera, long_side)
        photo = view.image
        if photo.shape[:2] != (camera.height, camera.width):
            photo = cv2.resize(photo, (camera.width, camera.height), interpolation=cv2.INTER_AREA)
        render = lambda c=camera, v=view: scene.render(v.c2w, c, OUTPUTS)
        scores.append(psnr(photo, render().rgb))
        rates.append(1.0 / min(timeit.repeat(render, number=1, repeat=repeats)))
    return scores, statistics.median(rates)


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("scene", nargs="?", help="a fitted scene file (.n2r) with its photos, or demo:NAME (the fitted "
                        "demo field, scored against the exact renders)")
    parser.add_argument("--size", type=float, default=None, help="Gaussian standard deviation in cell sides")
    parser.add_argument("--path", type=float, default=None, help="voxels of density a Gaussian's opacity stands for")
    parser.add_argument("--long-side", type=int, default=480, help="render size: pixels of the longer side")
    parser.add_argument("--split", choices=("heldout", "train"), default="heldout",
                        help="the views to score (train: to choose --size and --path without the held-out views)")
    parser.add_argument("--every", type=int, default=1, metavar="N", help="every N-th view of the split")
    parser.add_argument("--smoke", action="store_true", help="the demo field, one view at 48 px")
    args = parser.parse_args(argv)
    knobs = {k: v for k, v in (("size", args.size), ("path", args.path)) if v is not None}
    repeats, long_side = 3, args.long_side
    scene_name = "demo:object" if args.smoke else args.scene
    if scene_name is None:
        parser.error("SCENE is required (or --smoke)")
    if args.smoke:
        long_side, repeats = 48, 1
    if scene_name.startswith("demo:"):  # the fitted demo field; its exact renders stand for the photos
        from dataclasses import replace

        from pytest_n2r.demo import fitted_scene, ground_truth

        field, exact = fitted_scene(scene_name[5:], device="cpu"), ground_truth(scene_name[5:])
        views = [v for v in field.views if v.split == args.split][::args.every][:1 if args.smoke else None]
        views = [replace(v, image=exact.render(v.c2w, sized(v.camera, long_side), "rgb").rgb) for v in views]
    else:
        field = load_scene(scene_name, device="cpu")
        views = [v for v in field.views if v.split == args.split and v.image is not None][::args.every]
    if not views:
        raise SystemExit(f"{scene_name}: no {args.split} view with its photo")
    start = time.perf_counter()
    splats = splat_scene_from_field(field, **knobs)
    convert_s = time.perf_counter() - start
    fit_s = (field.report or {}).get("train_seconds") if hasattr(field, "report") else None
    print(f"scene {field.name}: field {field.field.resolution}³ grid, {int(field.field.occupancy.sum())} occupied "
          f"cells, fitted in {fit_s if fit_s is not None else '?'} s; converted to {len(splats.gaussians)} "
          f"Gaussians in {convert_s:.1f} s ({knobs or 'default size and path'})")
    cam = sized(views[0].camera, long_side)
    split = "held-out" if args.split == "heldout" else "training"
    print(f"{len(views)} {split} views at {cam.width}×{cam.height}\n")
    print(f"| representation | {split} PSNR dB (mean) | per view | frames/s (median) |")
    print("|---|---|---|---|")
    for name, scene in (("field", field), ("splats from the field", splats)):
        scores, rate = score(scene, views, long_side, repeats)
        print(f"| {name} | {np.mean(scores):.2f} | {', '.join(f'{s:.2f}' for s in scores)} | {rate:.1f} |")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
