"""Every training pixel of a capture as a ray and its colour: what each step of a fit draws its batch from.

The rays are held for the whole fit, 23 bytes a pixel (:data:`RAY_BYTES`); each photo's origin is stored once, not
per pixel (every ray of a photo leaves its camera's centre: 12 bytes a pixel saved, the same rays). They are built
on the host and then moved to the fitting device; before they are built they are priced
(:func:`ray_bytes`) against the memory free on each (:func:`~pytest_n2r.fit.free_memory.free_bytes`): a capture
too large for the machine is refused with its pixels, the bytes and how much smaller to fit it, not killed by the
kernel while its rays are built (``n2r fit --downscale 1`` on a hundred 12-megapixel photos would hold 28 GB of
rays).

Every view of a capture is checked before a fit spends any time on it (:func:`fit_views`): its pose is a rigid
transform, and its photo, where loaded, is the RGB image its ideal pinhole camera takes (one colour for each ray
of its camera, in order); a view that is not is refused naming it.

Convention
----------
Rays in the field's normalized space (:meth:`~pytest_n2r.field.space.SceneSpace.normalize_rays`), float32, on the
fitting device; colours as the photos hold them (uint8 RGB); ``view`` indexes the training views.
"""

from __future__ import annotations

import math
from collections.abc import Sequence

import numpy as np
import torch

from ..data.capture import Capture, CapturedView
from ..errors import FitError, InvalidArgument
from ..field.space import SceneSpace
from ..geometry import camera_rays, check_pose
from .free_memory import free_bytes
from .memory import HEADROOM, byte_count

__all__ = ["CONVERT_BYTES", "RAY_BYTES", "TrainingRays", "check_view", "fit_views", "ray_bytes"]

#: Bytes a training pixel holds for the fit: its direction (3 float32), colour (3 uint8) and photo (int64).
RAY_BYTES = 3 * 4 + 3 + 8
#: Bytes a pixel of the photo being converted takes at the peak: its pixel grid, directions and origins in float64
#: and the normalized float32 copies (measured with ``tracemalloc``: 120).
CONVERT_BYTES = 128


def check_view(view: CapturedView) -> None:
    """Refuse ``view`` with an :class:`~pytest_n2r.errors.InvalidArgument` naming it where a fit cannot use it:
    its ``c2w`` is not a rigid transform, or it has a photo that is not ``height × width × 3`` uint8 RGB of an
    undistorted camera (a fit's rays are ideal pinhole rays, one a pixel of the camera, coloured in order)."""
    check_pose(view.c2w, f"view {view.name!r}: c2w")
    image, camera = view.image, view.camera
    if image is None:
        return
    if camera.distortion:
        raise InvalidArgument(f"view {view.name!r}: its camera has lens distortion {camera.distortion}; a fit's rays "
                              "are ideal pinhole rays: undistort the photo (Camera.undistort_image) and give its "
                              "camera.undistorted()")
    expected = (camera.height, camera.width, 3)
    if not isinstance(image, np.ndarray) or image.dtype != np.uint8 or image.shape != expected:
        found = (f"{image.dtype} of shape {image.shape}" if isinstance(image, np.ndarray)
                 else f"a {type(image).__name__}")
        raise InvalidArgument(f"view {view.name!r}: image is {found}; expected uint8 RGB of shape {expected}, "
                              f"the size of its camera ({camera.width}×{camera.height} pixels)")


def fit_views(capture: Capture) -> list[CapturedView]:
    """The training views of ``capture`` with a photo, what a fit draws its rays from, once every view is checked
    (:func:`check_view`: held-out views' poses and photos are used too); a :class:`~pytest_n2r.errors.FitError`
    where there is none, saying why."""
    for view in capture.views:
        check_view(view)
    train = capture.train_views
    if not train:
        raise FitError(f"capture {capture.source!r} has no training view: " + (
            f"all {len(capture.views)} of its views are held out" if capture.views else "it has no views"))
    with_image = [v for v in train if v.image is not None]
    if not with_image:
        raise FitError(f"capture {capture.source!r} has no training view with an image: its {len(train)} training "
                       "views were loaded without images; load it with images")
    return with_image


def ray_bytes(views: Sequence[CapturedView]) -> tuple[int, int]:
    """The bytes the rays of ``views`` take: held for the fit, and at the peak while they are built on the host
    (each photo's rays and their concatenation alive at once, with one photo's conversion)."""
    sizes = [photo.shape[0] * photo.shape[1] for photo in map(_photo, views)]
    return RAY_BYTES * sum(sizes), 2 * RAY_BYTES * sum(sizes) + CONVERT_BYTES * max(sizes)


def _photo(view: CapturedView) -> np.ndarray:
    """The photo of ``view`` that its rays are coloured from; refused naming ``view`` where none was loaded."""
    if view.image is None:
        raise InvalidArgument(f"view {view.name!r} has no photo: training rays are drawn from photos (load the "
                              "capture with images; fit_views keeps the training views that have one)")
    return view.image


class TrainingRays:
    """The training pixels of ``views`` (each with a photo) as rays in ``space`` on ``device``: ``origins``
    ``(views, 3)``, and per pixel ``d`` ``(n, 3)``, ``rgb`` ``(n, 3)`` uint8 and ``view`` ``(n,)``. A view a fit
    cannot use is refused naming it (:func:`check_view`); the rays are refused with a
    :class:`~pytest_n2r.errors.FitError` where building them would take more than :data:`HEADROOM` of the host's
    free memory, or holding them more than that of the device's (not checked where it is unknown)."""

    def __init__(self, views: Sequence[CapturedView], space: SceneSpace, device: torch.device):
        for view in views:
            check_view(view)
        held, building = ray_bytes(views)
        pixels = held // RAY_BYTES
        _check(views, pixels, building, free_bytes(torch.device("cpu")), "")
        if device.type != "cpu":
            _check(views, pixels, held, free_bytes(device), f" on {device}")
        origins, directions, colors, owners = [], [], [], []
        for k, view in enumerate(views):
            o, d = space.normalize_rays(*camera_rays(view.camera, view.c2w))
            origins.append(o.reshape(-1, 3)[0].copy())  # a copy: the view would keep the photo's every origin
            directions.append(d.reshape(-1, 3))
            colors.append(_photo(view).reshape(-1, 3))
            owners.append(np.full(len(colors[-1]), k, dtype=np.int64))
        self.origins = torch.from_numpy(np.stack(origins)).to(device)
        self.view = torch.from_numpy(np.concatenate(owners)).to(device)
        self.d = torch.from_numpy(np.concatenate(directions)).to(device)
        self.rgb = torch.from_numpy(np.concatenate(colors)).to(device)
        self.n = self.d.shape[0]

    def o(self, pick: torch.Tensor) -> torch.Tensor:
        """The origins of the rays ``pick``, ``(len(pick), 3)``."""
        return self.origins[self.view[pick]]


def _check(views: Sequence[CapturedView], pixels: int, needed: int, free: int | None, where: str) -> None:
    if free is None or needed <= HEADROOM * free:
        return
    said = (f"the {len(views)} training photos hold {pixels:,} pixels: as training rays they need {byte_count(needed)}"
            f"{where}")
    if free <= 0:
        raise FitError(f"{said}, and no memory is free")
    smaller = math.ceil(10 * math.sqrt(needed / (HEADROOM * free))) / 10
    raise FitError(f"{said}, {byte_count(free)} free (at most {HEADROOM:.0%} of it is taken); fit them at least "
                   f"{smaller:g}× smaller along each side (with n2r fit, --downscale {smaller:g} times the one given)")
