"""The fused forward renderer of a scene field, compiled for the CPU (numba): each ray on its own, ranges of rays
on the render threads (:mod:`pytest_n2r.render.threads`).

It samples the lattice of :mod:`pytest_n2r.field.lattice` with the field's compiled sampling maths
(:mod:`pytest_n2r.field.kernels`, inlined), skips boxes of empty 8³-cell blocks in one jump and empty cells
one by one, and stops a ray once its transmittance falls below ``t_stop`` (early ray termination). Each ray
is independent, so results do not depend on the thread count.

Colour is the costly part of a sample (docs/performance-log.md, "Rendering"), and two settings make it cheaper:

- **colour logits baked per frame** (:func:`bake_logits`): every stored vertex's colour logits for the direction
  from the camera to that vertex, so a sample interpolates 3 values instead of ``3·n_sh`` SH coefficients. A
  sample then sees its corners' colours from the directions of the corners, not of its ray: they differ by at
  most the angle θ a cell subtends from the camera (the logit error is at most ``θ·(SH_C1·‖c₁‖ + SH_C2[0]·‖c₂‖)``,
  ``c₁``, ``c₂`` a corner's degree-1 and degree-2 coefficients: the fastest each degree's basis turns with the
  direction; the contracted shell's outermost cells reach infinity, so from a camera outside the scene they
  subtend large angles); a degree-0 field's colours do not depend on direction and stay exact.
- **coarser samples behind the surface** (``tail``): each time the ray's transmittance falls below the next of
  the ``tail`` thresholds, the ray's samples stand for twice as many lattice steps as before (one sample at the
  middle of the steps it stands for, its opacity over their length; never across the cube's face or the
  lattice's end). What lies behind a transmittance ``T`` adds at most
  ``T`` to a channel in either render, so the two differ by at most the transmittance at the first threshold
  crossed; measured, far less (docs/performance-log.md, "Rendering").
- **colour only where it carries weight** (``min_weight``): a sample whose compositing weight, plus the weight
  carried from the samples before it, stays below ``min_weight`` is not coloured; its weight is carried to the
  next coloured sample (at the ray's end: the last colour, else the background). Every carried sample weighs less
  than ``min_weight`` and colours lie in [0, 1], so each channel is off by at most the summed weight of the ray's
  samples lighter than ``min_weight`` (times the colour difference it is moved across).
"""

from __future__ import annotations

import math

import numpy as np
from numba import njit

from ..field.kernels import (
    BLOCK,
    SH_C0,
    SH_C1,
    cell_of,
    grid_coords_xyz,
    lattice_setup,
    sample_alpha,
    sh2_terms,
)
from .cell_bits import cell_occupied

__all__ = ["render_pixels", "bake_logits", "colour_columns", "pixel_rays", "vertex_positions"]


