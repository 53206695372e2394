"""Realistic ways a change to the shipped ORB could make it worse while still clearing every ``eps``.

Not shipped code: pytest-n2r's test of the regression gate (its ``tests/example/test_regression_gate.py``)
and the gate's power measurement (``gate_power.py``) use them to show that the committed baseline catches
each, and with how many examples.
Each wraps the shipped ``orb`` and returns keypoints as it does (``(N, 2)`` float32 ``(u, v)`` pixels).
"""

from __future__ import annotations

from dataclasses import dataclass

import cv2
import numpy as np

from .detectors import DETECTORS, Detector

__all__ = ["REGRESSIONS", "regression"]


@dataclass(frozen=True)
class HalfResolution:
    """A speed-up that detects on the image downscaled by 2 and scales the coordinates back: keypoints lose
    their sub-pixel accuracy (they fall on a 2-pixel grid) and fine corners disappear."""

    base: Detector

    def __call__(self, rgb: np.ndarray) -> np.ndarray:
        small = cv2.resize(rgb, (rgb.shape[1] // 2, rgb.shape[0] // 2), interpolation=cv2.INTER_AREA)
        return (np.round(self.base(small)) * 2.0).astype(np.float32)


@dataclass(frozen=True)
class CoarseGrid:
    """Keypoints lose their sub-pixel accuracy: snapped to the corner of a ``cell``-pixel grid, as a grid-cell
    non-maximum suppression that returns the cell instead of the corner would."""

    base: Detector
    cell: float = 3.0

    def __call__(self, rgb: np.ndarray) -> np.ndarray:
        return (np.floor(self.base(rgb) / self.cell) * self.cell).astype(np.float32)


@dataclass(frozen=True)
class FewerPoints:
    """A cheaper configuration that keeps half the keypoints (the strongest 250 of 500)."""

    base: Detector

    def __call__(self, rgb: np.ndarray) -> np.ndarray:
        points = self.base(rgb)
        return points[: (len(points) + 1) // 2]


@dataclass(frozen=True)
class DeadRegion:
    """A region-of-interest bug: nothing is detected in the right quarter of the image."""

    base: Detector

    def __call__(self, rgb: np.ndarray) -> np.ndarray:
        points = self.base(rgb)
        return points[points[:, 0] < 0.75 * rgb.shape[1]]


#: name -> the regressed detector (``orb-candidate`` is the configuration proposed for review;
#: ``orb-fast-threshold-25`` a smaller tweak of the shipped one: FAST threshold 20 -> 25, fewer weak corners).
REGRESSIONS = {
    "orb-candidate": DETECTORS["orb-candidate"],
    "orb-half-resolution": HalfResolution(DETECTORS["orb"]),
    "orb-half-the-points": FewerPoints(DETECTORS["orb"]),
    "orb-dead-right-quarter": DeadRegion(DETECTORS["orb"]),
    "orb-fast-threshold-25": Detector("orb", params={**DETECTORS["orb"].params, "fastThreshold": 25}),
    "orb-3px-grid": CoarseGrid(DETECTORS["orb"]),
}


def regression(name: str):
    """A regressed ORB by name (a key of :data:`REGRESSIONS`)."""
    if name not in REGRESSIONS:
        raise KeyError(f"regression {name!r} is not defined; expected one of {sorted(REGRESSIONS)}")
    return REGRESSIONS[name]
