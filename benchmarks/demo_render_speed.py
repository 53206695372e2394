"""Render speed of the exact demo scenes, compiled kernel against the vectorized numpy definition, and how
far their images are apart.

Run: ``python benchmarks/demo_render_speed.py [--poses N] [--size WxH] [--threads T] [--repeats R]``. Prints,
per demo scene at the given size (default 480x270, the capture size):

1. frames/s of the compiled renderer for RGB + depth + opacity and for each output alone (best of ``R``,
   default 10, after a warm-up: on a shared machine the best run is the one least disturbed), and of the
   numpy reference for all three (one run after a warm-up);
2. the agreement over ``N`` random poses (the captured views moved by up to 20°/30° and half a reference
   length): the largest RGB difference in grey levels outside pixels where two surfaces coincide, the share
   of pixels that differ at all, the largest relative z-depth difference and the opacity pixels that differ.

Results: docs/performance.md.
"""

from __future__ import annotations

import argparse
import sys

import numpy as np
from _timing import best_seconds

from pytest_n2r.demo import demo_scene_names, ground_truth
from pytest_n2r.geometry import Transform

OUTPUTS = ("rgb", "depth", "opacity")


def frames_per_second(scene, camera, c2w, repeats: int) -> tuple[dict[tuple[str, ...], float], float]:
    """Frames/s of the compiled renderer per set of outputs, and of the numpy reference for all three."""
    fps = {outs: 1 / best_seconds(lambda o=outs: scene.render(c2w, camera, o), repeats=repeats)
           for outs in (OUTPUTS, ("rgb",), ("depth",), ("opacity",))}
    return fps, 1 / best_seconds(lambda: scene.render_reference(c2w, camera, OUTPUTS), repeats=1)


def random_poses(scene, n: int, seed: int = 0) -> list[np.ndarray]:
    rng = np.random.default_rng(seed)
    poses = []
    for _ in range(n):
        view = scene.views[rng.integers(len(scene.views))]
        tau = Transform(roll=rng.uniform(-20, 20), pitch=rng.uniform(-20, 20), yaw=rng.uniform(-30, 30),
                        x=rng.uniform(-0.5, 0.5), y=rng.uniform(-0.5, 0.5), z=rng.uniform(-0.5, 0.5))
        poses.append(tau.apply(view.c2w, scene.reference_length))
    return poses


def agreement(scene, camera, poses) -> dict[str, float]:
    """Largest differences between the compiled and the reference renders over ``poses``."""
    worst_rgb, differ, pixels, depth_rel, opacity_px, tied = 0, 0, 0, 0.0, 0, 0
    for c2w in poses:
        got = scene.render(c2w, camera, OUTPUTS)
        want = scene.render_reference(c2w, camera, OUTPUTS)
        diff = np.abs(got.rgb.astype(int) - want["rgb"].astype(int)).max(axis=2)
        tie = scene.coincident_pixels(c2w, camera)
        worst_rgb = max(worst_rgb, int(diff[~tie].max()))
        differ += int(np.sum(diff > 0))
        tied += int(np.sum(tie & (diff > 1)))
        pixels += diff.size
        depth_rel = max(depth_rel, float((np.abs(got.depth.astype(float) - want["depth"]) / want["depth"]).max()))
        opacity_px += int(np.sum(got.opacity != want["opacity"]))
    return {"rgb_max": worst_rgb, "rgb_differ": differ / pixels, "coincident_over_1": tied / pixels,
            "depth_rel": depth_rel, "opacity_px": opacity_px}


def main(argv: list[str]) -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--poses", type=int, default=40, help="random poses per scene for the agreement check")
    parser.add_argument("--size", default="480x270", help="render size WxH (default 480x270)")
    parser.add_argument("--threads", type=int, default=None, help="numba threads (default: all)")
    parser.add_argument("--repeats", type=int, default=10, help="timed renders per output set (the best counts)")
    args = parser.parse_args(argv)
    width, height = (int(v) for v in args.size.lower().split("x"))
    if args.threads:
        import numba

        numba.set_num_threads(args.threads)
    print(f"{width}x{height}, frames/s (best of {args.repeats} after a warm-up); agreement over {args.poses} random "
          "poses\n")
    print("| scene | rgb+depth+opacity | rgb | depth | opacity | numpy reference, all three | speed-up |"
          " rgb max diff (grey levels) | pixels differing | coincident-surface pixels > 1 |"
          " depth rel. diff | opacity pixels differing |")
    print("| --- " * 12 + "|")
    for name in demo_scene_names():
        scene = ground_truth(name)
        camera = scene.views[5].camera.resized(width, height)
        fps, ref = frames_per_second(scene, camera, scene.views[5].c2w, args.repeats)
        a = agreement(scene, camera, random_poses(scene, args.poses))
        print(f"| {name} | {fps[OUTPUTS]:.1f} | {fps[('rgb',)]:.1f} | {fps[('depth',)]:.1f} | "
              f"{fps[('opacity',)]:.1f} | {ref:.2f} | {fps[OUTPUTS] / ref:.0f}× | {a['rgb_max']} | "
              f"{a['rgb_differ']:.4%} | {a['coincident_over_1']:.4%} | {a['depth_rel']:.1e} | {a['opacity_px']} |")
    return 0


if __name__ == "__main__":
    sys.exit(main(sys.argv[1:]))