@njit(cache=True, nogil=True)
def render_pixels(first, last, index, width, pinhole, c2w, center, radius, density, values, logits, rows, bits, reach,
                  res, shell, step, shell_samples, far, density_shift, sigma_step, sh_degree, t_stop, tail, min_weight,
                  background, want_depth, rgb, depth, opacity):
    """Volume-render the rays through the pixels ``index[first:last]`` (flat, ``y·width + x``) into ``rgb[p]`` (3
    values), ``depth[p]`` and ``opacity[p]`` of each such pixel ``p`` (float32).

    A pixel's ray is :func:`pixel_rays`' to the bit, made here instead of stored: the same arithmetic from the pinhole
    camera (``pinhole``: ``fx, fy, cx, cy``) at ``c2w`` and the scene's ``center`` and ``radius``, rounded to
    float32 as :func:`pixel_rays` stores it.

    ``values`` is ``(n_rows, 1 + 3·n_sh)`` float32: the raw density then the SH colour coefficients
    (``[l·3 + channel]``) of each stored vertex, ``rows`` the ``res³`` int32 map of a sparse field from a
    flat vertex index to its row (empty for a dense field); ``density`` is a contiguous copy of the first
    column (read for every sample, so kept dense in cache; colours are read only where a sample is
    visible). Density is per voxel: a sample's
    opacity is ``1 - exp(-σ·sigma_step)`` with ``sigma_step`` the sample spacing in voxels. The transmittance
    left when a ray ends (at the far end, or early at ``t_stop``) shows ``background``. Depth is the z-depth
    of the ray's compositing weight, ``Σ w·t / Σ w``, and the far end of the ray where it has no weight at
    all: finite everywhere, not to be trusted where opacity is ~0. ``logits`` ``(n_rows, 3)`` float32 holds the
    colour logits baked for this frame (:func:`bake_logits`), or is empty: each sample's logits from its ray's
    direction (exact). ``tail`` (float64, decreasing) and ``min_weight``: see the module docstring (an empty
    ``tail`` takes every lattice sample, 0 colours every sample).

    ``bits`` is the cells' occupancy (:mod:`pytest_n2r.render.cell_bits`) and ``reach`` its blocks'
    (:mod:`pytest_n2r.render.block_reach`):
    a ray whose sample lies in an empty block jumps to the first lattice step whose middle is past where it leaves
    the box of empty blocks around that block. Every step skipped lies in an empty block, and block by block the
    ray would land on the same step (the first one in an occupied block), so the samples taken are the same as
    one block at a time. That holds while each sample is one step; once the tail has doubled a ray's samples, a
    jump lands on a step but the sample is taken at the middle of the next ones, so a longer jump would move the
    samples after it (on the fox, 19 of 388 800 RGB values), and the ray jumps one block at a time. The exit is
    found in the samples' own coordinates, the lattice index ``m`` of ``g0 + m·step`` (vertex units), from the
    step's inverse along each axis (once a ray: no division a jump), less 1e-9 of a step, so rounding can land a
    jump one step early (a sample in the empty box, checked again), never past a sample outside it.
    """
    rr = res * res
    half = 1.0 + shell
    scale = (res - 1) / (2.0 * half)  # normalized units → vertex coordinates (grid_coords_xyz)
    ox, oy, oz = _rounded(_camera_origin(c2w, center, radius))
    for r in range(first, last):
        i = index[r]
        dx, dy, dz = _rounded(_pixel_direction(i, width, pinhole, c2w, radius))
        t0, dt, n_inner, ts, du = lattice_setup(ox, oy, oz, dx, dy, dz, step, shell_samples, far)
        dn = math.sqrt(dx * dx + dy * dy + dz * dz)
        # the SH basis for this ray's direction, coefficient by coefficient (degree 0's is the constant SH_C0)
        q4, q5, q6, q7, q8 = sh2_terms(dx / dn, dy / dn, dz / dn)
        basis = (SH_C0, -SH_C1 * dy / dn, SH_C1 * dz / dn, -SH_C1 * dx / dn, q4, q5, q6, q7, q8)
        baked = logits.shape[0] > 0
        carried = 0.0  # weight of the samples not coloured yet
        last_r, last_g, last_b = background[0], background[1], background[2]
        trans = 1.0
        cr = cg = cb = 0.0
        zd = wsum = 0.0
        u0 = 1.0 / ts
        k = 0
        stride = 1  # lattice steps a sample stands for: doubled at each tail threshold crossed
        crossed = 0
        total = n_inner + shell_samples
        # inside the cube the contraction is the identity: vertex coordinates are affine in the lattice index
        gx0, gy0, gz0 = ((ox + t0 * dx + half) * scale, (oy + t0 * dy + half) * scale, (oz + t0 * dz + half) * scale)
        # a lattice step in vertex units from the unit direction: not from dt·d, whose rounding depends on d's
        # length, and moves a sample that lies on a cell face to the other cell at another scene scale
        gdx, gdy, gdz = dx / dn * (step * scale), dy / dn * (step * scale), dz / dn * (step * scale)
        # lattice steps a vertex unit along each axis: a jump's exit found by multiplying, not dividing
        igx, igy, igz = _inverse(gdx, dx), _inverse(gdy, dy), _inverse(gdz, dz)
        while k < total and trans > t_stop:
            # this sample stands for lattice steps k..k+n-1 (never across the end of the cube or the lattice),
            # taken at their middle
            n = min(stride, (n_inner if k < n_inner else total) - k)
            if k < n_inner:
                m = k + 0.5 * n
                t = t0 + m * dt
                gx, gy, gz = gx0 + m * gdx, gy0 + m * gdy, gz0 + m * gdz
            else:
                t = 1.0 / (u0 - (k + 0.5 * n - n_inner) * du)
                gx, gy, gz = grid_coords_xyz(ox + t * dx, oy + t * dy, oz + t * dz, shell, res)
            ci, cj, ck = cell_of(gx, res), cell_of(gy, res), cell_of(gz, res)
            bi, bj, bk = ci // BLOCK, cj // BLOCK, ck // BLOCK
            block_reach = reach[np.uint64(bi), np.uint64(bj), np.uint64(bk)]  # unsigned: see _row
            if k < n_inner and block_reach >= 0:
                # an empty block: jump to where the ray leaves the box of empty blocks around it (one sample a
                # step: see the docstring), or this block alone
                e = np.int64(block_reach) if stride == 1 else 0
                m_exit = min(_exit_steps(bi, e, gx0, igx), _exit_steps(bj, e, gy0, igy), _exit_steps(bk, e, gz0, igz))
                k = min(max(k + 1, int(math.ceil(m_exit - 0.5 - 1e-9 * (1.0 + m_exit)))), n_inner)
                continue
            k += n
            if not cell_occupied(bits, bi, bj, bk, ci, cj, ck):
                continue
            # trilinear weights of the cell's corners v0..v7 (bits i, j, k of the corner index), computed once
            fx, fy, fz = gx - ci, gy - cj, gz - ck
            ex, ey, ez = 1.0 - fx, 1.0 - fy, 1.0 - fz
            a00, a01, a10, a11 = ex * ey, ex * fy, fx * ey, fx * fy
            w0, w1, w2, w3 = a00 * ez, a00 * fz, a01 * ez, a01 * fz
            w4, w5, w6, w7 = a10 * ez, a10 * fz, a11 * ez, a11 * fz
            v = (ci * res + cj) * res + ck
            v0, v1 = _row(rows, v), _row(rows, v + 1)
            v2, v3 = _row(rows, v + res), _row(rows, v + res + 1)
            v4, v5 = _row(rows, v + rr), _row(rows, v + rr + 1)
            v6, v7 = _row(rows, v + rr + res), _row(rows, v + rr + res + 1)
            sigma_raw = (w0 * density[v0] + w1 * density[v1] + w2 * density[v2] + w3 * density[v3]
                         + w4 * density[v4] + w5 * density[v5] + w6 * density[v6] + w7 * density[v7])
            alpha = _alpha(sigma_raw + density_shift, sigma_step * n)
            if alpha <= 0.0:
                continue
            weight = trans * alpha
            trans *= 1.0 - alpha
            while crossed < tail.shape[0] and trans < tail[crossed]:
                crossed += 1
                stride *= 2
            if want_depth:
                zd += weight * t
                wsum += weight
            if weight + carried < min_weight:
                carried += weight
                continue
            weight += carried
            carried = 0.0
            vs, ws = (v0, v1, v2, v3, v4, v5, v6, v7), (w0, w1, w2, w3, w4, w5, w6, w7)
            if baked:
                lr, lg, lb = _at(logits, 0, vs, ws), _at(logits, 1, vs, ws), _at(logits, 2, vs, ws)
            else:
                lr, lg, lb = _sh_logits(values, sh_degree, basis, vs, ws)
            last_r = 1.0 / (1.0 + math.exp(-lr))
            last_g = 1.0 / (1.0 + math.exp(-lg))
            last_b = 1.0 / (1.0 + math.exp(-lb))
            cr += weight * last_r
            cg += weight * last_g
            cb += weight * last_b
        cr += carried * last_r
        cg += carried * last_g
        cb += carried * last_b
        rgb[i, 0] = cr + trans * background[0]
        rgb[i, 1] = cg + trans * background[1]
        rgb[i, 2] = cb + trans * background[2]
        opacity[i] = 1.0 - trans
        if want_depth:
            depth[i] = zd / wsum if trans < 1.0 else ts + far / dn


