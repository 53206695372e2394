"""The field's sampling maths compiled for the CPU (numba): lattice, contraction, cells, marching, opacity.

These are the scalar building blocks that the compiled renderer (:mod:`pytest_n2r.render.field_kernels`) and
the compiled training step (:mod:`pytest_n2r.fit.train_kernels`) inline, and the marching kernels that find
a ray's occupied samples. They follow the torch formulas of :mod:`pytest_n2r.field.lattice` exactly (float64
inside, float32 in and out; tests compare them, the contraction on random points and at its boundary).
Each ray is independent and handled by one thread, so results do not depend on the thread count.
Empty space is skipped two ways: 8³-cell blocks with nothing in them are crossed in one jump, and only
samples in occupied cells are kept.

numba's cache checks a kernel's own file only (numba/numba#1833): after editing a function here, delete the
``__pycache__`` folders of ``pytest_n2r/render`` and ``pytest_n2r/fit``, whose cached kernels inline it, or
they keep running the old code.
"""

from __future__ import annotations

import math

import numba
import numpy as np
from numba import njit, prange

__all__ = [
    "BLOCK", "SH_C0", "SH_C1", "SH_C2", "sh2_terms", "block_occupancy", "lattice_setup", "contract_xyz",
    "grid_coords_xyz", "cell_of", "block_exit", "march_packed", "sample_alpha", "thread_ranges", "vertex_row",
]

#: Side of an empty-space-skipping block, in cells.
BLOCK = 8
#: Real spherical-harmonics constants of degree 0, 1 and 2 (the signs of the 3DGS reference code:
#: :mod:`pytest_n2r.splats.sh` evaluates the same basis for splats).
SH_C0 = 0.28209479177387814
SH_C1 = 0.4886025119029199
SH_C2 = (1.0925484305920792, -1.0925484305920792, 0.31539156525252005, -1.0925484305920792, 0.5462742152960396)


def block_occupancy(occupancy: np.ndarray) -> np.ndarray:
    """``uint8`` grid of BLOCK³-cell blocks, 1 where any cell of the block is occupied."""
    n = occupancy.shape[0]
    nb = (n + BLOCK - 1) // BLOCK
    padded = np.zeros((nb * BLOCK,) * 3, dtype=bool)
    padded[:n, :n, :n] = occupancy.astype(bool)
    return np.asarray(padded.reshape(nb, BLOCK, nb, BLOCK, nb, BLOCK).any(axis=(1, 3, 5)), dtype=np.uint8)


def thread_ranges(n: int) -> np.ndarray:
    """Bounds ``(groups + 1,)`` int64 splitting ``n`` items into one contiguous range per numba thread (at most
    one range per item, at least one range): thread ``g`` takes ``bounds[g]:bounds[g + 1]``."""
    groups = max(1, min(numba.get_num_threads(), n))
    return np.linspace(0, n, groups + 1).round().astype(np.int64)


@njit(cache=True, inline="always")
def sh2_terms(x, y, z):
    """The five degree-2 SH basis values at the unit direction ``(x, y, z)`` (world axes): a field's colour
    coefficients 4 to 8 (degree 0's is ``SH_C0``, degree 1's ``SH_C1·(-y, z, -x)``).

    >>> [round(b, 6) for b in sh2_terms(0.0, 0.0, 1.0)]
    [0.0, -0.0, 0.630783, -0.0, 0.0]
    """
    return (SH_C2[0] * x * y, SH_C2[1] * y * z, SH_C2[2] * (2.0 * z * z - x * x - y * y), SH_C2[3] * x * z,
            SH_C2[4] * (x * x - y * y))


@njit(cache=True, inline="always")
def lattice_setup(ox, oy, oz, dx, dy, dz, step, shell_samples, far):
    """One ray's ``(t0, dt, n_inner, ts, du)``, as :func:`pytest_n2r.field.lattice.lattice_counts`."""
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
def contract_xyz(px, py, pz, shell):
    """Normalized point → contracted point (see :mod:`pytest_n2r.field.space`)."""
    r = max(abs(px), abs(py), abs(pz))
    if r > 1.0:
        s = (1.0 + shell * (1.0 - 1.0 / r)) / r
        return px * s, py * s, pz * s
    return px, py, pz


