"""Differentiable evaluation of a scene field at packed ray samples (torch; CPU or CUDA).

Samples are *packed*: one flat list over all rays, sorted by ray (``ray_idx`` ascending) and, within a ray,
by ``t``. Training uses these functions with autograd; the reference renderer uses them without.
"""

from __future__ import annotations

import torch
import torch.nn.functional as F

from .kernels import SH_C0, SH_C1, SH_C2

__all__ = ["trilinear", "interpolate", "distinct_rows", "sh_basis", "shade", "composite", "distortion", "ALPHA_MAX"]

#: Per-sample opacity is capped here so ``log(1 - alpha)`` stays finite (transmittance cannot underflow).
ALPHA_MAX = 1.0 - 1e-6


def trilinear(g: torch.Tensor, resolution: int) -> tuple[torch.Tensor, torch.Tensor]:
    """Vertex coordinates ``(N, 3)`` → the 8 corner rows ``(N, 8)`` (flat, x-major) and weights ``(N, 8)``.

    Corner ``c`` is offset by ``(c>>2 & 1, c>>1 & 1, c & 1)`` along (x, y, z), as in the compiled kernel.
    """
    res = resolution
    cell = g.floor().clamp(0, res - 2)
    f = g - cell
    ci = cell.to(torch.int64)
    base = (ci[:, 0] * res + ci[:, 1]) * res + ci[:, 2]
    bits = torch.arange(8, device=g.device)
    a, b, c = (bits >> 2) & 1, (bits >> 1) & 1, bits & 1
    offsets = a * res * res + b * res + c
    wx = torch.where(a.bool(), f[:, :1], 1.0 - f[:, :1])
    wy = torch.where(b.bool(), f[:, 1:2], 1.0 - f[:, 1:2])
    wz = torch.where(c.bool(), f[:, 2:3], 1.0 - f[:, 2:3])
    return base[:, None] + offsets[None, :], wx * wy * wz


def sh_basis(directions: torch.Tensor, sh_degree: int) -> torch.Tensor:
    """Real SH basis ``(N, n_sh)`` at unit ``directions`` (N, 3), world axes."""
    c0 = torch.full_like(directions[:, :1], SH_C0)
    if sh_degree == 0:
        return c0
    x, y, z = directions.unbind(-1)
    terms = [-SH_C1 * y, SH_C1 * z, -SH_C1 * x]
    if sh_degree == 2:
        terms += [SH_C2[0] * x * y, SH_C2[1] * y * z, SH_C2[2] * (2.0 * z * z - x * x - y * y), SH_C2[3] * x * z,
                  SH_C2[4] * (x * x - y * y)]
    return torch.cat([c0, torch.stack(terms, dim=-1)], dim=-1)


def interpolate(values: torch.Tensor, rows: torch.Tensor, weights: torch.Tensor) -> torch.Tensor:
    """Trilinear interpolation ``(N, F)`` of ``values`` at the corner ``rows`` / ``weights`` of :func:`trilinear`. A
    corner of row -1 (a vertex a sparse field does not store) counts as zeros: its weight is dropped (row 0 stands
    in as its index), so no other vertex's row reaches the sum, nor its gradient. Such corners are, in
    :meth:`~pytest_n2r.field.grid.SceneField.upsampled`, coarse vertices not stored; in a render or a training step,
    corners of a sample marched in an occupied cell at a float64 ``t`` and stored at float32, which can round it
    into an unoccupied neighbour."""
    stored = rows >= 0
    return torch.einsum("nk,nkf->nf", weights.masked_fill(~stored, 0.0), values[rows.clamp(min=0)])


def distinct_rows(rows: torch.Tensor) -> tuple[torch.Tensor, torch.Tensor]:
    """``(unique, inverse)``: the distinct stored rows of the corner ``rows`` (ascending) and ``rows`` as indices
    into them; a row of -1 (a vertex not stored) is left out and stays -1, so no row answers for it."""
    unique, inverse = torch.unique(rows, return_inverse=True)
    if unique.numel() and bool(unique[0] < 0):  # the vertex map's -1 sorts first
        return unique[1:], inverse - 1
    return unique, inverse


