"""A relief wall's hits for a batch of rays (numba): Newton's method in lockstep over the rays of one sub-row of
pixels, the relief's waves evaluated for all of the batch's rays in one loop that LLVM vectorizes.

The arithmetic is :meth:`.primitives.ReliefWall.height_and_gradient` and its safeguarded Newton search,
operation for operation (float32 waves, float64 roots); what changes is the order: one ray's chain of
evaluations was latency-bound (its sines in one 8-lane vector, then a chain of float32 sums and Newton's
division), so each evaluation of the waves now runs for every ray of the batch still searching, four rays to
a vector, and only the Newton update is per ray. Rays that converge leave the batch (it is compacted after
each round).

Convention
----------
- A relief's row of ``prims`` holds the columns named below (:func:`.raycast._primitive_row`); its waves are
  rows ``amp, fx, px, fz, pz`` (float32) of ``waves``.
- Rays ``o + t d`` share their origin ``o`` (a camera's centre), world frame, scene units.
- Roots end where the residual is below ``1e-7`` or Newton's step is so short that the relief's gradient cannot
  change by more than :data:`GRADIENT_TOLERANCE` over it (``curvature * |d_xz| * |step|``); the gradient of the
  last evaluation then serves as the normal's (``have``).
"""

from __future__ import annotations

import math

import numpy as np
from numba import njit

from .primitives import T_MIN
from .trig import sincos

__all__ = ["GRADIENT_TOLERANCE", "HIT_ROWS", "LANES", "MODEL_GRADIENT_TOLERANCE", "MODEL_ROWS", "RELIEF_COLUMNS",
           "STATE_ROWS", "SUM_ROWS", "relief_at", "relief_hits", "set_models"]

#: Columns of a relief's row in ``prims``: the wall's plane and extent, relief depth, slope bound, first wave
#: and wave count, Newton iterations, march steps, bisections, curvature bound, the relief's slot among the
#: scene's reliefs (see :func:`relief_hits`), the bound of its third derivatives (see :func:`_model_roots`).
Y0, X0, X1, Z0, Z1, DEPTH, SLOPE, FIRST, COUNT, NEWTON, STEPS, BISECTIONS, CURVATURE, SLOT, THIRD = range(15)
RELIEF_COLUMNS = 15
#: How far a relief's gradient may change between Newton's last evaluation and its last step: 1e-5 turns a
#: normal by at most 1e-5 rad, a colour by a few thousandths of a grey level.
GRADIENT_TOLERANCE = 1e-5
#: Rows of a batch's search state (``state[:, i]`` for its ray ``i``): bracket ``a, b``, ``t``, direction, the
#: step that is short enough, the ray's index; the last evaluation's float32 ``h``, ``dh/dx``, ``dh/dz`` (before
#: ``depth``) go to rows of another array (``sums``: were they rows of ``state``, LLVM could not tell that the
#: loop's stores do not overlap its loads, and would not vectorize it).
_A, _B, _T, _DX, _DY, _DZ, _SHORT, _RAY = range(8)
_H, _GX, _GZ, _HXX, _HXZ, _HZZ = range(6)
STATE_ROWS = 8
#: Rows of a batch's wave sums (``sums``, and of the scratch ``spare``, see :func:`relief_hits`).
SUM_ROWS = 6
#: Rows of a batch's hits (``hits[:, j]``, see :func:`relief_hits`): ``t``, ``dh/dx``, ``dh/dz``, whether they are
#: the last evaluation's, and the second derivatives there (times ``depth``).
HIT_ROWS = 7
#: Rows of a relief's models at the hits of a row of pixel-centre rays (``model[:, u]``, see :func:`set_models`):
#: the hit's ``x``, ``z`` (NaN: no model), gradient, second derivatives, and ``t (d_y + g . d)`` of its ray.
_MX, _MZ, _MGX, _MGZ, _MXX, _MXZ, _MZZ, _MN = range(8)
MODEL_ROWS = 8
#: Where a sub-pixel ray's hit is taken from its pixel centre's model (:func:`_model_roots`): while the model's
#: bound of its error in the height is at most the residual that ends a search (1e-7), and in the gradient at most
#: ``MODEL_GRADIENT_TOLERANCE`` (1e-4 turns a normal by at most 1e-4 rad, a colour by at most 0.02 grey levels).
MODEL_GRADIENT_TOLERANCE = 1e-4
#: Waves evaluated at once by :func:`relief_at`; its ``lanes`` buffer holds 6 of this many float64.
_WAVE_CHUNK = 4
LANES = 6 * _WAVE_CHUNK
_F0 = np.float32(0.0)


