"""The scene field: a sparse voxel grid of density and colour over a contracted scene space.

Values live on grid vertices (trilinear interpolation between them):

- column 0: raw density; the density is ``σ = softplus(raw + density_shift)`` per voxel (a sample spanning
  ``step_ratio`` voxels has opacity ``1 - exp(-σ·step_ratio)``), so it is rescaled when the grid is refined;
- columns 1…: colour as real spherical harmonics of degree ``sh_degree`` (0: view-independent, 1: four
  coefficients per channel, 2: nine), stored ``[l·3 + channel]``; the colour is ``sigmoid(Σ_l Y_l(dir)·k_l)``.

An occupancy grid over the ``(resolution - 1)³`` cells marks where the field has something; rays take
samples only in occupied cells, so only the vertices of occupied cells are ever read.

Storage: a *dense* field holds one row of ``values`` per vertex, x-major (flat index ``(i·R + j)·R + k``). A
*sparse* field holds rows for the vertices of occupied cells only, and ``rows`` (``R³`` int32) maps a flat
vertex index to its row (-1: not stored). A fit refines to sparse fields and scene files load as sparse
fields, so memory follows the surfaces, not the cube: the demo wall's 384³ grid of four values per vertex
takes 0.9 GB dense and 0.28 GB sparse, most of it the row map. A scene file stores only the vertices of
occupied cells (float16).
"""

from __future__ import annotations

import math
from dataclasses import dataclass, replace

import numpy as np
import torch
import torch.nn.functional as F

from .._validation import as_unit_rgb
from ..errors import InvalidArgument, SceneFileError
from .config import SH_DEGREES
from .density import MAX_DENSITY_SHIFT, density_shift_for
from .query import interpolate, trilinear
from .space import SceneSpace

__all__ = ["SceneField", "check_field_metadata", "dilated", "n_sh_coefficients", "opacity", "used_vertex_index",
           "used_vertex_mask", "vertex_ijk", "FIELD_TENSORS", "UPSAMPLE_CHUNK"]

#: Names of the tensors a scene file stores for the field.
FIELD_TENSORS = ("occupancy", "vertex_index", "vertex_values")
#: Vertices :meth:`SceneField.upsampled` resamples (and :meth:`SceneField.quantized` rounds) at a time: the
#: 8 corners gathered for each take 2²⁰ values (16 MB at 4 values a vertex, 117 MB at SH degree 2's 28), where
#: all at once a dense 384³ grid's took 51 GB.
UPSAMPLE_CHUNK = 1 << 17


def n_sh_coefficients(sh_degree: int) -> int:
    """Spherical-harmonics coefficients per colour channel of ``sh_degree`` (0, 1 or 2).

    >>> [n_sh_coefficients(d) for d in SH_DEGREES]
    [1, 4, 9]
    """
    if sh_degree not in SH_DEGREES or isinstance(sh_degree, bool):
        raise InvalidArgument(f"sh_degree={sh_degree!r}: expected 0 (view-independent colour), 1 or 2")
    return (sh_degree + 1) ** 2


def opacity(raw: torch.Tensor, density_shift: float, step_ratio: float) -> torch.Tensor:
    """The opacity of one sample of ``step_ratio`` voxels at raw density ``raw``."""
    return -torch.expm1(-F.softplus(raw + density_shift) * step_ratio)


def inverse_softplus(y: torch.Tensor) -> torch.Tensor:
    """``softplus⁻¹`` for ``y > 0`` (clamped at 1e-12), stable for large and small ``y``."""
    y = y.clamp(min=1e-12)
    return y + torch.log(-torch.expm1(-y))


