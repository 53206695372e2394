"""The two built-in demo scenes, modelled on the paper's two missions.

- ``wall`` (AUV wall inspection): a harbour wall of brick with smooth relief and patches of marine growth,
  a rusty pipe along it and a gravel seabed, in open water; the camera moves along the wall in two rows,
  2.2 units away, like an inspection drone.
- ``object`` (UAV vehicle inspection): a delivery van with pictures on its sides and back, two crates,
  on grass with a gravel road under the sky; the camera circles the van at a fixed height, looking at it.

World frame: z up, scene units are metres (``metres_per_unit = 1``). Both trajectories have 48 views of
480×270 pixels with a 60° horizontal field of view; every 8th view is held out (object: 0, 8, ...; wall:
4, 12, ..., never the end of a row).
"""

from __future__ import annotations

import math
from collections.abc import Callable

import numpy as np
from numba import njit

from ..data.capture import heldout_split
from ..geometry import Camera
from ..scene.base import SceneView
from .exact import GroundTruthScene
from .materials import Blend, Flat, Poster, Radial, Textured
from .portable_math import cos, norm3, sin, tan
from .primitives import Box, Cylinder, Disc, Group, ReliefWall
from .textures import Texture

__all__ = ["SCENES", "build_scene", "look_at", "default_camera"]

N_VIEWS = 48


def default_camera(width: int = 480, height: int = 270, hfov_deg: float = 60.0) -> Camera:
    """A pinhole camera with square pixels, principal point at the image centre (OpenCV pixels)."""
    f = 0.5 * width / tan(math.radians(hfov_deg) / 2)
    return Camera(width, height, f, f, (width - 1) / 2, (height - 1) / 2)


#: world up of the demo scenes (+z)
Z_UP = np.array([0.0, 0.0, 1.0])


def look_at(eye: np.ndarray, target: np.ndarray, up: np.ndarray = Z_UP) -> np.ndarray:
    """Camera-to-world pose (OpenCV axes) at ``eye`` looking at ``target``, image 'up' towards world ``up``;
    the same bits on every machine (:mod:`.portable_math`)."""
    eye, target = np.asarray(eye, float), np.asarray(target, float)
    z = target - eye
    z /= norm3(z)
    x = np.cross(z, up)
    x /= norm3(x)
    y = np.cross(z, x)
    c2w = np.eye(4)
    c2w[:3, 0], c2w[:3, 1], c2w[:3, 2], c2w[:3, 3] = x, y, z, eye
    return c2w


@njit(cache=True, error_model="numpy")
def _smoothstep(lo: float | np.ndarray, hi: float | np.ndarray, x: np.ndarray) -> np.ndarray:
    """Smooth 0 → 1 between ``lo`` and ``hi`` (numpy ufuncs only: masks also run compiled, on floats; no
    zero-division check, ``lo < hi``, so that a loop over compiled masks vectorizes)."""
    s = np.minimum(np.maximum((x - lo) / (hi - lo), 0.0), 1.0)
    return s * s * (3 - 2 * s)


def _views(poses: list[np.ndarray], camera: Camera, prefix: str, heldout_first: int = 0) -> list[SceneView]:
    """The trajectory's views; every 8th from ``heldout_first`` is held out."""
    splits = heldout_split(len(poses), first=heldout_first)
    return [
        SceneView(index=i, name=f"{prefix}_{i:03d}.png", camera=camera, c2w=c2w, split=splits[i])
        for i, c2w in enumerate(poses)
    ]


# -- wall ------------------------------------------------------------------------------------------------
def _growth_mask(a: np.ndarray, b: np.ndarray) -> np.ndarray:
    """Where marine growth covers the wall (``a`` = x, ``b`` = -z on the wall face): soft-edged patches."""
    n = 0.5 + 0.3 * np.sin(1.3 * a + 0.5) * np.sin(1.9 * b + 0.2) + 0.2 * np.sin(3.7 * a + 1.0) * np.sin(2.9 * b + 2.0)
    n = n + 0.08 * np.sin(11.0 * a + 0.3) * np.sin(9.0 * b + 1.7)
    return _smoothstep(0.5, 0.65, n)


