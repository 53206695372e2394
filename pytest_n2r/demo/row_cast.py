"""A row of rays cast into the exact demo scenes (numba): each ray's nearest hit over the scene's primitives, a
relief's hits for the whole row at once (:mod:`.relief_rows`), and the row cast the ray caster's kernel calls
once per row of rays (:func:`cast_row_kernel`).

The row cast is a *kernel piece* (:func:`~pytest_n2r.scene.first_render.claim_piece`): compiled apart from the
kernel (:mod:`.raycast`), which calls it through a function pointer of one type (:data:`CAST_ROW_SIGNATURE`) and
compiles against a placeholder of that type (:func:`no_cast_row`). The two are about half of the ray caster's
compile each, and two processes can compile them at once (the kernel helper, or a process waiting for another's
kernels: ``docs/performance-log.md``).

Convention
----------
- Rays, hits and surface coordinates as in :mod:`.primitives`: a ray ``o + t d`` (scene units, world frame),
  ``t`` is ``inf`` on a miss; ``prims`` rows as :func:`.raycast.compile_scene` lays them out, their kind in
  ``kinds`` (:data:`DISC`, :data:`BOX`, :data:`CYLINDER`, :data:`RELIEF`).
- A row's outputs are rows of the kernel's arrays (``ts, ks, gxs, gzs, haves[row]``), written in place.
"""

from __future__ import annotations

import functools
import math
import platform
from typing import Any

import numpy as np
from llvmlite import ir
from numba import njit, types
from numba.extending import intrinsic

from ..render.borrow import borrowed as _borrowed
from ..scene.first_render import claim_piece
from .primitives import T_MIN
from .relief_kernel import HIT_ROWS, MODEL_ROWS, SLOT, STATE_ROWS, SUM_ROWS, relief_hits
from .relief_rows import relief_row

__all__ = ["BOX", "CAST_ROW_PIECE", "CAST_ROW_SIGNATURE", "CYLINDER", "DISC", "RELIEF", "barrier_constraint",
           "cast_rays", "cast_row_kernel", "no_cast_row"]

#: Primitive kinds (the ``kinds`` column of a compiled scene).
DISC, BOX, CYLINDER, RELIEF = 0, 1, 2, 3


def barrier_constraint(machine: str) -> str | None:
    """The inline-asm constraint that keeps a float64 in place in a vector register on ``machine`` (as
    ``platform.machine()`` names it): ``"=x,0"`` on x86-64; ``None`` elsewhere, where :func:`_opaque` is the
    plain value (the same images; LLVM may then hoist the divisions again). Other architectures spell the
    register class differently, and an unknown letter would fail the kernel's compile.

    >>> barrier_constraint("x86_64"), barrier_constraint("AMD64"), barrier_constraint("arm64")
    ('=x,0', '=x,0', None)
    """
    return "=x,0" if machine.lower() in ("x86_64", "amd64") else None


@intrinsic
def _opaque(typingctx, x):
    """``x`` itself, through an empty asm statement that LLVM may not move: a division of it stays in the branch that
    needs it. (LLVM hoists a division out of a loop when its inputs are invariant, even out of a branch: the
    three of ``1 / d`` went to every ray, a tenth of an object frame, though only rays that meet a box use them.)
    Only where :func:`barrier_constraint` knows the machine."""
    def codegen(context, builder, signature, args):
        constraint = barrier_constraint(platform.machine())
        if constraint is None:
            return args[0]
        double = ir.DoubleType()
        barrier = ir.InlineAsm(ir.FunctionType(double, [double]), "", constraint, side_effect=True)
        return builder.call(barrier, args)

    return types.float64(types.float64), codegen


@njit(cache=True, error_model="numpy")
def _slab(ox, oy, oz, ix, iy, iz, lo0, lo1, lo2, hi0, hi1, hi2):
    """Entry and exit ``t`` of a ray (inverse direction ``1 / d``) through a box, NaN-safe like ``np.fmin`` /
    ``np.fmax``."""
    t_near, t_far = -math.inf, math.inf
    for o, inv, lo, hi in ((ox, ix, lo0, hi0), (oy, iy, lo1, hi1), (oz, iz, lo2, hi2)):
        t0, t1 = (lo - o) * inv, (hi - o) * inv
        lo_t = t1 if math.isnan(t0) else (t0 if math.isnan(t1) else min(t0, t1))
        hi_t = t1 if math.isnan(t0) else (t0 if math.isnan(t1) else max(t0, t1))
        if not math.isnan(lo_t):
            t_near = max(t_near, lo_t)
        if not math.isnan(hi_t):
            t_far = min(t_far, hi_t)
    return t_near, t_far