@njit(cache=True, error_model="numpy")
def relief_at(waves, lanes, first, count, depth, x, z):
    """``h``, ``dh/dx``, ``dh/dz`` of a relief at one point ``(x, z)``, in float32 like
    :meth:`ReliefWall.height_and_gradient`: the sines of up to :data:`_WAVE_CHUNK` waves' two phases in one
    loop over the ``lanes`` buffer (float64, :data:`LANES` long, the caller's), which LLVM vectorizes."""
    x32, z32 = np.float32(x), np.float32(z)
    h = np.float32(0.5)
    gx = np.float32(0.0)
    gz = np.float32(0.0)
    n = _WAVE_CHUNK
    for start in range(first, first + count, n):
        used = min(n, first + count - start)
        for lane in range(n):  # phases of x, then of z; the unused lanes repeat the last wave
            k = start + min(lane, used - 1)
            lanes[lane] = np.float64(waves[k, 1] * x32 + waves[k, 2])
            lanes[n + lane] = np.float64(waves[k, 3] * z32 + waves[k, 4])
        for lane in range(2 * n):
            lanes[2 * n + lane], lanes[4 * n + lane] = sincos(lanes[lane])
        for lane in range(used):
            k = start + lane
            amp, fx, fz = waves[k, 0], waves[k, 1], waves[k, 3]
            sx, sz = np.float32(lanes[2 * n + lane]), np.float32(lanes[3 * n + lane])
            cx, cz = np.float32(lanes[4 * n + lane]), np.float32(lanes[5 * n + lane])
            h += amp * sx * sz
            gx += amp * fx * cx * sz
            gz += amp * fz * sx * cz
    return depth * np.float64(h), depth * np.float64(gx), depth * np.float64(gz)


@njit(cache=True, inline="always", error_model="numpy")
def _evaluate(waves, first, count, ox, oz, state, sums, spare, live):
    """The waves' float32 sums (height, gradient, second derivatives) at ``o + t d`` of the first ``live`` rays of
    the batch, into ``sums``: one pass
    over the rays per wave, a loop that LLVM vectorizes. Each pass adds its wave to the sums of the pass before,
    from one array into the other (``spare`` and ``sums`` by turns, the last pass into ``sums``): LLVM
    vectorizes a loop whose stores go to another array than its loads."""
    for k in range(first, first + count):
        into_sums = (first + count - 1 - k) % 2 == 0
        dst, src = (sums, spare) if into_sums else (spare, sums)
        amp, fx, px, fz, pz = waves[k, 0], waves[k, 1], waves[k, 2], waves[k, 3], waves[k, 4]
        fresh = k == first
        for i in range(live):
            x32 = np.float32(ox + state[_T, i] * state[_DX, i])
            z32 = np.float32(oz + state[_T, i] * state[_DZ, i])
            h, gx, gz, hxx, hxz, hzz = np.float32(0.5), _F0, _F0, _F0, _F0, _F0
            if not fresh:
                h, gx, gz = np.float32(src[_H, i]), np.float32(src[_GX, i]), np.float32(src[_GZ, i])
                hxx, hxz, hzz = np.float32(src[_HXX, i]), np.float32(src[_HXZ, i]), np.float32(src[_HZZ, i])
            sx, cx = sincos(np.float64(fx * x32 + px))
            sz, cz = sincos(np.float64(fz * z32 + pz))
            sx32, cx32, sz32, cz32 = np.float32(sx), np.float32(cx), np.float32(sz), np.float32(cz)
            dst[_H, i] = np.float64(h + amp * sx32 * sz32)
            dst[_GX, i] = np.float64(gx + amp * fx * cx32 * sz32)
            dst[_GZ, i] = np.float64(gz + amp * fz * sx32 * cz32)
            dst[_HXX, i] = np.float64(hxx - amp * fx * fx * sx32 * sz32)
            dst[_HXZ, i] = np.float64(hxz + amp * fx * fz * cx32 * cz32)
            dst[_HZZ, i] = np.float64(hzz - amp * fz * fz * sx32 * sz32)