def shade(v: torch.Tensor, basis: torch.Tensor, density_shift: float, step_ratio: float
          ) -> tuple[torch.Tensor, torch.Tensor]:
    """Interpolated values ``(N, F)`` → per-sample opacity ``(N,)`` over ``step_ratio`` voxels and colour
    ``(N, 3)`` in [0, 1]."""
    alpha = -torch.expm1(-F.softplus(v[:, 0] + density_shift) * step_ratio)
    coeff = v[:, 1:].reshape(v.shape[0], basis.shape[1], 3)
    rgb = torch.sigmoid(torch.einsum("nl,nlc->nc", basis, coeff))
    return alpha, rgb


def _exclusive_per_ray(x: torch.Tensor, offsets: torch.Tensor, ray_idx: torch.Tensor) -> torch.Tensor:
    """The sum of ``x`` over the earlier samples of the same ray (packed samples)."""
    exclusive = torch.cumsum(x, 0) - x
    if not x.numel():
        return exclusive
    return exclusive - exclusive[offsets[:-1].clamp(max=x.numel() - 1)][ray_idx]


def composite(alpha: torch.Tensor, rgb: torch.Tensor, t: torch.Tensor, ray_idx: torch.Tensor,
              offsets: torch.Tensor, n_rays: int, background: torch.Tensor, t_far: torch.Tensor | None = None
              ) -> dict[str, torch.Tensor]:
    """Alpha-composite packed samples front to back.

    Returns per ray ``rgb`` (N, 3) over ``background``, ``opacity`` (the sum of weights, ≤ 1), ``weights``
    per sample and, when ``t_far`` (N,) is given, ``depth``: the z-depth of the ray's weight, ``Σ w·t / Σ w``
    (``t_far`` where the ray has no weight at all). Transmittance is a float64 prefix sum of ``log(1 - alpha)``.
    """
    alpha = alpha.clamp(max=ALPHA_MAX)
    trans = torch.exp(_exclusive_per_ray(torch.log1p(-alpha.double()), offsets, ray_idx)).to(alpha.dtype)
    weights = trans * alpha
    zeros = torch.zeros(n_rays, device=alpha.device, dtype=alpha.dtype)
    opacity = zeros.index_add(0, ray_idx, weights)
    remaining = (1.0 - opacity).clamp(min=0.0)
    out = {
        "rgb": torch.zeros(n_rays, 3, device=alpha.device, dtype=alpha.dtype).index_add(
            0, ray_idx, weights[:, None] * rgb) + remaining[:, None] * background,
        "opacity": opacity.clamp(max=1.0),
        "weights": weights,
    }
    if t_far is not None:
        weighted = zeros.double().index_add(0, ray_idx, weights.double() * t.double())
        total = zeros.double().index_add(0, ray_idx, weights.double())
        out["depth"] = torch.where(total > 0, weighted / total.clamp(min=1e-300), t_far.double()).to(alpha.dtype)
    return out


def distortion(weights: torch.Tensor, s: torch.Tensor, ray_idx: torch.Tensor, offsets: torch.Tensor,
               n_rays: int, delta: float) -> torch.Tensor:
    """The distortion loss of mip-NeRF 360 per ray ``(N,)``: ``Σᵢ Σⱼ wᵢ wⱼ |sᵢ - sⱼ| + ⅓ Σᵢ wᵢ² δ``.

    ``s`` is each packed sample's position along its ray and ``delta`` the length every sample stands for
    (the same units; the field uses contracted units). It is small when a ray's weight sits in one short
    interval (a surface) and large for weight smeared along the ray (fog, floaters).
    """
    w, s = weights.double(), s.double()
    pairs = w * (s * _exclusive_per_ray(w, offsets, ray_idx) - _exclusive_per_ray(w * s, offsets, ray_idx))
    per_sample = 2.0 * pairs + w * w * (delta / 3.0)
    return torch.zeros(n_rays, dtype=torch.float64, device=w.device).index_add(0, ray_idx, per_sample).to(weights.dtype)