@njit(cache=True, inline="always")
def _inverse(g_step, d):
    """Lattice steps a vertex unit along one axis (``1 / g_step``, signed), or 0 where the ray's direction ``d``
    has no component along it (``|d| <= 1e-12``, as :func:`~pytest_n2r.field.kernels.block_exit`)."""
    return 1.0 / g_step if abs(d) > 1e-12 else 0.0


@njit(cache=True, inline="always")
def _exit_steps(b, e, g0, inverse):
    """Lattice index ``m`` (a sample at ``g0 + m·step``) where the ray leaves, along one axis, the box of blocks
    ``b - e .. b + e`` (vertex coordinates ``BLOCK·(b - e)`` to ``BLOCK·(b + e + 1)``); infinity along an axis it
    does not move along (``inverse`` 0)."""
    if inverse > 0.0:
        return ((b + e + 1) * BLOCK - g0) * inverse
    if inverse < 0.0:
        return ((b - e) * BLOCK - g0) * inverse
    return math.inf


@njit(cache=True, inline="always")
def _row(rows, v):
    """:func:`~pytest_n2r.field.kernels.vertex_row` as an unsigned index. The kernel reads only the corners of
    occupied cells, which a field stores (a scene file's are checked when it is read, a field's when its renderer is
    built), and its cell and block indices are >= 0; numba indexes an array with a signed integer by adding the
    axis length to a negative one, a few instructions at every lookup, and with an unsigned one it does not."""
    return np.uint64(v) if rows.shape[0] == 0 else np.uint64(rows[np.uint64(v)])


