"""Interest-point detector metrics: repeatability and interest-point spread.

SUT output: keypoints as an ``(N, 2)`` array of ``(u, v)`` pixels (OpenCV pixel centres), an
``(N, K >= 2)`` array whose extra columns are ignored, or a sequence of ``cv2.KeyPoint``.

Both metrics compare the points in the **follow-up image frame**: source points are mapped into it
(:mod:`~pytest_n2r.metrics.correspondence`), and only points *visible in both views* count: source points
that map into the follow-up view unoccluded, and follow-up points that map back into the source view.

Edge cases (``n1``, ``n2`` = visible source / follow-up points):

- the SUT found no keypoint in either view: *undefined* (``valid=False``, see
  :class:`~pytest_n2r.metrics.base.MetricResult`): the SUT gave nothing to compare, which is never a
  perfect score;
- ``n1 = n2 = 0`` otherwise: no keypoint lies in the region both views see, so the pair tests nothing:
  undefined as well;
- either point set covers at least :data:`MAX_COVERAGE` (90 %) of its image with discs of the metric's
  tolerance (``px``, ``radius``): undefined, because then any point set would match by chance (a dense grid
  of points, the same on every image, scores about 1 whatever the content);
- exactly one of ``n1``, ``n2`` is 0: score 0 (points found in the common region have no counterpart).

Keypoint coordinates are rounded to 1e-6 px, and keypoints at the same coordinates (a multi-scale
detector reporting one location at several octaves) count once.
"""

from __future__ import annotations

import weakref
from abc import abstractmethod
from collections import OrderedDict
from dataclasses import dataclass, field
from typing import Any, Literal

import numpy as np

from .._validation import check_positive, check_range
from ..errors import InvalidArgument, InvalidType
from ..geometry import Camera
from ..render.view import RenderedView
from ._matching import maximum_matching, mutual_nearest
from ._outputs import as_keypoints
from .base import Metric, MetricResult
from .correspondence import (
    DEFAULT_DEPTH_TOLERANCE,
    DEFAULT_MIN_OPACITY,
    DepthMapping,
    HomographyMapping,
    LiftedPoints,
    MappedPoints,
    PointMapping,
    check_plane,
)
from .coverage import DISC_SLACK, capped_radius, coverage_bound, coverage_mask

__all__ = [
    "Repeatability", "InterestPointSpread", "KeypointCorrespondences", "repeatability", "interest_point_spread",
    "coverage_mask", "MAX_COVERAGE",
]

Mapping = Literal["depth", "homography"]
_MAPPINGS = ("depth", "homography")
_FORMS = ("schmid", "symmetric")
_MATCHINGS = ("maximum", "mutual")
#: Share of an image that one view's points may cover with discs of the metric's tolerance before the
#: metric is undefined (chance matches). Measured on the demo scenes at 320×180 with discs of radius 8 px:
#: shipped OpenCV detectors cover at most 0.67 (SIFT on the wall), ORB 0.35; a grid of points every 8 px
#: covers 1.0 and scored 0.99 interest-point spread under any motion before this rule.
MAX_COVERAGE = 0.9
#: The least disc radius (pixels) that holds a pixel centre wherever its point lies in the image: √0.5, the
#: distance from the middle of four pixel centres to each.
_ALWAYS_HOLDS = float(np.sqrt(0.5))
#: Source renders whose lifted keypoints a metric keeps (least recently used first out): a relation's
#: examples draw their source from a few views, and a warm main job's 714 keypoint pairs come from far fewer.
_KEPT_SOURCES = 32


def _unique_rows(points: np.ndarray) -> np.ndarray:
    """``points`` rounded to 1e-6 px, without duplicate rows, sorted by ``u`` then ``v``.

    Rounding first means two detections closer than round-off count once, so mapping round-off
    (~1e-12 px) can never swap which of them is whose nearest neighbour. Faster than ``np.unique``.
    """
    with np.errstate(over="ignore"):  # past 1.8e302 px rounding overflows: such points (far off) stay as given
        rounded = np.round(points, 6)
    points = np.where(np.isfinite(rounded), rounded, points)
    if len(points) < 2:
        return points
    sorted_points = points[np.lexsort((points[:, 1], points[:, 0]))]
    keep = np.r_[True, np.any(sorted_points[1:] != sorted_points[:-1], axis=1)]
    return sorted_points[keep]


