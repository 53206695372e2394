"""Every training pixel of a capture as a ray and its colour: what each step of a fit draws its batch from.

The rays are held for the whole fit, 23 bytes a pixel; each photo's origin is stored once, not per pixel (every ray
of a photo leaves its camera's centre: 12 bytes a pixel saved, the same rays). They are sized against the memory
free before they are made (:func:`~pytest_n2r.fit.free_memory.free_bytes`): a capture too large for the machine is
refused with its pixels, the bytes and how much smaller to fit it, not killed by the kernel while its rays are built
(``n2r fit --downscale 1`` on a hundred 12-megapixel photos would hold 28 GB of rays, twice that while built).

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

from ..data.capture import CapturedView
from ..errors import FitError
from ..field.space import SceneSpace
from ..geometry import camera_rays
from .free_memory import free_bytes
from .memory import HEADROOM, byte_count

__all__ = ["RAY_BYTES", "TrainingRays"]

#: Bytes a training pixel holds for the fit: its direction (3 float32), colour (3 uint8) and photo (int64).
RAY_BYTES = 3 * 4 + 3 + 8
#: Bytes a pixel of the photo being converted takes on top: its origin and direction in float64 and float32.
_CONVERT_BYTES = 2 * 3 * 8 + 2 * 3 * 4


class TrainingRays:
    """The training pixels of ``views`` as rays in ``space`` on ``device``: ``origins`` ``(views, 3)``, and per
    pixel ``d`` ``(n, 3)``, ``rgb`` ``(n, 3)`` uint8 and ``view`` ``(n,)``. ``free``: the bytes that may be
    allocated (default: what the device has free, :func:`~pytest_n2r.fit.free_memory.free_bytes`; not checked
    where that is unknown); a capture whose rays would take more than :data:`HEADROOM` of them is a
    :class:`~pytest_n2r.errors.FitError`."""

    def __init__(self, views: Sequence[CapturedView], space: SceneSpace, device: torch.device,
                 free: int | None = None):
        free = free_bytes(device) if free is None else free
        sizes = [v.image.shape[0] * v.image.shape[1] for v in views]
        # the photos' arrays and their concatenation are alive at once, with one photo's conversion
        needed = 2 * RAY_BYTES * sum(sizes) + _CONVERT_BYTES * max(sizes)
        if free is not None and needed > HEADROOM * free:
            smaller = math.ceil(10 * math.sqrt(needed / (HEADROOM * free))) / 10
            raise FitError(f"the {len(views)} training photos hold {sum(sizes):,} pixels: as training rays they need "
                           f"{byte_count(needed)}, {byte_count(free)} free (at most {HEADROOM:.0%} of it is "
                           f"taken); fit them at least {smaller:g}× smaller along each side (n2r fit --downscale)")
        origins, directions, colors, owners = [], [], [], []
        for k, view in enumerate(views):
            o, d = space.normalize_rays(*camera_rays(view.camera, view.c2w))
            origins.append(o.reshape(-1, 3)[0])
            directions.append(d.reshape(-1, 3))
            colors.append(view.image.reshape(-1, 3))
            owners.append(np.full(len(colors[-1]), k, dtype=np.int64))
        self.origins = torch.from_numpy(np.stack(origins)).to(device)
        self.view = torch.from_numpy(np.concatenate(owners)).to(device)
        self.d = torch.from_numpy(np.concatenate(directions)).to(device)
        self.rgb = torch.from_numpy(np.concatenate(colors)).to(device)
        self.n = self.d.shape[0]

    def o(self, pick: torch.Tensor) -> torch.Tensor:
        """The origins of the rays ``pick``, ``(len(pick), 3)``."""
        return self.origins[self.view[pick]]
