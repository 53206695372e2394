"""Systems under test for ``n2r study``: built-in OpenCV detectors, or any ``module:attribute`` callable.

A SUT maps an RGB ``uint8`` image (H×W×3) to either keypoints (an ``(N, 2)`` array of pixel coordinates,
or a list of ``cv2.KeyPoint``) — a *detector* — or a 1-D score vector (probabilities or logits) — a
*classifier*. The kind decides which metrics the study applies (:data:`METRICS_BY_KIND`); it is read from the
output on a probe image, or given (``--sut-kind``) where the output's shape cannot say: ``(1, K)`` is one
keypoint or a batch of one score vector.
"""

from __future__ import annotations

import importlib
import os
import sys
from collections.abc import Callable
from dataclasses import dataclass
from typing import Any, Literal

import numpy as np

from ..errors import InvalidArgument, InvalidType
from ..metrics import Metric, class_invariance, cosine_similarity, interest_point_spread, l2_norm, repeatability

__all__ = ["SUT", "BUILTIN_SUTS", "KINDS", "resolve_sut", "check_points", "METRICS_BY_KIND",
           "SAME_POSE_METRICS_BY_KIND"]

Kind = Literal["detector", "classifier"]

#: The paper's metrics for each kind of SUT (name → metric with the paper's parameters).
METRICS_BY_KIND: dict[str, Callable[[], dict[str, Metric]]] = {
    "detector": lambda: {"repeatability": repeatability(px=2.0), "ip_spread": interest_point_spread()},
    "classifier": lambda: {
        "cosine": cosine_similarity(), "l2": l2_norm(), "class_invariance": class_invariance(),
    },
}

#: The same metrics for two images of one pose: a reference photo and the render there (the paper's τ0, the
#: reality-to-field shift). The detectors' map points as the paper does, by the homography between the two
#: cameras, the identity at one pose, so every point counts; a depth mapping would leave out of both sides the
#: points where the field rendered nothing (opacity < 0.5), and a field that left half the photo empty would
#: score as if that half were right (a photo with 40 points, the render with the 20 of its left half and nothing on
#: the right: interest-point spread 1.0 by depth, 0.515 by the identity; repeatability, matches over the smaller
#: count, 1.0 by both).
SAME_POSE_METRICS_BY_KIND: dict[str, Callable[[], dict[str, Metric]]] = {
    "detector": lambda: {"repeatability": repeatability(px=2.0, mapping="homography"),
                         "ip_spread": interest_point_spread(mapping="homography")},
    "classifier": METRICS_BY_KIND["classifier"],
}


def _strongest(keypoints: Any, points: int) -> list:
    """The ``points`` keypoints of largest ``response``; ties broken by position (``y``, then ``x``, pixels), then
    size, angle and octave, so the choice depends on the points found, not on the order OpenCV lists them in."""
    ranked = sorted(keypoints, key=lambda k: (-k.response, k.pt[1], k.pt[0], k.size, k.angle, k.octave))
    return ranked[:points]


def _opencv_detector(make: Callable[[], Any], points: int | None = None) -> Callable[[np.ndarray], np.ndarray]:
    """A detector returning ``(N, 2)`` pixel coordinates (x, y); with ``points``, only the ``points`` keypoints of
    largest response (:func:`_strongest`), else every keypoint ``make()``'s feature detects."""
    import cv2

    feature = make()

    def detect(rgb: np.ndarray) -> np.ndarray:
        keypoints = feature.detect(cv2.cvtColor(rgb, cv2.COLOR_RGB2GRAY), None)
        if points is not None:
            keypoints = _strongest(keypoints, points)
        return np.array([k.pt for k in keypoints], dtype=np.float32).reshape(-1, 2)

    return detect


def check_points(points: object) -> int:
    """``points`` (``--points``) as an ``int`` >= 1, else :class:`~pytest_n2r.errors.InvalidArgument`."""
    if isinstance(points, bool) or not isinstance(points, (int, np.integer)) or points < 1:
        raise InvalidArgument(f"--points {points!r}: expected a positive integer, the number of highest-response "
                              f"points each built-in detector keeps per image (the paper's: 100)")
    return int(points)


