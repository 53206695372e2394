"""Throughput of the DeepXplore baseline mutations on 480×270 RGB images (target: >= 1000 images/s).

Run: ``python benchmarks/mutations.py [--images N]``. Each mutation type is applied to N images with
parameters drawn from a fixed seed, in the ranges the default strategies use; the table gives images
per second (single thread) and, side by side, a plain-numpy brightness as the reference variant.
"""

from __future__ import annotations

import argparse
import time

import numpy as np

from pytest_n2r.strategies import BlackPatches, Brightness, NoisePatch

WIDTH, HEIGHT = 480, 270


def numpy_brightness(rgb: np.ndarray, levels: int) -> np.ndarray:
    """The obvious numpy version of m1, for comparison."""
    return np.clip(rgb.astype(np.int16) + levels, 0, 255).astype(np.uint8)


def rate(fn, images: list[np.ndarray], repeats: int = 3) -> float:
    """Best-of-``repeats`` images per second of ``fn(i, image)`` over ``images``."""
    best = np.inf
    for _ in range(repeats):
        t0 = time.perf_counter()
        for i, image in enumerate(images):
            fn(i, image)
        best = min(best, time.perf_counter() - t0)
    return len(images) / best


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--images", type=int, default=500, help="images per mutation type (default 500)")
    args = parser.parse_args()
    rng = np.random.default_rng(0)
    images = [rng.integers(0, 256, (HEIGHT, WIDTH, 3), dtype=np.uint8) for _ in range(8)] * (args.images // 8)
    n = len(images)
    m1 = [Brightness(int(v)) for v in rng.integers(-128, 129, n)]
    m2 = [NoisePatch(float(s), float(x), float(y), int(k)) for s, x, y, k in
          zip(rng.uniform(0, 0.5, n), rng.random(n), rng.random(n), rng.integers(0, 2**32 - 1, n))]
    m3 = [BlackPatches(float(s), 6, int(k)) for s, k in zip(rng.uniform(0, 0.08, n), rng.integers(0, 2**32 - 1, n))]
    mixed = [(m1, m2, m3)[i % 3][i] for i in range(n)]
    rows = [
        ("m1 brightness (cv2.LUT)", rate(lambda i, im: m1[i].apply(im), images)),
        ("m1 brightness (numpy clip, reference)", rate(lambda i, im: numpy_brightness(im, m1[i].levels), images)),
        ("m2 noise patch (size <= 0.5)", rate(lambda i, im: m2[i].apply(im), images)),
        ("m3 six black patches (size <= 0.08)", rate(lambda i, im: m3[i].apply(im), images)),
        ("m1/m2/m3 mixed", rate(lambda i, im: mixed[i].apply(im), images)),
    ]
    print(f"Mutations of {WIDTH}x{HEIGHT} RGB uint8 images, {n} images per row, best of 3, one thread")
    print(f"{'mutation':<40} {'images/s':>10} {'vs target 1000/s':>17}")
    for name, r in rows:
        print(f"{name:<40} {r:>10.0f} {r / 1000:>16.1f}x")
    print(f"LUT brightness is {rows[0][1] / rows[1][1]:.1f}x the numpy reference")


if __name__ == "__main__":
    main()
