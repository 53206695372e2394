"""A stand-in for a fitted scene with real photos: :class:`~tests.plugin.fakescene.PlaneScene` rendered
through a Gaussian blur of ``blur`` pixels (sigma), as a soft field would, while its held-out views store
the sharp exact render as their "photo". The field floor of a SUT on it is then known in kind: zero for
``blur=0`` (render = photo), growing with the blur.
"""

from __future__ import annotations

import hashlib

import cv2
import numpy as np

from pytest_n2r.scene import SceneView

from .fakescene import PlaneScene


class BlurredPlane(PlaneScene):
    is_exact = False

    def __init__(self, blur: float = 2.0, photos: bool = True, **kwargs):
        super().__init__(**kwargs)
        self.blur = 0.0
        if photos:
            self.views = [SceneView(v.index, v.name, v.camera, v.c2w, v.split,
                                    super(BlurredPlane, self)._render(v.c2w, v.camera, ("rgb",))["rgb"])
                          for v in self.views]
        self.blur = float(blur)
        self.calls = 0

    @property
    def content_hash(self) -> str:
        return hashlib.sha256(f"{super().content_hash}|blur {self.blur}".encode()).hexdigest()

    def _render(self, c2w, camera, outputs):
        out = super()._render(c2w, camera, outputs)
        if self.blur > 0 and "rgb" in out:
            out["rgb"] = cv2.GaussianBlur(out["rgb"], (0, 0), self.blur)
        return out


def corners(rgb: np.ndarray) -> np.ndarray:
    """A deterministic corner detector SUT: up to 200 Shi-Tomasi corners, (N, 2) pixels."""
    gray = cv2.cvtColor(rgb, cv2.COLOR_RGB2GRAY)
    pts = cv2.goodFeaturesToTrack(gray, 200, 0.01, 3)
    return np.zeros((0, 2), np.float32) if pts is None else pts.reshape(-1, 2)


def blurred_plane() -> BlurredPlane:
    return BlurredPlane(blur=2.5, name="blurred", width=160, height=120)


def sharp_plane_field() -> BlurredPlane:
    return BlurredPlane(blur=0.0, name="sharp", width=160, height=120)
