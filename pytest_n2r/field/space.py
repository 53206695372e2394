"""The space a scene field lives in: a normalized cube around the captured region plus a contracted shell.

Conventions
-----------
- World (scene) coordinates are normalized by ``p = (x - center) / radius``: the captured region (the SfM
  points and the cameras) becomes the cube ``[-1, 1]³``.
- Everything outside that cube is *contracted* into a shell of thickness ``shell`` (mip-NeRF 360 style, with
  the ∞-norm so the cube stays a cube): with ``r = ‖p‖∞``, ``q = p`` for ``r ≤ 1`` and
  ``q = (1 + shell·(1 - 1/r)) · p / r`` beyond, so all of space fits in ``[-(1+shell), 1+shell]³``. Far walls
  and sky therefore have a place in the field and keep their parallax.
- The field's values live on the vertices of a regular grid of ``resolution³`` vertices over that contracted
  cube; vertex ``(i, j, k)`` sits at ``q = -L + 2L·(i, j, k)/(resolution-1)`` with ``L = 1 + shell``, stored
  x-major (flat index ``(i·R + j)·R + k``).
- Rays are ``x(t) = o + t·d`` with camera-frame ``d_z = 1`` (see :func:`pytest_n2r.geometry.camera_rays`), so the
  ray parameter ``t`` is the z-depth in scene units.
"""

from __future__ import annotations

import json
import math
from dataclasses import dataclass

import numpy as np

from ..errors import InvalidArgument

__all__ = ["SceneSpace"]


@dataclass(frozen=True)
class SceneSpace:
    """A normalized, contracted scene space (see the module docstring).

    ``center`` (3,) and ``radius`` are in scene units; ``shell`` is the thickness of the contracted shell in
    normalized units (0.25: the outer world gets a fifth of the grid on each side).
    """

    center: tuple[float, float, float]
    radius: float
    shell: float = 0.25

    def __post_init__(self) -> None:
        c = np.asarray(self.center, dtype=np.float64)
        if c.shape != (3,) or not np.isfinite(c).all():
            raise InvalidArgument(f"center={self.center!r}: expected three finite numbers")
        if not (math.isfinite(self.radius) and self.radius > 0):
            raise InvalidArgument(f"radius={self.radius!r}: expected a finite number > 0 (scene units)")
        if not (math.isfinite(self.shell) and 0.0 < self.shell <= 4.0):
            raise InvalidArgument(f"shell={self.shell!r}: expected a thickness in (0, 4] (normalized units)")
        object.__setattr__(self, "center", tuple(float(v) for v in c))
        object.__setattr__(self, "radius", float(self.radius))
        object.__setattr__(self, "shell", float(self.shell))

    @classmethod
    def around(cls, bounds: np.ndarray, camera_centers: np.ndarray | None = None, *, shell: float = 0.25,
               padding: float = 0.05) -> SceneSpace:
        """The space whose unit cube holds ``bounds`` ((2, 3) box, scene units) and the camera centres,
        widened by ``padding`` of its size."""
        bounds = np.asarray(bounds, dtype=np.float64)
        if bounds.shape != (2, 3) or not np.isfinite(bounds).all() or (bounds[1] < bounds[0]).any():
            raise InvalidArgument(f"bounds must be a finite (2, 3) box [min, max]; got {bounds!r}")
        lo, hi = bounds[0].copy(), bounds[1].copy()
        if camera_centers is not None and len(camera_centers):
            centers = np.asarray(camera_centers, dtype=np.float64).reshape(-1, 3)
            lo, hi = np.minimum(lo, centers.min(0)), np.maximum(hi, centers.max(0))
        center = (lo + hi) / 2.0
        radius = float((hi - lo).max() / 2.0) * (1.0 + padding)
        if radius <= 0:
            raise InvalidArgument(f"bounds {bounds.tolist()} and the cameras span no volume")
        return cls(tuple(center), radius, shell)

    @property
    def half_size(self) -> float:
        """Half the side of the contracted cube, ``1 + shell`` (normalized units)."""
        return 1.0 + self.shell

    def voxel_size(self, resolution: int) -> float:
        """The spacing of the grid's vertices in normalized units."""
        return 2.0 * self.half_size / (resolution - 1)

    def normalize_rays(self, origins: np.ndarray, directions: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """World rays (scene units, float64) → normalized rays (float32); ``t`` keeps its meaning."""
        center = np.asarray(self.center)
        o = (np.asarray(origins, dtype=np.float64) - center) / self.radius
        d = np.asarray(directions, dtype=np.float64) / self.radius
        return o.astype(np.float32), d.astype(np.float32)

    def contract(self, p: np.ndarray) -> np.ndarray:
        """Normalized points ``(..., 3)`` → contracted points in ``[-(1+shell), 1+shell]³`` (NumPy, float64)."""
        p = np.asarray(p, dtype=np.float64)
        r = np.max(np.abs(p), axis=-1, keepdims=True)
        with np.errstate(divide="ignore", invalid="ignore", over="ignore"):
            outer = (1.0 + self.shell * (1.0 - 1.0 / r)) * p / r
        return np.where(r <= 1.0, p, outer)

    def to_dict(self) -> dict:
        return {"center": list(self.center), "radius": self.radius, "shell": self.shell}

    @classmethod
    def from_dict(cls, data: dict) -> SceneSpace:
        try:
            return cls(tuple(data["center"]), float(data["radius"]), float(data["shell"]))
        except (KeyError, TypeError) as exc:
            raise InvalidArgument(
                f"space {json.dumps(data)[:200]}: expected center, radius and shell ({exc})") from None