@dataclass(frozen=True)
class KeypointCorrespondences:
    """The keypoints of a pair as a keypoint metric sees them, for overlays and debugging.

    ``source`` ``(n_s, 2)`` and ``follow`` ``(n_f, 2)`` are the distinct keypoints (rounded to 1e-6 px) in
    their own images; ``source_in_follow`` ``(n_s, 2)`` are the source points mapped into the follow-up
    image (NaN where not visible in both views); ``source_visible`` / ``follow_visible`` say which points
    count; ``matches`` ``(M, 2)`` holds index pairs ``(i, j)`` into ``source`` / ``follow`` of the points
    matched within the tolerance (empty for metrics that do not match points). With the depth
    mapping ``source`` is read-only: the metric keeps it for later pairs on the same (cached) source render.
    """

    source: np.ndarray
    follow: np.ndarray
    source_in_follow: np.ndarray
    source_visible: np.ndarray
    follow_visible: np.ndarray
    matches: np.ndarray
    rejected: dict[str, int] = field(default_factory=dict)


class _KeypointMetric(Metric):
    """Shared machinery: parse keypoints, map them between the views, apply the edge-case rules."""

    def __init__(
        self, mapping: Mapping, plane: tuple[np.ndarray, float] | None, min_opacity: float,
        depth_tolerance: float,
    ) -> None:
        if mapping not in _MAPPINGS:
            raise InvalidArgument(f"mapping={mapping!r}; expected one of {_MAPPINGS}")
        if plane is not None and mapping != "homography":
            raise InvalidArgument(f"plane={plane!r} is only used with mapping='homography', not {mapping!r}")
        self.mapping = mapping
        self.plane = check_plane(plane)
        self.min_opacity = check_range("min_opacity", min_opacity, 0.0, 1.0)
        self.depth_tolerance = check_range("depth_tolerance", depth_tolerance, 0.0)
        self.needs = ("depth", "opacity") if mapping == "depth" else ()
        self._kept: OrderedDict[tuple[Any, ...], tuple[Any, ...]] = OrderedDict()

    def point_mapping(self, source: Any, follow: Any) -> PointMapping:
        """The mapping between the two views this metric was configured with."""
        for name, view in (("source", source), ("follow", follow)):
            if not isinstance(view, RenderedView):
                raise InvalidType(
                    f"{self.name} needs the {name} RenderedView to map points between the views, "
                    f"got {type(view).__name__}"
                )
        if self.mapping == "depth":
            return DepthMapping(source, follow, min_opacity=self.min_opacity, depth_tolerance=self.depth_tolerance)
        return HomographyMapping.from_views(source, follow, self.plane)

    def correspondences(self, out_source: Any, out_follow: Any, source: Any, follow: Any) -> KeypointCorrespondences:
        """Which keypoints count, where the source points land in the follow-up image, and (for
        repeatability) which ones match: what :meth:`compute` scores, for overlays."""
        raw = as_keypoints(out_source, "source")
        # exact duplicates (one location reported at several scales) are one detection
        q = _unique_rows(as_keypoints(out_follow, "follow-up"))
        if len(raw) == 0 and len(q) == 0:
            empty = np.zeros((0, 2))
            return KeypointCorrespondences(empty, q, empty, np.zeros(0, bool), np.zeros(0, bool),
                                           np.zeros((0, 2), np.intp))
        mapping = self.point_mapping(source, follow)
        if isinstance(mapping, DepthMapping):
            p, lifted = self._lifted_source(raw, source, mapping)
            fwd: MappedPoints = mapping.land(lifted, follow)
        else:
            p = _unique_rows(raw)
            fwd = mapping.to_follow(p)
        bwd = mapping.to_source(q)
        rejected = {key: fwd.rejected.get(key, 0) + bwd.rejected.get(key, 0)
                    for key in sorted(set(fwd.rejected) | set(bwd.rejected))}
        matches = np.zeros((0, 2), np.intp)
        if fwd.visible.any() and bwd.visible.any():
            i_vis, j_vis = np.flatnonzero(fwd.visible), np.flatnonzero(bwd.visible)
            pairs = self._match(fwd.uv[i_vis], q[j_vis])
            matches = np.stack([i_vis[pairs[:, 0]], j_vis[pairs[:, 1]]], axis=1)
        return KeypointCorrespondences(p, q, fwd.uv, fwd.visible, bwd.visible, matches, rejected)

    def _lifted_source(self, raw: np.ndarray, source: RenderedView,
                       mapping: DepthMapping) -> tuple[np.ndarray, LiftedPoints]:
        """The source's distinct keypoints (read-only) and their world points, kept for the next pairs on the
        same source render: a cached render's depth and opacity are read-only arrays, so the same two arrays,
        camera, pose, keypoints and mapping parameters give the same points (views with writeable arrays are
        never kept)."""
        key = (id(source.depth), source.camera, np.asarray(source.c2w, dtype=np.float64).tobytes(), raw.shape,
               raw.tobytes(), mapping.min_opacity, mapping.depth_tolerance)
        kept = self._kept.get(key)
        if kept is not None and kept[0]() is source.depth and kept[1]() is source.opacity:
            self._kept.move_to_end(key)
            return kept[2], kept[3]
        p = _unique_rows(raw)
        p.setflags(write=False)
        lifted = mapping.lift(p, source)
        assert source.depth is not None and source.opacity is not None, "lift checked the view has both"
        if not (source.depth.flags.writeable or source.opacity.flags.writeable):
            self._kept[key] = (weakref.ref(source.depth), weakref.ref(source.opacity), p, lifted)
            while len(self._kept) > _KEPT_SOURCES:
                self._kept.popitem(last=False)
        return p, lifted

    def __getstate__(self) -> dict[str, Any]:
        return {**self.__dict__, "_kept": OrderedDict()}  # weak references do not pickle

    def _match(self, p: np.ndarray, q: np.ndarray) -> np.ndarray:
        """``(M, 2)`` index pairs of matched points (none unless the metric matches points)."""
        return np.zeros((0, 2), np.intp)

    #: The metric's match tolerance in pixels (the disc radius of :data:`MAX_COVERAGE`).
    tolerance: float

    def compute(self, out_source: Any, out_follow: Any, source: Any, follow: Any) -> MetricResult:
        c = self.correspondences(out_source, out_follow, source, follow)
        if len(c.source) == 0 and len(c.follow) == 0:
            return MetricResult.undefined(self.name, "the SUT found no keypoint in either view (nothing to compare)",
                                          n_source=0, n_follow=0)
        for which, points, view in (("source", c.source, source), ("follow-up", c.follow, follow)):
            if not _may_cover(len(points), view.camera, self.tolerance) or (
                    coverage_bound(points, view.camera, self.tolerance) < MAX_COVERAGE):
                continue  # the discs cannot cover MAX_COVERAGE of the image: no need to paint them
            covered = float(coverage_mask(points, view.camera, self.tolerance).mean())
            if covered >= MAX_COVERAGE:
                return MetricResult.undefined(
                    self.name, f"the {which} keypoints cover {covered:.0%} of the image within "
                    f"{self.tolerance:g} px: any point set would match by chance", n_source=len(c.source),
                    n_follow=len(c.follow), coverage=round(covered, 3))
        n1, n2 = int(c.source_visible.sum()), int(c.follow_visible.sum())
        details: dict[str, Any] = {
            "n_source": len(c.source), "n_follow": len(c.follow), "n_source_visible": n1, "n_follow_visible": n2,
            **{f"rejected_{key}": n for key, n in c.rejected.items()},
        }
        if n1 == 0 and n2 == 0:
            return MetricResult.undefined(
                self.name, "no keypoint of either view lies in the region both views see", **details
            )
        if n1 == 0 or n2 == 0:
            return self.result(0.0, **details)
        return self._score(c, follow.camera, details)

    @abstractmethod
    def _score(self, c: KeypointCorrespondences, camera: Camera, details: dict[str, Any]) -> MetricResult:
        """Score the correspondences (at least one visible point on each side) on the follow-up
        ``camera``'s pixel grid."""

    def _mapping_repr(self) -> str:
        parts = [f"mapping={self.mapping!r}"]
        if self.plane is not None:
            n, d = self.plane
            parts.append(f"plane=({n.tolist()!r}, {d!r})")
        if self.mapping == "depth":
            if self.min_opacity != DEFAULT_MIN_OPACITY:
                parts.append(f"min_opacity={self.min_opacity!r}")
            if self.depth_tolerance != DEFAULT_DEPTH_TOLERANCE:
                parts.append(f"depth_tolerance={self.depth_tolerance!r}")
        return ", ".join(parts)