@njit(cache=True, inline="always")
def grid_coords_xyz(px, py, pz, shell, res):
    """Normalized point → continuous vertex coordinates in ``[0, res - 1]³`` (contracted), as
    :func:`pytest_n2r.field.lattice.grid_coords`."""
    px, py, pz = contract_xyz(px, py, pz, shell)
    half = 1.0 + shell
    scale = (res - 1) / (2.0 * half)
    top = res - 1.0
    gx = min(max((px + half) * scale, 0.0), top)
    gy = min(max((py + half) * scale, 0.0), top)
    gz = min(max((pz + half) * scale, 0.0), top)
    return gx, gy, gz


@njit(cache=True, inline="always")
def cell_of(g, res):
    """The cell (its lower vertex) of continuous vertex coordinate ``g`` along one axis."""
    return min(int(g), res - 2)


@njit(cache=True, inline="always")
def block_exit(ox, oy, oz, dx, dy, dz, bi, bj, bk, shell, res):
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
def _march_ray(ox, oy, oz, dx, dy, dz, occ, blocks, res, shell, step, shell_samples, far, out, offset):
    """Store the occupied lattice samples of one ray at ``out[offset:]``; returns how many."""
    t0, dt, n_inner, ts, du = lattice_setup(ox, oy, oz, dx, dy, dz, step, shell_samples, far)
    n = 0
    k = 0
    while k < n_inner:
        t = t0 + (k + 0.5) * dt
        gx, gy, gz = grid_coords_xyz(ox + t * dx, oy + t * dy, oz + t * dz, shell, res)
        ci, cj, ck = cell_of(gx, res), cell_of(gy, res), cell_of(gz, res)
        bi, bj, bk = ci // BLOCK, cj // BLOCK, ck // BLOCK
        if blocks[bi, bj, bk] == 0:
            t_exit = block_exit(ox, oy, oz, dx, dy, dz, bi, bj, bk, shell, res)
            k = max(k + 1, int(math.ceil((t_exit - t0) / dt - 0.5)))
            continue
        if occ[ci, cj, ck]:
            out[offset + n] = t
            n += 1
        k += 1
    u0 = 1.0 / ts
    for j in range(shell_samples):
        t = 1.0 / (u0 - (j + 0.5) * du)
        gx, gy, gz = grid_coords_xyz(ox + t * dx, oy + t * dy, oz + t * dz, shell, res)
        if occ[cell_of(gx, res), cell_of(gy, res), cell_of(gz, res)]:
            out[offset + n] = t
            n += 1
    return n


@njit(cache=True, parallel=True)
def march_packed(o, d, occ, blocks, res, shell, step, shell_samples, far, bounds):
    """Every ray's occupied lattice samples in one pass: ``(counts (N,), t)``, ray ``r``'s ``t`` (float32)
    following those of the rays before it. Thread ``g`` marches rays ``bounds[g]:bounds[g + 1]`` into its own
    part of a scratch buffer sized by the rays' lattice lengths (only the samples written touch its memory);
    the parts are then joined. (Counting every ray first, then marching it again to fill its place, made the
    march of a late fox training step twice as long.)"""
    n = o.shape[0]
    groups = bounds.shape[0] - 1
    starts = np.zeros(groups + 1, dtype=np.int64)
    for g in range(groups):
        room = 0
        for r in range(bounds[g], bounds[g + 1]):
            _, _, n_inner, _, _ = lattice_setup(o[r, 0], o[r, 1], o[r, 2], d[r, 0], d[r, 1], d[r, 2], step,
                                                shell_samples, far)
            room += n_inner + shell_samples
        starts[g + 1] = starts[g] + room
    scratch = np.empty(starts[groups], dtype=np.float32)
    counts = np.empty(n, dtype=np.int64)
    filled = np.zeros(groups, dtype=np.int64)
    for g in prange(groups):
        at = starts[g]
        for r in range(bounds[g], bounds[g + 1]):
            counts[r] = _march_ray(o[r, 0], o[r, 1], o[r, 2], d[r, 0], d[r, 1], d[r, 2], occ, blocks, res, shell,
                                   step, shell_samples, far, scratch, at)
            at += counts[r]
        filled[g] = at - starts[g]
    t = np.empty(filled.sum(), dtype=np.float32)
    at = 0
    for g in range(groups):
        t[at:at + filled[g]] = scratch[starts[g]:starts[g] + filled[g]]
        at += filled[g]
    return counts, t


@njit(cache=True, inline="always")
def _softplus(x):
    return x if x > 20.0 else math.log1p(math.exp(x))


@njit(cache=True, inline="always")
def sample_alpha(x, sigma_step):
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


