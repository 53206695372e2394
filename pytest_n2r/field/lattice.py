"""Where a ray is sampled: the sample lattice shared by training, the compiled renderer and the reference.

Every ray is sampled on a fixed lattice of ray parameters ``t`` (z-depth, scene units), computed in the
normalized space of :class:`pytest_n2r.field.space.SceneSpace`:

- **inside the unit cube**: ``t_k = t0 + (k + ½)·dt`` with ``dt = step / |d|`` (``step`` in normalized
  units), from where the ray enters the cube (or the camera, if it is inside) to where it leaves;
- **in the contracted shell**: ``shell_samples`` samples uniformly spaced in ``1/t`` (that is, evenly in the
  contracted coordinate) from where the ray leaves the cube to ``far`` normalized units beyond.

A sample is *taken* only where the occupancy grid says the field has something (empty-space skipping).
Every sample stands for the same length ``step`` of contracted space; densities are per voxel of the grid, so
a sample's opacity is ``alpha = 1 - exp(-σ·step_ratio)`` with ``step_ratio = step / voxel``.
The part of a ray between a camera *outside* the cube and the cube is not sampled (the field is empty there:
fitted captures put every camera inside the cube).

The NumPy/Torch functions here and the compiled kernels in :mod:`pytest_n2r.field.kernels` follow the same
formulas; tests check that they agree.
"""

from __future__ import annotations

import math

import torch

__all__ = ["ray_box", "lattice_counts", "lattice_t", "lattice_position", "contract", "grid_coords"]


def ray_box(o: torch.Tensor, d: torch.Tensor) -> tuple[torch.Tensor, torch.Tensor]:
    """Entry and exit ``t`` of normalized rays ``o + t·d`` with the cube ``[-1, 1]³`` (exit < entry: a miss)."""
    with torch.no_grad():
        safe = torch.where(d.abs() > 1e-12, d, torch.full_like(d, 1e-12))
        t1, t2 = (-1.0 - o) / safe, (1.0 - o) / safe
        t_in = torch.minimum(t1, t2).amax(-1)
        t_out = torch.maximum(t1, t2).amin(-1)
    return t_in, t_out


def lattice_counts(o: torch.Tensor, d: torch.Tensor, step: float, shell_samples: int,
                   far: float) -> tuple[torch.Tensor, torch.Tensor, torch.Tensor, torch.Tensor, torch.Tensor]:
    """Per ray: ``(t0, dt, n_inner, ts, du)`` — the inner lattice start, spacing and size, and the shell
    lattice's start ``ts`` and spacing ``du`` in ``1/t``."""
    dn = d.norm(dim=-1)
    dt = step / dn
    t_in, t_out = ray_box(o, d)
    t0 = t_in.clamp(min=0.0)
    n_inner = torch.floor((t_out - t0) / dt).clamp(min=0).to(torch.int64)
    hit = n_inner > 0
    ts = torch.where(hit, t_out, torch.zeros_like(t_out)).maximum(dt)
    t_far = ts + far / dn
    du = (1.0 / ts - 1.0 / t_far) / shell_samples
    return t0, dt, n_inner, ts, du


def lattice_t(o: torch.Tensor, d: torch.Tensor, step: float, shell_samples: int, far: float) -> torch.Tensor:
    """Every lattice ``t`` of every ray, ``(N, n_inner_max + shell_samples)``; unused inner slots are ``inf``."""
    t0, dt, n_inner, ts, du = lattice_counts(o, d, step, shell_samples, far)
    k_max = int(n_inner.max()) if n_inner.numel() else 0
    k = torch.arange(k_max, dtype=o.dtype, device=o.device)
    inner = t0[:, None] + (k[None, :] + 0.5) * dt[:, None]
    inner = torch.where(k[None, :] < n_inner[:, None], inner, torch.full_like(inner, math.inf))
    j = torch.arange(shell_samples, dtype=o.dtype, device=o.device)
    shell = 1.0 / (1.0 / ts[:, None] - (j[None, :] + 0.5) * du[:, None])
    return torch.cat([inner, shell], dim=1)


def lattice_position(o: torch.Tensor, d: torch.Tensor, t: torch.Tensor, ray_idx: torch.Tensor, step: float,
                     shell_samples: int, far: float) -> torch.Tensor:
    """Where packed samples ``t`` (of rays ``ray_idx``) lie along their rays, in contracted units from the
    start of the lattice: ``step`` times the lattice index, so every sample stands for a length ``step``
    (float64). Inner and shell samples are one continuous scale."""
    t0, dt, n_inner, ts, du = (x[ray_idx] for x in lattice_counts(o.double(), d.double(), step, shell_samples, far))
    t = t.double()
    index = torch.where(t < ts, (t - t0) / dt, n_inner + (1.0 / ts - 1.0 / t) / du)
    return step * index


def contract(p: torch.Tensor, shell: float) -> torch.Tensor:
    """Normalized points → contracted points (see :mod:`pytest_n2r.field.space`)."""
    r = p.abs().amax(-1, keepdim=True)
    r_safe = r.clamp(min=1.0)
    outer = (1.0 + shell * (1.0 - 1.0 / r_safe)) * p / r_safe
    return torch.where(r <= 1.0, p, outer)


def grid_coords(p: torch.Tensor, shell: float, resolution: int) -> torch.Tensor:
    """Normalized points → continuous vertex coordinates in ``[0, resolution - 1]³``."""
    half = 1.0 + shell
    g = (contract(p, shell) + half) * ((resolution - 1) / (2.0 * half))
    return g.clamp(0.0, resolution - 1.0)
