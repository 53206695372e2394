"""The scene interface every renderable scene implements (fitted fields and exact demo scenes alike)."""

from __future__ import annotations

from abc import ABC, abstractmethod
from collections.abc import Iterable, Sequence
from dataclasses import dataclass
from typing import Any

import numpy as np

from .._validation import check_choice, repeated_name
from ..errors import InvalidArgument, InvalidType, N2RError
from ..geometry import Camera, Transform, Units, check_pose
from ..render.size import MAX_SIDE
from ..render.view import OUTPUTS, RenderedView

__all__ = ["MAX_CAMERA_DISTANCE", "MAX_FOCAL", "MIN_FOCAL", "PRINCIPAL_POINT_REACH", "Scene", "SceneView",
           "check_render_camera", "hash_views", "normalize_outputs"]

#: How far from the captured cameras a render may be, in reference lengths: beyond it a float32 renderer
#: cannot place a sample within a thousandth of a reference length, so the picture would be noise or NaN.
MAX_CAMERA_DISTANCE = 1e4
#: The focal lengths ``fx``, ``fy`` a render camera may have, in pixels: with :data:`PRINCIPAL_POINT_REACH` and
#: :data:`~pytest_n2r.render.size.MAX_SIDE` they keep every ray direction ``((u - cx) / fx, (v - cy) / fy, 1)`` and its
#: squared length within float32 (below 1e27, a pixel step above 1e-10), where the renderers' kernels work.
MIN_FOCAL, MAX_FOCAL = 1e-6, 1e9
#: How far the principal point may lie from the image's centre, in image sizes: ``|cx - (width - 1) / 2|`` at most
#: this many widths, ``|cy - (height - 1) / 2|`` this many heights (an off-axis crop of a far larger picture).
PRINCIPAL_POINT_REACH = 1000


@dataclass(frozen=True, eq=False)
class SceneView:
    """A captured view of a scene: its name, ideal pinhole camera, camera-to-world pose (OpenCV axes),
    train / held-out split and, if the scene stores it, the real photo (H×W×3 uint8 RGB)."""

    index: int
    name: str
    camera: Camera
    c2w: np.ndarray
    split: str = "train"
    image: np.ndarray | None = None

    def _repr_pretty_(self, printer: Any, cycle: bool) -> None:
        """Hypothesis's "Falsifying example" names the view, not its arrays (nor its camera: a relation renders
        it at the size it asks for)."""
        printer.text(f"SceneView(index={self.index}, name={self.name!r}, split={self.split!r})")


def hash_views(h: Any, views: Iterable[SceneView]) -> None:
    """Feed ``views`` to the hash ``h`` (a ``hashlib`` object), in order: each view's name, split and camera, then
    its pose's bytes. A scene's ``content_hash`` takes its views this way; render cache keys depend on the bytes."""
    for v in views:
        h.update(f"{v.name}/{v.split}/{v.camera.to_dict()}".encode())
        h.update(np.ascontiguousarray(v.c2w).tobytes())


def normalize_outputs(outputs: str | Iterable[str]) -> tuple[str, ...]:
    """Validate ``outputs`` and return them in canonical order (``rgb``, ``depth``, ``opacity``)."""
    if isinstance(outputs, str):
        outputs = (outputs,)
    try:
        asked = set(outputs)
    except TypeError:
        raise InvalidType(f"outputs={outputs!r} must be a name or a sequence of names from {OUTPUTS}") from None
    unknown = asked - set(OUTPUTS)
    if unknown or not asked:
        raise InvalidArgument(f"outputs={tuple(outputs)!r}: expected one or more of {OUTPUTS}")
    return tuple(o for o in OUTPUTS if o in asked)


def check_render_camera(camera: Camera) -> Camera:
    """``camera`` if a renderer can draw it; else an :class:`InvalidArgument` naming the field out of bounds: a side
    above :data:`~pytest_n2r.render.size.MAX_SIDE` pixels, a focal length outside [:data:`MIN_FOCAL`,
    :data:`MAX_FOCAL`] pixels, a principal point more than :data:`PRINCIPAL_POINT_REACH` image sizes from the image's
    centre (beyond them ray directions overflow or underflow float32, or the image does not fit in memory).

    >>> check_render_camera(Camera(64, 48, 1e-38, 1e-38, 31.5, 23.5))
    Traceback (most recent call last):
    ...
    pytest_n2r.errors.InvalidArgument: camera fx=1e-38 pixels is out of bounds; expected a focal length in [1e-06, \
1e+09] pixels (beyond it ray directions overflow or underflow float32)
    """
    for name in ("width", "height"):
        side = getattr(camera, name)
        if side > MAX_SIDE:
            raise InvalidArgument(f"camera {name}={side} pixels is too large; expected at most {MAX_SIDE} pixels "
                                  "(the largest side a render is asked for)")
    for name in ("fx", "fy"):
        focal = getattr(camera, name)
        if not MIN_FOCAL <= focal <= MAX_FOCAL:
            raise InvalidArgument(f"camera {name}={focal!r} pixels is out of bounds; expected a focal length in "
                                  f"[{MIN_FOCAL:g}, {MAX_FOCAL:g}] pixels (beyond it ray directions overflow or "
                                  "underflow float32)")
    for name, side in (("cx", camera.width), ("cy", camera.height)):
        offset = abs(getattr(camera, name) - (side - 1) / 2)
        if not offset <= PRINCIPAL_POINT_REACH * side:
            raise InvalidArgument(f"camera {name}={getattr(camera, name)!r} pixels is {offset:.4g} pixels from the "
                                  f"image's centre; expected at most {PRINCIPAL_POINT_REACH} image sizes "
                                  f"({PRINCIPAL_POINT_REACH * side} pixels) from it (beyond it ray directions "
                                  "overflow or underflow float32)")
    return camera