@njit(cache=True, inline="always", error_model="numpy")
def _finish(prims, row, hits, j, ox, oz, dx, dz, t, gx, gz, have, hxx, hxz, hzz):
    """A ray's result: its root where it lies within the wall's extent, else a miss (``t = inf``)."""
    px, pz = ox + t * dx, oz + t * dz
    if math.isfinite(t) and px >= prims[row, X0] and px <= prims[row, X1] and pz >= prims[row, Z0] \
            and pz <= prims[row, Z1]:
        hits[0, j], hits[1, j], hits[2, j], hits[3, j] = t, gx, gz, 1.0 if have else 0.0
        hits[4, j], hits[5, j], hits[6, j] = hxx, hxz, hzz


#: A ray's search (:func:`_brackets`): none (it misses the relief's slab or its screen rectangle), Newton's method
#: (a monotonic residual) or a march (a grazing ray).
_NONE, _NEWTON, _MARCH = 0.0, 1.0, 2.0


@njit(cache=True, nogil=True, error_model="numpy")
def _brackets(us, v, rect, oy, y0, depth, slope, curvature, dxs, dys, dzs, los, his, shorts, searches):
    """Each ray ``j``'s bracket ``los[j], his[j]`` of ``t`` across the relief's slab ``y0 - depth <= y <= y0``,
    the step short enough to end its Newton search (``shorts[j]``, see the module *Convention*) and its search
    (``searches[j]``: :data:`_NONE`, :data:`_NEWTON` or :data:`_MARCH`), for rays from height ``oy`` in directions
    ``dxs[j], dys[j], dzs[j]`` at pixel ``(us[j], v)`` (outside ``rect``: none). Compiled apart and called with each
    row as its own array, so that LLVM vectorizes the loop (its three divisions and square root four rays to a
    vector; per ray, in the loop that fills the search state, they were a latency-bound chain)."""
    for j in range(dxs.shape[0]):  # a length, not a count argument: numba would compile once more for a literal
        dx, dy, dz = dxs[j], dys[j], dzs[j]
        t_in = (y0 - depth - oy) / dy
        t_out = (y0 - oy) / dy
        across = math.sqrt(dx * dx + dz * dz)  # not hypot (several times slower): only picks the search below
        los[j], his[j] = max(t_in, T_MIN), t_out
        shorts[j] = GRADIENT_TOLERANCE / (curvature * across + 1e-300)
        inside = not (us[j] < rect[0] or us[j] > rect[1] or v < rect[2] or v > rect[3]) and dy > 0 and t_out > T_MIN
        searches[j] = (_NEWTON if dy > 1.05 * slope * across else _MARCH) if inside else _NONE


#: How a Newton step ended (:func:`_newton_steps`): converged, or the root lies above the last ``t`` (which becomes
#: the bracket's ``a``), or below it (its ``b``).
_DONE, _ABOVE, _BELOW = 0.0, 1.0, 2.0