@njit(cache=True, inline="always", error_model="numpy")
def _cylinder_hit(prims, row, ox, oy, oz, dx, dy, dz):
    """First hit of a capped :class:`~.primitives.Cylinder`, ``inf`` on a miss."""
    qx, qy, qz = ox - prims[row, 0], oy - prims[row, 1], oz - prims[row, 2]
    k = int(prims[row, 3])
    if k == 0:  # (i, j, k) = the two cross axes and the axis, without indexing a tuple at run time
        qi, qj, qk, di, dj, dk = qy, qz, qx, dy, dz, dx
    elif k == 1:
        qi, qj, qk, di, dj, dk = qx, qz, qy, dx, dz, dy
    else:
        qi, qj, qk, di, dj, dk = qx, qy, qz, dx, dy, dz
    radius, half = prims[row, 4], prims[row, 5]
    A = di * di + dj * dj
    B = 2 * (qi * di + qj * dj)
    C = qi * qi + qj * qj - radius ** 2
    disc = B * B - 4 * A * C
    best = math.inf
    if disc >= 0:
        root = math.sqrt(disc)
        for t in ((-B - root) / (2 * A), (-B + root) / (2 * A)):
            along = qk + t * dk
            if t > T_MIN and abs(along) <= half and t < best:
                best = t
    for sign in (-1.0, 1.0):
        t = (sign * half - qk) / dk
        pi, pj = qi + t * di, qj + t * dj
        if t > T_MIN and pi * pi + pj * pj <= radius ** 2 and t < best:
            best = t
    return best


@njit(cache=True, inline="always", error_model="numpy")
def _hit(kind, prims, row, reliefs, j, ox, oy, oz, dx, dy, dz, ix, iy, iz):
    """``t`` of the first hit of one primitive (``inf`` on a miss), and a relief's gradient there: a relief's hits
    are found beforehand for a whole batch of rays (``reliefs[slot, 0:4, j]``, :func:`.relief_kernel.relief_hits`)."""
    if kind == RELIEF:
        slot = int(prims[row, SLOT])
        return reliefs[slot, 0, j], reliefs[slot, 1, j], reliefs[slot, 2, j], reliefs[slot, 3, j] != 0.0
    if kind == DISC:
        t = _disc_hit(prims, row, ox, oy, oz, dx, dy, dz)
    elif kind == BOX:
        t = _box_hit(prims, row, ox, oy, oz, ix, iy, iz)
    else:
        t = _cylinder_hit(prims, row, ox, oy, oz, dx, dy, dz)
    return t, 0.0, 0.0, False


@njit(cache=True, inline="always", error_model="numpy")
def _disc_hit(prims, row, ox, oy, oz, dx, dy, dz):
    """First hit of a :class:`~.primitives.Disc`, ``inf`` on a miss."""
    t = (prims[row, 0] - oz) / dz
    qx, qy = ox + t * dx - prims[row, 2], oy + t * dy - prims[row, 3]
    return t if t > T_MIN and qx ** 2 + qy ** 2 <= prims[row, 1] ** 2 else math.inf


@njit(cache=True, inline="always", error_model="numpy")
def _box_hit(prims, row, ox, oy, oz, ix, iy, iz):
    """First hit of a box ``lo, hi`` (``prims[row, 0:6]``) by a ray of inverse direction ``1 / d``, ``inf`` on a
    miss; from inside, the exit face."""
    t_near, t_far = _slab(ox, oy, oz, ix, iy, iz, prims[row, 0], prims[row, 1], prims[row, 2], prims[row, 3],
                          prims[row, 4], prims[row, 5])
    if t_near <= t_far and t_far > T_MIN:
        return t_near if t_near > T_MIN else t_far
    return math.inf


