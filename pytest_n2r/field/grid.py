"""The scene field: a sparse voxel grid of density and colour over a contracted scene space.

Values live on grid vertices (trilinear interpolation between them):

- column 0: raw density; the density is ``σ = softplus(raw + density_shift)`` per voxel (a sample spanning
  ``step_ratio`` voxels has opacity ``1 - exp(-σ·step_ratio)``), so it is rescaled when the grid is refined;
- columns 1…: colour as real spherical harmonics of degree ``sh_degree`` (0: view-independent, 1: four
  coefficients per channel), stored ``[l·3 + channel]``; the colour is ``sigmoid(Σ_l Y_l(dir)·k_l)``.

An occupancy grid over the ``(resolution - 1)³`` cells marks where the field has something; rays take
samples only in occupied cells. A scene file stores only the vertices of occupied cells (float16).
"""

from __future__ import annotations

import math
from dataclasses import dataclass, replace

import torch
import torch.nn.functional as F

from .._validation import as_unit_rgb
from ..errors import InvalidArgument, SceneFileError
from .space import SceneSpace

__all__ = ["SceneField", "n_sh_coefficients", "FIELD_TENSORS"]

#: Names of the tensors a scene file stores for the field.
FIELD_TENSORS = ("occupancy", "vertex_index", "vertex_values")


def n_sh_coefficients(sh_degree: int) -> int:
    """Spherical-harmonics coefficients per colour channel of ``sh_degree`` (0 or 1)."""
    if sh_degree not in (0, 1):
        raise InvalidArgument(f"sh_degree={sh_degree!r}: expected 0 (view-independent colour) or 1")
    return (sh_degree + 1) ** 2


def density_shift_for(alpha: float, step_ratio: float) -> float:
    """The shift that makes a raw density of 0 give opacity ``alpha`` over one sample of ``step_ratio`` voxels."""
    sigma = -math.log1p(-alpha) / step_ratio
    return float(sigma + math.log(-math.expm1(-sigma)))  # softplus⁻¹(σ)


def inverse_softplus(y: torch.Tensor) -> torch.Tensor:
    """``softplus⁻¹`` for ``y > 0`` (clamped at 1e-12), stable for large and small ``y``."""
    y = y.clamp(min=1e-12)
    return y + torch.log(-torch.expm1(-y))


