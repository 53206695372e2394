"""Interest-point detectors: RGB image in, ``(N, 2)`` float32 keypoints ``(u, v)`` in pixels out.

Images are H×W×3 ``uint8`` **RGB** (what pytest-n2r renders); they are converted to grey before OpenCV
sees them, so the channel order never matters. Keypoint coordinates follow OpenCV: the centre of the
top-left pixel is ``(0, 0)``. Every detector keeps at most ``max_points`` keypoints, the strongest first
(the paper configures its detectors to the 100 strongest; we keep 500, as a visual odometry front end
does).
"""

from __future__ import annotations

import os
from dataclasses import dataclass, field
from typing import Any

import cv2
import numpy as np

__all__ = ["Detector", "DETECTORS", "detector"]


@dataclass(frozen=True)
class Detector:
    """A configured OpenCV detector (``kind`` is ``"orb"``, ``"sift"`` or ``"akaze"``)."""

    kind: str
    max_points: int = 500
    params: dict[str, Any] = field(default_factory=dict)

    def _create(self) -> Any:
        if self.kind == "orb":
            return cv2.ORB_create(nfeatures=self.max_points, **self.params)
        if self.kind == "sift":
            return cv2.SIFT_create(nfeatures=self.max_points, **self.params)
        if self.kind == "akaze":  # OpenCV 5 moved AKAZE to the contrib module xfeatures2d
            create = getattr(cv2, "AKAZE_create", None) or cv2.xfeatures2d.AKAZE_create
            return create(**self.params)
        raise ValueError(f"kind={self.kind!r}; expected 'orb', 'sift' or 'akaze'")

    def __call__(self, rgb: np.ndarray) -> np.ndarray:
        """Keypoints of an RGB image as ``(N, 2)`` float32 pixel coordinates, strongest first."""
        rgb = np.asarray(rgb)
        if rgb.ndim != 3 or rgb.shape[2] != 3 or rgb.dtype != np.uint8:
            raise ValueError(f"expected an H×W×3 uint8 RGB image, got {rgb.dtype} array of shape {rgb.shape}")
        gray = cv2.cvtColor(rgb, cv2.COLOR_RGB2GRAY)
        keypoints = sorted(self._create().detect(gray, None), key=lambda k: -k.response)[: self.max_points]
        return np.array([k.pt for k in keypoints], dtype=np.float32).reshape(-1, 2)

    def __repr__(self) -> str:
        extra = "".join(f", {k}={v!r}" for k, v in sorted(self.params.items()))
        return f"Detector({self.kind!r}, max_points={self.max_points}{extra})"


#: The configurations this project ships. ``orb`` is what the robot runs; ``orb-candidate`` is a proposed
#: cheaper configuration (2 pyramid levels instead of 8 and a higher FAST threshold) that CI must judge.
DETECTORS: dict[str, Detector] = {
    "orb": Detector("orb", params={"scaleFactor": 1.2, "nlevels": 8, "fastThreshold": 20}),
    "orb-candidate": Detector("orb", params={"scaleFactor": 1.2, "nlevels": 2, "fastThreshold": 40}),
    "sift": Detector("sift", params={"contrastThreshold": 0.04, "edgeThreshold": 10}),
    "akaze": Detector("akaze", params={"threshold": 0.001}),
}


def detector(name: str | None = None) -> Any:
    """A shipped detector by name; ``None`` reads ``PERCEPTION_ORB`` (default ``"orb"``), which is how CI
    swaps in a candidate configuration without editing the tests. The names of
    :data:`perception.regressions.REGRESSIONS` are accepted too, to run the suite on a known regression."""
    name = name or os.environ.get("PERCEPTION_ORB", "orb")
    if name in DETECTORS:
        return DETECTORS[name]
    from .regressions import REGRESSIONS

    if name not in REGRESSIONS:
        raise KeyError(f"detector {name!r} is not configured; expected one of {sorted({*DETECTORS, *REGRESSIONS})}")
    return REGRESSIONS[name]