@njit(cache=True, nogil=True, error_model="numpy")
def _hits_along(kind, table, row, ox, oy, oz, dxs, dys, dzs, out):
    """``t`` of the first hit of one disc, box or cylinder (``kind``, its parameters ``table[row]``; a group's box
    is a box) along rays ``o + t d`` (``d`` = ``dxs[j], dys[j], dzs[j]``) into ``out[j]``, ``inf`` on a miss. Compiled
    apart and called with each row as its own array, so that LLVM vectorizes the loops (see :func:`_nearest_hits`)."""
    if kind == DISC:
        for j in range(out.shape[0]):
            out[j] = _disc_hit(table, row, ox, oy, oz, dxs[j], dys[j], dzs[j])
    elif kind == BOX:
        for j in range(out.shape[0]):
            out[j] = _box_hit(table, row, ox, oy, oz, 1.0 / dxs[j], 1.0 / dys[j], 1.0 / dzs[j])
    else:
        for j in range(out.shape[0]):
            out[j] = _cylinder_hit(table, row, ox, oy, oz, dxs[j], dys[j], dzs[j])


@njit(cache=True, inline="always", error_model="numpy")
def _nearest_hits(groups, group_box, kinds, prims, reliefs, rects, us, v, ox, oy, oz, ds, count, row, ts, ks, gxs,
                  gzs, haves, spare):
    """:func:`_cast` for rays ``j < count`` of a row at once (pixel columns ``us[j]``, increasing in ``j``, and
    row ``v``; directions ``ds[0:3, j]``) into ``ts, ks, gxs, gzs, haves[row, j]``: the same tests in the same order
    with the same arithmetic, but one group's box and one primitive at a time over the rays under its screen
    rectangle (a span of ``j``), each a loop LLVM vectorizes (:func:`_hits_along`, into ``spare[0]``; the group's
    box into ``spare[1]``)."""
    for j in range(count):
        ts[row, j], ks[row, j], gxs[row, j], gzs[row, j], haves[row, j] = math.inf, 0, 0.0, 0.0, 0
    columns = us[:count]
    n_groups = groups.shape[0]
    for g in range(n_groups):
        if v < rects[g, 2] or v > rects[g, 3]:
            continue
        g0, g1 = np.searchsorted(columns, rects[g, 0], "left"), np.searchsorted(columns, rects[g, 1], "right")
        if g1 <= g0:
            continue
        if groups[g, 2]:  # rays that miss the group's box skip its primitives (BOX as a run-time value: numba
            # would compile _hits_along once more for a literal kind)
            _hits_along(groups[g, 2] * BOX, group_box, g, ox, oy, oz, ds[0, g0:g1], ds[1, g0:g1], ds[2, g0:g1],
                        spare[1, g0:g1])
        else:
            spare[1, g0:g1] = 0.0
        for k in range(groups[g, 0], groups[g, 1]):
            r = n_groups + k
            if v < rects[r, 2] or v > rects[r, 3]:
                continue
            j0 = max(g0, np.searchsorted(columns, rects[r, 0], "left"))
            j1 = min(g1, np.searchsorted(columns, rects[r, 1], "right"))
            if j1 <= j0:
                continue
            relief = kinds[k] == RELIEF
            hits = reliefs[int(prims[k, SLOT])] if relief else reliefs[0]
            if not relief:
                _hits_along(kinds[k], prims, k, ox, oy, oz, ds[0, j0:j1], ds[1, j0:j1], ds[2, j0:j1],
                            spare[0, j0:j1])
            for j in range(j0, j1):
                t = hits[0, j] if relief else spare[0, j]
                if math.isfinite(spare[1, j]) and t < ts[row, j]:
                    ts[row, j], ks[row, j] = t, k
                    gxs[row, j], gzs[row, j], haves[row, j] = ((hits[1, j], hits[2, j], hits[3, j] != 0.0) if relief
                                                               else (0.0, 0.0, False))


