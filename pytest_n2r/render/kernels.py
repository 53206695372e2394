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


@njit(cache=True, inline="always")
def _alpha(x, sigma_step):
    """Opacity ``1 - exp(-softplus(x)·sigma_step)`` of a sample with raw density ``x`` (float64).

    At the default spacing of half a voxel it is ``1 - (1 + e^x)^-½``: one exponential and a square root
    instead of three transcendental functions (the same value to rounding).
    """
    if sigma_step == 0.5:
        return 1.0 - 1.0 / math.sqrt(1.0 + math.exp(x)) if x < 40.0 else -math.expm1(-0.5 * x)
    return -math.expm1(-_softplus(x) * sigma_step)


@njit(cache=True, inline="always")
def vertex_row(rows, v):
    """The values row of flat vertex ``v``: ``rows[v]`` for a sparse field, ``v`` itself when ``rows`` is
    empty (a dense field)."""
    return v if rows.shape[0] == 0 else np.int64(rows[v])


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
        t0, dt, n_inner, ts, du = _setup(ox, oy, oz, dx, dy, dz, step, shell_samples, far)
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
            alpha = _alpha(sigma_raw + density_shift, sigma_step)
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
