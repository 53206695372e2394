"""The splat scenes shipped in tests/splats/data, built from the exact demo scenes: ``python -m
tests.splats.make_data`` rewrites them (deterministically; a test checks that the shipped files are what this
builds: the cameras' text, their numbers to 1e-13, the Gaussians to 1e-5).

- ``object-sh0``: the object scene, 4000 Gaussians, SH degree 0, in the 3DGS output layout
  (``point_cloud/iteration_7000/point_cloud.ply`` and ``cameras.json``);
- ``wall-sh3``: the wall scene, 1500 Gaussians, SH degree 3, with a nerfstudio ``transforms.json`` (OpenGL
  camera axes, no images, the demo's held-out views as ``val_filenames``);
- ``object-rotated``: the object scene, 1500 Gaussians, in a world rotated, shifted and scaled by 2.5, as
  an ASCII .ply with a COLMAP text model (``sparse/0``).
"""

from __future__ import annotations

import math
from pathlib import Path

import numpy as np

from pytest_n2r.data import SourceFrame, write_colmap_text, write_transforms_json
from pytest_n2r.data.gs_cameras import write_gs_cameras
from pytest_n2r.demo import ground_truth
from pytest_n2r.demo.splats import sample_splats, similarity_transformed
from pytest_n2r.geometry import apply_similarity_to_pose
from pytest_n2r.geometry.conventions import quaternion_to_rotation
from pytest_n2r.splats import write_ply

DATA = Path(__file__).resolve().parent / "data"
#: The similarity of ``object-rotated``: world' = SCALE · R(ROTATION) · world + SHIFT.
ROTATION = np.array([math.cos(0.6), 0.3 * math.sin(0.6), -0.5 * math.sin(0.6), math.sqrt(0.66) * math.sin(0.6)])
SHIFT = np.array([3.0, -1.5, 0.75])
SCALE = 2.5
#: Paths of the shipped files, by data set: (ply, cameras).
FILES = {
    "object-sh0": ("object-sh0/point_cloud/iteration_7000/point_cloud.ply", "object-sh0/cameras.json"),
    "wall-sh3": ("wall-sh3/splat.ply", "wall-sh3/transforms.json"),
    "object-rotated": ("object-rotated/scene.ply", "object-rotated/sparse/0"),
}


def frames(name: str, similarity: tuple[float, np.ndarray, np.ndarray] | None = None) -> list[SourceFrame]:
    """The demo scene's views as source frames (no images), optionally moved by ``(s, R, t)``."""
    out = []
    for v in ground_truth(name).views:
        c2w = v.c2w if similarity is None else apply_similarity_to_pose(v.c2w, *similarity)
        out.append(SourceFrame(name=v.name, path=None, camera=v.camera, c2w=c2w))
    return out


def build(root: Path = DATA) -> list[Path]:
    """Write every data set under ``root``; return the files written."""
    written = []
    ply, cams = FILES["object-sh0"]
    written.append(write_ply(root / ply, sample_splats(ground_truth("object"), 4000, seed=1)))
    written.append(write_gs_cameras(root / cams, frames("object")))
    ply, cams = FILES["wall-sh3"]
    written.append(write_ply(root / ply, sample_splats(ground_truth("wall"), 1500, sh_degree=3, seed=2)))
    held = [v.name for v in ground_truth("wall").views if v.split == "heldout"]
    written.append(write_transforms_json(root / cams, frames("wall"), extra={"val_filenames": held}))
    ply, cams = FILES["object-rotated"]
    rotated = similarity_transformed(sample_splats(ground_truth("object"), 1500, seed=3), ROTATION, SHIFT, SCALE)
    written.append(write_ply(root / ply, rotated, ascii=True))
    similarity = (SCALE, quaternion_to_rotation(ROTATION), SHIFT)
    written.extend(sorted((write_colmap_text(root / cams, frames("object", similarity))).glob("*.txt")))
    return written


if __name__ == "__main__":
    for path in build():
        print(f"wrote {path.relative_to(DATA.parent)} ({path.stat().st_size / 1e3:.0f} kB)")