def _builtin(name: str, points: int | None = None) -> Callable[[np.ndarray], np.ndarray]:
    """Built-in detector ``name``: with ``points=None`` as it always was (ORB and SIFT capped at 1000 points by
    OpenCV, AKAZE uncapped; the fidelity report and ``n2r info --shift`` publish numbers with these), else the
    ``points`` highest-response keypoints per image, as the paper configured its detectors (100)."""
    import cv2

    # "Configured to produce N highest-confidence points" (the paper, internal validity): OpenCV's own knob for
    # that is nfeatures, which is what ORB and SIFT are given, and every detector's keypoints then go through the
    # same filter, the N of largest response (_strongest), because nfeatures alone does not give exactly that:
    # - SIFT ranks all its keypoints by response (contrast) and keeps the best nfeatures, but also every keypoint
    #   tied with the N-th, so it can return more than N; the filter trims the ties, and SIFT's N are then the N
    #   of largest response of its uncapped detection.
    # - ORB shares nfeatures out over its 8 pyramid levels (geometrically by scale) and keeps each level's best by
    #   Harris score: at most N in all, fewer where a coarse level finds fewer corners than its share (43 of 50 on
    #   demo:wall at 320 pixels, 100 of 100 at 480); the filter keeps them all. These are the points of ORB
    #   configured for N, as the paper describes its setup, not the global top N of a 1000-point ORB, whose
    #   levels would share the N otherwise.
    # - AKAZE has no cap in OpenCV: the filter alone keeps the N of largest response of its uncapped detection.
    cap = 1000 if points is None else points
    makers = {
        "orb": lambda: cv2.ORB.create(nfeatures=cap),
        "sift": lambda: cv2.SIFT.create(nfeatures=cap),
        # OpenCV 5 moved AKAZE to the contrib module xfeatures2d (its stubs name it there, 4's in cv2)
        "akaze": lambda: (getattr(cv2, "AKAZE_create", None)
                          or cv2.xfeatures2d.AKAZE_create)(),  # type: ignore[attr-defined, unused-ignore]
    }
    return _opencv_detector(makers[name], points)


#: Built-in SUT names (OpenCV detectors with default settings; by default at most 1000 points for ORB and SIFT and
#: AKAZE uncapped, with ``points=N`` the N highest-response points for all three).
BUILTIN_SUTS: dict[str, Kind] = {"orb": "detector", "sift": "detector", "akaze": "detector"}


@dataclass(frozen=True)
class SUT:
    """A named SUT with its kind and the metrics the study applies to it."""

    name: str
    kind: Kind
    fn: Callable[[np.ndarray], Any]
    #: Keypoints a built-in detector keeps per image (its ``points`` highest-response ones); None: not capped by
    #: the study (an imported SUT, or a built-in with OpenCV's caps).
    points: int | None = None

    def metrics(self) -> dict[str, Metric]:
        """The metrics between a source view and a follow-up at another pose (:data:`METRICS_BY_KIND`)."""
        return METRICS_BY_KIND[self.kind]()

    def same_pose_metrics(self) -> dict[str, Metric]:
        """The metrics between two images of one pose, a reference photo and its render
        (:data:`SAME_POSE_METRICS_BY_KIND`)."""
        return SAME_POSE_METRICS_BY_KIND[self.kind]()


#: The kinds of SUT (``--sut-kind``).
KINDS: tuple[Kind, ...] = ("detector", "classifier")


