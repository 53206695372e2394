"""Compiled CPU kernels (numba): ray marching with empty-space skipping, and the fused forward renderer.

They follow the lattice of :mod:`pytest_n2r.render.lattice` exactly (float64 inside, float32 in and out).
Each ray is independent and handled by one thread, so results do not depend on the thread count.
Empty space is skipped two ways: 8³-cell blocks with nothing in them are crossed in one jump, and only
samples in occupied cells are kept. The fused renderer also stops a ray once its transmittance falls below
``t_stop`` (early ray termination).
"""

from __future__ import annotations

import math

import numpy as np
from numba import njit, prange

__all__ = ["BLOCK", "block_occupancy", "march_count", "march_fill", "render_rays", "SH_C0", "SH_C1"]

#: Side of an empty-space-skipping block, in cells.
BLOCK = 8
#: Real spherical-harmonics constants of degree 0 and 1.
SH_C0 = 0.28209479177387814
SH_C1 = 0.4886025119029199


def block_occupancy(occupancy: np.ndarray) -> np.ndarray:
    """``uint8`` grid of BLOCK³-cell blocks, 1 where any cell of the block is occupied."""
    n = occupancy.shape[0]
    nb = (n + BLOCK - 1) // BLOCK
    padded = np.zeros((nb * BLOCK,) * 3, dtype=bool)
    padded[:n, :n, :n] = occupancy.astype(bool)
    return padded.reshape(nb, BLOCK, nb, BLOCK, nb, BLOCK).any(axis=(1, 3, 5)).astype(np.uint8)


@njit(cache=True, inline="always")
def _setup(ox, oy, oz, dx, dy, dz, step, shell_samples, far):
    dn = math.sqrt(dx * dx + dy * dy + dz * dz)
    dt = step / dn
    t_in, t_out = -math.inf, math.inf
    for o, d in ((ox, dx), (oy, dy), (oz, dz)):
        if abs(d) <= 1e-12:
            d = 1e-12
        t1, t2 = (-1.0 - o) / d, (1.0 - o) / d
        t_in = max(t_in, min(t1, t2))
        t_out = min(t_out, max(t1, t2))
    t0 = max(t_in, 0.0)
    n_inner = max(int(math.floor((t_out - t0) / dt)), 0)
    ts = t_out if n_inner > 0 else 0.0
    ts = max(ts, dt)
    t_far = ts + far / dn
    du = (1.0 / ts - 1.0 / t_far) / shell_samples
    return t0, dt, n_inner, ts, du


@njit(cache=True, inline="always")
def _grid(px, py, pz, shell, res):
    """Normalized point → continuous vertex coordinates (contracted)."""
    r = max(abs(px), abs(py), abs(pz))
    if r > 1.0:
        s = (1.0 + shell * (1.0 - 1.0 / r)) / r
        px, py, pz = px * s, py * s, pz * s
    half = 1.0 + shell
    scale = (res - 1) / (2.0 * half)
    top = res - 1.0
    gx = min(max((px + half) * scale, 0.0), top)
    gy = min(max((py + half) * scale, 0.0), top)
    gz = min(max((pz + half) * scale, 0.0), top)
    return gx, gy, gz


@njit(cache=True, inline="always")
def _cell(g, res):
    return min(int(g), res - 2)


@njit(cache=True, inline="always")
def _block_exit(ox, oy, oz, dx, dy, dz, bi, bj, bk, shell, res):
    """Ray parameter where the ray leaves block (bi, bj, bk) (valid inside the unit cube, where q = p)."""
    half = 1.0 + shell
    cell = 2.0 * half / (res - 1)
    t_exit = math.inf
    for o, d, b in ((ox, dx, bi), (oy, dy, bj), (oz, dz, bk)):
        lo = -half + b * BLOCK * cell
        hi = lo + BLOCK * cell
        if d > 1e-12:
            t_exit = min(t_exit, (hi - o) / d)
        elif d < -1e-12:
            t_exit = min(t_exit, (lo - o) / d)
    return t_exit


@njit(cache=True)
def _march_ray(ox, oy, oz, dx, dy, dz, occ, blocks, res, shell, step, shell_samples, far, out, offset, write):
    """Count (and, with ``write``, store at ``out[offset:]``) the occupied lattice samples of one ray."""
    t0, dt, n_inner, ts, du = _setup(ox, oy, oz, dx, dy, dz, step, shell_samples, far)
    n = 0
    k = 0
    while k < n_inner:
        t = t0 + (k + 0.5) * dt
        gx, gy, gz = _grid(ox + t * dx, oy + t * dy, oz + t * dz, shell, res)
        ci, cj, ck = _cell(gx, res), _cell(gy, res), _cell(gz, res)
        bi, bj, bk = ci // BLOCK, cj // BLOCK, ck // BLOCK
        if blocks[bi, bj, bk] == 0:
            t_exit = _block_exit(ox, oy, oz, dx, dy, dz, bi, bj, bk, shell, res)
            k = max(k + 1, int(math.ceil((t_exit - t0) / dt - 0.5)))
            continue
        if occ[ci, cj, ck]:
            if write:
                out[offset + n] = t
            n += 1
        k += 1
    u0 = 1.0 / ts
    for j in range(shell_samples):
        t = 1.0 / (u0 - (j + 0.5) * du)
        gx, gy, gz = _grid(ox + t * dx, oy + t * dy, oz + t * dz, shell, res)
        if occ[_cell(gx, res), _cell(gy, res), _cell(gz, res)]:
            if write:
                out[offset + n] = t
            n += 1
    return n


