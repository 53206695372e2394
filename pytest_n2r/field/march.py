"""Ray marching: the occupied lattice samples of a batch of normalized rays, packed.

Two implementations of the same lattice (:mod:`pytest_n2r.field.lattice`): :func:`march_compiled` (numba,
CPU, skips empty 8³ blocks in one jump) and :func:`march_dense` (torch on any device: enumerates every
lattice sample, then keeps the occupied ones). Both return ``(ray_idx, t, offsets)``: the ray of each
sample, its ``t`` (z-depth), and ``offsets`` (N+1) so ray ``r`` owns samples ``offsets[r]:offsets[r+1]``.
"""

from __future__ import annotations

import math

import numpy as np
import torch

from . import kernels
from .lattice import grid_coords, lattice_counts, lattice_t

__all__ = ["DENSE_MARCH_BYTES", "MarchGrid", "dense_rays", "march_compiled", "march_dense"]

#: Bytes :func:`march_dense` holds at its peak for each lattice slot of the rays it marches (``(rays, slots)``:
#: the float64 lattice, the indices of its samples, their float64 positions and the contraction's temporaries).
#: Measured (the torch tensors alive at once) with every slot in use, rays along the cube's diagonal on 32³, 96³
#: and 224³ grids: 128; rays of mixed lengths leave slots unused and take less (54 a slot on random rays at 224³).
DENSE_MARCH_BYTES = 128


class MarchGrid:
    """An occupancy grid prepared for marching: the cells (and, on CPU, the 8³ blocks) plus the lattice."""

    def __init__(self, occupancy: torch.Tensor, shell: float, step_ratio: float, shell_samples: int | None,
                 far: float):
        self.occupancy = occupancy
        self.resolution = occupancy.shape[0] + 1
        voxel = 2.0 * (1.0 + shell) / (self.resolution - 1)
        #: Sample spacing in voxels (the density unit) and in normalized units (the lattice).
        self.step_ratio, self.step = step_ratio, step_ratio * voxel
        if shell_samples is None:
            shell_samples = max(1, math.ceil(shell / self.step))
        self.shell, self.shell_samples, self.far = shell, shell_samples, far
        self._cells: np.ndarray | None = None
        self._blocks: np.ndarray | None = None

    def numpy(self) -> tuple[np.ndarray, np.ndarray]:
        """``(cells, blocks)`` as uint8 arrays for the compiled kernels (built once)."""
        if self._cells is None or self._blocks is None:  # built together
            self._cells = np.ascontiguousarray(self.occupancy.cpu().numpy().astype(np.uint8))
            self._blocks = kernels.block_occupancy(self._cells)
        return self._cells, self._blocks

    def lattice_slots(self) -> int:
        """The most lattice samples a ray has: the cube's diagonal (2√3 normalized units, the longest chord a ray
        can take through it) in steps, then the shell's; :func:`march_dense` lists this many slots a ray."""
        return math.floor(2.0 * math.sqrt(3.0) / self.step) + self.shell_samples

    def t_far(self, o: torch.Tensor, d: torch.Tensor) -> torch.Tensor:
        """Where each ray's lattice ends (the ``t`` the remaining transmittance is placed at)."""
        _, _, _, ts, _ = lattice_counts(o, d, self.step, self.shell_samples, self.far)
        return ts + self.far / d.norm(dim=-1)


def _packed(counts: torch.Tensor) -> tuple[torch.Tensor, torch.Tensor]:
    offsets = torch.zeros(counts.numel() + 1, dtype=torch.int64, device=counts.device)
    torch.cumsum(counts, 0, out=offsets[1:])
    ray_idx = torch.repeat_interleave(torch.arange(counts.numel(), device=counts.device), counts)
    return ray_idx, offsets


def march_compiled(
    o: torch.Tensor, d: torch.Tensor, grid: MarchGrid
) -> tuple[torch.Tensor, torch.Tensor, torch.Tensor]:
    """Packed occupied samples of CPU float32 rays ``o, d (N, 3)`` (normalized space)."""
    cells, blocks = grid.numpy()
    counts, t = kernels.march_packed(o.numpy(), d.numpy(), cells, blocks, grid.resolution, grid.shell, grid.step,
                                     grid.shell_samples, grid.far, kernels.thread_ranges(o.shape[0]))
    ray_idx, offsets = _packed(torch.from_numpy(counts))
    return ray_idx, torch.from_numpy(t), offsets


def dense_rays(grid: MarchGrid, budget: int) -> int:
    """The most rays :func:`march_dense` marches on ``grid`` within ``budget`` bytes (at least one): it lists every
    lattice slot of every ray before it keeps the occupied ones, :data:`DENSE_MARCH_BYTES` a slot."""
    return max(1, budget // (DENSE_MARCH_BYTES * grid.lattice_slots()))


def march_dense(o: torch.Tensor, d: torch.Tensor, grid: MarchGrid) -> tuple[torch.Tensor, torch.Tensor, torch.Tensor]:
    """The same samples as :func:`march_compiled`, by enumerating the whole lattice (torch, any device): it holds
    :data:`DENSE_MARCH_BYTES` for each of a ray's :meth:`~MarchGrid.lattice_slots` at its peak (march at most
    :func:`dense_rays` rays at a time where memory is bounded)."""
    lattice = lattice_t(o.double(), d.double(), grid.step, grid.shell_samples, grid.far)
    ray, slot = torch.nonzero(torch.isfinite(lattice), as_tuple=True)
    t = lattice[ray, slot]
    p = o.double()[ray] + t[:, None] * d.double()[ray]
    g = grid_coords(p, grid.shell, grid.resolution)
    cell = g.floor().to(torch.int64).clamp(0, grid.resolution - 2)
    keep = grid.occupancy[cell[:, 0], cell[:, 1], cell[:, 2]]
    ray, t = ray[keep], t[keep].to(torch.float32)
    counts = torch.bincount(ray, minlength=o.shape[0])
    _, offsets = _packed(counts)
    return ray, t, offsets
