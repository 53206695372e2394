"""Synthetic captures for ingestion tests: a textured room corner ray-cast at known poses.

The scene is three textured squares meeting at the world origin (the planes x = 0, y = 0 and z = 0,
each covering [0, 2] x [0, 2]); cameras sit in the positive octant and look at (0.6, 0.6, 0.6). Images
are exact renders (no lens distortion unless asked), so loaders can be checked against ground truth.
"""

from __future__ import annotations

import json
from dataclasses import dataclass
from pathlib import Path

import cv2
import numpy as np

from pytest_n2r.geometry import Camera, camera_rays, opencv_to_opengl

SIZE = 2.0  # side of each textured square, world units
TEX = 400  # texture resolution, pixels per side


def texture(seed: int) -> np.ndarray:
    """A blob-rich colour texture (SIFT-friendly): noise blurred at several scales, plus discs."""
    rng = np.random.default_rng(seed)
    img = np.zeros((TEX, TEX, 3))
    for sigma, weight in ((1.5, 0.5), (4.0, 1.0), (12.0, 1.0)):
        noise = rng.normal(size=(TEX, TEX, 3))
        img += weight * cv2.GaussianBlur(noise, (0, 0), sigma) * sigma
    img = (img - img.min()) / (img.max() - img.min()) * 255
    for _ in range(60):
        c = tuple(int(x) for x in rng.integers(0, TEX, 2))
        cv2.circle(img, c, int(rng.integers(3, 14)), tuple(float(x) for x in rng.integers(0, 256, 3)), -1)
    return img.astype(np.uint8)


_PLANES = [  # (normal axis, in-plane axes u, v)
    (0, 1, 2),
    (1, 0, 2),
    (2, 0, 1),
]


#: world up of the synthetic captures (-z)
NEG_Z_UP = np.array([0.0, 0.0, -1.0])


def look_at(centre: np.ndarray, target: np.ndarray, up: np.ndarray = NEG_Z_UP) -> np.ndarray:
    """Camera-to-world (OpenCV axes) at ``centre`` looking at ``target``; image-down along ``-up``."""
    z = target - centre
    z = z / np.linalg.norm(z)
    x = np.cross(-up, z)  # x right = down x forward
    x /= np.linalg.norm(x)
    y = np.cross(z, x)
    c2w = np.eye(4)
    c2w[:3, :3] = np.stack([x, y, z], axis=1)
    c2w[:3, 3] = centre
    return c2w


def render(camera: Camera, c2w: np.ndarray, textures: list[np.ndarray]) -> tuple[np.ndarray, np.ndarray]:
    """``(rgb, depth)`` of the corner: H x W x 3 uint8 RGB and z-depth (inf where no plane is hit)."""
    o, d = camera_rays(camera, c2w)
    best = np.full(d.shape[:2], np.inf)
    rgb = np.zeros(d.shape[:2] + (3,), dtype=np.uint8)
    for (n, a, b), tex in zip(_PLANES, textures):
        with np.errstate(divide="ignore", invalid="ignore"):
            t = -o[..., n] / d[..., n]
        p = o + d * t[..., None]
        ok = (t > 0) & (p[..., a] >= 0) & (p[..., a] <= SIZE) & (p[..., b] >= 0) & (p[..., b] <= SIZE) & (t < best)
        map_x = (p[..., a] / SIZE * (TEX - 1)).astype(np.float32)
        map_y = (p[..., b] / SIZE * (TEX - 1)).astype(np.float32)
        sample = cv2.remap(tex, np.nan_to_num(map_x), np.nan_to_num(map_y), cv2.INTER_LINEAR,
                           borderMode=cv2.BORDER_REFLECT)
        rgb[ok] = sample[ok]
        best[ok] = t[ok]
    return rgb, best


@dataclass
class SyntheticCapture:
    root: Path
    images_dir: Path
    names: list[str]
    camera: Camera
    c2ws: list[np.ndarray]
    depths: list[np.ndarray]


def orbit_poses(n: int, radius: float = 4.0, spread_deg: float = 50.0) -> list[np.ndarray]:
    """``n`` cameras on an arc around the corner's diagonal, all looking at (0.6, 0.6, 0.6)."""
    target = np.full(3, 0.6)
    poses = []
    for k in range(n):
        phi = np.radians(45.0 - spread_deg / 2 + spread_deg * k / max(n - 1, 1))
        theta = np.radians(50.0 + 8.0 * np.sin(k))
        centre = radius * np.array([np.sin(theta) * np.cos(phi), np.sin(theta) * np.sin(phi), np.cos(theta)])
        poses.append(look_at(centre, target))
    return poses


