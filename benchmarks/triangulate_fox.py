"""Points for a transforms.json: triangulation image size vs time and reference length, on fox.

Ingesting a transforms.json triangulates SIFT matches between neighbouring views with the shipped
poses (``pytest_n2r.data.triangulate``) to measure the reference length and bounds. This compares the
working image size side by side in one run: time, points, reference length, and ratios to the
640 px variant.

Usage: ``nice -n 10 python benchmarks/triangulate_fox.py``
"""

from __future__ import annotations

import sys
import time
import warnings
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))

from pytest_n2r.data.extent import reference_length
from pytest_n2r.data.images import read_image, resize_image
from pytest_n2r.data.transforms_json import read_transforms_json
from pytest_n2r.data.triangulate import triangulate_views

FOX = ROOT.parent / "shared" / "scenes" / "fox"
SIZES = (640, 480, 320)


def main() -> int:
    if not (FOX / "transforms.json").is_file():
        print(f"fox scene not found at {FOX}; nothing to benchmark")
        return 1
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        poses = read_transforms_json(FOX / "transforms.json")
    full = [f.camera.undistort_image(read_image(f.path)) for f in poses.frames]
    c2ws = [f.c2w for f in poses.frames]
    rows = []
    for size in SIZES:
        cams = [f.camera.undistorted().fit_within(size) for f in poses.frames]
        images = [resize_image(im, c.width, c.height) for im, c in zip(full, cams)]
        start = time.perf_counter()
        points = triangulate_views(images, cams, c2ws)
        took = time.perf_counter() - start
        rows.append((size, took, len(points), reference_length(points, cams, c2ws)))
    base_t, base_ref = rows[0][1], rows[0][3]
    print(f"triangulation on {len(poses.frames)} fox views with the shipped poses")
    print(f"{'max size':>8}  {'time':>7}  {'time ratio':>10}  {'points':>7}  {'reference':>9}  {'ref ratio':>9}")
    for size, took, n, ref in rows:
        print(f"{size:>6}px  {took:>6.2f}s  {took / base_t:>10.2f}  {n:>7}  {ref:>9.4f}  {ref / base_ref:>9.4f}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