@njit(cache=True, nogil=True, error_model="numpy")
def _newton_steps(oy, y0, depth, as_, bs, ts, dxs, dys, dzs, shorts, hs, gxs, gzs, steps, sides):
    """One safeguarded Newton step of each ray ``i`` of a search (bracket ``as_[i], bs[i]``, root ``ts[i]``,
    direction ``dxs[i], dys[i], dzs[i]``, the step that ends it ``shorts[i]``; the waves' sums at ``ts[i]`` in
    ``hs, gxs, gzs``, see :func:`_evaluate`): the next root into ``steps[i]`` and into ``sides[i]`` whether the
    search ended (:data:`_DONE`: the residual is below 1e-7, ``steps[i]`` is ``ts[i]``, or the step was short) or
    which end of the bracket ``ts[i]`` replaces. Compiled apart and called with each row as its own array, so that
    LLVM vectorizes the loop (Newton's division four rays to a vector)."""
    for i in range(ts.shape[0]):
        a, b, t = as_[i], bs[i], ts[i]
        dx, dy, dz = dxs[i], dys[i], dzs[i]
        gx, gz = depth * gxs[i], depth * gzs[i]
        f = oy + t * dy - y0 + depth * hs[i]
        converged = abs(f) <= 1e-7
        df = dy + gx * dx + gz * dz
        above = f < 0
        a, b = (t, b) if above else (a, t)
        step = t - f / df
        inside = step > a and step < b
        short = inside and abs(step - t) <= shorts[i]
        steps[i] = t if converged else (step if inside else 0.5 * (a + b))
        sides[i] = _DONE if converged or short else (_ABOVE if above else _BELOW)


@njit(cache=True, nogil=True, error_model="numpy")
def _model_roots(third, ox, oz, dxs, dys, dzs, los, his, xf, zf, mgx, mgz, mxx, mxz, mzz, mn, ts, gxs, gzs):
    """Each ray ``j``'s root and gradient (``ts[j], gxs[j], gzs[j]``, the gradient times ``depth``) from the model
    of the relief at its pixel centre's hit (column ``j`` of the model's rows, as :func:`set_models` fills them):
    the second-order Taylor expansion of the height about that hit, its tangent plane's root refined by one
    Newton step on the expansion (its derivative taken as the plane's: the step is some 1e-6 scene units, the
    second-order term changes it by under 1 %). NaN where there is no model; where the root lies outside
    ``[los[j], his[j]]`` or the bound of the expansion's error (``third``: of the relief's third derivatives)
    exceeds the residual that ends a search (1e-7) in the height or :data:`MODEL_GRADIENT_TOLERANCE` in the
    gradient, the gradient is NaN and the root is a guess for a search. Rays whose residual is monotonic across
    the slab (steep ones) have one root, so the root near their pixel centre's is theirs. Compiled apart and
    called with each row as its own array, so that LLVM vectorizes the loop (its division four rays to a
    vector)."""
    for j in range(dxs.shape[0]):
        dx, dy, dz = dxs[j], dys[j], dzs[j]
        gx, gz, hxx, hxz, hzz = mgx[j], mgz[j], mxx[j], mxz[j], mzz[j]
        inverse = 1.0 / (dy + gx * dx + gz * dz)
        t = mn[j] * inverse  # the tangent plane's root: t_f (d_y + g . d) of the centre over the ray's
        ex, ez = ox + t * dx - xf[j], oz + t * dz - zf[j]
        t -= 0.5 * (ex * (hxx * ex + hxz * ez) + ez * (hxz * ex + hzz * ez)) * inverse
        ex, ez = ox + t * dx - xf[j], oz + t * dz - zf[j]
        reach = ex * ex + ez * ez
        ok = t > los[j] and t < his[j] and third * third * reach * reach * reach <= 3.6e-13 \
            and third * reach <= 2.0 * MODEL_GRADIENT_TOLERANCE
        ts[j] = t
        gxs[j] = gx + hxx * ex + hxz * ez if ok else math.nan
        gzs[j] = gz + hxz * ex + hzz * ez