#: A camera turned half a turn about its own viewing direction (right-multiplied onto a camera-to-world pose).
HALF_TURN = np.diag([-1.0, -1.0, 1.0, 1.0])


def make_capture(root: Path, n: int = 6, camera: Camera | None = None, seed: int = 0,
                 suffix: str = ".png", upside_down: tuple[int, ...] = ()) -> SyntheticCapture:
    """Render ``n`` views into ``root/images`` (file names ``view_000.png`` ...); the views numbered in
    ``upside_down`` are taken with the camera held upside down (:data:`HALF_TURN`)."""
    camera = camera or Camera(160, 120, 150.0, 150.0, 79.5, 59.5)
    textures = [texture(seed + k) for k in range(3)]
    images_dir = root / "images"
    images_dir.mkdir(parents=True, exist_ok=True)
    names, depths = [], []
    c2ws = [c2w @ HALF_TURN if k in upside_down else c2w for k, c2w in enumerate(orbit_poses(n))]
    for k, c2w in enumerate(c2ws):
        rgb, depth = render(camera, c2w, textures)
        name = f"view_{k:03d}{suffix}"
        cv2.imwrite(str(images_dir / name), cv2.cvtColor(rgb, cv2.COLOR_RGB2BGR))
        names.append(name)
        depths.append(depth)
    return SyntheticCapture(root, images_dir, names, camera, c2ws, depths)


def write_transforms(cap: SyntheticCapture, path: Path | None = None, **overrides) -> Path:
    """A nerfstudio transforms.json for ``cap`` written by hand (not with the code under test)."""
    cam = cap.camera
    meta = {
        "fl_x": cam.fx, "fl_y": cam.fy, "cx": cam.cx + 0.5, "cy": cam.cy + 0.5, "w": cam.width, "h": cam.height,
        "frames": [
            {"file_path": f"images/{name}", "transform_matrix": opencv_to_opengl(c2w).tolist()}
            for name, c2w in zip(cap.names, cap.c2ws)
        ],
    }
    meta.update(overrides)
    path = path or cap.root / "transforms.json"
    path.write_text(json.dumps(meta))
    return path


def distance_to_corner(points: np.ndarray) -> np.ndarray:
    """Distance of each point to the nearest of the three textured squares (inside their extent)."""
    p = np.clip(points, 0.0, SIZE)
    d = np.min(np.abs(points), axis=1)  # distance to the nearest plane through the origin
    outside = np.linalg.norm(points - p, axis=1)
    return np.maximum(d, outside)


# Camera rigs for the up check (pytest_n2r.data.upright), world up +z; benchmarks/upright_rings.py uses them too.


def rolled(c2w: np.ndarray, degrees: float) -> np.ndarray:
    """The camera-to-world pose ``c2w`` turned by ``degrees`` about its own viewing direction (z)."""
    c, s = np.cos(np.radians(degrees)), np.sin(np.radians(degrees))
    return c2w @ np.array([[c, -s, 0, 0], [s, c, 0, 0], [0, 0, 1, 0], [0, 0, 0, 1.0]])


def ring_poses(n: int, rng: np.random.Generator, elevation_deg: tuple[float, float],
               roll_deg: float = 8.0) -> list[np.ndarray]:
    """``n`` cameras around the origin looking at it from ``elevation_deg`` (a range, degrees above the horizon),
    each rolled by up to ``roll_deg`` as a hand does; world up is +z."""
    poses = []
    for k in range(n):
        azimuth, elevation = 2 * np.pi * k / n, np.radians(rng.uniform(*elevation_deg))
        eye = 4.0 * np.array([np.cos(azimuth) * np.cos(elevation), np.sin(azimuth) * np.cos(elevation),
                              np.sin(elevation)])
        poses.append(rolled(look_at(eye, np.zeros(3), up=np.array([0.0, 0.0, 1.0])),
                            rng.uniform(-roll_deg, roll_deg)))
    return poses


def in_a_random_frame(poses: list[np.ndarray], rng: np.random.Generator) -> list[np.ndarray]:
    """The poses in another world frame, as structure from motion is free to choose one."""
    q, r = np.linalg.qr(rng.normal(size=(3, 3)))
    q *= np.sign(np.diag(r))
    world = np.eye(4)
    world[:3, :3], world[:3, 3] = q * np.linalg.det(q), rng.normal(size=3) * 10
    return [world @ p for p in poses]
