"""The fused forward renderer of a scene field, compiled for the CPU (numba): one thread per ray.

It samples the lattice of :mod:`pytest_n2r.field.lattice` with the field's compiled sampling maths
(:mod:`pytest_n2r.field.kernels`, inlined), skips empty 8³-cell blocks in one jump and occupied-cell misses
one by one, and stops a ray once its transmittance falls below ``t_stop`` (early ray termination). Each ray
is independent, so results do not depend on the thread count.
"""

from __future__ import annotations

import math

import numpy as np
from numba import njit, prange

from ..field.kernels import (
    BLOCK,
    SH_C0,
    SH_C1,
    block_exit,
    cell_of,
    grid_coords_xyz,
    lattice_setup,
    sample_alpha,
    vertex_row,
)

__all__ = ["render_rays"]


@njit(cache=True, parallel=True)
def render_rays(o, d, density, values, rows, occ, blocks, res, shell, step, shell_samples, far, density_shift,
                sigma_step, sh_degree, t_stop, background, want_depth, rgb, depth, opacity):
    """Volume-render every ray into ``rgb (N, 3)``, ``depth (N,)`` and ``opacity (N,)`` (float32).

    ``values`` is ``(n_rows, 1 + 3·n_sh)`` float32: the raw density then the SH colour coefficients
    (``[l·3 + channel]``) of each stored vertex, ``rows`` the ``res³`` int32 map of a sparse field from a
    flat vertex index to its row (empty for a dense field); ``density`` is a contiguous copy of the first
    column (read for every sample, so kept dense in cache; colours are read only where a sample is
    visible). Density is per voxel: a sample's
    opacity is ``1 - exp(-σ·sigma_step)`` with ``sigma_step`` the sample spacing in voxels. The transmittance
    left when a ray ends (at the far end, or early at ``t_stop``) shows ``background``. Depth is the z-depth
    of the ray's compositing weight, ``Σ w·t / Σ w``, and the far end of the ray where it has no weight at
    all: finite everywhere, not to be trusted where opacity is ~0.
    """
    n_coef = 12 if sh_degree == 1 else 3
    rr = res * res
    for r in prange(o.shape[0]):
        ox, oy, oz = np.float64(o[r, 0]), np.float64(o[r, 1]), np.float64(o[r, 2])
        dx, dy, dz = np.float64(d[r, 0]), np.float64(d[r, 1]), np.float64(d[r, 2])
        t0, dt, n_inner, ts, du = lattice_setup(ox, oy, oz, dx, dy, dz, step, shell_samples, far)
        dn = math.sqrt(dx * dx + dy * dy + dz * dz)
        # degree-1 basis for this ray's direction (degree 0 is the constant SH_C0)
        b1, b2, b3 = -SH_C1 * dy / dn, SH_C1 * dz / dn, -SH_C1 * dx / dn
        coef = np.empty(12)
        trans = 1.0
        cr = cg = cb = 0.0
        zd = wsum = 0.0
        u0 = 1.0 / ts
        k = 0
        total = n_inner + shell_samples
        while k < total and trans > t_stop:
            if k < n_inner:
                t = t0 + (k + 0.5) * dt
            else:
                t = 1.0 / (u0 - (k - n_inner + 0.5) * du)
            gx, gy, gz = grid_coords_xyz(ox + t * dx, oy + t * dy, oz + t * dz, shell, res)
            ci, cj, ck = cell_of(gx, res), cell_of(gy, res), cell_of(gz, res)
            if k < n_inner and blocks[ci // BLOCK, cj // BLOCK, ck // BLOCK] == 0:
                t_exit = block_exit(ox, oy, oz, dx, dy, dz, ci // BLOCK, cj // BLOCK, ck // BLOCK, shell, res)
                k_next = max(k + 1, int(math.ceil((t_exit - t0) / dt - 0.5)))
                k = min(k_next, n_inner)
                continue
            k += 1
            if not occ[ci, cj, ck]:
                continue
            # trilinear weights of the cell's corners v0..v7 (bits i, j, k of the corner index), computed once
            fx, fy, fz = gx - ci, gy - cj, gz - ck
            ex, ey, ez = 1.0 - fx, 1.0 - fy, 1.0 - fz
            a00, a01, a10, a11 = ex * ey, ex * fy, fx * ey, fx * fy
            w0, w1, w2, w3 = a00 * ez, a00 * fz, a01 * ez, a01 * fz
            w4, w5, w6, w7 = a10 * ez, a10 * fz, a11 * ez, a11 * fz
            v = (ci * res + cj) * res + ck
            v0, v1 = vertex_row(rows, v), vertex_row(rows, v + 1)
            v2, v3 = vertex_row(rows, v + res), vertex_row(rows, v + res + 1)
            v4, v5 = vertex_row(rows, v + rr), vertex_row(rows, v + rr + 1)
            v6, v7 = vertex_row(rows, v + rr + res), vertex_row(rows, v + rr + res + 1)
            sigma_raw = (w0 * density[v0] + w1 * density[v1] + w2 * density[v2] + w3 * density[v3]
                         + w4 * density[v4] + w5 * density[v5] + w6 * density[v6] + w7 * density[v7])
            alpha = sample_alpha(sigma_raw + density_shift, sigma_step)
            if alpha <= 0.0:
                continue
            weight = trans * alpha
            for j in range(1, n_coef + 1):
                coef[j - 1] = (w0 * values[v0, j] + w1 * values[v1, j] + w2 * values[v2, j]
                               + w3 * values[v3, j] + w4 * values[v4, j] + w5 * values[v5, j]
                               + w6 * values[v6, j] + w7 * values[v7, j])
            lr, lg, lb = SH_C0 * coef[0], SH_C0 * coef[1], SH_C0 * coef[2]  # colour logits
            if n_coef == 12:
                lr += b1 * coef[3] + b2 * coef[6] + b3 * coef[9]
                lg += b1 * coef[4] + b2 * coef[7] + b3 * coef[10]
                lb += b1 * coef[5] + b2 * coef[8] + b3 * coef[11]
            cr += weight / (1.0 + math.exp(-lr))
            cg += weight / (1.0 + math.exp(-lg))
            cb += weight / (1.0 + math.exp(-lb))
            if want_depth:
                zd += weight * t
                wsum += weight
            trans *= 1.0 - alpha
        rgb[r, 0] = cr + trans * background[0]
        rgb[r, 1] = cg + trans * background[1]
        rgb[r, 2] = cb + trans * background[2]
        opacity[r] = 1.0 - trans
        if want_depth:
            depth[r] = zd / wsum if trans < 1.0 else ts + far / dn
