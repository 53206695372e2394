"""Fingerprints of fitted-field renders and of a short fit: proof that a refactor changed no pixel.

Run: ``python benchmarks/render_fingerprint.py --out before.json`` on one commit, then
``python benchmarks/render_fingerprint.py --compare before.json`` on another (same machine, same library
versions: another CPU may round differently). It prints one SHA-256 per item and, with ``--compare``,
every item whose bytes changed (exit status 1 when any did):

1. the shipped fitted demo twins (``--twins``, default ``wall object``): RGB, z-depth and opacity at four
   captured poses and two poses moved off the capture (rays that cross the contracted shell at grazing
   angles), with the compiled backend at the capture size and the torch backend at a quarter of it;
2. short fits of the demo ``object`` scene (``--steps`` steps at 48×27 through
   :func:`pytest_n2r.demo.fitted.build_fitted`, which writes the same bytes for the same fit), one of SH degree 1
   and one of degree 2: each scene file's bytes, and its renders in both backends and, compiled, with each sample's
   colour from its ray's direction (``colour_direction="ray"``: the SH coefficients read in the kernel, the path
   the twins, of degree 0, and the default baked colour do not take).

Timings are not compared; the script takes about a minute on two CPU threads.
"""

from __future__ import annotations

import argparse
import hashlib
import json
import sys
import tempfile
from pathlib import Path

import numpy as np

from pytest_n2r.demo.fitted import RECIPES, build_fitted, fitted_path
from pytest_n2r.field.config import FieldConfig
from pytest_n2r.geometry import Camera
from pytest_n2r.render.field_render import FieldRenderer, RenderSettings
from pytest_n2r.scene.file import SceneFile, read_scene_file

OUTPUTS = ("rgb", "depth", "opacity")
#: The short fit: two small grids, as the fit tests use (tests/fit/conftest.py), without the total-variation
#: priors (defaults since 2 December 2026), so fingerprints taken before and after that change compare.
SHORT_CONFIG = FieldConfig(resolutions=(16, 24), stage_fractions=(0.5,), batch_rays=256, prune_every=20,
                           alpha_init=0.01, tv=0.0, tv_density=0.0)


def _digest(*arrays: np.ndarray) -> str:
    h = hashlib.sha256()
    for a in arrays:
        h.update(f"{a.dtype}{a.shape}".encode())
        h.update(np.ascontiguousarray(a).tobytes())
    return h.hexdigest()


def _poses(file: SceneFile) -> list[tuple[str, np.ndarray, Camera]]:
    """Four captured poses, and two moved off the capture: pulled back and turned 40° about the camera's y."""
    views = file.views
    picks = [views[round(i * (len(views) - 1) / 3)] for i in range(4)]
    poses = [(view.name, view.c2w, view.camera) for view in picks]
    angle = np.radians(40.0)
    turn = np.array([[np.cos(angle), 0.0, np.sin(angle)], [0.0, 1.0, 0.0], [-np.sin(angle), 0.0, np.cos(angle)]])
    for view in picks[:2]:
        c2w = view.c2w.copy()
        c2w[:3, :3] = c2w[:3, :3] @ turn
        c2w[:3, 3] -= 0.5 * file.field.space.radius * c2w[:3, 2]
        poses.append((f"{view.name}+moved", c2w, view.camera))
    return poses


#: Each render's backend, its size as a fraction of the capture's, and where a sample's colour takes its direction.
RENDERS = (("compiled", 1.0, "vertex"), ("torch", 0.25, "vertex"))
RAY_COLOUR = (("compiled", 1.0, "ray"),)


def _renders(label: str, path: Path, renders: tuple[tuple[str, float, str], ...] = RENDERS) -> dict[str, str]:
    file = read_scene_file(path, images=False)
    out = {}
    for backend, scale, direction in renders:
        renderer = FieldRenderer(file.field, RenderSettings(backend=backend, colour_direction=direction))
        kind = backend if direction == "vertex" else f"{backend}-{direction}"
        for name, c2w, camera in _poses(file):
            small = camera.resized(max(8, round(camera.width * scale)), max(8, round(camera.height * scale)))
            images = renderer.render(c2w, small, OUTPUTS)
            out[f"{label}/{kind}/{name}"] = _digest(*(images[k] for k in OUTPUTS))
    return out


def fingerprints(twins: list[str], steps: int) -> dict[str, str]:
    """Item name → SHA-256 of its bytes."""
    result = {}
    for name in twins:
        result.update(_renders(f"twin:{name}", fitted_path(name, build=False)))
    for label, degree in (("short-fit", 1), ("short-fit-sh2", 2)):
        config = SHORT_CONFIG.replace(sh_degree=degree)
        recipe = RECIPES["object"].replace(size=(48, 27), config=config, max_steps=steps)
        with tempfile.TemporaryDirectory() as tmp:
            path, _ = build_fitted("object", Path(tmp) / "short.n2r", recipe=recipe)
            result[f"{label}/file"] = hashlib.sha256(path.read_bytes()).hexdigest()
            result.update(_renders(label, path, RENDERS + RAY_COLOUR))
    return result


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    parser.add_argument("--twins", nargs="*", default=["wall", "object"], help="shipped fitted demo twins")
    parser.add_argument("--steps", type=int, default=80, help="steps of the short fit (default 80)")
    parser.add_argument("--out", type=Path, help="write the fingerprints to this JSON file")
    parser.add_argument("--compare", type=Path, help="compare with fingerprints written by --out")
    args = parser.parse_args(argv)
    prints = fingerprints(args.twins, args.steps)
    for key, value in prints.items():
        print(f"| {key} | {value[:16]} |")
    if args.out:
        args.out.write_text(json.dumps(prints, indent=1, sort_keys=True))
    if args.compare:
        before = json.loads(args.compare.read_text())
        changed = sorted(k for k in prints if k in before and before[k] != prints[k])
        missing = sorted(set(before) ^ set(prints))
        print(f"{len(prints) - len(changed)} of {len(prints)} items identical; changed: {changed or 'none'}; "
              f"only on one side: {missing or 'none'}")
        return 1 if changed or missing else 0
    return 0


if __name__ == "__main__":
    sys.exit(main())
