"""Render settings side by side on one fitted scene: CPU time a frame, pixels traced, and the error each costs.

Run: ``python benchmarks/render_settings.py SCENE VARIANT [VARIANT ...]`` with ``SCENE`` a ``.n2r`` file or
``demo:NAME`` (the fitted twin of demo scene ``NAME``, whose truth is the exact scene's render) and each
``VARIANT`` either ``default`` or ``KEY=VALUE`` pairs of :class:`pytest_n2r.render.RenderSettings` separated by
spaces (values as Python literals without spaces), e.g. ``"t_stop=0.03 min_weight=0.01"``; the first variant is
the base of the ratios. ``--size`` (default ``480x270``; portrait captures turned), ``--rounds`` (default 3),
``--train-views`` (default 7) and ``--smoke`` (a tiny size, one round, two views) change the run.

All variants render in this one process, taking turns each round, so the machine's load hits them alike. Per
variant: CPU ms a frame on one numba thread (the median over rounds of the mean over the held-out views of the
least of 2 renders: what an idle core takes), the share of pixels traced (adaptive sampling), the PSNR against
the best-quality render (``render_speed.BEST``) at training poses — the column to choose settings by — and the
PSNR against the truth at the held-out views (photos resized, or the exact scene), the column to report and not
to tune on. Results: docs/performance.md.
"""

from __future__ import annotations

import argparse
import ast
import statistics
import sys

import numba
import numpy as np
import torch
from render_speed import BEST, cpu_ms, load, sized

from pytest_n2r.errors import N2RError
from pytest_n2r.metrics.image_quality import psnr
from pytest_n2r.render.field_render import RenderSettings


def variant(text: str) -> RenderSettings:
    """``default``, or ``KEY=VALUE`` pairs separated by spaces, as :class:`RenderSettings` (``ValueError`` naming the
    pair that is not one)."""
    if text.strip() == "default":
        return RenderSettings()
    changes = {}
    for pair in text.split():
        key, sep, value = pair.partition("=")
        try:
            if not sep:
                raise ValueError(pair)
            changes[key] = ast.literal_eval(value)
        except (ValueError, SyntaxError):
            raise ValueError(f"variant {text!r}: {pair!r} is not KEY=VALUE with VALUE a Python literal (0.03, "
                             "(0.3,0.1) without spaces, 'ray')") from None
    try:
        return RenderSettings(**changes)
    except TypeError as exc:
        raise ValueError(f"variant {text!r}: {exc}") from None


def main(argv: list[str]) -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("scene")
    parser.add_argument("variants", nargs="+", metavar="VARIANT")
    parser.add_argument("--size", default="480x270")
    parser.add_argument("--rounds", type=int, default=3)
    parser.add_argument("--train-views", type=int, default=7)
    parser.add_argument("--smoke", action="store_true", help="a tiny size, one round, two views")
    args = parser.parse_args(argv)
    try:
        settings = {text: variant(text) for text in args.variants}
    except ValueError as exc:
        parser.error(str(exc))
    width, height = (int(v) for v in ("64x36" if args.smoke else args.size).split("x"))
    rounds, n_views = (1, 2) if args.smoke else (args.rounds, 8)
    numba.set_num_threads(1)
    torch.set_num_threads(1)
    try:
        scene, views, truth = load(args.scene, n_views)
    except N2RError as exc:  # a missing or unreadable scene file, an unknown demo scene
        parser.error(str(exc))
    if not views:
        parser.error(f"{args.scene}: no held-out view with a photo or an exact twin to compare against")
    train = [v for v in scene.views if v.split == "train"]
    train = train[::max(1, len(train) // (2 if args.smoke else args.train_views))][:args.train_views]
    camera = sized(views[0].camera, width * height)
    best = scene.with_settings(BEST)
    reference = [best.render(v.c2w, camera, ("rgb",)).rgb for v in train]
    photos = [truth(v, camera) for v in views]
    scenes = {text: scene.with_settings(s) for text, s in settings.items()}
    ms: dict[str, list[float]] = {text: [] for text in scenes}
    traced: dict[str, float] = {}
    for _ in range(rounds):
        for text, variant_scene in scenes.items():
            variant_scene.render(views[0].c2w, camera, ("rgb",))  # warm-up: the renderer built, the kernels loaded
            frame_ms, shares = [], []
            for v in views:
                frame_ms.append(cpu_ms(lambda s=variant_scene, v=v: s.render(v.c2w, camera, ("rgb",)), 2))
                shares.append(variant_scene._renderer.last_traced / (camera.width * camera.height))
            ms[text].append(float(np.mean(frame_ms)))
            traced[text] = float(np.mean(shares))
    print(f"{args.scene} at {camera.width}×{camera.height}, one thread, {rounds} rounds; {len(views)} held-out views "
          f"(timed, reported), {len(train)} training poses (to choose by)\n\n| variant | CPU ms a frame | speed-up | "
          "pixels traced | PSNR → best, training poses | PSNR → truth, held out | difference |\n|" + " --- |" * 7)
    base_ms = base_db = None  # the first variant's
    for text, variant_scene in scenes.items():
        m = statistics.median(ms[text])
        at_train = [psnr(r, variant_scene.render(v.c2w, camera, ("rgb",)).rgb) for r, v in zip(reference, train)]
        to_best = f"{np.mean(at_train):.2f} dB" if at_train else "no training poses"
        to_truth = float(np.mean([psnr(p, variant_scene.render(v.c2w, camera, ("rgb",)).rgb)
                                  for p, v in zip(photos, views)]))
        if base_ms is None:
            base_ms, base_db = m, to_truth
        print(f"| {text} | {m:.1f} | {base_ms / m:.3f}× | {traced[text]:.1%} | {to_best} | {to_truth:.3f} dB | "
              f"{to_truth - base_db:+.3f} dB |")
    return 0


if __name__ == "__main__":
    sys.exit(main(sys.argv[1:]))
