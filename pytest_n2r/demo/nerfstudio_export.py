"""Write a demo scene's ground-truth images and a nerfstudio ``transforms.json``, to fit with any tool.

Convention
----------
``transform_matrix`` is camera-to-world with OpenGL camera axes (ours ``@ diag(1, -1, -1, 1)``) and
``cx, cy`` put the top-left pixel centre at ``(0.5, 0.5)`` (ours + 0.5), as nerfstudio and instant-ngp
expect. ``train_filenames`` / ``val_filenames`` carry the split (every 8th view held out), which
nerfstudio's own data parser honours. ``n2r_reference_length`` and ``n2r_content_hash`` say which scene
and what translation unit the files belong to.

The first file written is a placeholder ``transforms.json`` (``n2r_complete: false``, no frames) naming the
scene: an export interrupted among its images leaves a folder ``n2r demo export`` knows as its own, so the same
command run again writes into it without ``--force``; the real one replaces it last.
"""

from __future__ import annotations

import json
import os
from pathlib import Path

import numpy as np

from ..data.atomic import atomic_write_bytes, atomic_write_text
from ..data.poses import SourceFrame
from ..data.transforms_json import write_transforms_json
from .exact import GroundTruthScene
from .rendered_capture import capture_scene

__all__ = ["export_scene"]


def export_scene(scene: GroundTruthScene, out_dir: str | os.PathLike, size: int | tuple[int, int]) -> Path:
    """Write ``out_dir/images/*.png`` and ``out_dir/transforms.json`` (atomically); return the json's path."""
    import cv2

    out = Path(out_dir)
    cap = capture_scene(scene, size)
    marker = {"n2r_scene": scene.name, "n2r_content_hash": scene.content_hash, "n2r_complete": False, "frames": []}
    atomic_write_text(out / "transforms.json", json.dumps(marker, indent=1) + "\n")  # before any image
    frames: list[SourceFrame] = []
    train: list[str] = []
    val: list[str] = []
    for v in cap.views:
        assert v.image is not None, "capture_scene renders every view's image"
        ok, png = cv2.imencode(".png", cv2.cvtColor(v.image, cv2.COLOR_RGB2BGR))  # OpenCV wants BGR
        if not ok:  # pragma: no cover - encoding an uint8 RGB image does not fail
            raise RuntimeError(f"could not encode {v.name}")
        rel = f"images/{v.name}"
        atomic_write_bytes(out / rel, png.tobytes())
        frames.append(SourceFrame(name=rel, path=out / rel, camera=v.camera, c2w=v.c2w))
        (train if v.split == "train" else val).append(rel)
    extra = {
        "train_filenames": train, "val_filenames": val,
        "n2r_scene": scene.name, "n2r_content_hash": scene.content_hash,
        "n2r_reference_length": cap.reference_length, "n2r_bounds": np.asarray(cap.bounds).tolist(),
    }
    return write_transforms_json(out / "transforms.json", frames, extra=extra)
