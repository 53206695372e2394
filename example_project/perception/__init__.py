"""perception: the interest-point detectors and image classifiers of a (small, example) robot perception stack."""

from .detectors import DETECTORS, Detector, detector

__all__ = ["DETECTORS", "Detector", "detector"]
