"""Map pixels of one rendered view into the other: by rendered depth, or by a homography.

Convention
----------
- Pixels are ``(u, v)`` with pixel centres at integer coordinates (OpenCV); a point is *inside* an
  image of ``W x H`` pixels when ``-0.5 <= u < W - 0.5`` and ``-0.5 <= v < H - 0.5`` (half-open, as
  :func:`~pytest_n2r.geometry.inside_image`).
- Depth is the rendered **z-depth** (scene units), poses are camera-to-world with OpenCV axes.

Depth mapping (:class:`DepthMapping`), for a point ``uv`` of view *a* mapped into view *b*:

1. ``uv`` must lie inside image *a*, on opacity ``>= min_opacity`` (nearest pixel) with a finite,
   positive depth; otherwise it is rejected as ``low_opacity`` (the field has nothing there).
2. Its depth is sampled from *a*'s depth map (see :func:`sample_depth`), the point is lifted to the
   world with :func:`~pytest_n2r.geometry.backproject` and projected into *b* with
   :func:`~pytest_n2r.geometry.project`.
3. Rejected as ``outside`` if it lands behind camera *b* or outside image *b*; as ``low_opacity`` if
   *b*'s opacity there (nearest pixel) is ``< min_opacity``; as ``occluded`` if its predicted z-depth
   ``z`` in *b* disagrees with *b*'s rendered depth ``d`` there: ``|z - d| > depth_tolerance * d``
   (something else is in front of it, or the field is inconsistent between the views).

Homography mapping (:class:`HomographyMapping`) is exact for a planar scene, or for any scene under a
pure camera rotation; it rejects only points that land outside the other image.
"""

from __future__ import annotations

import math
from abc import ABC, abstractmethod
from dataclasses import dataclass, field
from typing import Any

import numpy as np

from .._validation import check_array, check_range, check_real
from ..errors import InvalidArgument, InvalidType, MetricArgumentError
from ..geometry import (
    Camera,
    apply_homography,
    backproject,
    camera_rays,
    inside_image,
    plane_homography,
    project,
    rotation_homography,
)
from ..render.view import RenderedView

__all__ = [
    "MappedPoints",
    "LiftedPoints",
    "PointMapping",
    "DepthMapping",
    "HomographyMapping",
    "sample_depth",
    "check_plane",
    "DEFAULT_MIN_OPACITY",
    "DEFAULT_DEPTH_TOLERANCE",
]

#: Opacity below which a rendered pixel is treated as empty (the field has nothing there).
DEFAULT_MIN_OPACITY = 0.5
#: Relative z-depth disagreement beyond which a mapped point counts as occluded (5 %).
DEFAULT_DEPTH_TOLERANCE = 0.05


@dataclass(frozen=True)
class MappedPoints:
    """Points of one view mapped into the other.

    ``uv`` is ``(N, 2)`` in the other view's pixels (NaN where not visible), ``visible`` is ``(N,)``
    bool, ``rejected`` counts the points dropped per reason (``outside``, ``low_opacity``, ``occluded``).
    """

    uv: np.ndarray
    visible: np.ndarray
    rejected: dict[str, int] = field(default_factory=dict)


@dataclass(frozen=True)
class LiftedPoints:
    """``n`` points of one view lifted into the world through its depth, half of a :class:`DepthMapping`.

    ``index`` ``(M,)`` are the points with a surface under them, ``world`` ``(M, 3)`` their world positions
    (scene units); ``outside`` points lay outside the image and ``empty`` on no surface (``low_opacity``).
    """

    n: int
    index: np.ndarray
    world: np.ndarray
    outside: int
    empty: int


def _inside(uv: np.ndarray, camera: Camera) -> np.ndarray:
    """``(N,)`` bool: the points ``(N, 2)`` lie inside the camera's image (False for NaN)."""
    return inside_image(uv[:, 0], uv[:, 1], camera.width, camera.height)