@dataclass(eq=False)
class SceneField:
    """A fitted (or fitting) scene field on one device: ``values`` ``(rows, 1 + 3·n_sh)`` float32, the
    ``occupancy`` ``(resolution-1,)*3`` bool and, for a sparse field, ``rows`` ``(resolution³,)`` int32 (see
    the module docstring; ``None``: dense, one row per vertex).

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
    rows: torch.Tensor | None = None

    def __post_init__(self) -> None:
        if self.occupancy.ndim != 3 or len(set(self.occupancy.shape)) != 1 or self.occupancy.shape[0] < 3:
            raise InvalidArgument(f"occupancy has shape {tuple(self.occupancy.shape)}; expected "
                                  "(R-1, R-1, R-1) with R ≥ 4 vertices per axis")
        res = self.occupancy.shape[0] + 1
        n = self.values.shape[0]
        width = 1 + 3 * n_sh_coefficients(self.sh_degree)
        if self.values.ndim != 2 or self.values.shape[1] != width:
            raise InvalidArgument(f"values has shape {tuple(self.values.shape)}; expected ({n}, {width}) "
                                  f"for sh_degree={self.sh_degree}")
        if self.rows is None and n != res ** 3:
            raise InvalidArgument(f"values has {n} rows; a dense field of occupancy "
                                  f"{tuple(self.occupancy.shape)} has resolution³ = {res ** 3}")
        if self.rows is not None and (self.rows.dtype != torch.int32
                                      or tuple(self.rows.shape) != (res ** 3,)):
            raise InvalidArgument(f"rows is {self.rows.dtype} {tuple(self.rows.shape)}; expected int32 "
                                  f"({res ** 3},), a row per vertex of the {res}³ grid")
        background = as_unit_rgb(self.background)
        if background is None:
            raise InvalidArgument(f"background={self.background!r}: expected three values in [0, 1]")
        self.background = background

    @classmethod
    def empty(cls, space: SceneSpace, resolution: int, sh_degree: int, alpha: float, step_ratio: float,
              device: torch.device | str = "cpu",
              background: tuple[float, float, float] = (0.0, 0.0, 0.0)) -> SceneField:
        """A dense field with opacity ``alpha`` per sample everywhere, grey colour, every cell occupied."""
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

    @property
    def is_sparse(self) -> bool:
        return self.rows is not None

    def to(self, device: torch.device | str) -> SceneField:
        rows = None if self.rows is None else self.rows.to(device)
        return replace(self, values=self.values.to(device), occupancy=self.occupancy.to(device), rows=rows)

    def vertex_rows(self, flat: torch.Tensor) -> torch.Tensor:
        """The rows of ``values`` holding the vertices with flat indices ``flat`` (int64; -1 where a sparse
        field does not store the vertex)."""
        return flat if self.rows is None else self.rows[flat].to(torch.int64)

    def row_vertices(self) -> torch.Tensor:
        """The flat vertex index ``(i·R + j)·R + k`` of each row of ``values`` (int64, on the field's device): the
        inverse of :meth:`vertex_rows`."""
        flat = torch.arange(self.values.shape[0], device=self.device)
        if self.rows is not None:
            stored = torch.nonzero(self.rows >= 0).reshape(-1)
            flat[self.rows[stored].to(torch.int64)] = stored
        return flat

    def kernel_rows(self) -> np.ndarray:
        """The row map as the compiled kernels take it: int32 ``R³``, empty for a dense field."""
        if self.rows is None:
            return np.zeros(0, dtype=np.int32)
        return np.ascontiguousarray(self.rows.cpu().numpy())

    def _stored_rows(self, flat: torch.Tensor) -> torch.Tensor:
        """:meth:`vertex_rows` of vertices the field must store (those of occupied cells)."""
        rows = self.vertex_rows(flat)
        if self.rows is not None and bool((rows < 0).any()):
            raise InvalidArgument("the field does not store every vertex of its occupied cells")
        return rows

    def density_grid(self) -> torch.Tensor:
        """The raw density as a dense ``(R, R, R)`` grid; ``-inf`` at vertices a sparse field does not
        store."""
        res = self.resolution
        if self.rows is None:
            return self.values[:, 0].reshape(res, res, res)
        grid = torch.full((res ** 3,), -math.inf, device=self.device)
        stored = self.rows >= 0
        grid[stored] = self.values[self.rows[stored].to(torch.int64), 0]
        return grid.reshape(res, res, res)

    def cell_alpha(self, step_ratio: float) -> torch.Tensor:
        """``(R-1)³`` opacity over one sample of ``step_ratio`` voxels at each cell's densest (stored)
        corner."""
        corner_max = F.max_pool3d(self.density_grid()[None, None], kernel_size=2, stride=1)[0, 0]
        return opacity(corner_max, self.density_shift, step_ratio)

    def occupied_cell_alpha(self, step_ratio: float) -> torch.Tensor:
        """:meth:`cell_alpha` of the occupied cells only, in ``occupancy.nonzero()`` order (the same values,
        without a dense grid of them: a render needs no more)."""
        rows = self._stored_rows(_cell_corners(self.occupancy))
        corner_max = self.values[rows, 0].reshape(-1, 8).amax(dim=1)
        return opacity(corner_max, self.density_shift, step_ratio)

    def upsampled_occupancy(self, resolution: int) -> torch.Tensor:
        """``(resolution - 1)³`` bool: the occupancy :meth:`upsampled` carries to a grid of ``resolution``: each
        cell takes its nearest coarse cell's (``F.interpolate``'s ``"nearest"``: coarse index ``⌊i·n/m⌋`` in
        float32), then one cell of dilation; in bools, 3 bytes a fine cell at the peak."""
        n, m = self.resolution - 1, resolution - 1
        nearest = (torch.arange(m, dtype=torch.float32, device=self.device) * torch.tensor(n / m, dtype=torch.float32)
                   ).floor().long().clamp(max=n - 1)
        occ = self.occupancy.bool()
        for axis in range(3):
            occ = occ.index_select(axis, nearest)
        return dilated(occ)

    def upsampled(self, resolution: int, chunk: int = UPSAMPLE_CHUNK) -> SceneField:
        """The same field on a finer grid, sparse: occupancy carried over with one cell of dilation, values
        resampled trilinearly at the vertices of the occupied cells (a vertex the coarse field does not store
        counts as zeros), densities rescaled to the smaller voxel (same opacity per unit length). The vertices
        are resampled ``chunk`` at a time, so the 8 corners gathered for each take ``chunk``-bounded memory."""
        if isinstance(chunk, bool) or not isinstance(chunk, int) or chunk < 1:
            raise InvalidArgument(f"chunk={chunk!r}: expected a number of vertices >= 1")
        occ = self.upsampled_occupancy(resolution)
        flat = used_vertex_index(occ)
        values = torch.empty((flat.numel(), self.values.shape[1]), dtype=self.values.dtype, device=self.device)
        for start in range(0, flat.numel(), chunk):
            ijk = vertex_ijk(flat[start:start + chunk], resolution).to(self.values.dtype)
            corners, weights = trilinear(ijk * ((self.resolution - 1) / (resolution - 1)), self.resolution)
            # a vertex the coarse field does not store counts as zeros
            values[start:start + chunk] = interpolate(self.values, self.vertex_rows(corners), weights)
        ratio = (resolution - 1) / (self.resolution - 1)
        sigma = F.softplus(values[:, 0] + self.density_shift) / ratio
        values[:, 0] = inverse_softplus(sigma) - self.density_shift
        return replace(self, values=values.contiguous(), occupancy=occ, rows=_row_map(flat, resolution))

    def used_vertex_index(self) -> torch.Tensor:
        """The flat indices of the vertices of occupied cells (the only ones a render reads), ascending."""
        return used_vertex_index(self.occupancy)

    def used_vertices(self) -> torch.Tensor:
        """``R³`` bool, flat: the vertices of occupied cells."""
        return used_vertex_mask(self.occupancy).reshape(-1)

    def compact(self) -> SceneField:
        """The field as a sparse one that stores exactly the vertices of its occupied cells."""
        flat = self.used_vertex_index()
        return replace(self, values=self.values[self._stored_rows(flat)].contiguous(),
                       occupancy=self.occupancy.clone(), rows=_row_map(flat, self.resolution))

    def quantized(self) -> SceneField:
        """The field as a scene file stores it: sparse, its values rounded to float16 (in place, a chunk at a
        time: a fit takes this copy every checkpoint while it holds its own)."""
        field = self.compact()
        for start in range(0, field.values.shape[0], UPSAMPLE_CHUNK):
            part = field.values[start:start + UPSAMPLE_CHUNK]
            part.copy_(part.half())
        return field

    # -- serialization (the scene file module wraps these in a zip) -----------------------------------------
    def metadata(self) -> dict:
        """JSON-ready description of the field (everything but the tensors)."""
        return {"space": self.space.to_dict(), "resolution": self.resolution, "sh_degree": self.sh_degree,
                "density_shift": self.density_shift, "background": list(self.background)}

    def tensors(self) -> dict[str, torch.Tensor]:
        """The field's tensors as a scene file stores them (CPU, contiguous; see :data:`FIELD_TENSORS`)."""
        index = self.used_vertex_index()
        return {
            "occupancy": self.occupancy.cpu().to(torch.uint8).contiguous(),
            "vertex_index": index.cpu().contiguous(),
            "vertex_values": self.values[self.vertex_rows(index)].cpu().half().contiguous(),
        }

    @classmethod
    def from_tensors(cls, metadata: dict, tensors: dict[str, torch.Tensor], source: str = "scene file") -> SceneField:
        """Rebuild a (sparse) field from :meth:`metadata` and :meth:`tensors`, checking the metadata
        (:func:`check_field_metadata`), names, dtypes and shapes."""
        space, res, sh_degree, shift, background = check_field_metadata(metadata, source)
        width = 1 + 3 * n_sh_coefficients(sh_degree)
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
                raise SceneFileError(
                    f"{source}: tensor {name!r} is {t.dtype} {tuple(t.shape)}; expected {dtype} {shape}")
        if index.numel() and (int(index.min()) < 0 or int(index.max()) >= res ** 3):
            raise SceneFileError(f"{source}: tensor 'vertex_index' points outside the {res}³ grid")
        if not torch.isfinite(vals).all():
            raise SceneFileError(f"{source}: tensor 'vertex_values' holds NaN or Inf")
        occupancy = occ.bool()
        if not torch.equal(used_vertex_index(occupancy), index):
            raise SceneFileError(f"{source}: 'vertex_index' does not list exactly the vertices of occupied cells")
        return cls(space, vals.float(), occupancy, shift, sh_degree, background, _row_map(index, res))

    def describe(self) -> dict:
        """Size figures for reports: resolution, occupied fraction, stored vertices."""
        used = int(self.used_vertex_index().numel())
        return {"resolution": self.resolution, "sh_degree": self.sh_degree,
                "occupied_fraction": float(self.occupancy.float().mean()), "stored_vertices": used}

    def memory_bytes(self) -> int:
        """The bytes the field's tensors take (values, occupancy and a sparse field's row map)."""
        tensors = [self.values, self.occupancy] + ([] if self.rows is None else [self.rows])
        return sum(t.numel() * t.element_size() for t in tensors)

