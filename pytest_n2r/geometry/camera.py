"""Pinhole camera intrinsics.

Convention
----------
- Pixel centres at integer coordinates (OpenCV): the top-left pixel's centre is ``(0, 0)`` and the
  image spans ``[-0.5, width - 0.5] x [-0.5, height - 0.5]``. COLMAP, nerfstudio and instant-ngp put
  the top-left centre at ``(0.5, 0.5)``: ``cx_opencv = cx_colmap - 0.5`` (see :meth:`Camera.from_colmap_pixels`).
- Camera axes: x right, y down, z forward (OpenCV). A camera-frame point ``(X, Y, Z)`` with ``Z > 0``
  projects to ``u = fx * X / Z + cx``, ``v = fy * Y / Z + cy``.
- ``distortion`` holds OpenCV coefficients ``(k1, k2, p1, p2[, k3[, k4, k5, k6]])``, stored without
  trailing zero terms (8 → 5 → 4 → none), so equal lenses compare equal; rendered views are always
  ideal pinhole images, so a camera used for rendering has ``distortion == ()``.
- A lens model is used only while it does not fold over: with ``r`` the normalized undistorted radius
  (``sqrt(x² + y²)``, ``x = (u - cx) / fx``) and ``r_d = r·(1 + k1 r² + k2 r⁴ + k3 r⁶) / (1 + k4 r² + k5 r⁴ + k6 r⁶)``,
  ``r_d`` must increase (``d r_d / d r > 0``, the denominator ``> 0``) from 0 out to the radius of the image's
  farthest corner, and the corner's distorted pixel offset must fit a float32. Tangential ``p1 p2`` are left out of
  the check (they shift a point sideways, they do not fold the radial map). :meth:`Camera.undistort_image` refuses
  a lens that fails it (:meth:`Camera.check_lens`); building a ``Camera`` does not, as a camera kept for its
  numbers (a scene file, a pose set written back) undistorts nothing.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field, replace
from functools import lru_cache

import numpy as np

from .._validation import check_array, check_positive, check_real
from ..errors import InvalidArgument, InvalidType

__all__ = ["Camera"]

#: Radii sampled from 0 to the corner radius by :meth:`Camera.check_lens` (the slope of a polynomial of degree 7
#: over 7 of degree 6: far more samples than it has sign changes).
_FOLD_SAMPLES = 4097
_FLOAT32_MAX = float(np.finfo(np.float32).max)


@dataclass(frozen=True)
class Camera:
    """Pinhole intrinsics of an image of ``width`` x ``height`` pixels (all values in pixels)."""

    width: int
    height: int
    fx: float
    fy: float
    cx: float
    cy: float
    distortion: tuple[float, ...] = field(default=())

    def __post_init__(self) -> None:
        for name in ("width", "height"):
            object.__setattr__(self, name, _pixels(f"Camera {name}", getattr(self, name)))
        for name in ("fx", "fy"):
            object.__setattr__(self, name, check_positive(f"Camera {name}", getattr(self, name)))
        for name in ("cx", "cy"):
            object.__setattr__(self, name, check_real(f"Camera {name}", getattr(self, name)))
        coeffs = tuple(check_real("Camera distortion", c) for c in self.distortion)
        if len(coeffs) not in (0, 4, 5, 8):
            raise InvalidArgument(
                f"Camera distortion has {len(coeffs)} coefficients; expected 0, 4 (k1 k2 p1 p2), 5 (+k3) or 8"
            )
        # Canonical form, so equal lenses compare equal: trailing zero terms add nothing in OpenCV's model.
        if len(coeffs) == 8 and not any(coeffs[5:]):
            coeffs = coeffs[:5]
        if len(coeffs) == 5 and not coeffs[4]:
            coeffs = coeffs[:4]
        if coeffs and not any(coeffs):
            coeffs = ()
        object.__setattr__(self, "distortion", coeffs)

    @classmethod
    def from_K(cls, K: np.ndarray, width: int, height: int, distortion: tuple[float, ...] = ()) -> Camera:
        """Build from a 3x3 OpenCV intrinsic matrix (pixel centres at integer coordinates): ``[[fx, 0, cx],
        [0, fy, cy], [0, 0, 1]]``. A skew, a last row other than ``[0, 0, 1]`` (a K scaled as a whole) or an
        entry below the diagonal is refused: this camera model has none of them.

        >>> Camera.from_K(2 * Camera(640, 480, 500, 500, 319.5, 239.5).K, 640, 480)
        Traceback (most recent call last):
        ...
        pytest_n2r.errors.InvalidArgument: K's last row is [0.0, 0.0, 2.0]; expected [0, 0, 1]
        """
        K = check_array("K", K, "3 3", dtype=np.float64)
        if np.abs(K[2] - (0.0, 0.0, 1.0)).max() > 1e-9:
            raise InvalidArgument(f"K's last row is {K[2].tolist()}; expected [0, 0, 1]")
        # a K decomposed from a projection matrix carries rounding: a skew of 1e-12 pixels is none
        if max(abs(K[0, 1]), abs(K[1, 0])) > 1e-9 * max(abs(K[0, 0]), abs(K[1, 1]), 1.0):
            raise InvalidArgument(f"K has skew or shear (K[0, 1]={float(K[0, 1])!r}, K[1, 0]={float(K[1, 0])!r}); "
                                  "this camera model has none: expected 0")
        return cls(width, height, K[0, 0], K[1, 1], K[0, 2], K[1, 2], tuple(distortion))

    @classmethod
    def from_colmap_pixels(
        cls, width: int, height: int, fx: float, fy: float, cx: float, cy: float,
        distortion: tuple[float, ...] = (),
    ) -> Camera:
        """Build from intrinsics whose top-left pixel centre is ``(0.5, 0.5)`` (COLMAP, nerfstudio)."""
        return cls(width, height, fx, fy, float(cx) - 0.5, float(cy) - 0.5, tuple(distortion))

    @property
    def K(self) -> np.ndarray:
        """The 3x3 intrinsic matrix, float64."""
        return np.array([[self.fx, 0.0, self.cx], [0.0, self.fy, self.cy], [0.0, 0.0, 1.0]])

    @property
    def size(self) -> tuple[int, int]:
        """``(width, height)`` in pixels, the order OpenCV uses."""
        return self.width, self.height

    def resized(self, width: int, height: int) -> Camera:
        """The same camera for an image resized to ``width`` x ``height``.

        Per axis with scale ``s = new / old``: ``f' = f * s`` and ``c' = (c + 0.5) * s - 0.5``, so the
        image borders (not the pixel centres) stay where they were. ``width`` and ``height`` are whole pixels
        (ints >= 1): a fractional size has no image.

        >>> Camera(640, 480, 500.0, 500.0, 319.5, 239.5).resized(320, 240).cx
        159.5
        >>> Camera(640, 480, 500.0, 500.0, 319.5, 239.5).resized(320.5, 240)
        Traceback (most recent call last):
        ...
        pytest_n2r.errors.InvalidType: Camera.resized width=320.5 must be an int (pixels)
        """
        width, height = _pixels("Camera.resized width", width), _pixels("Camera.resized height", height)
        sx, sy = width / self.width, height / self.height
        return replace(
            self, width=width, height=height, fx=self.fx * sx, fy=self.fy * sy,
            cx=(self.cx + 0.5) * sx - 0.5, cy=(self.cy + 0.5) * sy - 0.5,
        )

    def scaled(self, scale: float) -> Camera:
        """Resize by a factor (``0.25`` = a quarter of the width and height, rounded to whole pixels)."""
        scale = check_positive("scale", scale)
        return self.resized(max(1, round(self.width * scale)), max(1, round(self.height * scale)))

    def fit_within(self, max_size: int) -> Camera:
        """Downscale (never upscale) so the longer side is at most ``max_size`` pixels."""
        longer = max(self.width, self.height)
        return self if longer <= max_size else self.scaled(max_size / longer)

    def undistorted(self) -> Camera:
        """The ideal pinhole camera that :func:`undistort_image` maps this camera's images to."""
        return replace(self, distortion=())

    def undistort_image(self, image: np.ndarray) -> np.ndarray:
        """Remove lens distortion from an image taken with this camera (keeps ``K`` and the size).

        The result is what :meth:`undistorted` sees. Pixels that map from outside the source image are
        filled by replicating the border, so no black wedges enter a fit.
        """
        import cv2

        if not self.distortion:
            return image
        if image.shape[:2] != (self.height, self.width):
            raise InvalidArgument(
                f"image of shape {image.shape[:2]} does not match the camera's {self.height}x{self.width}"
            )
        self.check_lens()
        map1, map2 = _undistort_maps(self)
        return cv2.remap(image, map1, map2, cv2.INTER_LINEAR, borderMode=cv2.BORDER_REPLICATE)

    def corner_radius(self) -> float:
        """The normalized radius ``sqrt(((u - cx) / fx)² + ((v - cy) / fy)²)`` of the image's farthest corner (the
        corners of the outer pixels' edges, ``u`` in ``{-0.5, width - 0.5}``, ``v`` in ``{-0.5, height - 0.5}``)."""
        dx = max(abs(-0.5 - self.cx), abs(self.width - 0.5 - self.cx)) / self.fx
        dy = max(abs(-0.5 - self.cy), abs(self.height - 0.5 - self.cy)) / self.fy
        return math.hypot(dx, dy)

    def check_lens(self) -> Camera:
        """This camera if its distortion does not fold over within the image (see the module's *Convention*), else
        an :class:`InvalidArgument` naming the coefficients, the radius where it folds and the corner radius.

        >>> Camera(400, 300, 180.0, 180.0, 199.5, 149.5, (-0.25, 0.0, 0.0, 0.0)).check_lens()
        Traceback (most recent call last):
        ...
        pytest_n2r.errors.InvalidArgument: Camera distortion (k1, k2, p1, p2)=(-0.25, 0.0, 0.0, 0.0) folds over at \
normalized radius 1.155 (the distorted radius stops increasing there), inside the radius 1.389 of the image's \
corners: undistorting would mirror the image beyond it; expected a lens model whose distorted radius increases \
out to the corners (recalibrate the camera, or crop the photo)
        """
        if not self.distortion:
            return self
        k = (*self.distortion, 0.0, 0.0, 0.0, 0.0)[:8]
        names = ("k1", "k2", "p1", "p2", "k3", "k4", "k5", "k6")[: len(self.distortion)]
        lens = f"Camera distortion ({', '.join(names)})={self.distortion!r}"
        corner = self.corner_radius()
        r = np.linspace(0.0, corner, _FOLD_SAMPLES)
        r2 = r * r
        with np.errstate(all="ignore"):
            num = 1.0 + r2 * (k[0] + r2 * (k[1] + r2 * k[4]))
            den = 1.0 + r2 * (k[5] + r2 * (k[6] + r2 * k[7]))
            dnum = r * (2 * k[0] + r2 * (4 * k[1] + r2 * 6 * k[4]))  # d num / d r
            dden = r * (2 * k[5] + r2 * (4 * k[6] + r2 * 6 * k[7]))
            slope = (num + r * dnum) * den - r * num * dden  # d r_d / d r times den², whose sign it has where den > 0
            offset = r[-1] * num[-1] / den[-1] * max(self.fx, self.fy)  # the corner's distorted offset, pixels
        bad = ~((den > 0) & (slope > 0) & np.isfinite(slope))
        if bad.any():
            where = float(r[int(np.argmax(bad))])
            why = "its rational denominator reaches 0" if not den[int(np.argmax(bad))] > 0 else \
                "the distorted radius stops increasing"
            raise InvalidArgument(
                f"{lens} folds over at normalized radius {where:.4g} ({why} there), inside the radius {corner:.4g} of "
                "the image's corners: undistorting would mirror the image beyond it; expected a lens model whose "
                "distorted radius increases out to the corners (recalibrate the camera, or crop the photo)")
        if not abs(offset) < _FLOAT32_MAX:
            raise InvalidArgument(
                f"{lens} moves the image's corner (normalized radius {corner:.4g}) {abs(offset):.4g} pixels from the "
                "principal point, beyond a float32 remap table; expected coefficients of a real lens")
        return self

    def to_dict(self) -> dict:
        """Plain JSON-ready form (OpenCV pixel convention)."""
        return {
            "width": self.width, "height": self.height, "fx": self.fx, "fy": self.fy,
            "cx": self.cx, "cy": self.cy, "distortion": list(self.distortion),
        }

    @classmethod
    def from_dict(cls, data: dict) -> Camera:
        """Inverse of :meth:`to_dict`."""
        try:
            return cls(
                int(data["width"]), int(data["height"]), data["fx"], data["fy"], data["cx"], data["cy"],
                tuple(data.get("distortion", ())),
            )
        except KeyError as exc:
            raise InvalidArgument(f"camera record is missing the field {exc.args[0]!r}") from None


def _pixels(name: str, value: object) -> int:
    """``value`` as a whole number of pixels >= 1, or raise naming ``name`` (a bool or a float is not one)."""
    if isinstance(value, bool) or not isinstance(value, (int, np.integer)):
        raise InvalidType(f"{name}={value!r} must be an int (pixels)")
    if value < 1:
        raise InvalidArgument(f"{name}={value!r} must be >= 1 pixel")
    return int(value)


@lru_cache(maxsize=8)
def _undistort_maps(camera: Camera) -> tuple[np.ndarray, np.ndarray]:
    """The remap tables of :meth:`Camera.undistort_image`, cached: a capture has one camera for many images."""
    import cv2

    return cv2.initUndistortRectifyMap(
        camera.K, np.asarray(camera.distortion), None, camera.K, (camera.width, camera.height), cv2.CV_32FC1
    )