def _nearest_index(uv: np.ndarray, shape: tuple[int, int]) -> tuple[np.ndarray, np.ndarray]:
    """Row and column of the pixel nearest to each (inside) point."""
    cols = np.clip(np.floor(uv[:, 0] + 0.5).astype(np.intp), 0, shape[1] - 1)
    rows = np.clip(np.floor(uv[:, 1] + 0.5).astype(np.intp), 0, shape[0] - 1)
    return rows, cols


def sample_depth(depth: np.ndarray, uv: np.ndarray, rel_tolerance: float = DEFAULT_DEPTH_TOLERANCE) -> np.ndarray:
    """Z-depth at sub-pixel points ``uv`` (``(N, 2)``, inside the image) of an ``H x W`` depth map.

    Interpolates **inverse** depth bilinearly between the four surrounding pixel centres: inverse
    depth is an affine function of ``(u, v)`` on a plane, so the result is exact on planar surfaces.
    Where the four depths differ by more than ``rel_tolerance`` (a depth edge), interpolating would
    invent a point floating between foreground and background, so the nearest pixel's depth is used.
    Non-positive or non-finite depths give NaN.
    """
    h, w = depth.shape
    u0 = np.clip(np.floor(uv[:, 0]).astype(np.intp), 0, max(w - 2, 0))
    v0 = np.clip(np.floor(uv[:, 1]).astype(np.intp), 0, max(h - 2, 0))
    u1, v1 = np.minimum(u0 + 1, w - 1), np.minimum(v0 + 1, h - 1)
    fu, fv = uv[:, 0] - u0, uv[:, 1] - v0
    # the four depths read first, then widened: not a float64 copy of a whole float32 map at every call
    corners = np.stack([depth[v0, u0], depth[v0, u1], depth[v1, u0], depth[v1, u1]], axis=1).astype(np.float64)
    with np.errstate(divide="ignore", invalid="ignore"):
        good = np.all(np.isfinite(corners) & (corners > 0), axis=1)
        inv = 1.0 / corners
        inv_d = (
            inv[:, 0] * (1 - fu) * (1 - fv) + inv[:, 1] * fu * (1 - fv)
            + inv[:, 2] * (1 - fu) * fv + inv[:, 3] * fu * fv
        )
        smooth = good & (corners.max(axis=1) <= corners.min(axis=1) * (1.0 + rel_tolerance)) & (inv_d > 0)
        rows, cols = _nearest_index(uv, depth.shape)
        nearest = depth[rows, cols].astype(np.float64)
        out = np.where(smooth, 1.0 / np.where(smooth, inv_d, 1.0), nearest)
    return np.where(np.isfinite(out) & (out > 0), out, np.nan)


def check_plane(plane: Any) -> tuple[np.ndarray, float] | None:
    """``plane = (n, d)`` of the world plane ``n·X + d = 0`` as ``(float64 (3,), float)``; ``None`` stays
    ``None`` (the plane at infinity). Raises naming what is wrong."""
    if plane is None:
        return None
    try:
        normal, offset = plane
    except (TypeError, ValueError):
        raise InvalidType(f"plane={plane!r} must be a pair (normal (3,), offset) or None") from None
    normal = check_array("plane normal", normal, "3", dtype=np.float64)
    offset = check_real("plane offset", offset)
    if not np.any(normal):
        raise InvalidArgument("plane normal is the zero vector; expected the plane's normal n of n·X + d = 0")
    return normal, offset


class PointMapping(ABC):
    """Maps pixels between the source view and the follow-up view of a pair."""

    @abstractmethod
    def to_follow(self, uv_source: np.ndarray) -> MappedPoints:
        """Source pixels ``(N, 2)`` → follow-up pixels."""

    @abstractmethod
    def to_source(self, uv_follow: np.ndarray) -> MappedPoints:
        """Follow-up pixels ``(N, 2)`` → source pixels."""


