"""The example project's classifiers as a careful user would run them: CPU time per call and whether their outputs
change with two torch threads or with channels-last weights.

Run: ``python benchmarks/classifier_threads.py`` (``--views N``, default 4; ``--repeats R``, default 3). Renders
``N`` views of ``demo:object`` at 320×180 (the main job's size), then for each classifier of
``example_project/perception/classifiers.py`` (its weights packages installed): CPU milliseconds per call on
one thread (the example's setting), wall milliseconds per call on one and on two threads, and the same with the
network's weights in channels-last memory format; beside each, whether the probabilities are bit for bit those
of one thread in the default format, else the largest difference. Skips a classifier whose weights are missing.
"""

from __future__ import annotations

import argparse
import sys
import time
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parents[1]


def per_call(fn, images: list[np.ndarray], repeats: int) -> tuple[float, float, list[np.ndarray]]:
    """CPU and wall milliseconds per call of ``fn`` over ``images`` (``repeats`` passes after a warm-up), and the
    warm-up's outputs."""
    outputs = [fn(image) for image in images]
    c0, t0 = time.process_time(), time.perf_counter()
    for _ in range(repeats):
        for image in images:
            fn(image)
    calls = repeats * len(images)
    return 1e3 * (time.process_time() - c0) / calls, 1e3 * (time.perf_counter() - t0) / calls, outputs


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--views", type=int, default=4)
    parser.add_argument("--repeats", type=int, default=3)
    args = parser.parse_args(argv)
    sys.path[:0] = [str(ROOT), str(ROOT / "example_project")]
    import torch
    from perception.classifiers import CLASSIFIERS, WeightsMissing, classifier

    from pytest_n2r.demo import ground_truth

    scene = ground_truth("object")
    views = scene.views[:: max(1, len(scene.views) // args.views)][: args.views]
    images = [scene.render(v.c2w, v.camera.resized(320, 180), ("rgb",)).rgb for v in views]
    print(f"{len(images)} views of demo:object at 320x180, {args.repeats} passes\n")
    print("| classifier | setting | CPU ms / call | wall ms / call | outputs against one thread |")
    print("|---|---|---|---|---|")
    for name in CLASSIFIERS:
        try:
            fn = classifier(name)
        except WeightsMissing as exc:
            print(f"| {name} | skipped: {exc} | | | |")
            continue
        net = next(c.cell_contents for c in fn.__closure__ if isinstance(c.cell_contents, torch.nn.Module))
        base = None
        settings = (("1 thread", 1, torch.contiguous_format), ("2 threads", 2, torch.contiguous_format),
                    ("1 thread, channels-last weights", 1, torch.channels_last))
        for label, threads, layout in settings:
            torch.set_num_threads(threads)
            net.to(memory_format=layout)
            cpu, wall, outputs = per_call(fn, images, args.repeats)
            if base is None:
                base, same = outputs, "(the reference)"
            else:
                worst = max(float(np.abs(a - b).max()) for a, b in zip(outputs, base))
                same = "bit for bit the same" if worst == 0 else f"differ, up to {worst:.1e}"
            print(f"| {name} | {label} | {cpu:.1f} | {wall:.1f} | {same} |")
        net.to(memory_format=torch.contiguous_format)
        torch.set_num_threads(1)
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