#: What :meth:`Scene._render` returns for each output: its dtype and its shape after the image's height and width.
_RENDERED = {"rgb": (np.dtype(np.uint8), (3,)), "depth": (np.dtype(np.float32), ()),
             "opacity": (np.dtype(np.float32), ())}


def _check_rendered(scene: str, rendered: dict[str, np.ndarray], outputs: tuple[str, ...], camera: Camera) -> None:
    """Refuse, naming the scene and the output, a render that left out an output it was asked for or returned one
    of another shape or type than :class:`~pytest_n2r.render.view.RenderedView` describes (a ``_render`` of one's
    own that returns a float RGB image in [0, 1], say): never a silently wrong picture."""
    for name in outputs:
        value = rendered.get(name)
        dtype, channels = _RENDERED[name]
        shape = (camera.height, camera.width, *channels)
        if not isinstance(value, np.ndarray) or value.dtype != dtype or value.shape != shape:
            got = "nothing" if value is None else (f"a {value.dtype} array of shape {value.shape}"
                                                   if isinstance(value, np.ndarray) else type(value).__name__)
            raise InvalidArgument(f"scene {scene!r} rendered {got} as {name!r}; its _render must return every "
                                  f"output it is asked for, {name!r} as a {dtype} array of shape {shape}")


class Scene(ABC):
    """A scene that renders RGB, z-depth and opacity at any pinhole camera and pose.

    Subclasses implement :meth:`_render`; this class validates arguments and handles transforms.
    Rendering must be deterministic: the same pose, camera and settings give bit-identical output.
    """

    #: Short name used in test ids and reports.
    name: str
    _views: Sequence[SceneView]  # behind the property views, which refuses two views of one name
    #: Median z-depth of the surface seen from the training cameras, in scene units.
    reference_length: float
    #: Metres per scene unit when the capture's scale is known, else ``None``.
    metres_per_unit: float | None = None
    #: True when renders are the exact truth (procedural demo scenes), not a fitted approximation.
    is_exact: bool = False
    #: Why the scene has no captured views, when it has none (a splat scene without cameras); said in errors.
    no_views_reason: str | None = None
    #: Changes when the renderer's pixels change for the same content (keys the render cache beside
    #: :attr:`content_hash`, which also keys what was fitted to the scene's renders and stays put).
    renderer_version: str = "1"

    @property
    def views(self) -> Sequence[SceneView]:
        """The captured views (held-out ones are the natural sources of metamorphic tests), each of its own name."""
        return self._views

    @views.setter
    def views(self, views: Sequence[SceneView]) -> None:
        repeat = repeated_name(v.name for v in views)
        if repeat is not None:
            first, second, name = repeat
            raise InvalidArgument(f"scene {getattr(self, 'name', type(self).__name__)!r}: views [{first}] and "
                                  f"[{second}] are both named {name!r}; expected one view a name (a view is "
                                  "looked up and reported by its name)")
        self._views = views

    @property
    @abstractmethod
    def content_hash(self) -> str:
        """A hex digest that changes whenever anything that affects rendering changes (cache key)."""

    @abstractmethod
    def _render(self, c2w: np.ndarray, camera: Camera, outputs: tuple[str, ...]) -> dict[str, np.ndarray]:
        """Render the validated ``outputs`` (canonical order) and return them by name, each as
        :class:`~pytest_n2r.render.view.RenderedView` describes it (``rgb`` H×W×3 ``uint8``, ``depth`` and
        ``opacity`` H×W ``float32``); :meth:`render` refuses anything else, naming the scene and the output."""

    def compile_apart(self) -> bool:
        """Compile the parts of this scene's renderer that compile apart from its kernels' first render (into
        numba's on-disk cache, where a process rendering the scene loads them); ``False`` when there are none,
        the default. The kernel helper calls it while the session compiles the kernels
        (:mod:`pytest_n2r.plugin.precompile`)."""
        return False

    def render(self, c2w: np.ndarray, camera: Camera, outputs: str | Iterable[str] = ("rgb",)) -> RenderedView:
        """Render the view of ``camera`` at camera-to-world pose ``c2w`` (OpenCV axes, scene units).

        Only the ``outputs`` asked for are computed (``"rgb"``, ``"depth"``, ``"opacity"``).
        """
        c2w = self.check_camera_position(check_pose(c2w))
        if not isinstance(camera, Camera):
            raise InvalidType(f"camera must be a pytest_n2r.geometry.Camera, got {type(camera).__name__}")
        if camera.distortion:
            raise InvalidArgument("camera has lens distortion; scenes render ideal pinhole views only")
        check_render_camera(camera)
        outputs = normalize_outputs(outputs)
        rendered = self._render(c2w, camera, outputs)
        _check_rendered(self.name, rendered, outputs, camera)
        for name in ("depth", "opacity"):
            value = rendered.get(name)
            if value is not None and not np.isfinite(value).all():
                bad = int(value.size - np.isfinite(value).sum())
                raise InvalidArgument(f"scene {self.name!r} rendered {bad} NaN/Inf {name} value(s) at camera "
                                      f"position {np.round(c2w[:3, 3], 6).tolist()}; its field holds values "
                                      "the renderer cannot use")
        return RenderedView(camera=camera, c2w=c2w, **rendered)

    def check_camera_position(self, c2w: np.ndarray) -> np.ndarray:
        """``c2w`` if its camera lies within :data:`MAX_CAMERA_DISTANCE` reference lengths of the captured
        cameras' mean position; else an :class:`InvalidArgument` naming the position and the limit. A scene
        without captured views or a reference length (yet) has no such limit."""
        try:
            limit = MAX_CAMERA_DISTANCE * float(self.reference_length)
        except (AttributeError, N2RError):  # being built, or without cameras: nothing to measure against
            return c2w
        if not self.views:
            return c2w
        anchor = np.mean([np.asarray(v.c2w, dtype=np.float64)[:3, 3] for v in self.views], axis=0)
        offset = np.abs(np.asarray(c2w, dtype=np.float64)[:3, 3] - anchor)
        if not (np.isfinite(offset).all() and offset.max() <= limit):
            position = ", ".join(f"{v:.4g}" for v in np.asarray(c2w)[:3, 3])
            raise InvalidArgument(
                f"camera position ({position}) is {offset.max():.3g} scene units from the captured cameras of "
                f"scene {self.name!r}; renders are defined within {MAX_CAMERA_DISTANCE:g} reference lengths "
                f"({limit:.4g} scene units) of them; use a smaller translation")
        return c2w

    def length_scale(self, units: Units | str = Units.REFERENCE) -> float:
        """Scene units per unit of transform translation in ``units``."""
        units = check_choice("units", units, Units, "a unit")
        if units is Units.REFERENCE:
            return float(self.reference_length)
        if units is Units.SCENE:
            return 1.0
        if self.metres_per_unit is None:
            raise InvalidArgument(
                f"units='metres' needs a scene with a known scale; scene {self.name!r} has none "
                "(pass the scale at fit time, or use units='reference')"
            )
        return 1.0 / float(self.metres_per_unit)

    def view(self, index: int | str | object) -> SceneView:
        """A captured view by index (an int or NumPy integer) or image name (or a drawn ``strategies.ViewPick``,
        resolved here)."""
        resolve = getattr(index, "resolve", None)
        if callable(resolve):
            return resolve(self)
        if isinstance(index, str):
            for v in self.views:
                if v.name == index:
                    return v
            raise InvalidArgument(f"scene {self.name!r} has no view named {index!r}")
        if isinstance(index, bool) or not isinstance(index, (int, np.integer)):
            raise InvalidType(f"view={index!r} must be a view index (an int) or an image name (a str), not "
                              f"{type(index).__name__}")
        if not 0 <= index < len(self.views):
            raise InvalidArgument(f"view={index!r} is out of range; scene {self.name!r} has {len(self.views)} views")
        return self.views[int(index)]

    def pair(
        self,
        view: SceneView | int | str,
        tau: Transform,
        outputs: str | Iterable[str] = ("rgb",),
        camera: Camera | None = None,
        units: Units | str | None = None,
    ) -> tuple[RenderedView, RenderedView]:
        """Render the source view and its follow-up under ``tau`` (applied in the source camera frame).

        ``camera`` overrides the view's own camera (e.g. a smaller render size); translations of ``tau``
        are in ``units``: by default the units ``tau`` carries (a drawn ``PoseChange``), else reference
        lengths; ``units`` that contradict the ones ``tau`` carries are an error.
        """
        if not isinstance(view, SceneView):
            view = self.view(view)
        if not isinstance(tau, Transform):
            raise InvalidType(f"tau must be a pytest_n2r.Transform, got {type(tau).__name__}")
        own = getattr(tau, "units", None)  # a PoseChange (pytest_n2r.strategies) carries its units
        if units is None:
            units = own if own is not None else Units.REFERENCE
        else:
            units = check_choice("units", units, Units, "a unit")
            if own is not None and units is not own:
                raise InvalidArgument(f"units={units.value!r} contradicts tau={tau!r}, whose translation is in "
                                      f"{own.value!r} units; leave units out")
        camera = view.camera if camera is None else camera
        source = self.render(view.c2w, camera, outputs)
        follow = self.render(tau.apply(view.c2w, self.length_scale(units)), camera, outputs)
        return source, follow

    def __repr__(self) -> str:
        return f"<{type(self).__name__} {self.name!r}: {len(self.views)} views>"