def _kind_of(output: Any, name: str, kind: Kind | None = None) -> Kind:
    """The kind of SUT whose output on the probe image is ``output``: ``kind`` when given (checked against the
    output), else what the output's shape says; an output of shape ``(1, K)`` is either one keypoint or a batch
    of one score vector, and needs ``kind``."""
    keypoint_list = isinstance(output, (list, tuple)) and (not output or hasattr(output[0], "pt"))
    arr = np.asarray([]) if keypoint_list else np.asarray(output)
    looks_detector = keypoint_list or (arr.ndim == 2 and arr.shape[1] >= 2)
    looks_classifier = not keypoint_list and (arr.ndim == 1 or (arr.ndim == 2 and arr.shape[0] == 1))
    shape = "a list of keypoints" if keypoint_list else f"shape {arr.shape}"
    if kind is not None:
        fits = looks_detector if kind == "detector" else looks_classifier
        if not fits:
            expected = ("keypoints (N, 2) or a list of cv2.KeyPoint" if kind == "detector"
                        else "a score vector (C,) or a batch of one (1, C)")
            raise InvalidType(f"--sut {name} is a {kind} (--sut-kind), but its output on the probe image has "
                              f"{shape}; a {kind} returns {expected}")
        return kind
    if looks_detector and looks_classifier:
        raise InvalidType(
            f"--sut {name}: its output on the probe image has shape {arr.shape}, which is either one keypoint of a "
            f"detector (N, {arr.shape[1]}) or a classifier's batch of one score vector (1, C); say which with "
            f"--sut-kind {name}=detector or --sut-kind {name}=classifier (kind= of resolve_sut)"
        )
    if looks_detector:
        return "detector"
    if looks_classifier:
        return "classifier"
    raise InvalidType(
        f"--sut {name}: output of shape {arr.shape} is neither keypoints (N, 2) nor a score vector (C,)"
    )


def _working_folder_importable() -> None:
    """The working folder on the module path, as for a ``module:function`` scene (``n2r study --sut mysut:detect``
    with ``mysut.py`` there); appended, so a ``cv2.py`` there cannot shadow the packages imported later."""
    cwd = os.getcwd()
    if cwd not in sys.path and "" not in sys.path:
        sys.path.append(cwd)


def resolve_sut(spec: str, probe: np.ndarray | None, kind: Kind | None = None, *,
                points: int | None = None) -> SUT:
    """A SUT from a built-in name (``orb``, ``sift``, ``akaze``) or ``package.module:attribute``.

    ``probe`` (an RGB image; ``None`` will do for a built-in SUT) is run once to tell detectors from classifiers
    for imported SUTs; ``kind`` (``"detector"`` or ``"classifier"``) says which where the output cannot (shape
    ``(1, K)``: one keypoint, or a batch of one score vector). ``points`` (``n2r study --points``): a built-in
    detector keeps the ``points`` keypoints of largest response per image (see :func:`_builtin`); None keeps OpenCV's
    caps (1000 for ORB and SIFT, none for AKAZE). An imported SUT runs as given, whatever ``points``.
    """
    if not isinstance(spec, str):
        raise InvalidType(f"--sut {spec!r} must be a str: a built-in SUT ({', '.join(BUILTIN_SUTS)}) or "
                          "'module:attribute'")
    if points is not None:
        points = check_points(points)
    if kind is not None and kind not in KINDS:
        raise InvalidArgument(f"--sut-kind {spec}={kind!r}; expected one of {', '.join(KINDS)}")
    if spec in BUILTIN_SUTS:
        if kind is not None and kind != BUILTIN_SUTS[spec]:
            raise InvalidArgument(f"--sut-kind {spec}={kind}: the built-in {spec} is a {BUILTIN_SUTS[spec]}")
        return SUT(spec, BUILTIN_SUTS[spec], _builtin(spec, points), points)
    if ":" not in spec:
        raise InvalidArgument(
            f"--sut {spec!r} is not a built-in SUT ({', '.join(BUILTIN_SUTS)}) nor 'module:attribute'"
        )
    module_name, _, attr = spec.partition(":")
    if not all(part.isidentifier() for part in module_name.split(".")) or not attr.isidentifier():
        raise InvalidArgument(
            f"--sut {spec!r} is not 'module:attribute': expected an absolute module name (package.module) before "
            "the ':' and the name of a callable in it after (e.g. mysut:detect)"
        )
    _working_folder_importable()
    try:
        fn = getattr(importlib.import_module(module_name), attr)
    except (ImportError, AttributeError) as exc:
        raise InvalidArgument(f"--sut {spec!r}: cannot import {attr!r} from {module_name!r} ({exc})") from None
    if not callable(fn):
        raise InvalidType(f"--sut {spec!r} is a {type(fn).__name__}, not a callable image -> output")
    if probe is None:
        raise InvalidArgument(f"--sut {spec!r} is imported: probe=None; expected an RGB image to run it on once "
                              "(its output tells a detector from a classifier)")
    return SUT(attr, _kind_of(fn(probe), spec, kind), fn)