def wall_scene() -> GroundTruthScene:
    """The AUV wall-inspection scene (see the module docstring)."""
    brick = Texture.photo("brick", tint=(0.95, 0.85, 0.72), contrast=1.6, gain=0.95, quarter_turns=1)
    growth = Texture.photo("grass", tint=(0.62, 0.66, 0.30), contrast=1.5, gain=0.75)
    wall_material = Blend(Textured(brick, 200.0), Textured(growth, 260.0, (0.3, 0.1)), _growth_mask, "growth-v1")
    wall = ReliefWall(
        y0=0.0, extent=(-8.0, 8.0, -1.6, 2.6), depth=0.15,
        waves=((0.25, 1.7, 0.3, 2.3, 1.1), (0.15, 4.1, 1.3, 3.3, 0.2), (0.1, 7.3, 2.1, 6.1, 0.7)),
        material=wall_material,
    )
    rust = Texture.photo("gravel", tint=(0.75, 0.45, 0.25), contrast=1.4, gain=0.9)
    pipe = Cylinder((0.0, -0.45, 1.45), "x", 0.18, 7.5, Textured(rust, 300.0), Flat((0.3, 0.2, 0.15)))
    sand = Texture.photo("gravel", tint=(0.85, 0.80, 0.62), contrast=1.3)
    seabed = Disc(-1.6, 14.0, Textured(sand, 220.0), centre=(0.0, -5.0))

    camera = default_camera()
    poses = []
    per_row = N_VIEWS // 2
    for row, (z, pitch_drop) in enumerate(((1.0, 0.15), (0.1, 0.55))):
        for k in range(per_row):
            s = k / (per_row - 1)
            x = -3.0 + 6.0 * (s if row == 0 else 1 - s)
            i = row * per_row + k
            eye = np.array([x, -2.2 + 0.15 * sin(0.9 * i), z + 0.08 * sin(1.7 * i)])
            target = np.array([x + 0.35 * sin(0.6 * i + 0.4), 0.0, z - pitch_drop])
            poses.append(look_at(eye, target))
    # Held out: views 4, 12, ..., each with captured views on both sides. A row's end (views 0 and 24) sees
    # a stretch of wall that no other view sees, where a field can only guess, whatever its quality.
    return GroundTruthScene(
        "wall", [wall, pipe, seabed], _views(poses, camera, "wall", heldout_first=4),
        light=(0.3, -1.0, 0.9), ambient=0.35, background=(0.05, 0.22, 0.28), far=30.0,
        reference_length=2.158607831570264,  # median_train_depth(), tests/demo/test_ground_truth.py
    )


# -- object ----------------------------------------------------------------------------------------------
def _road_mask(a: np.ndarray, b: np.ndarray) -> np.ndarray:
    """A gravel road along x under the van (``a`` = x, ``b`` = y on the ground), with a ragged edge."""
    edge = 2.4 + 0.35 * np.sin(0.7 * a + 0.3) + 0.15 * np.sin(2.3 * a + 1.1)
    return 1.0 - _smoothstep(edge - 0.4, edge + 0.4, np.abs(b + 0.2 * np.sin(0.25 * a)))


def _glass() -> Texture:
    """A dark window pane: a vertical gradient with a lighter diagonal reflection band."""
    t, s = np.meshgrid(np.linspace(0, 1, 32), np.linspace(0, 1, 64), indexing="ij")
    base = 0.08 + 0.12 * (1 - t)
    band = 0.18 * np.exp(-(((s - 0.35) - 0.6 * (t - 0.5)) ** 2) / 0.01)
    rgb = np.stack([base + band, base + 0.03 + band, base + 0.08 + band], axis=-1)
    return Texture(rgb.astype(np.float32), wrap="clamp")


