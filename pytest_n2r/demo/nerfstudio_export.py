"""Write a demo scene's ground-truth images and a nerfstudio ``transforms.json``, to fit with any tool.

Convention
----------
``transform_matrix`` is camera-to-world with OpenGL camera axes (ours ``@ diag(1, -1, -1, 1)``) and
``cx, cy`` put the top-left pixel centre at ``(0.5, 0.5)`` (ours + 0.5), as nerfstudio and instant-ngp
expect. ``train_filenames`` / ``val_filenames`` carry the split (every 8th view held out), which
nerfstudio's own data parser honours. ``n2r_reference_length`` and ``n2r_content_hash`` say which scene
and what translation unit the files belong to.
"""

from __future__ import annotations

import json
import os
import tempfile
from pathlib import Path

import numpy as np

from ..geometry import opencv_to_opengl
from .rendered_capture import capture_scene
from .exact import GroundTruthScene

__all__ = ["export_scene"]


def _atomic_write(path: Path, data: bytes) -> None:
    """Write ``data`` to a temporary file beside ``path``, then rename it over ``path``."""
    fd, tmp = tempfile.mkstemp(prefix=f".{path.name}.", dir=path.parent)
    try:
        with os.fdopen(fd, "wb") as fh:
            fh.write(data)
        os.replace(tmp, path)
    except BaseException:
        Path(tmp).unlink(missing_ok=True)
        raise


def export_scene(scene: GroundTruthScene, out_dir: str | os.PathLike, size: int | tuple[int, int]) -> Path:
    """Write ``out_dir/images/*.png`` and ``out_dir/transforms.json``; return the json's path."""
    import cv2

    out = Path(out_dir)
    (out / "images").mkdir(parents=True, exist_ok=True)
    cap = capture_scene(scene, size)
    cam = cap.views[0].camera
    frames, train, val = [], [], []
    for v in cap.views:
        ok, png = cv2.imencode(".png", cv2.cvtColor(v.image, cv2.COLOR_RGB2BGR))  # OpenCV wants BGR
        if not ok:  # pragma: no cover - encoding an uint8 RGB image does not fail
            raise RuntimeError(f"could not encode {v.name}")
        rel = f"images/{v.name}"
        _atomic_write(out / rel, png.tobytes())
        frames.append({"file_path": rel, "transform_matrix": opencv_to_opengl(v.c2w).tolist()})
        (train if v.split == "train" else val).append(rel)
    meta = {
        "camera_model": "OPENCV", "w": cam.width, "h": cam.height, "fl_x": cam.fx, "fl_y": cam.fy,
        "cx": cam.cx + 0.5, "cy": cam.cy + 0.5, "k1": 0.0, "k2": 0.0, "p1": 0.0, "p2": 0.0,
        "frames": frames, "train_filenames": train, "val_filenames": val,
        "n2r_scene": scene.name, "n2r_content_hash": scene.content_hash,
        "n2r_reference_length": cap.reference_length,
        "n2r_bounds": np.asarray(cap.bounds).tolist(),
    }
    path = out / "transforms.json"
    _atomic_write(path, (json.dumps(meta, indent=2) + "\n").encode())
    return path