@njit(cache=True, parallel=True)
def march_count(o, d, occ, blocks, res, shell, step, shell_samples, far):
    """Number of occupied lattice samples of every ray ``(N,)``."""
    n = o.shape[0]
    counts = np.empty(n, dtype=np.int64)
    dummy = np.empty(0, dtype=np.float32)
    for r in prange(n):
        counts[r] = _march_ray(o[r, 0], o[r, 1], o[r, 2], d[r, 0], d[r, 1], d[r, 2], occ, blocks, res, shell,
                               step, shell_samples, far, dummy, 0, False)
    return counts


@njit(cache=True, parallel=True)
def march_fill(o, d, occ, blocks, res, shell, step, shell_samples, far, offsets, out):
    """Write every ray's occupied lattice ``t`` into ``out[offsets[r]:offsets[r + 1]]`` (float32)."""
    for r in prange(o.shape[0]):
        _march_ray(o[r, 0], o[r, 1], o[r, 2], d[r, 0], d[r, 1], d[r, 2], occ, blocks, res, shell,
                   step, shell_samples, far, out, offsets[r], True)


@njit(cache=True, inline="always")
def _softplus(x):
    return x if x > 20.0 else math.log1p(math.exp(x))


@njit(cache=True, parallel=True)
def render_rays(o, d, density, values, occ, blocks, res, shell, step, shell_samples, far, density_shift,
                sigma_step, sh_degree, t_stop, background, want_depth, rgb, depth, opacity):
    """Volume-render every ray into ``rgb (N, 3)``, ``depth (N,)`` and ``opacity (N,)`` (float32).

    ``values`` is ``(res³, 1 + 3·n_sh)`` float32: the raw density then the SH colour coefficients
    (``[l·3 + channel]``); ``density`` is a contiguous copy of its first column (read for every sample, so
    kept dense in cache; colours are read only where a sample is visible). Density is per voxel: a sample's opacity is ``1 - exp(-σ·sigma_step)`` with
    ``sigma_step`` the sample spacing in voxels. Depth is the expected z-depth with the remaining transmittance placed at the far
    end of the ray, so it is finite everywhere (not to be trusted where opacity is ~0).
    """
    n_sh = 4 if sh_degree == 1 else 1
    rr = res * res
    for r in prange(o.shape[0]):
        ox, oy, oz = np.float64(o[r, 0]), np.float64(o[r, 1]), np.float64(o[r, 2])
        dx, dy, dz = np.float64(d[r, 0]), np.float64(d[r, 1]), np.float64(d[r, 2])
        t0, dt, n_inner, ts, du = _setup(ox, oy, oz, dx, dy, dz, step, shell_samples, far)
        dn = math.sqrt(dx * dx + dy * dy + dz * dz)
        ux, uy, uz = dx / dn, dy / dn, dz / dn
        basis = (SH_C0, -SH_C1 * uy, SH_C1 * uz, -SH_C1 * ux)
        trans = 1.0
        cr = cg = cb = 0.0
        zd = 0.0
        u0 = 1.0 / ts
        k = 0
        total = n_inner + shell_samples
        while k < total and trans > t_stop:
            if k < n_inner:
                t = t0 + (k + 0.5) * dt
            else:
                t = 1.0 / (u0 - (k - n_inner + 0.5) * du)
            gx, gy, gz = _grid(ox + t * dx, oy + t * dy, oz + t * dz, shell, res)
            ci, cj, ck = _cell(gx, res), _cell(gy, res), _cell(gz, res)
            if k < n_inner and blocks[ci // BLOCK, cj // BLOCK, ck // BLOCK] == 0:
                t_exit = _block_exit(ox, oy, oz, dx, dy, dz, ci // BLOCK, cj // BLOCK, ck // BLOCK, shell, res)
                k_next = max(k + 1, int(math.ceil((t_exit - t0) / dt - 0.5)))
                k = min(k_next, n_inner)
                continue
            k += 1
            if not occ[ci, cj, ck]:
                continue
            fx, fy, fz = gx - ci, gy - cj, gz - ck
            base = (ci * res + cj) * res + ck
            sigma_raw = 0.0
            for c in range(8):
                w = (fx if c & 4 else 1.0 - fx) * (fy if c & 2 else 1.0 - fy) * (fz if c & 1 else 1.0 - fz)
                sigma_raw += w * density[base + (c >> 2) * rr + ((c >> 1) & 1) * res + (c & 1)]
            alpha = 1.0 - math.exp(-_softplus(sigma_raw + density_shift) * sigma_step)
            if alpha <= 0.0:
                continue
            weight = trans * alpha
            lr = lg = lb = 0.0  # colour logits
            for c in range(8):
                w = (fx if c & 4 else 1.0 - fx) * (fy if c & 2 else 1.0 - fy) * (fz if c & 1 else 1.0 - fz)
                row = base + (c >> 2) * rr + ((c >> 1) & 1) * res + (c & 1)
                for l in range(n_sh):
                    wb = w * basis[l]
                    lr += wb * values[row, 1 + l * 3]
                    lg += wb * values[row, 2 + l * 3]
                    lb += wb * values[row, 3 + l * 3]
            cr += weight / (1.0 + math.exp(-lr))
            cg += weight / (1.0 + math.exp(-lg))
            cb += weight / (1.0 + math.exp(-lb))
            if want_depth:
                zd += weight * t
            trans *= 1.0 - alpha
        rgb[r, 0] = cr + trans * background[0]
        rgb[r, 1] = cg + trans * background[1]
        rgb[r, 2] = cb + trans * background[2]
        opacity[r] = 1.0 - trans
        if want_depth:
            depth[r] = zd + trans * (ts + far / dn)