@njit(cache=True, inline="always", error_model="numpy")
def _cast(groups, group_box, kinds, prims, reliefs, j, rects, u, v, ox, oy, oz, dx, dy, dz):
    """Nearest hit ``(t, primitive, dh/dx, dh/dz, have)`` of ray ``j`` of a batch over all groups (``t = inf`` and
    primitive 0 on a miss; a relief's hit and gradient from ``reliefs``, see :func:`_hit`). ``u, v``: the ray's
    pixel coordinates; groups and primitives whose screen rectangle (``rects``, :func:`.raycast.screen_rects`)
    does not hold them are skipped."""
    best, which, best_gx, best_gz, best_have = math.inf, 0, 0.0, 0.0, False
    ix = iy = iz = math.nan
    inverse = False  # 1 / d only for rays that meet a box (see _opaque)
    n_groups = groups.shape[0]
    for g in range(n_groups):
        if u < rects[g, 0] or u > rects[g, 1] or v < rects[g, 2] or v > rects[g, 3]:
            continue
        if groups[g, 2] and not inverse:
            ix, iy, iz, inverse = 1.0 / _opaque(dx), 1.0 / _opaque(dy), 1.0 / _opaque(dz), True
        if groups[g, 2]:
            t_near, t_far = _slab(ox, oy, oz, ix, iy, iz, group_box[g, 0], group_box[g, 1], group_box[g, 2],
                                  group_box[g, 3], group_box[g, 4], group_box[g, 5])
            if not (t_near <= t_far and t_far > T_MIN):
                continue
        for k in range(groups[g, 0], groups[g, 1]):
            r = n_groups + k
            if u < rects[r, 0] or u > rects[r, 1] or v < rects[r, 2] or v > rects[r, 3]:
                continue
            if kinds[k] == BOX and not inverse:
                ix, iy, iz, inverse = 1.0 / _opaque(dx), 1.0 / _opaque(dy), 1.0 / _opaque(dz), True
            t, gx, gz, have = _hit(kinds[k], prims, k, reliefs, j, ox, oy, oz, dx, dy, dz, ix, iy, iz)
            if t < best:
                best, which, best_gx, best_gz, best_have = t, k, gx, gz, have
    return best, which, best_gx, best_gz, best_have


@njit(cache=True, error_model="numpy")
def cast_rays(o, d, groups, group_box, kinds, prims, waves, lanes, rects, t_out, which_out):
    """:meth:`CompiledScene.cast`: one ray at a time (each its own origin), serial (used for small batches)."""
    ds, no_guess, pixel = np.empty((3, 1)), np.full(1, math.nan), np.zeros(1)
    state, sums, spare = np.empty((STATE_ROWS, 1)), np.empty((SUM_ROWS, 1)), np.empty((SUM_ROWS, 1))
    reliefs, model = np.empty((_relief_count(kinds), HIT_ROWS, 1)), np.empty((MODEL_ROWS, 1))
    everywhere = rects[0]
    for r in range(o.shape[0]):
        ds[0, 0], ds[1, 0], ds[2, 0] = d[r, 0], d[r, 1], d[r, 2]
        for k in range(kinds.shape[0]):
            if kinds[k] == RELIEF:
                relief_hits(prims, k, waves, lanes, o[r, 0], o[r, 1], o[r, 2], ds, no_guess, 1, pixel, 0.0,
                            everywhere, state, sums, spare, reliefs[int(prims[k, SLOT])], model, False)
        t_out[r], which_out[r], _, _, _ = _cast(groups, group_box, kinds, prims, reliefs, 0, rects, 0.0, 0.0,
                                                o[r, 0], o[r, 1], o[r, 2], d[r, 0], d[r, 1], d[r, 2])


@njit(cache=True, inline="always", error_model="numpy")
def _relief_count(kinds):
    """How many reliefs a scene has (at least 1: the size of the kernels' relief buffers)."""
    count = 0
    for k in range(kinds.shape[0]):
        count += kinds[k] == RELIEF
    return max(count, 1)


# -- a row of rays, the kernel piece -------------------------------------------------------------------------


#: The signature of :func:`_cast_row`: the kernel calls it through a function pointer of this type, so that the
#: two compile apart and two processes can compile them at once (:func:`cast_row_kernel`). It must name the types
#: the kernel passes exactly (numba refuses the kernel's compile otherwise: "mismatch of argument types").
CAST_ROW_SIGNATURE = (
    "void(int64, int64, float64, int64, float64[:, ::1], float64[::1], float64[:, ::1], float64[:, ::1], "
    "float64[:, ::1], int64[:, ::1], float64[:, ::1], int64[::1], float64[:, ::1], float32[:, ::1], float64[::1], "
    "float64[:, ::1], float64[:, ::1], float64[:, ::1], float64[:, ::1], float64[:, :, ::1], float64[:, ::1], "
    "int64[:, ::1], float64[:, ::1], float64[:, ::1], int64[:, ::1])")


