"""The capture's nearest other photo brought to a view's pose: what a real image taken nearby gives a detector,
the yardstick a field floor is read against (:class:`~pytest_n2r.relation.floor.FieldFloor`'s ``nearby``, printed
beside each relation's floor and by ``n2r info --shift``).

Convention
----------
- "Nearest" is by camera distance in reference lengths plus the angle between the optical axes in radians
  (:mod:`pytest_n2r.geometry.view_gap`, which a fit's report also measures its held-out views with), among the
  scene's fitted (training) views; a view at the very same pose is never its own neighbour.
- "Brought to the pose": every pixel centre of the view is mapped into the neighbour through the rendered
  z-depth of both, by the same :class:`~pytest_n2r.metrics.correspondence.DepthMapping` the keypoint metrics map
  points with (a point needs a surface under it in both views, opacity ≥ 0.5, and depths that agree within 5 %);
  where it lands, the pixel takes the neighbour's image there (bilinear); elsewhere (what the neighbour does not
  see) it keeps the view's render. So the image has the neighbour's real texture placed by the field's geometry.
"""

from __future__ import annotations

from collections import OrderedDict
from collections.abc import Callable
from dataclasses import dataclass

import numpy as np

from ...geometry import Camera, pixel_grid
from ...geometry.view_gap import nearest_pose
from ...metrics.correspondence import DepthMapping
from ...render.size import RenderSize
from ...render.view import RenderedView
from ...scene.base import Scene, SceneView
from .reference import reference_image

__all__ = ["NearbyImage", "nearest_fitted_view", "brought_to_view", "nearby_image"]


def nearest_fitted_view(scene: Scene, c2w: np.ndarray,
                        usable: Callable[[SceneView], bool] = lambda view: True) -> tuple[SceneView, float, float]:
    """The fitted view of ``scene`` nearest to pose ``c2w`` (see the Convention) among those ``usable`` says yes
    to, with the angle between their optical axes (degrees) and the distance between their centres (reference
    lengths); a ``ValueError`` when there is none.

    >>> from types import SimpleNamespace
    >>> at = lambda x: np.array([[1, 0, 0, x], [0, 1, 0, 0], [0, 0, 1, 0], [0, 0, 0, 1.0]])
    >>> views = [SimpleNamespace(name=str(x), split="train", c2w=at(x)) for x in (0.0, 0.5, -0.2)]
    >>> scene = SimpleNamespace(views=views, reference_length=2.0)
    >>> view, degrees, distance = nearest_fitted_view(scene, at(0.0))
    >>> view.name, degrees, distance
    ('-0.2', 0.0, 0.1)
    """
    c2w = np.asarray(c2w, dtype=np.float64)
    candidates = [v for v in scene.views if v.split == "train" and usable(v) and not np.array_equal(v.c2w, c2w)]
    if not candidates:
        raise ValueError(f"scene {getattr(scene, 'name', '?')!r} has no other fitted view to bring to this pose")
    index, degrees, distance = nearest_pose(c2w, [v.c2w for v in candidates], scene.reference_length)
    return candidates[index], degrees, distance


def brought_to_view(view: RenderedView, image: np.ndarray, image_view: RenderedView) -> tuple[np.ndarray, float]:
    """``image`` (H'×W'×3 uint8 RGB, seen from ``image_view``, which has its rendered depth and opacity) brought
    to ``view`` (rendered with RGB, depth and opacity) through both depths; and the share of ``view``'s pixels
    that took their colour from ``image`` (the rest keep ``view.rgb``)."""
    import cv2

    view.require("rgb", "depth", "opacity")
    image_view.require("depth", "opacity", name="image_view")
    assert view.rgb is not None and view.depth is not None and image_view.depth is not None, "required above"
    if image.shape[:2] != image_view.depth.shape:
        raise ValueError(f"image is {image.shape[1]}x{image.shape[0]} pixels but its view's depth is "
                         f"{image_view.depth.shape[1]}x{image_view.depth.shape[0]}")
    mapped = DepthMapping(view, image_view).to_follow(pixel_grid(view.camera).reshape(-1, 2))
    h, w = view.depth.shape
    where = np.nan_to_num(mapped.uv, nan=-1e6).astype(np.float32).reshape(h, w, 2)
    colour = cv2.remap(np.ascontiguousarray(image), where[..., 0], where[..., 1], cv2.INTER_LINEAR,
                       borderMode=cv2.BORDER_REPLICATE)
    seen = mapped.visible.reshape(h, w)
    return np.where(seen[..., None], colour, view.rgb), float(seen.mean())



@dataclass(frozen=True, eq=False)
class NearbyImage:
    """The nearest other fitted view's reference image brought to a view's pose (:func:`nearby_image`):
    ``image`` (H×W×3 uint8 RGB, the view's size), the ``other`` view, how far it is (``degrees`` between optical
    axes, ``distance`` in reference lengths) and the ``share`` of pixels that took its colour."""

    image: np.ndarray
    other: SceneView
    degrees: float
    distance: float
    share: float


#: Brought images of this process, by scene content, view, size and reference kind: every floor of one scene and
#: size (each SUT and metric) asks for the same ones (42 requests for 7 images in ``n2r info --shift`` on the fox,
#: 3.1 of its 6.8 s). Rendering is deterministic, so the key names the image; the oldest go first.
_BROUGHT: OrderedDict[tuple[str, str, str, str], NearbyImage | None] = OrderedDict()
_BROUGHT_KEPT = 64


def nearby_image(scene: Scene, view: SceneView, rendered: RenderedView, size: RenderSize | None, kind: str,
                 render: Callable[[Scene, np.ndarray, Camera], RenderedView]) -> NearbyImage | None:
    """The nearest other fitted view's reference image (a stored photo for ``kind="photo"``, the exact render for
    ``"exact"``) brought to ``view``'s pose, whose render at ``size`` (``None``: each view's camera) is
    ``rendered`` (RGB, depth and opacity); ``render(scene, c2w, camera)`` renders the other view the same way (a
    render cache's, say). ``None`` when the scene has no other fitted view with a reference image. Kept for the
    process (:data:`_BROUGHT`), so the floors of several SUTs and metrics bring each view once."""
    key = (scene.content_hash, view.name, str(size), kind)
    if key in _BROUGHT:
        _BROUGHT.move_to_end(key)
        return _BROUGHT[key]
    usable = (lambda v: v.image is not None) if kind == "photo" else (lambda v: True)
    try:
        other, degrees, distance = nearest_fitted_view(scene, view.c2w, usable)
    except ValueError:
        near = None
    else:
        camera = other.camera if size is None else size.apply(other.camera)
        image, share = brought_to_view(rendered, np.asarray(reference_image(scene, other, camera, kind, render)),
                                       render(scene, other.c2w, camera))
        image.setflags(write=False)  # a SUT gets it as it gets a photo or a cached render: it may not draw on it
        near = NearbyImage(image, other, degrees, distance, share)
    _BROUGHT[key] = near
    while len(_BROUGHT) > _BROUGHT_KEPT:
        _BROUGHT.popitem(last=False)
    return near