def _check_view(name: str, view: Any, outputs: tuple[str, ...]) -> RenderedView:
    if not isinstance(view, RenderedView):
        raise InvalidType(
            f"{name} must be the RenderedView the SUT saw (to map points between the views), "
            f"got {type(view).__name__}"
        )
    view.require(*outputs, name=name)
    for out in outputs:
        arr = getattr(view, out)
        if np.shape(arr) != (view.camera.height, view.camera.width):
            raise InvalidType(
                f"{name}.{out} has shape {np.shape(arr)}; expected ({view.camera.height}, {view.camera.width}) "
                "to match its camera"
            )
    return view


class DepthMapping(PointMapping):
    """Map pixels through the rendered z-depth and the two poses, rejecting what the other view cannot see.

    Parameters
    ----------
    source, follow:
        Views rendered with ``depth`` and ``opacity``.
    min_opacity:
        Pixels with opacity below this (in ``[0, 1]``, default 0.5) are empty: points there are rejected.
    depth_tolerance:
        Relative z-depth disagreement (default 0.05 = 5 %) beyond which a point counts as occluded.
    """

    def __init__(
        self, source: RenderedView, follow: RenderedView, *, min_opacity: float = DEFAULT_MIN_OPACITY,
        depth_tolerance: float = DEFAULT_DEPTH_TOLERANCE,
    ) -> None:
        self.source = _check_view("source", source, ("depth", "opacity"))
        self.follow = _check_view("follow", follow, ("depth", "opacity"))
        self.min_opacity = check_range("min_opacity", min_opacity, 0.0, 1.0)
        self.depth_tolerance = check_range("depth_tolerance", depth_tolerance, 0.0)

    def to_follow(self, uv_source: np.ndarray) -> MappedPoints:
        return self._map(uv_source, self.source, self.follow)

    def to_source(self, uv_follow: np.ndarray) -> MappedPoints:
        return self._map(uv_follow, self.follow, self.source)

    def _surface(self, view: RenderedView, uv: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """(has surface, depth) at points inside ``view`` (one checked by :func:`_check_view`)."""
        assert view.depth is not None and view.opacity is not None, "a checked view has both"
        rows, cols = _nearest_index(uv, view.opacity.shape)
        depth = sample_depth(view.depth, uv, self.depth_tolerance)
        return (view.opacity[rows, cols] >= self.min_opacity) & np.isfinite(depth), depth

    def lift(self, uv: np.ndarray, view: RenderedView) -> LiftedPoints:
        """Points ``uv`` ``(N, 2)`` of ``view`` (the source or the follow-up) lifted into the world: the half
        of the mapping that does not depend on the other view, so a caller may keep it for several pairs."""
        uv = check_array("uv", uv, "N 2", dtype=np.float64)
        view = _check_view("view", view, ("depth", "opacity"))
        inside = _inside(uv, view.camera)
        idx = np.flatnonzero(inside)
        has, depth = self._surface(view, uv[idx])
        idx = idx[has]
        return LiftedPoints(len(uv), idx, backproject(uv[idx], depth[has], view.camera, view.c2w),
                            int(np.count_nonzero(~inside)), int(np.count_nonzero(~has)))

    def land(self, lifted: LiftedPoints, view: RenderedView) -> MappedPoints:
        """``lifted`` points projected into ``view``, kept where it sees them (see the module's rules)."""
        if not isinstance(lifted, LiftedPoints):
            raise InvalidType(f"lifted must be the LiftedPoints of DepthMapping.lift, got {type(lifted).__name__}")
        view = _check_view("view", view, ("depth", "opacity"))
        out = np.full((lifted.n, 2), np.nan)
        visible = np.zeros(lifted.n, dtype=bool)
        uv_b, z_b = project(lifted.world, view.camera, view.c2w)
        inside_b = (z_b > 0) & _inside(uv_b, view.camera)
        idx, uv_b, z_b = lifted.index[inside_b], uv_b[inside_b], z_b[inside_b]

        has_b, depth_b = self._surface(view, uv_b)
        with np.errstate(invalid="ignore"):
            agrees = has_b & (np.abs(z_b - depth_b) <= self.depth_tolerance * depth_b)
        out[idx[agrees]] = uv_b[agrees]
        visible[idx[agrees]] = True
        rejected = {
            "outside": lifted.outside + int(np.count_nonzero(~inside_b)),
            "low_opacity": lifted.empty + int(np.count_nonzero(~has_b)),
            "occluded": int(np.count_nonzero(has_b & ~agrees)),
        }
        return MappedPoints(out, visible, rejected)

    def _map(self, uv: np.ndarray, a: RenderedView, b: RenderedView) -> MappedPoints:
        return self.land(self.lift(uv, a), b)

    def __repr__(self) -> str:
        return f"DepthMapping(min_opacity={self.min_opacity!r}, depth_tolerance={self.depth_tolerance!r})"


#: Relative tolerance of the camera-centre checks of :meth:`HomographyMapping.from_views` (a pure rotation moves
#: the centre by round-off only).
_CENTRE_TOLERANCE = 1e-9


def _check_pure_rotation(source: RenderedView, centre_a: np.ndarray, centre_b: np.ndarray) -> None:
    """Raise :class:`MetricArgumentError` when the camera centres differ by more than :data:`_CENTRE_TOLERANCE` of the
    scene scale (the larger of the centres' distances from the origin and the source's median depth, if rendered):
    the homography of the plane at infinity is exact only for a pure rotation."""
    depth = source.depth[np.isfinite(source.depth) & (source.depth > 0)] if source.depth is not None else ()
    scale = max(float(np.linalg.norm(centre_a)), float(np.linalg.norm(centre_b)),
                float(np.median(depth)) if len(depth) else 0.0)
    baseline = float(np.linalg.norm(centre_b - centre_a))
    if baseline > _CENTRE_TOLERANCE * scale:
        raise MetricArgumentError(
            f"mapping='homography' without plane= is exact only for a pure camera rotation, but the camera centres "
            f"are {baseline:.3g} scene units apart (more than {_CENTRE_TOLERANCE:g} of the scene scale "
            f"{scale:.3g}); use mapping='depth', or give plane=(n, d), the world plane n·X + d = 0 the scene lies on")


class HomographyMapping(PointMapping):
    """Map pixels through a 3x3 homography ``H`` (source → follow-up pixels, OpenCV pixel centres).

    Exact for a planar scene (:meth:`from_views` with ``plane``) or a pure camera rotation (``plane=None``);
    points landing outside the other image are rejected. No depth or opacity is used. Built with
    :meth:`from_views`, it also rejects points whose scene point is behind either camera (a homography
    alone maps those to plausible-looking pixels); built from a bare ``H`` it cannot tell. ``H`` may have any
    scale (``s H`` is the same homography); it is refused as singular when its condition number (the ratio of its
    largest to its smallest singular value, which no scale changes) exceeds 1e12: its inverse would keep fewer
    than four of float64's digits. A pure shift of 20 000 pixels has 4e8.
    """

    def __init__(self, H: np.ndarray, source_camera: Camera, follow_camera: Camera) -> None:
        self.H = check_array("H", H, "3 3", dtype=np.float64)
        # H and s H are one homography: test and apply H / max|H| (entries in [-1, 1]), whatever the scale given
        scale = float(np.abs(self.H).max())
        condition = float(np.linalg.cond(self.H / scale)) if scale > 0.0 else math.inf
        if not condition <= 1e12:  # not <=: inf and NaN are singular too
            raise InvalidArgument(f"H is singular (condition number {condition:.3g} > 1e12); a homography between two "
                                  "views must be invertible")
        self._H = self.H / scale
        inverse = np.linalg.inv(self._H)
        #: The inverse homography (follow-up → source pixels), scaled so that its largest entry is ±1.
        self.H_inv = inverse / np.abs(inverse).max()
        self.source_camera = source_camera
        self.follow_camera = follow_camera
        self._views: tuple[RenderedView, RenderedView] | None = None
        self.plane: tuple[np.ndarray, float] | None = None

    @classmethod
    def from_views(
        cls, source: RenderedView, follow: RenderedView,
        plane: tuple[np.ndarray, float] | None = None,
    ) -> HomographyMapping:
        """The homography between two views of the world plane ``plane = (n, d)`` (``n·X + d = 0``,
        world coordinates, scene units), or of the plane at infinity (pure rotation) when ``None``."""
        source = _check_view("source", source, ())
        follow = _check_view("follow", follow, ())
        plane = check_plane(plane)
        centres = [np.asarray(view.c2w, dtype=np.float64)[:3, 3] for view in (source, follow)]
        if plane is None:
            _check_pure_rotation(source, *centres)
            H = rotation_homography(source.camera, source.c2w, follow.camera, follow.c2w)
        else:
            n, d = plane
            for name, centre in zip(("source", "follow-up"), centres):
                if abs(float(n @ centre) + d) <= _CENTRE_TOLERANCE * float(np.linalg.norm(n)) * max(
                        1.0, float(np.linalg.norm(centre))):
                    raise MetricArgumentError(
                        f"plane=({n.tolist()!r}, {d!r}) passes through the {name} camera's centre "
                        f"{np.round(centre, 6).tolist()}, so its homography is undefined; expected the world plane "
                        "n·X + d = 0 the scene lies on (check the sign of d), or use mapping='depth'")
            H = plane_homography(source.camera, source.c2w, follow.camera, follow.c2w, *plane)
        mapping = cls(H, source.camera, follow.camera)
        mapping._views = (source, follow)
        mapping.plane = plane
        return mapping

    def to_follow(self, uv_source: np.ndarray) -> MappedPoints:
        return self._map(uv_source, self._H, self.source_camera, self.follow_camera, forward=True)

    def to_source(self, uv_follow: np.ndarray) -> MappedPoints:
        return self._map(uv_follow, self.H_inv, self.follow_camera, self.source_camera, forward=False)

    def _in_front(self, uv: np.ndarray, forward: bool) -> np.ndarray:
        """(N,) bool: the scene point seen at ``uv`` is in front of both cameras (True without views)."""
        if self._views is None:
            return np.ones(len(uv), dtype=bool)
        a, b = self._views if forward else self._views[::-1]
        origins, dirs = camera_rays(a.camera, a.c2w, uv)
        if self.plane is None:  # a direction (point at infinity): in front of b if it points forward there
            return (dirs @ np.asarray(b.c2w, dtype=np.float64)[:3, 2]) > 0
        n, d = self.plane
        with np.errstate(divide="ignore", invalid="ignore"):
            t = -(origins @ n + d) / (dirs @ n)  # z-depth in a of the plane along each ray
        front = np.isfinite(t) & (t > 0)
        z_b = project(origins + dirs * np.where(front, t, 0.0)[:, None], b.camera, b.c2w)[1]
        return front & (z_b > 0)

    def _map(self, uv: np.ndarray, H: np.ndarray, cam_a: Camera, cam_b: Camera, forward: bool) -> MappedPoints:
        uv = check_array("uv", uv, "N 2", dtype=np.float64)
        mapped = apply_homography(H, uv)
        visible = _inside(uv, cam_a) & _inside(mapped, cam_b) & self._in_front(uv, forward)
        mapped[~visible] = np.nan
        return MappedPoints(mapped, visible, {"outside": int(np.count_nonzero(~visible))})

    def __repr__(self) -> str:
        return f"HomographyMapping(H={np.round(self.H, 6).tolist()!r})"