_CORNERS = torch.tensor([[(c >> 2) & 1, (c >> 1) & 1, c & 1] for c in range(8)])


def vertex_ijk(flat: torch.Tensor, resolution: int) -> torch.Tensor:
    """Flat vertex indices (x-major) → their ``(N, 3)`` grid indices ``(i, j, k)``."""
    res = resolution
    return torch.stack([flat // (res * res), (flat // res) % res, flat % res], dim=-1)


def _cell_corners(occupancy: torch.Tensor) -> torch.Tensor:
    """The flat indices of the 8 corner vertices of each occupied cell, ``(cells · 8,)`` in
    ``occupancy.nonzero()`` order (corner order as :func:`~pytest_n2r.field.query.trilinear`)."""
    res = occupancy.shape[0] + 1
    cells = occupancy.nonzero()
    corners = (cells[:, None, :] + _CORNERS.to(cells.device)[None]).reshape(-1, 3)
    return (corners[:, 0] * res + corners[:, 1]) * res + corners[:, 2]


def used_vertex_index(occupancy: torch.Tensor) -> torch.Tensor:
    """The flat indices (int64, ascending) of the ``(R-1)³`` ``occupancy``'s cells' corner vertices in the
    ``R³`` vertex grid: the unique :func:`_cell_corners`, found as the occupancy dilated onto the vertices (a
    vertex is used when one of its up to 8 cells is occupied; 11× faster than sorting the corners on a 384³
    grid: 0.28 against 3.1 s, so loading a fitted scene no longer waits on it)."""
    return used_vertex_mask(occupancy).reshape(-1).nonzero().reshape(-1)


def check_field_metadata(metadata: dict, source: str) -> tuple[SceneSpace, int, int, float, tuple]:
    """``(space, resolution, sh_degree, density_shift, background)`` of a field's :meth:`SceneField.metadata`,
    checked without its tensors; a :class:`SceneFileError` naming ``source`` and the setting otherwise."""
    try:
        space = SceneSpace.from_dict(metadata["space"])
        res, sh_degree, shift = metadata["resolution"], metadata["sh_degree"], metadata["density_shift"]
        try:
            background = as_unit_rgb(metadata["background"])
        except OverflowError:  # an integer such as 10**400: named below
            background = None
    except (KeyError, TypeError, ValueError, InvalidArgument, OverflowError) as exc:
        raise SceneFileError(f"{source}: field metadata is incomplete or invalid ({exc})") from None
    if isinstance(res, bool) or not isinstance(res, int) or not 4 <= res <= 2048:
        raise SceneFileError(f"{source}: field.resolution={res!r}; expected an integer in 4..2048 (grid vertices "
                             "per axis)")
    if isinstance(sh_degree, bool) or sh_degree not in SH_DEGREES:
        raise SceneFileError(f"{source}: field.sh_degree={sh_degree!r}; expected 0, 1 or 2")
    if isinstance(shift, bool) or not isinstance(shift, (int, float)) or not abs(shift) <= MAX_DENSITY_SHIFT:
        raise SceneFileError(f"{source}: field.density_shift={shift!r}; expected a finite number within "
                             f"±{MAX_DENSITY_SHIFT:g} (a fit writes -8.5 by default; beyond the limit every "
                             "sample is empty or opaque and the scene renders flat)")
    if background is None:
        raise SceneFileError(f"{source}: field.background={metadata['background']!r}; expected three values in [0, 1]")
    return space, res, sh_degree, float(shift), background


def dilated(cells: torch.Tensor) -> torch.Tensor:
    """The bool ``cells`` and every cell within one cell of them (26-neighbourhood, not past the borders): the
    3×3×3 box as three passes of 3 cells, one along each axis.

    >>> cells = torch.zeros(5, 5, 5, dtype=torch.bool)
    >>> cells[0, 2, 4] = True
    >>> int(dilated(cells).sum())  # 2 × 3 × 2 cells: the box clipped at two borders
    12
    """
    out = cells.bool()
    for axis in range(3):
        n = out.shape[axis]
        grown = out.clone()
        grown.narrow(axis, 1, n - 1).logical_or_(out.narrow(axis, 0, n - 1))
        grown.narrow(axis, 0, n - 1).logical_or_(out.narrow(axis, 1, n - 1))
        out = grown
    return out


def used_vertex_mask(occupancy: torch.Tensor) -> torch.Tensor:
    """``R³`` bool: the vertices of the ``(R-1)³`` ``occupancy``'s occupied cells (see :func:`used_vertex_index`)."""
    n = occupancy.shape[0]
    occupied = occupancy.bool()
    used = torch.zeros((n + 1,) * 3, dtype=torch.bool, device=occupancy.device)
    for i, j, k in _CORNERS.tolist():
        used[i:i + n, j:j + n, k:k + n] |= occupied
    return used


def _row_map(flat: torch.Tensor, resolution: int) -> torch.Tensor:
    """``R³`` int32: row ``n`` for the vertex ``flat[n]``, -1 elsewhere."""
    rows = torch.full((resolution ** 3,), -1, dtype=torch.int32, device=flat.device)
    rows[flat] = torch.arange(flat.numel(), dtype=torch.int32, device=flat.device)
    return rows