@njit(cache=True, inline="always")
def _at(table, column, rows, weights):
    """The trilinear interpolation of ``table[:, column]`` at a sample: its 8 corner ``rows`` and ``weights``."""
    return (weights[0] * table[rows[0], column] + weights[1] * table[rows[1], column]
            + weights[2] * table[rows[2], column] + weights[3] * table[rows[3], column]
            + weights[4] * table[rows[4], column] + weights[5] * table[rows[5], column]
            + weights[6] * table[rows[6], column] + weights[7] * table[rows[7], column])


@njit(cache=True, inline="always")
def _sh_logits(values, sh_degree, basis, rows, weights):
    """A sample's colour logits from its corners' SH coefficients (coefficient ``l·3 + channel`` is column
    ``1 + l·3 + channel`` of ``values``) and the ``basis`` of its ray's direction (9 values): each degree's terms
    summed in order, then added to the logits degree by degree. A loop, so numba inlines the interpolation (``_at``)
    three times, not 27: the kernel compiles in about 3 CPU s less (docs/performance.md, "The main job")."""
    lr = lg = lb = 0.0
    for degree in range(sh_degree + 1):
        sr = sg = sb = 0.0
        for c in range(degree * degree, (degree + 1) * (degree + 1)):
            column = 1 + 3 * c
            sr += basis[c] * _at(values, column, rows, weights)
            sg += basis[c] * _at(values, column + 1, rows, weights)
            sb += basis[c] * _at(values, column + 2, rows, weights)
        lr, lg, lb = lr + sr, lg + sg, lb + sb
    return lr, lg, lb


