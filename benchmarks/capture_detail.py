"""How many training pixels a voxel spans: the fox and the demo captures against the grids they are fitted with.

Run: ``python benchmarks/capture_detail.py [--fox-grid 192] [--demo-grid 384] [--demo-size 240x135]``

For each capture, :func:`pytest_n2r.fit.detail.capture_detail` in the space a fit would build: the
training views' pixel footprint (z-depth / fx at the median depth of the sparse points each sees) where
the cameras look closely (10th percentile) and at the median view, the finest grid's voxel in those pixels,
and the grid that would match them. No fit: seconds. The fox (``../shared/scenes/fox``, 1/4 resolution,
as benchmarks/field_fit.py fits it) is skipped when absent. Results: docs/scene-field-log.md.
"""

from __future__ import annotations

import argparse
import sys
import warnings
from pathlib import Path

import numpy as np

from pytest_n2r.data import ingest
from pytest_n2r.data.capture import Capture
from pytest_n2r.demo import capture as demo_capture
from pytest_n2r.field.config import FieldConfig
from pytest_n2r.field.space import SceneSpace
from pytest_n2r.fit.detail import capture_detail

FOX = Path(__file__).resolve().parents[2] / "shared" / "scenes" / "fox" / "transforms.json"


def row(name: str, capture: Capture, grid: int) -> str:
    centers = np.stack([v.c2w[:3, 3] for v in capture.views])
    detail = capture_detail(capture, SceneSpace.around(capture.bounds, centers))
    view = capture.train_views[0].camera
    if detail is None:
        return f"| {name} | {view.width}×{view.height} | {grid}³ | no view sees enough sparse points | — |"
    median = detail.space.voxel_size(grid) / detail.median
    return (f"| {name} | {view.width}×{view.height} | {grid}³ | {detail.pixels_per_voxel(grid):.1f} / {median:.1f} | "
            f"{detail.matching_resolution()}³ |")


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    finest = FieldConfig().resolutions[-1]
    parser.add_argument("--fox-grid", type=int, default=finest, help=f"the fox fit's finest grid (default: {finest})")
    parser.add_argument("--demo-grid", type=int, default=384, help="the demo twins' finest grid (shipped: 384)")
    parser.add_argument("--demo-size", default="240x135", help="the demo captures' photo size (shipped: 240x135)")
    args = parser.parse_args(argv)
    width, height = (int(v) for v in args.demo_size.lower().split("x"))
    print("| capture | photos | finest grid | training pixels per voxel (close / median view) "
          "| grid that would match |")
    print("| --- | --- | --- | --- | --- |")
    if FOX.exists():
        with warnings.catch_warnings():
            warnings.simplefilter("ignore")  # the fox transforms.json lists frames whose photos are absent
            print(row("fox", ingest(FOX, downscale=0.25), args.fox_grid))
    else:
        print(f"fox skipped: {FOX} is absent (the fox capture lives in ../shared beside the checkout)")
    for name in ("wall", "object"):
        print(row(f"demo:{name}", demo_capture(name, (width, height)), args.demo_grid))
    return 0


if __name__ == "__main__":
    sys.exit(main())