def object_scene() -> GroundTruthScene:
    """The UAV vehicle-inspection scene (see the module docstring)."""
    grass = Texture.photo("grass", tint=(0.55, 0.75, 0.35), contrast=1.3, gain=0.85)
    gravel = Texture.photo("gravel", tint=(0.80, 0.76, 0.68), contrast=1.2)
    ground = Disc(0.0, 25.0, Blend(Textured(grass, 256.0), Textured(gravel, 256.0), _road_mask, "road-v1"))

    white = Flat((0.86, 0.86, 0.83))
    red = Flat((0.70, 0.12, 0.09))
    glass = _glass()
    coffee = Texture.photo("coffee", wrap="clamp")
    cat = Texture.photo("chelsea", wrap="clamp")
    cargo = Box((-2.2, -1.0, 0.75), (0.6, 1.0, 2.6), {
        "*": white,
        "-y": Poster(white, coffee, (-2.0, -2.5, 0.4, -0.9)),
        "+y": Poster(white, coffee, (-0.4, -2.5, 2.0, -0.9)),
        "-x": Poster(white, cat, (-0.8, -2.35, 0.8, -1.28)),
    })
    cabin = Box((0.6, -0.95, 0.75), (2.2, 0.95, 2.0), {
        "*": red,
        "+x": Poster(red, glass, (-0.85, -1.9, 0.85, -1.35)),
        "-y": Poster(red, glass, (1.2, -1.9, 2.05, -1.4)),
        "+y": Poster(red, glass, (-2.05, -1.9, -1.2, -1.4)),
    })
    chassis_tex = Texture.photo("gravel", tint=(0.25, 0.25, 0.27), contrast=1.5)
    chassis = Box((-2.2, -0.95, 0.35), (2.2, 0.95, 0.75), {"*": Textured(chassis_tex, 300.0)})
    tyre = Texture.photo("gravel", tint=(0.16, 0.16, 0.17), contrast=1.6)
    hub = Radial((0.2, 0.25), ((0.72, 0.72, 0.74), (0.25, 0.25, 0.26)), Flat((0.08, 0.08, 0.09)))
    wheels = [
        Cylinder((x, y, 0.42), "y", 0.42, 0.15, Textured(tyre, 300.0), hub)
        for x in (-1.45, 1.45) for y in (-0.85, 0.85)
    ]
    wood = Texture.photo("gravel", tint=(0.72, 0.52, 0.30), contrast=1.5)
    crates = [
        Box((3.6, 2.0, 0.0), (4.4, 2.8, 0.8), {"*": Textured(wood, 300.0)}),
        Box((-4.6, -3.0, 0.0), (-3.8, -2.2, 0.6), {"*": Textured(wood, 300.0, (0.3, 0.7))}),
    ]

    camera = default_camera()
    poses = []
    for i in range(N_VIEWS):
        angle = 2 * math.pi * i / N_VIEWS + 0.1
        radius = 7.5 + 0.3 * sin(3.1 * i)
        eye = np.array([radius * cos(angle), radius * sin(angle), 3.2 + 0.15 * sin(1.3 * i)])
        target = np.array([0.2 * sin(0.7 * i), 0.2 * cos(0.9 * i), 1.0])
        poses.append(look_at(eye, target))
    return GroundTruthScene(
        "object",
        [ground, Group((-2.3, -1.1, -0.01), (2.3, 1.1, 2.7), (cargo, cabin, chassis, *wheels)),
         Group((3.5, 1.9, -0.01), (4.5, 2.9, 0.9), (crates[0],)),
         Group((-4.7, -3.1, -0.01), (-3.7, -2.1, 0.7), (crates[1],))],
        _views(poses, camera, "object"),
        light=(0.5, 0.35, 1.0), ambient=0.45, background=(0.62, 0.75, 0.90), far=60.0,
        reference_length=6.983797794055911,  # median_train_depth(), tests/demo/test_ground_truth.py
    )


#: Scene name -> builder, in the order ``n2r demo list`` shows them.
SCENES: dict[str, Callable[[], GroundTruthScene]] = {"wall": wall_scene, "object": object_scene}


def build_scene(name: str) -> GroundTruthScene:
    """Build the named scene (see :data:`SCENES`)."""
    return SCENES[name]()