@njit(cache=True, error_model="numpy")
def set_models(hits, ox, oz, ds, m, n, model):
    """The models of the relief at the hits ``hits[:, u]`` of a row of ``m`` pixel-centre rays in directions
    ``ds[0:3, u]`` (:func:`relief_hits`), for the ``n`` sub-pixel rays along a row of each of those pixels
    (columns ``u n`` to ``u n + n - 1``, :func:`_model_roots`): the hit's
    ``x, z``, the gradient and second derivatives of the relief's last evaluation, and ``t (d_y + g . d)``; NaN in
    ``x`` where the ray found no root by Newton's method (a miss, a march, or out of iterations).

    The model of a hit ``p_f`` is ``y0 - depth h(p) = y_f - g . e - e H e / 2`` with ``e = p - p_f``: the last
    evaluation lies a step that changes the gradient by at most :data:`GRADIENT_TOLERANCE` from ``p_f``, and its
    tangent plane goes through ``p_f`` (Newton's step)."""
    for u in range(m):
        t, dx, dy, dz = hits[0, u], ds[0, u], ds[1, u], ds[2, u]
        have = math.isfinite(t) and hits[3, u] != 0.0
        gx, gz = hits[1, u], hits[2, u]
        x, z, numerator = (ox + t * dx if have else math.nan), oz + t * dz, t * (dy + gx * dx + gz * dz)
        for j in range(u * n, u * n + n):
            model[_MX, j], model[_MZ, j], model[_MGX, j], model[_MGZ, j] = x, z, gx, gz
            model[_MXX, j], model[_MXZ, j], model[_MZZ, j] = hits[4, u], hits[5, u], hits[6, u]
            model[_MN, j] = numerator