class Repeatability(_KeypointMetric):
    """Fraction of keypoints detected again at the same scene point (Schmid et al. 2000).

    With ``n1`` source points mapped into the follow-up image and ``n2`` follow-up points, all visible in
    both views, ``m`` is the number of pairs at most ``px`` pixels apart, each point in at most one pair.
    The score is ``m / min(n1, n2)`` (``form="schmid"``, default) or ``2 m / (n1 + n2)``
    (``form="symmetric"``). Range [0, 1], ideal 1, deviation ``1 - score``.

    ``matching="maximum"`` (default) counts the most such pairs one-to-one matching allows;
    ``matching="mutual"`` only mutual nearest neighbours, what this metric counted before ``result_version``
    2. Where a detector's points crowd (ORB finds one corner at several pyramid levels), mutual nearest
    neighbours lose a point whose neighbour's counterpart lies nearer than its own, and its neighbour's
    counterpart with it: on the fox, a photo moved by one whole pixel kept 0.61 of ORB's points that way
    (docs/metrics.md, "Repeatability: which points pair").
    """

    name = "repeatability"
    ideal = 1.0
    result_version = "4"  # 4: pairs px + DISC_SLACK apart match; 3: mutual ties to the lowest index, H / max|H|

    def __init__(
        self, px: float = 2.0, mapping: Mapping = "depth", *, form: Literal["schmid", "symmetric"] = "schmid",
        matching: Literal["maximum", "mutual"] = "maximum", plane: tuple[np.ndarray, float] | None = None,
        min_opacity: float = DEFAULT_MIN_OPACITY, depth_tolerance: float = DEFAULT_DEPTH_TOLERANCE,
    ) -> None:
        self.px = check_positive("px", px)
        if form not in _FORMS:
            raise InvalidArgument(f"form={form!r}; expected one of {_FORMS}")
        if matching not in _MATCHINGS:
            raise InvalidArgument(f"matching={matching!r}; expected one of {_MATCHINGS}")
        self.form = form
        self.matching = matching
        self.tolerance = self.px
        super().__init__(mapping, plane, min_opacity, depth_tolerance)

    def _match(self, p: np.ndarray, q: np.ndarray) -> np.ndarray:
        match = maximum_matching if self.matching == "maximum" else mutual_nearest
        return match(p, q, self.px)

    def _score(self, c: KeypointCorrespondences, camera: Camera, details: dict[str, Any]) -> MetricResult:
        m = len(c.matches)
        n1, n2 = int(c.source_visible.sum()), int(c.follow_visible.sum())
        score = m / min(n1, n2) if self.form == "schmid" else 2.0 * m / (n1 + n2)
        return self.result(score, n_matched=m, **details)

    def __repr__(self) -> str:
        # the matching is always named: a baseline saved when mutual nearest neighbours were all this metric
        # counted names none, so comparing it with today's scores reads as a changed metric, not a change
        form = "" if self.form == "schmid" else f", form={self.form!r}"
        return f"repeatability(px={self.px!r}{form}, matching={self.matching!r}, {self._mapping_repr()})"