@dataclass(eq=False)
class SceneField:
    """A fitted (or fitting) scene field; ``values`` ``(resolution³, 1 + 3·n_sh)`` float32 and ``occupancy``
    ``(resolution-1,)*3`` bool live on the same device.

    ``background`` (RGB in [0, 1]) is what the transmittance a ray has left stands for: the colour the fit
    composited its rays over, in expectation (mid-grey for a fit over random backgrounds). Rendering over
    it is the prediction the fit's loss was minimized for.
    """

    space: SceneSpace
    values: torch.Tensor
    occupancy: torch.Tensor
    density_shift: float
    sh_degree: int
    background: tuple[float, float, float] = (0.0, 0.0, 0.0)

    def __post_init__(self) -> None:
        n = self.values.shape[0]
        res = round(n ** (1.0 / 3.0))
        if res ** 3 != n or res < 4:
            raise InvalidArgument(f"values has {n} rows; expected resolution³ rows with resolution ≥ 4")
        width = 1 + 3 * n_sh_coefficients(self.sh_degree)
        if self.values.ndim != 2 or self.values.shape[1] != width:
            raise InvalidArgument(f"values has shape {tuple(self.values.shape)}; expected ({n}, {width}) "
                                  f"for sh_degree={self.sh_degree}")
        if tuple(self.occupancy.shape) != (res - 1,) * 3:
            raise InvalidArgument(f"occupancy has shape {tuple(self.occupancy.shape)}; expected {(res - 1,) * 3}")
        background = as_unit_rgb(self.background)
        if background is None:
            raise InvalidArgument(f"background={self.background!r}: expected three values in [0, 1]")
        self.background = background

    @classmethod
    def empty(cls, space: SceneSpace, resolution: int, sh_degree: int, alpha: float, step_ratio: float,
              device: torch.device | str = "cpu",
              background: tuple[float, float, float] = (0.0, 0.0, 0.0)) -> "SceneField":
        """A field with opacity ``alpha`` per sample everywhere, grey colour, every cell occupied."""
        width = 1 + 3 * n_sh_coefficients(sh_degree)
        return cls(space, torch.zeros(resolution ** 3, width, device=device),
                   torch.ones((resolution - 1,) * 3, dtype=torch.bool, device=device),
                   density_shift_for(alpha, step_ratio), sh_degree, background)

    @property
    def resolution(self) -> int:
        return self.occupancy.shape[0] + 1

    @property
    def device(self) -> torch.device:
        return self.values.device

    def to(self, device: torch.device | str) -> "SceneField":
        return replace(self, values=self.values.to(device), occupancy=self.occupancy.to(device))

    def vertex_grid(self) -> torch.Tensor:
        """The values as a ``(channels, R, R, R)`` view."""
        res = self.resolution
        return self.values.T.reshape(-1, res, res, res)

    def cell_alpha(self, step_ratio: float) -> torch.Tensor:
        """``(R-1)³`` opacity over one sample of ``step_ratio`` voxels at each cell's densest corner."""
        raw = self.vertex_grid()[:1][None]
        corner_max = F.max_pool3d(raw, kernel_size=2, stride=1)[0, 0]
        return -torch.expm1(-F.softplus(corner_max + self.density_shift) * step_ratio)

    def upsampled(self, resolution: int) -> "SceneField":
        """The same field on a finer grid: vertex values resampled trilinearly, densities rescaled to the
        smaller voxel (same opacity per unit length), occupancy carried over with one cell of dilation."""
        grid = F.interpolate(self.vertex_grid()[None], size=(resolution,) * 3, mode="trilinear",
                             align_corners=True)[0]
        values = grid.reshape(grid.shape[0], -1).T.contiguous()
        ratio = (resolution - 1) / (self.resolution - 1)
        sigma = F.softplus(values[:, 0] + self.density_shift) / ratio
        values[:, 0] = inverse_softplus(sigma) - self.density_shift
        occ = F.interpolate(self.occupancy[None, None].float(), size=(resolution - 1,) * 3, mode="nearest")
        occ = F.max_pool3d(occ, kernel_size=3, stride=1, padding=1)[0, 0] > 0
        return replace(self, values=values, occupancy=occ)

    def used_vertices(self) -> torch.Tensor:
        """``R³`` bool: the vertices of occupied cells (the only ones a render reads)."""
        occ = F.pad(self.occupancy[None, None].float(), (1, 1, 1, 1, 1, 1))
        return (F.max_pool3d(occ, kernel_size=2, stride=1)[0, 0] > 0).reshape(-1)

    def quantized(self) -> "SceneField":
        """The field as a scene file stores it: float16 values at used vertices, zeros elsewhere."""
        used = self.used_vertices()
        values = torch.zeros_like(self.values)
        values[used] = self.values[used].half().float()
        return replace(self, values=values, occupancy=self.occupancy.clone())

    # -- serialization (the scene file module wraps these in a zip) -----------------------------------------
    def metadata(self) -> dict:
        """JSON-ready description of the field (everything but the tensors)."""
        return {"space": self.space.to_dict(), "resolution": self.resolution, "sh_degree": self.sh_degree,
                "density_shift": self.density_shift, "background": list(self.background)}

    def tensors(self) -> dict[str, torch.Tensor]:
        """The field's tensors as a scene file stores them (CPU, contiguous; see :data:`FIELD_TENSORS`)."""
        used = self.used_vertices().cpu()
        index = torch.nonzero(used).reshape(-1).to(torch.int64)
        return {
            "occupancy": self.occupancy.cpu().to(torch.uint8).contiguous(),
            "vertex_index": index.contiguous(),
            "vertex_values": self.values.cpu()[index].half().contiguous(),
        }

    @classmethod
    def from_tensors(cls, metadata: dict, tensors: dict[str, torch.Tensor], source: str = "scene file") -> "SceneField":
        """Rebuild a field from :meth:`metadata` and :meth:`tensors`, checking names, dtypes and shapes."""
        try:
            space = SceneSpace.from_dict(metadata["space"])
            res, sh_degree = int(metadata["resolution"]), int(metadata["sh_degree"])
            shift = float(metadata["density_shift"])
            background = metadata["background"]
        except (KeyError, TypeError, ValueError, InvalidArgument) as exc:
            raise SceneFileError(f"{source}: field metadata is incomplete or invalid ({exc})") from None
        if not 4 <= res <= 2048 or not math.isfinite(shift):
            raise SceneFileError(f"{source}: field resolution {res} / density_shift {shift} out of range")
        if as_unit_rgb(background) is None:
            raise SceneFileError(f"{source}: field background {background!r} is not three values in [0, 1]")
        try:
            width = 1 + 3 * n_sh_coefficients(sh_degree)
        except InvalidArgument as exc:
            raise SceneFileError(f"{source}: {exc}") from None
        missing = [name for name in FIELD_TENSORS if name not in tensors]
        if missing:
            raise SceneFileError(f"{source}: field tensors {missing} are missing; expected {list(FIELD_TENSORS)}")
        occ, index, vals = (tensors[n] for n in FIELD_TENSORS)
        expected = {
            "occupancy": ((res - 1,) * 3, torch.uint8),
            "vertex_index": ((index.shape[0],), torch.int64),
            "vertex_values": ((index.shape[0], width), torch.float16),
        }
        for name, (shape, dtype) in expected.items():
            t = tensors[name]
            if tuple(t.shape) != shape or t.dtype != dtype or t.ndim != len(shape):
                raise SceneFileError(f"{source}: tensor {name!r} is {t.dtype} {tuple(t.shape)}; expected {dtype} {shape}")
        if index.numel() and (int(index.min()) < 0 or int(index.max()) >= res ** 3):
            raise SceneFileError(f"{source}: tensor 'vertex_index' points outside the {res}³ grid")
        if not torch.isfinite(vals).all():
            raise SceneFileError(f"{source}: tensor 'vertex_values' holds NaN or Inf")
        values = torch.zeros(res ** 3, width)
        values[index] = vals.float()
        field = cls(space, values, occ.bool(), shift, sh_degree, background)
        if not torch.equal(field.used_vertices().nonzero().reshape(-1), index):
            raise SceneFileError(f"{source}: 'vertex_index' does not list exactly the vertices of occupied cells")
        return field

    def describe(self) -> dict:
        """Size figures for reports: resolution, occupied fraction, stored vertices."""
        used = int(self.used_vertices().sum())
        return {"resolution": self.resolution, "sh_degree": self.sh_degree,
                "occupied_fraction": float(self.occupancy.float().mean()), "stored_vertices": used}