def _cast_row(row, n, v, rows, c2w, camera, uss, xcs, rects, groups, group_box, kinds, prims, waves,
              lanes, rays, state, sums, spare, reliefs, ts, ks, gxs, gzs, haves):  # pragma: no cover - compiled
    """Cast row ``row`` of a pixel row's rays (``row < n``: a sub-row of sub-pixel rays at image row ``v``;
    ``row == n``: the pixel centres) into ``ts, ks, gxs, gzs, haves[row]``: their directions, each relief's hits
    for all of them at once (:func:`.relief_rows.relief_row`: a centre's after the ``rows`` rows of centres above
    in this band, a sub-row's after its pixel row's centres), then each ray's nearest hit. Compiled apart from
    the kernel (:func:`cast_row_kernel`) and called once per row of rays through a function pointer; its helpers
    receive views of its arrays without reference counts, as the kernel's (:func:`_borrowed`)."""
    fy, cy = camera[1], camera[3]
    ox, oy, oz = c2w[0, 3], c2w[1, 3], c2w[2, 3]
    rects, groups, group_box, kinds = _borrowed(rects), _borrowed(groups), _borrowed(group_box), _borrowed(kinds)
    prims, waves, lanes, reliefs = _borrowed(prims), _borrowed(waves), _borrowed(lanes), _borrowed(reliefs)
    uss, xcs, rays, ts, ks = _borrowed(uss), _borrowed(xcs), _borrowed(rays), _borrowed(ts), _borrowed(ks)
    gxs, gzs, haves = _borrowed(gxs), _borrowed(gzs), _borrowed(haves)
    centre = row == n
    table = n if centre else 0
    count = ts.shape[1] // n if centre else ts.shape[1]
    ds, guesses = rays[0:3], rays[3]
    yc = (v - cy) / fy
    for j in range(count):
        xc = xcs[table, j]
        ds[0, j] = xc * c2w[0, 0] + yc * c2w[0, 1] + c2w[0, 2]
        ds[1, j] = xc * c2w[1, 0] + yc * c2w[1, 1] + c2w[1, 2]
        ds[2, j] = xc * c2w[2, 0] + yc * c2w[2, 1] + c2w[2, 2]
    for k in range(kinds.shape[0]):
        if kinds[k] == RELIEF:
            relief_row(k, prims, waves, lanes, ox, oy, oz, ds, guesses, count, uss[table], v,
                       rects[groups.shape[0] + k], state, sums, spare, reliefs[int(prims[k, SLOT])], n, rows, centre)
    _nearest_hits(groups, group_box, kinds, prims, reliefs, rects, uss[table], v, ox, oy, oz, ds, count, row, ts, ks,
                  gxs, gzs, haves, spare)


#: The kernel piece (:func:`~pytest_n2r.scene.first_render.claim_piece`) of :func:`cast_row_kernel`.
CAST_ROW_PIECE = "demo-cast-row"


@functools.cache
def cast_row_kernel() -> Any:
    """:func:`_cast_row` compiled for :data:`CAST_ROW_SIGNATURE` (or loaded from numba's cache), once a process,
    under its piece's lock: the kernel helper compiles it while the session compiles the kernel (about half of
    the ray caster's compile each, ``docs/performance-log.md``), and the session then waits for it and loads it."""
    with claim_piece(CAST_ROW_PIECE):
        return njit(CAST_ROW_SIGNATURE, cache=True, nogil=True, error_model="numpy")(_cast_row)


@functools.cache
def no_cast_row() -> Any:
    """A function of :func:`_cast_row`'s type that does nothing: the kernel's compile needs only the type."""
    return njit(CAST_ROW_SIGNATURE, cache=True)(_skip_row)


def _skip_row(row, n, v, rows, c2w, camera, uss, xcs, rects, groups, group_box, kinds, prims, waves, lanes, rays,
              state, sums, spare, reliefs, ts, ks, gxs, gzs, haves):  # pragma: no cover - compiled; never called
    pass