def _may_cover(n_points: int, camera: Camera, radius: float) -> bool:
    """Whether ``n_points`` discs of ``radius`` pixels could cover :data:`MAX_COVERAGE` of the image: a disc
    holds at most ``(floor(2 r) + 1)²`` pixel centres (at most that many columns and rows fit in its width),
    so fewer discs than the share needs cannot reach it, wherever they lie."""
    per_disc = (int(np.floor(2 * (capped_radius(radius, camera) + DISC_SLACK))) + 1) ** 2
    return n_points * per_disc >= MAX_COVERAGE * camera.width * camera.height


class InterestPointSpread(_KeypointMetric):
    """How much of the same image area the two point sets cover (after Bailo et al. 2018).

    Each set of points visible in both views covers the union of discs of ``radius`` pixels around its
    points, rasterized on the follow-up image's pixel grid (source points mapped into it). The score is
    the intersection over union of the two coverage areas. Range [0, 1], ideal 1, deviation ``1 - score``.

    A ``radius`` under √0.5 px (0.7071) is allowed, but such a disc can hold no pixel centre (a point at
    ``(10.5, 10.5)`` with radius 0.5): when one side's discs hold none, the pair is undefined, not scored.
    """

    name = "interest_point_spread"
    ideal = 1.0
    result_version = "2"  # 2: undefined where one side's discs hold no pixel centre; H applied as H / max|H|

    def __init__(
        self, radius: float = 8.0, mapping: Mapping = "depth", *,
        plane: tuple[np.ndarray, float] | None = None, min_opacity: float = DEFAULT_MIN_OPACITY,
        depth_tolerance: float = DEFAULT_DEPTH_TOLERANCE,
    ) -> None:
        self.radius = self.tolerance = check_positive("radius", radius)
        super().__init__(mapping, plane, min_opacity, depth_tolerance)

    def _score(self, c: KeypointCorrespondences, camera: Camera, details: dict[str, Any]) -> MetricResult:
        a = coverage_mask(c.source_in_follow[c.source_visible], camera, self.radius)
        b = coverage_mask(c.follow[c.follow_visible], camera, self.radius)
        inter, union = int(np.count_nonzero(a & b)), int(np.count_nonzero(a | b))
        covered = {"covered_source": int(a.sum()), "covered_follow": int(b.sum()), "covered_both": inter}
        for which, n in (("source", covered["covered_source"]), ("follow-up", covered["covered_follow"])):
            if n == 0:  # only a radius under √0.5 px can miss every pixel centre (one lies within √0.5 of any point)
                return MetricResult.undefined(
                    self.name, f"the {which} keypoints' discs of radius {self.radius:g} px hold no pixel centre "
                    f"(a radius under √0.5 = {_ALWAYS_HOLDS:.4f} px can miss them all): nothing to compare",
                    **covered, **details)
        return self.result(inter / union, **covered, **details)

    def __repr__(self) -> str:
        return f"interest_point_spread(radius={self.radius!r}, {self._mapping_repr()})"