@njit(cache=True, inline="always")
def _alpha(x, sigma_step):
    """:func:`~pytest_n2r.field.kernels.sample_alpha`, with the spacings of the tail's longer samples (1 and 2
    voxels: ``1 - (1 + e^x)^-1`` and ``1 - (1 + e^x)^-2``) without a logarithm (the same value to rounding)."""
    if x < 40.0:
        if sigma_step == 1.0:
            return 1.0 - 1.0 / (1.0 + math.exp(x))
        if sigma_step == 2.0:
            q = 1.0 / (1.0 + math.exp(x))
            return 1.0 - q * q
    return sample_alpha(x, sigma_step)


@njit(cache=True, nogil=True)
def vertex_positions(first, last, vertex, res, shell, position, outer):
    """Where :func:`bake_logits` takes the direction to each of the stored vertices ``first <= r < last`` from:
    ``position[:, r]`` (of ``(3, n_rows)`` float64, normalized space) is the vertex's uncontracted position, or, for a
    vertex on the shell's outer face (``outer[r]`` set), which stands for infinity, its contracted position, a
    direction. ``vertex`` is each row's flat vertex index ``(i·R + j)·R + k``. Once a renderer: a frame's bake
    then reads these instead of dividing each row's index into its three (docs/performance-log.md, "Rendering")."""
    half = 1.0 + shell
    cell = 2.0 * half / (res - 1)
    for r in range(first, last):
        f = vertex[r]
        qx, qy, qz = f // (res * res) * cell - half, (f // res) % res * cell - half, f % res * cell - half
        m = max(abs(qx), abs(qy), abs(qz))
        outer[r] = m >= half - 1e-9
        if outer[r]:
            position[0, r], position[1, r], position[2, r] = qx, qy, qz
        else:  # uncontract (pytest_n2r.field.space): ‖q‖∞ = 1 + shell·(1 - 1/‖p‖∞)
            s = 1.0 if m <= 1.0 else 1.0 / ((1.0 - (m - 1.0) / shell) * m)
            position[0, r], position[1, r], position[2, r] = qx * s, qy * s, qz * s


@njit(cache=True, nogil=True)
def colour_columns(first, last, values, colour):
    """The SH colour coefficients of rows ``first <= r < last`` by column: ``colour[c, r] = values[r, 1 + c]``
    (``colour`` ``(3·n_sh, n_rows)``, ``values`` ``(n_rows, 1 + 3·n_sh)``, of one dtype), what :func:`bake_logits`
    reads; once a renderer (3.3x less time than numpy's transposed copy on two threads)."""
    for r in range(first, last):
        for c in range(colour.shape[0]):
            colour[c, r] = values[r, 1 + c]


@njit(cache=True, nogil=True)
def bake_logits(first, last, colour, position, outer, origin, sh_degree, out):
    """Colour logits ``out[first:last]`` (of ``out (n_rows, 3)``) of those stored vertices seen from ``origin`` (the
    camera centre, normalized space): each one's SH colour for the direction from ``origin`` to the vertex, from
    :func:`vertex_positions`' ``position`` and ``outer`` (to a vertex on the shell's outer face, the direction of
    its contracted position). ``colour`` is the field's SH colour coefficients by column, ``(3·n_sh, n_rows)``
    (a field's ``values[:, 1:]`` transposed). A degree-0 field's logits take no direction (``position`` and
    ``outer`` unread).

    Column by column and without a branch, so the loop runs on vector registers: 2.1-2.3x less CPU than row by
    row with branches, the same bits (docs/performance-log.md, "Rendering")."""
    for r in range(first, last):
        lr, lg, lb = SH_C0 * colour[0, r], SH_C0 * colour[1, r], SH_C0 * colour[2, r]
        if sh_degree > 0:
            inner = not outer[r]
            ux = position[0, r] - (origin[0] if inner else 0.0)
            uy = position[1, r] - (origin[1] if inner else 0.0)
            uz = position[2, r] - (origin[2] if inner else 0.0)
            n = math.sqrt(ux * ux + uy * uy + uz * uz)
            n = n if n > 0.0 else 1.0  # a vertex at the camera centre (u = 0): its direction-free colour
            b1, b2, b3 = -SH_C1 * uy / n, SH_C1 * uz / n, -SH_C1 * ux / n
            lr += b1 * colour[3, r] + b2 * colour[6, r] + b3 * colour[9, r]
            lg += b1 * colour[4, r] + b2 * colour[7, r] + b3 * colour[10, r]
            lb += b1 * colour[5, r] + b2 * colour[8, r] + b3 * colour[11, r]
            if sh_degree == 2:
                q4, q5, q6, q7, q8 = sh2_terms(ux / n, uy / n, uz / n)
                lr += (q4 * colour[12, r] + q5 * colour[15, r] + q6 * colour[18, r] + q7 * colour[21, r]
                       + q8 * colour[24, r])
                lg += (q4 * colour[13, r] + q5 * colour[16, r] + q6 * colour[19, r] + q7 * colour[22, r]
                       + q8 * colour[25, r])
                lb += (q4 * colour[14, r] + q5 * colour[17, r] + q6 * colour[20, r] + q7 * colour[23, r]
                       + q8 * colour[26, r])
        out[r, 0], out[r, 1], out[r, 2] = lr, lg, lb