@njit(cache=True, error_model="numpy")
def relief_hits(prims, row, waves, lanes, ox, oy, oz, ds, guesses, m, us, v, rect, state, sums, spare, hits, model,
                models):
    """First hits of the relief in ``prims[row]`` along rays ``j < m`` from ``(ox, oy, oz)`` in directions
    ``ds[0:3, j]``: ``hits[0:4, j]`` = ``t`` (``inf`` on a miss), ``dh/dx``, ``dh/dz`` there and whether they are
    the last evaluation's at ``t`` (1.0) or not (0.0: the caller evaluates the relief again for the normal);
    ``hits[4:7, j]`` the second derivatives there (where 1.0).

    ``guesses[j]``: a predicted root (NaN: none; a guess outside the ray's bracket is not used; where ``models``,
    the model's root instead). Rays whose pixel
    coordinates ``(us[j], v)`` lie outside ``rect`` (``u_lo, u_hi, v_lo, v_hi``) miss. ``state``, ``sums`` and
    ``spare`` are the caller's scratch (:data:`STATE_ROWS`, :data:`SUM_ROWS` and :data:`SUM_ROWS` rows of ``m``,
    three arrays). Steep rays (a monotonic residual) take their root from their pixel centre's model where it is
    accurate (where ``models``: ray ``j``'s is ``model[:, j]``, see :func:`_model_roots`), else search by Newton's
    method in lockstep; grazing ones march (:func:`_relief_march`)."""
    y0, depth, slope, curvature = prims[row, Y0], prims[row, DEPTH], prims[row, SLOPE], prims[row, CURVATURE]
    first, count, newton = int(prims[row, FIRST]), int(prims[row, COUNT]), int(prims[row, NEWTON])
    third = prims[row, THIRD]
    _brackets(us[:m], v, rect, oy, y0, depth, slope, curvature, ds[0, :m], ds[1, :m], ds[2, :m], spare[0, :m],
              spare[1, :m], spare[2, :m], hits[0, :m])
    if models:
        _model_roots(third, ox, oz, ds[0, :m], ds[1, :m], ds[2, :m], spare[0, :m], spare[1, :m],
                     model[_MX], model[_MZ], model[_MGX], model[_MGZ], model[_MXX], model[_MXZ], model[_MZZ],
                     model[_MN], spare[3, :m], spare[4, :m], spare[5, :m])
    live = 0
    for j in range(m):
        search = hits[0, j]
        hits[0, j], hits[1, j], hits[2, j], hits[3, j] = math.inf, 0.0, 0.0, 0.0
        if search == _NEWTON and models and not math.isnan(spare[4, j]):
            _finish(prims, row, hits, j, ox, oz, ds[0, j], ds[2, j], spare[3, j], spare[4, j], spare[5, j], True,
                    model[_MXX, j], model[_MXZ, j], model[_MZZ, j])
            continue
        if search == _NEWTON:  # monotonic residual: safeguarded Newton
            lo, hi, guess = spare[0, j], spare[1, j], spare[3, j] if models else guesses[j]
            state[_A, live], state[_B, live] = lo, hi
            state[_T, live] = guess if (guess > lo and guess < hi) else 0.5 * (lo + hi)
            state[_DX, live], state[_DY, live], state[_DZ, live] = ds[0, j], ds[1, j], ds[2, j]
            state[_SHORT, live] = spare[2, j]
            state[_RAY, live] = j
            sums[_H, live] = sums[_GX, live] = sums[_GZ, live] = 0.0
            live += 1
        elif search == _MARCH:
            dx, dy, dz = ds[0, j], ds[1, j], ds[2, j]
            t = _relief_march(waves, lanes, first, count, depth, y0, ox, oy, oz, dx, dy, dz, spare[0, j], spare[1, j],
                              int(prims[row, STEPS]), int(prims[row, BISECTIONS]))
            _finish(prims, row, hits, j, ox, oz, dx, dz, t, 0.0, 0.0, False, 0.0, 0.0, 0.0)
    for _ in range(newton):
        if live == 0:
            break
        _evaluate(waves, first, count, ox, oz, state, sums, spare, live)
        _newton_steps(oy, y0, depth, state[_A, :live], state[_B, :live], state[_T, :live], state[_DX, :live],
                      state[_DY, :live], state[_DZ, :live], state[_SHORT, :live], sums[_H, :live], sums[_GX, :live],
                      sums[_GZ, :live], spare[0, :live], spare[1, :live])
        kept = 0
        for i in range(live):
            t, side = spare[0, i], spare[1, i]
            if side == _DONE:
                _finish(prims, row, hits, int(state[_RAY, i]), ox, oz, state[_DX, i], state[_DZ, i], t,
                        depth * sums[_GX, i], depth * sums[_GZ, i], True, depth * sums[_HXX, i],
                        depth * sums[_HXZ, i], depth * sums[_HZZ, i])
                continue
            before = state[_T, i]
            for r in range(STATE_ROWS):
                state[r, kept] = state[r, i]
            for r in range(3):
                sums[r, kept] = sums[r, i]
            state[_A if side == _ABOVE else _B, kept] = before
            state[_T, kept] = t
            kept += 1
        live = kept
    for i in range(live):  # out of iterations: the last step's root, without its gradient
        _finish(prims, row, hits, int(state[_RAY, i]), ox, oz, state[_DX, i], state[_DZ, i], state[_T, i],
                depth * sums[_GX, i], depth * sums[_GZ, i], False, 0.0, 0.0, 0.0)


@njit(cache=True, error_model="numpy")
def _relief_march(waves, lanes, first, count, depth, y0, ox, oy, oz, dx, dy, dz, lo, hi, steps, bisections):
    """The first root of a grazing ray's residual in ``[lo, hi]`` (which may not be monotonic there): march
    ``steps`` samples to the first sign change, then bisect ``bisections`` times; ``inf`` if there is none."""
    t_prev = lo
    found = oy + lo * dy - (y0 - relief_at(waves, lanes, first, count, depth, ox + lo * dx, oz + lo * dz)[0]) >= 0
    a = b = lo
    if not found:
        for s in range(1, steps + 1):
            t = lo + (hi - lo) * (s / steps)
            if oy + t * dy - (y0 - relief_at(waves, lanes, first, count, depth, ox + t * dx, oz + t * dz)[0]) >= 0:
                a, b, found = t_prev, t, True
                break
            t_prev = t
    if not found:
        return math.inf
    for _ in range(bisections):
        m = 0.5 * (a + b)
        if oy + m * dy - (y0 - relief_at(waves, lanes, first, count, depth, ox + m * dx, oz + m * dz)[0]) >= 0:
            b = m
        else:
            a = m
    return 0.5 * (a + b)