def repeatability(
    px: float = 2.0, mapping: Mapping = "depth", *, form: Literal["schmid", "symmetric"] = "schmid",
    matching: Literal["maximum", "mutual"] = "maximum", plane: tuple[np.ndarray, float] | None = None,
    min_opacity: float = DEFAULT_MIN_OPACITY, depth_tolerance: float = DEFAULT_DEPTH_TOLERANCE,
) -> Repeatability:
    """Keypoint repeatability with a tolerance of ``px`` pixels (follow-up image); see :class:`Repeatability`.

    ``mapping="depth"`` maps points with the rendered z-depth and poses (needs ``depth`` and ``opacity``;
    ``min_opacity`` in [0, 1], ``depth_tolerance`` relative); ``mapping="homography"`` uses the homography
    of the world plane ``plane = (n, d)`` (``n·X + d = 0``), or of a pure rotation when ``plane`` is None (camera
    centres apart are then an :class:`~pytest_n2r.errors.InvalidArgument`). ``px`` beyond the image diagonal acts
    as the diagonal.

    >>> repeatability(px=2)
    repeatability(px=2.0, matching='maximum', mapping='depth')
    """
    return Repeatability(px, mapping, form=form, matching=matching, plane=plane, min_opacity=min_opacity,
                         depth_tolerance=depth_tolerance)


def interest_point_spread(
    radius: float = 8.0, mapping: Mapping = "depth", *, plane: tuple[np.ndarray, float] | None = None,
    min_opacity: float = DEFAULT_MIN_OPACITY, depth_tolerance: float = DEFAULT_DEPTH_TOLERANCE,
) -> InterestPointSpread:
    """IoU of the areas covered by discs of ``radius`` pixels around each point set; see
    :class:`InterestPointSpread` (mapping parameters as in :func:`repeatability`).

    >>> interest_point_spread(radius=5)
    interest_point_spread(radius=5.0, mapping='depth')
    """
    return InterestPointSpread(radius, mapping, plane=plane, min_opacity=min_opacity,
                               depth_tolerance=depth_tolerance)