@njit(cache=True, nogil=True)
def pixel_rays(first, last, index, width, pinhole, c2w, center, radius, o, d):
    """The normalized rays ``o[first:last], d[first:last]`` (of ``(N, 3)``, float32) through the centres of the
    pixels with flat indices ``index[first:last]`` (``y·width + x``) of a pinhole camera (``pinhole``: ``fx, fy,
    cx, cy``) at ``c2w``:
    :func:`pytest_n2r.geometry.camera_rays` (camera-frame z-component 1, so ``t`` is z-depth) then
    :meth:`pytest_n2r.field.space.SceneSpace.normalize_rays` (minus ``center``, over ``radius``), in float64
    before the one rounding to float32, without their arrays."""
    ox, oy, oz = _camera_origin(c2w, center, radius)
    for r in range(first, last):
        o[r, 0], o[r, 1], o[r, 2] = ox, oy, oz
        d[r, 0], d[r, 1], d[r, 2] = _pixel_direction(index[r], width, pinhole, c2w, radius)


@njit(cache=True, inline="always")
def _camera_origin(c2w, center, radius):
    """The camera centre of ``c2w`` in normalized space (minus the scene's ``center``, over its ``radius``;
    float64, before :func:`pixel_rays` rounds it)."""
    return (c2w[0, 3] - center[0]) / radius, (c2w[1, 3] - center[1]) / radius, (c2w[2, 3] - center[2]) / radius


@njit(cache=True, inline="always")
def _pixel_direction(p, width, pinhole, c2w, radius):
    """The normalized direction (float64, before :func:`pixel_rays` rounds it) of the ray through the centre of pixel
    ``p`` (flat, ``y·width + x``) of a pinhole camera (``pinhole``: ``fx, fy, cx, cy``) at ``c2w``, the scene's
    ``radius`` the unit: camera-frame z-component 1 (``t`` is z-depth), rotated to the world, over ``radius``."""
    x = (p % width - pinhole[2]) / pinhole[0]
    y = (p // width - pinhole[3]) / pinhole[1]
    return ((x * c2w[0, 0] + y * c2w[0, 1] + c2w[0, 2]) / radius, (x * c2w[1, 0] + y * c2w[1, 1] + c2w[1, 2]) / radius,
            (x * c2w[2, 0] + y * c2w[2, 1] + c2w[2, 2]) / radius)


@njit(cache=True, inline="always")
def _rounded(v):
    """A float64 triple rounded to float32 and back, as a ray :func:`pixel_rays` stores is read."""
    return np.float64(np.float32(v[0])), np.float64(np.float32(v[1])), np.float64(np.float32(v[2]))
