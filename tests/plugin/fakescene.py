"""A tiny exact scene for plugin tests: a textured square plane seen by a row of cameras.

World frame = the OpenCV camera frame of the middle view: the plane is ``Z = depth`` with ``|X|, |Y| <=
half_width``; rays that miss it have opacity 0. Rendering is analytic (exact z-depth, no sampling), fast
at the tiny sizes tests use, and counts its calls: ``scene.calls`` in-process, and one line per render in
the file named by ``$N2R_FAKE_RENDER_LOG`` (so tests can count renders in pytester and xdist workers).
"""

from __future__ import annotations

import hashlib
import os
import time

import numpy as np

from pytest_n2r.geometry import Camera, camera_rays
from pytest_n2r.scene import Scene, SceneView

RENDER_LOG_ENV = "N2R_FAKE_RENDER_LOG"


class PlaneScene(Scene):
    """``texture="checker"``: a two-scale coloured checkerboard (corners for keypoint detectors);
    ``texture="ramp"``: red/green encode the world X coordinate of the hit point in 16 bits
    (``X = (256 R + G) / 65535 * 2 half_width - half_width``) and blue carries a checkerboard."""

    def __init__(self, name: str = "plane", texture: str = "checker", n_views: int = 4, width: int = 96,
                 height: int = 72, depth: float = 2.0, half_width: float = 2.0, spread: float = 0.3):
        self.name = name
        self.texture = texture
        self.depth = float(depth)
        self.half_width = float(half_width)
        self.reference_length = float(depth)
        camera = Camera(width, height, 0.8 * width, 0.8 * width, (width - 1) / 2, (height - 1) / 2)
        self.views = []
        for i, y in enumerate(np.linspace(-spread, spread, n_views) if n_views > 1 else [0.0]):
            c2w = np.eye(4)
            c2w[1, 3] = y  # views differ in height only, so the ramp's X at the image centre is 0
            self.views.append(SceneView(i, f"view{i}", camera, c2w, split="heldout" if i % 2 else "train"))
        self.calls = 0

    @property
    def content_hash(self) -> str:
        spec = f"{self.texture}|{self.depth}|{self.half_width}"
        return hashlib.sha256(spec.encode()).hexdigest()

    def _render(self, c2w, camera, outputs):
        self.calls += 1
        log = os.environ.get(RENDER_LOG_ENV)
        if log:
            with open(log, "a") as f:
                f.write(f"{os.getpid()}\n")
        origins, dirs = camera_rays(camera, c2w)
        with np.errstate(divide="ignore", invalid="ignore"):
            t = (self.depth - origins[..., 2]) / dirs[..., 2]
        hit_ok = np.isfinite(t) & (t > 0)
        t = np.where(hit_ok, t, 1.0)
        X = origins[..., 0] + t * dirs[..., 0]
        Y = origins[..., 1] + t * dirs[..., 1]
        inside = hit_ok & (np.abs(X) <= self.half_width) & (np.abs(Y) <= self.half_width)
        out = {}
        if "rgb" in outputs:
            out["rgb"] = np.where(inside[..., None], self._texture(X, Y), 0).astype(np.uint8)
        if "depth" in outputs:
            # camera_rays directions have camera-z = 1, so the ray parameter t is the z-depth
            out["depth"] = np.where(inside, t, 1e3).astype(np.float32)
        if "opacity" in outputs:
            out["opacity"] = inside.astype(np.float32)
        return out

    def _texture(self, X, Y):
        coarse = (np.floor(X / 0.5) + np.floor(Y / 0.5)) % 2
        fine = (np.floor(X / 0.125) + np.floor(Y / 0.125)) % 2
        if self.texture == "ramp":
            u = np.round((X + self.half_width) / (2 * self.half_width) * 65535).astype(np.int64)
            return np.stack([u >> 8, u & 255, 60 + 140 * coarse], axis=-1)
        r = 40 + 150 * coarse + 50 * fine
        g = 200 - 140 * coarse
        b = 90 + 120 * fine
        return np.stack([r, g, b], axis=-1)


def plane() -> PlaneScene:
    return PlaneScene()


def ramp() -> PlaneScene:
    return PlaneScene(name="ramp", texture="ramp")


def decode_ramp_x(rgb: np.ndarray, half_width: float = 2.0) -> np.ndarray:
    """World X of each pixel of a ``ramp`` render (inverse of the red/green encoding)."""
    u = rgb[..., 0].astype(np.int64) * 256 + rgb[..., 1].astype(np.int64)
    return u / 65535 * 2 * half_width - half_width


class SlowPlaneScene(PlaneScene):
    """:class:`PlaneScene` whose renders sleep ``first_s`` seconds on the first call (as a kernel's compilation)
    and ``later_s`` on every later one (a renderer kind of its own)."""

    def __init__(self, first_s: float, later_s: float) -> None:
        super().__init__(name="slow-plane")
        self.first_s, self.later_s = first_s, later_s

    def _render(self, c2w, camera, outputs):
        time.sleep(self.first_s if self.calls == 0 else self.later_s)
        return super()._render(c2w, camera, outputs)


def slow_first_render() -> SlowPlaneScene:
    return SlowPlaneScene(first_s=3.0, later_s=0.0)


def slow_later_renders() -> SlowPlaneScene:
    return SlowPlaneScene(first_s=0.0, later_s=3.0)
