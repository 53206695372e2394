"""A set of 3-D Gaussians as 3D Gaussian Splatting stores them (the parameters of a ``.ply``).

Convention
----------
- ``means`` are world points (scene units) in the world frame of the capture's cameras.
- ``quats`` are rotations as **w-first** quaternions ``(w, x, y, z)`` (Hamilton), local → world; they are
  stored as written (not necessarily unit) and normalized when used.
- ``log_scales`` are the natural logarithms of the standard deviations along the Gaussian's local axes
  (scene units); the 3-D covariance is ``R S Sᵀ Rᵀ`` with ``S = diag(exp(log_scales))``.
- ``opacity_logits`` are pre-sigmoid: the peak opacity is ``1 / (1 + exp(-logit))``.
- ``sh`` are spherical-harmonics colour coefficients ``(N, K, 3)`` (:mod:`pytest_n2r.splats.sh`).
All arrays are float32, as the file stores them, so a scene renders the same from a ``.ply`` and from the
``.n2r`` file it was packed into.
"""

from __future__ import annotations

import hashlib
from dataclasses import dataclass

import numpy as np

from ..errors import InvalidArgument, InvalidType
from .sh import sh_degree_of

__all__ = ["TENSORS", "Gaussians"]

#: The arrays of a Gaussian set, by name, with their shapes after the count ``N``.
TENSORS = {"means": (3,), "quats": (4,), "log_scales": (3,), "opacity_logits": (), "sh": (None, 3)}


@dataclass(frozen=True, eq=False)
class Gaussians:
    """``N`` Gaussians (see the module *Convention*); checked on construction (shapes, finite values,
    non-zero quaternions), so a renderer never sees a NaN."""

    means: np.ndarray
    quats: np.ndarray
    log_scales: np.ndarray
    opacity_logits: np.ndarray
    sh: np.ndarray

    def __post_init__(self) -> None:
        n = None
        for name, tail in TENSORS.items():
            value = getattr(self, name)
            try:
                array = np.ascontiguousarray(value, dtype=np.float32)
            except (TypeError, ValueError):
                raise InvalidType(f"Gaussians.{name} must be a numeric array, got {type(value).__name__}") from None
            n = len(array) if n is None and array.ndim else n
            ok = array.ndim == 1 + len(tail) and len(array) == n and all(
                t is None or t == s for t, s in zip(tail, array.shape[1:]))
            if not ok:
                shape = ", ".join(["N", *("K" if t is None else str(t) for t in tail)])
                raise InvalidType(f"Gaussians.{name} has shape {array.shape}; expected ({shape}) with N = {n}")
            finite = np.isfinite(array).reshape(len(array), int(np.prod(array.shape[1:]))).all(axis=1)
            if not finite.all():
                first = int(np.argmin(finite))
                raise InvalidArgument(f"Gaussians.{name} of Gaussian {first} is {array[first].tolist()}; "
                                      f"expected finite values ({int((~finite).sum())} Gaussians are not)")
            object.__setattr__(self, name, array)
        if sh_degree_of(self.sh.shape[1]) is None:
            raise InvalidArgument(f"Gaussians.sh has {self.sh.shape[1]} coefficients per channel; expected 1, 4, 9 "
                                  "or 16 (SH degree 0 to 3)")
        norms = np.einsum("ij,ij->i", self.quats.astype(np.float64), self.quats.astype(np.float64))
        if len(norms) and not (norms > 0).all():
            first = int(np.argmin(norms > 0))
            raise InvalidArgument(f"Gaussians.quats of Gaussian {first} is (0, 0, 0, 0); a rotation needs a non-zero "
                                  "quaternion (w, x, y, z)")

    def __len__(self) -> int:
        return len(self.means)

    @property
    def sh_degree(self) -> int:
        """The spherical-harmonics degree, 0 to 3."""
        degree = sh_degree_of(self.sh.shape[1])
        assert degree is not None, "__post_init__ checked the coefficient count"
        return degree

    @property
    def opacities(self) -> np.ndarray:
        """Peak opacities ``(N,)`` in ``(0, 1)``, float64."""
        x = self.opacity_logits.astype(np.float64)
        return 0.5 * (1.0 + np.tanh(0.5 * x))  # the sigmoid without overflow for large |x|

    @property
    def scales(self) -> np.ndarray:
        """Standard deviations ``(N, 3)`` along the local axes, scene units, float64."""
        return np.exp(self.log_scales.astype(np.float64))

    def rotations(self) -> np.ndarray:
        """Local-to-world rotation matrices ``(N, 3, 3)``, float64, of the normalized quaternions."""
        q = self.quats.astype(np.float64)
        w, x, y, z = (q / np.linalg.norm(q, axis=1, keepdims=True)).T
        return np.stack([
            np.stack([1 - 2 * (y * y + z * z), 2 * (x * y - w * z), 2 * (x * z + w * y)], -1),
            np.stack([2 * (x * y + w * z), 1 - 2 * (x * x + z * z), 2 * (y * z - w * x)], -1),
            np.stack([2 * (x * z - w * y), 2 * (y * z + w * x), 1 - 2 * (x * x + y * y)], -1),
        ], axis=1)

    def factors(self) -> np.ndarray:
        """``R S`` ``(N, 3, 3)`` float64 (scene units), the rotation times the scales: the world-frame covariance
        is ``F Fᵀ``. Renderers project ``F``, not the covariance: formed in float64, a long axis's rounding in
        the covariance's entries can exceed a short axis's whole extent."""
        return np.ascontiguousarray(self.rotations() * self.scales[:, None, :])

    def tensors(self) -> dict[str, np.ndarray]:
        """The arrays by name (:data:`TENSORS`), for storing."""
        return {name: getattr(self, name) for name in TENSORS}

    def digest(self) -> str:
        """SHA-256 of every array's bytes and shape (changes when any rendered pixel could)."""
        h = hashlib.sha256()
        for name, array in self.tensors().items():
            h.update(f"{name}{array.shape}".encode())
            h.update(array.tobytes())
        return h.hexdigest()

    def __repr__(self) -> str:
        return f"<Gaussians: {len(self)}, SH degree {self.sh_degree}>"
