"""The compiled albedo of the demo materials (numba), for the ray caster's kernel (:mod:`.raycast`).

Materials are flattened into nodes by :class:`.raycast._Builder`: ``node_kind`` (the kinds below),
``node_par`` (a Flat's colour, a Textured's texture, texels per unit and offset, a Poster's picture and
rectangle, a Blend's mask, a Radial's rings), ``node_child`` (a Poster's or Radial's base material, a Blend's
bottom and top). The functions follow :mod:`.materials` and :meth:`.textures.Texture.sample` operation for
operation: the bilinear lookup of OpenCV's ``remap`` bit for bit (its float32 maps, 1/32-texel steps and fused
multiply-adds), the float32 colour arithmetic of the numpy definition.

Convention
----------
Surface coordinates ``(a, b)`` and footprints in scene units, as :mod:`.materials`; colours float32 RGB.
"""

from __future__ import annotations

import math

import numpy as np
from llvmlite import ir
from numba import njit, types
from numba.extending import intrinsic

from ..render.borrow import borrowed

__all__ = ["albedo_of", "albedo_row", "bilinear", "level_constants", "log2", "look_up", "taps_at", "FLAT", "TEXTURED",
           "POSTER", "BLEND", "RADIAL", "F0", "F1", "META_COLUMNS"]

# material kinds (node_kind)
FLAT, TEXTURED, POSTER, BLEND, RADIAL = 0, 1, 2, 3, 4
F0, F1 = np.float32(0.0), np.float32(1.0)


#: Columns of a texture level's row in ``tex_meta`` (see :meth:`.raycast._Builder.texture_tables`): texel offset,
#: height, width, ``2**-level``, the mirror periods ``2 w``, ``2 h`` and their inverses, the wrap (0 mirror,
#: 1 clamp) and the texture's level count (the last two alike in every level's row).
OFFSET, HEIGHT, WIDTH, SCALE, PERIOD_S, PERIOD_T, INV_PERIOD_S, INV_PERIOD_T, CLAMP, LEVELS = range(10)
META_COLUMNS = 10


@njit(cache=True, inline="always", error_model="numpy")
def _mirror_period(x, period, inverse):
    """``x mod period`` in ``[0, period]``, the value ``np.mod`` gives (or ``period`` for its 0, which the mirror
    maps to the same texels). ``floor(x * inverse)`` may be one off ``floor(x / period)`` (a division is slow):
    ``x - period * n`` is exact for either (``period * n`` is an integer and ``|x| < 2**52``) and the correction
    brings it into range exactly."""
    r = x - period * np.floor(x * inverse)  # np.floor: a float, no round trip through an integer
    return r + period if r < 0 else (r - period if r > period else r)


@njit(cache=True, inline="always", error_model="numpy")
def _reflect(p, n):
    """OpenCV's ``borderInterpolate`` for ``BORDER_REFLECT`` (``fedcba|abcdefgh|hgfedcb``) of a texel index in
    ``[-1, 2 n + 1]`` (all a lookup after :func:`_mirror_period` asks), branch-free."""
    p = p if p < n else 2 * n - 1 - p
    p = p if p >= 0 else -p - 1
    return p if n > 1 else 0


@intrinsic
def _fma32(typingctx, a, b, c):
    """``a * b + c`` of float32s rounded once to float32 (LLVM's ``fma``: one instruction), as the fused
    multiply-add of OpenCV's vector code."""
    def codegen(context, builder, signature, args):
        single = ir.FloatType()
        fma = builder.module.declare_intrinsic("llvm.fma", [single], ir.FunctionType(single, [single] * 3))
        return builder.call(fma, args)

    return types.float32(types.float32, types.float32, types.float32), codegen


@intrinsic
def _bits(typingctx, x):
    """The bits of a float64 as an int64."""
    def codegen(context, builder, signature, args):
        return builder.bitcast(args[0], ir.IntType(64))

    return types.int64(types.float64), codegen


@intrinsic
def _float_of_bits(typingctx, bits):
    """The float64 whose bits are ``bits`` (an int64)."""
    def codegen(context, builder, signature, args):
        return builder.bitcast(args[0], ir.DoubleType())

    return types.float64(types.int64), codegen


# fdlibm's __ieee754_log: Reme's polynomial for log(1 + f) on [sqrt(2)/2 - 1, sqrt(2) - 1] (|error| < 2**-58.45)
_LG1, _LG2, _LG3, _LG4 = 6.666666666666735130e-01, 3.999999999940941908e-01, 2.857142874366239149e-01, \
    2.222219843214978396e-01
_LG5, _LG6, _LG7 = 1.818357216161805012e-01, 1.531383769920937332e-01, 1.479819860511658591e-01
_MANTISSA, _EXPONENT_ONE, _SQRT2_BITS = (1 << 52) - 1, 1023 << 52, 0x3FF6A09E667F3BCD
_INV_LN2 = 1.4426950408889634


@njit(cache=True, inline="always", error_model="numpy")
def log2(x):
    """``log2 x`` of a normal positive float64 (a mip level), inlined instead of the C library's call:
    ``x = 2**k m`` with ``m`` in ``[sqrt(2)/2, sqrt(2))`` from its bits, fdlibm's ``log(m)`` polynomial, times
    ``1 / ln 2``. Within 2 units in the last place of ``math.log2`` (tested).

    >>> log2(8.0), round(log2(3.0), 12)
    (3.0, 1.584962500721)
    """
    bits = _bits(x)
    k = (bits >> 52) - 1023
    m_bits = (bits & _MANTISSA) | _EXPONENT_ONE
    if m_bits > _SQRT2_BITS:  # m / 2 in [sqrt(2)/2, 1): one more in the exponent
        m_bits -= 1 << 52
        k += 1
    f = _float_of_bits(m_bits) - 1.0
    s = f / (2.0 + f)
    z = s * s
    w = z * z
    r = z * (_LG1 + w * (_LG3 + w * (_LG5 + w * _LG7))) + w * (_LG2 + w * (_LG4 + w * _LG6))
    half_f2 = 0.5 * f * f
    return k + (f - (half_f2 - s * (half_f2 + r))) * _INV_LN2


@njit(cache=True, inline="always", error_model="numpy")
def level_constants(tex_meta, tex, level):
    """What :func:`taps_at` needs of a texture's mip level, from its row of ``tex_meta``: height, width, scale from
    level 0, clamp (else mirror), the mirror periods and their inverses, the texel offset."""
    return (int(tex_meta[tex, level, HEIGHT]), int(tex_meta[tex, level, WIDTH]), tex_meta[tex, level, SCALE],
            tex_meta[tex, level, CLAMP] == 1.0, tex_meta[tex, level, PERIOD_S], tex_meta[tex, level, PERIOD_T],
            tex_meta[tex, level, INV_PERIOD_S], tex_meta[tex, level, INV_PERIOD_T], int(tex_meta[tex, level, OFFSET]))


@njit(cache=True, inline="always", error_model="numpy")
def taps_at(level, s, t):
    """Where a bilinear lookup like ``cv2.remap`` at level-0 texel coordinates ``(s, t)`` in a mip level (its
    :func:`level_constants`) reads: the offsets of its four texels ``p00, p01, p10, p11`` in the texel array and
    its float32 weights ``alpha, beta`` (no division, no branch but on the level's wrap)."""
    h, w, scale, clamp, period_s, period_t, inverse_s, inverse_t, offset = level
    s = (s + 0.5) * scale - 0.5
    t = (t + 0.5) * scale - 0.5
    if clamp:
        s, t = min(max(s, -1.0), float(w)), min(max(t, -1.0), float(h))
    else:
        s, t = _mirror_period(s, period_s, inverse_s), _mirror_period(t, period_t, inverse_t)
    s32, t32 = np.float32(s), np.float32(t)
    xf, yf = np.floor(np.float64(s32)), np.floor(np.float64(t32))  # integers in [-1, 2 w], exact in float32
    alpha, beta = s32 - np.float32(xf), t32 - np.float32(yf)
    x0, y0 = int(xf), int(yf)
    x1, y1 = x0 + 1, y0 + 1
    if clamp:
        x0, x1 = min(max(x0, 0), w - 1), min(max(x1, 0), w - 1)
        y0, y1 = min(max(y0, 0), h - 1), min(max(y1, 0), h - 1)
    else:
        x0, x1, y0, y1 = _reflect(x0, w), _reflect(x1, w), _reflect(y0, h), _reflect(y1, h)
    return (offset + (y0 * w + x0) * 3, offset + (y0 * w + x1) * 3, offset + (y1 * w + x0) * 3,
            offset + (y1 * w + x1) * 3, alpha, beta)


@njit(cache=True, inline="always", error_model="numpy")
def blend_taps(texels, r00, r01, r10, r11, alpha, beta):
    """The RGB of a bilinear lookup from its taps (:func:`taps_at`): ``p00 + a (p01 - p00)`` by fused
    multiply-adds, as OpenCV's vector code."""
    return (_lerp2(texels[r00], texels[r01], texels[r10], texels[r11], alpha, beta),
            _lerp2(texels[r00 + 1], texels[r01 + 1], texels[r10 + 1], texels[r11 + 1], alpha, beta),
            _lerp2(texels[r00 + 2], texels[r01 + 2], texels[r10 + 2], texels[r11 + 2], alpha, beta))


@njit(cache=True, error_model="numpy")
def bilinear(tex_meta, texels, tex, level, s, t):
    """Bilinear lookup like ``cv2.remap`` (float32 maps, fused multiply-adds) at level-0 texel coordinates."""
    r00, r01, r10, r11, alpha, beta = taps_at(level_constants(tex_meta, tex, level), s, t)
    return blend_taps(texels, r00, r01, r10, r11, alpha, beta)


@njit(cache=True, error_model="numpy")
def _lerp2(p00, p01, p10, p11, alpha, beta):
    """One channel of the bilinear blend of four texels."""
    v0 = _fma32(alpha, p01 - p00, p00)
    v1 = _fma32(alpha, p11 - p10, p10)
    return _fma32(beta, v1 - v0, v0)


#: Rows of a pixel row's texture requests (``requests[:, r]``, see :func:`albedo_row`): level-0 texel coordinates
#: ``s, t``, the footprint in texels and the texture's level count; ``request_slots[:, r]``: texture, colour slot;
#: ``lods[:, r]``: the mip level's floor and the float32 weight of the level above.
_S, _T, _FOOTPRINT, _LEVELS = range(4)


@njit(cache=True, inline="always", error_model="numpy")
def _request_leaf(node, node_kind, node_par, node_child, rings, tex_meta, a, b, fp, slot, colours, requests,
                  request_slots, count, direct, sizes):
    """Resolve a material without a blend (Flat, Textured, Poster, Radial) at ``(a, b)``: a constant colour goes to
    ``colours[slot]``; a texture's trilinear mip-mapped sample (see :meth:`Texture.sample`) is appended to the
    row's requests at ``count`` (its colour to ``slot`` and, from the level above, ``slot + 1``), or where its
    footprint is at most one texel (level 0 alone) to its texture's list of level-0 lookups (``direct[:, tex *
    capacity + sizes[tex]]``: ``s, t`` and the slot; ``capacity = direct.shape[1] // sizes.shape[0]``), which
    need no mip level and no sort. Returns the new request count."""
    tex = -1
    s = t = k = 0.0
    while tex < 0:
        kind = node_kind[node]
        if kind == FLAT:
            colours[slot, 0], colours[slot, 1], colours[slot, 2] = (
                np.float32(node_par[node, 0]), np.float32(node_par[node, 1]), np.float32(node_par[node, 2]))
            return count
        if kind == TEXTURED:
            k = node_par[node, 1]
            tex, s, t = int(node_par[node, 0]), (a - node_par[node, 2]) * k, (b - node_par[node, 3]) * k
        elif kind == POSTER:
            a0, b0, a1, b1 = node_par[node, 1], node_par[node, 2], node_par[node, 3], node_par[node, 4]
            if a >= a0 and a <= a1 and b >= b0 and b <= b1:
                tex = int(node_par[node, 0])
                k = tex_meta[tex, 0, WIDTH] / (a1 - a0)
                s, t = (a - a0) * k - 0.5, (b - b0) * (tex_meta[tex, 0, HEIGHT] / (b1 - b0)) - 0.5
            else:
                node = node_child[node, 0]
        else:  # radial: the smallest ring that holds the point, else the outer material
            r = math.hypot(a, b)
            ring = -1
            for i in range(int(node_par[node, 0]), int(node_par[node, 0]) + int(node_par[node, 1])):
                if r <= rings[i, 0]:
                    ring = i
            if ring >= 0:
                colours[slot, 0], colours[slot, 1], colours[slot, 2] = (
                    np.float32(rings[ring, 1]), np.float32(rings[ring, 2]), np.float32(rings[ring, 3]))
                return count
            node = node_child[node, 0]
    footprint = fp * k
    if footprint <= 1.0:  # log2(max(footprint, 1)) = 0: level 0, and no weight on the level above
        p = sizes[tex]
        sizes[tex] = p + 1
        p += tex * (direct.shape[1] // sizes.shape[0])
        direct[0, p], direct[1, p], direct[2, p] = s, t, slot
        return count
    requests[_S, count], requests[_T, count], requests[_FOOTPRINT, count] = s, t, footprint
    requests[_LEVELS, count] = tex_meta[tex, 0, LEVELS]
    request_slots[0, count], request_slots[1, count] = tex, slot
    return count + 1


@njit(cache=True, inline="always", error_model="numpy")
def _request_albedo(node, node_kind, node_par, node_child, rings, tex_meta, a, b, fp, mask, slot, colours, mix,
                    requests, request_slots, count, direct, sizes):
    """Resolve the material of a surface at ``(a, b)`` with footprint ``fp`` (scene units) into the four colour
    slots from ``slot`` (two per material, see :func:`_request_leaf`): a blend's two materials where its ``mask``
    value is strictly between 0 and 1 (only the one it shows where it is 0 or 1), else the material's own.
    ``mix[0, i]`` (``i = slot // 4``) gets the mask value (NaN: no second material), ``mix[1:3, i]`` the level
    weights (0 until :func:`albedo_row` sets a texture's); returns the new request count."""
    m = F0
    bottom, top = node, -1
    if node_kind[node] == BLEND:
        m = np.float32(min(max(mask, 0.0), 1.0))
        bottom, top = node_child[node, 0], node_child[node, 1]
        if m == F1:  # bottom * 0 + top * 1: exactly the top colour
            bottom, top, m = top, -1, F0
        elif m == F0:  # exactly the bottom colour
            top = -1
    i = slot // 4
    mix[0, i] = m if top >= 0 else np.float32(math.nan)
    for which in range(2):  # one call site: the leaf's code is inlined once (compile time)
        leaf = bottom if which == 0 else top
        if leaf < 0:
            break
        mix[1 + which, i] = F0
        count = _request_leaf(leaf, node_kind, node_par, node_child, rings, tex_meta, a, b, fp, slot + 2 * which,
                              colours, requests, request_slots, count, direct, sizes)
    return count


@njit(cache=True, inline="always", error_model="numpy")
def look_up(texels, taps, weights, count, colours):
    """Every planned bilinear lookup (rows of ``taps``: four texel offsets and the colour slot, -1: none; of
    ``weights``: alpha, beta), into its colour slot: one tight loop whose texel reads (cache misses on large
    textures) overlap."""
    for q in range(count):
        slot = taps[4, q]
        if slot >= 0:
            colours[slot, 0], colours[slot, 1], colours[slot, 2] = blend_taps(
                texels, taps[0, q], taps[1, q], taps[2, q], taps[3, q], weights[0, q], weights[1, q])


@njit(cache=True, nogil=True, error_model="numpy")
def _plan_bucket(level, s_row, t_row, f_row, slot_row, upper, p00, p01, p10, p11, slots, alphas, betas):
    """The lookups of queued requests (level-0 texel coordinates ``s_row, t_row``, all of one texture and mip level)
    in ``level`` (its :func:`level_constants`): texel offsets, colour slots and weights. ``upper``: the level above
    the requests' own, looked up only where its weight (``f_row``) is not 0 (slot -1 elsewhere). Compiled apart
    and called with each output row as its own array: LLVM vectorizes the loop (four lookups to a vector; rows of
    one array it cannot tell apart, numba passing no ``noalias``)."""
    for p in range(s_row.shape[0]):
        p00[p], p01[p], p10[p], p11[p], alphas[p], betas[p] = taps_at(level, s_row[p], t_row[p])
        slot = int(slot_row[p])
        slots[p] = (slot + 1 if f_row[p] != 0.0 else -1) if upper else slot


@njit(cache=True, nogil=True, error_model="numpy")
def albedo_row(samples, nodes, shade, node_kind, node_par, node_child, rings, tex_meta, texels, colours, mix,
               requests, request_slots, lods, queue, buckets, direct, sizes, taps, weights):
    """The albedo of a pixel row's ``samples`` sub-rays (sub-ray ``i`` hit material node ``nodes[i]``, -1: none;
    surface coordinates, footprint and mask value in ``shade[0, 1, 2, 4]``, see :mod:`.raycast`) into four colour
    slots each (``colours[4 i:4 i + 4]``) and ``mix[:, i]``, for :func:`albedo_of`.

    In passes over the row, each a short loop whose iterations overlap (one sub-ray's chain through its material,
    mip level and texel addresses was latency-bound): the materials resolved (constant colours written, texture
    samples requested; those of a footprint within one texel, level 0 alone, straight into their texture's list,
    ``direct``), then every other request's mip level, then those requests bucketed by texture and level (a
    counting sort into ``queue``), then each list's and bucket's bilinear lookups planned in one vectorized loop
    (texel offsets and weights, :func:`_plan_bucket`: level ``lo``, then ``lo + 1`` where it exists, into the next
    columns of ``taps``), then all lookups read in one loop whose texel reads (cache misses on large textures)
    overlap. Compiled apart from the render kernel (its compile time); its
    helpers receive views of its arrays without reference counts (:func:`pytest_n2r.render.borrow.borrowed`)."""
    nodes, shade, node_kind, node_par, node_child = (borrowed(nodes), borrowed(shade), borrowed(node_kind),
                                                     borrowed(node_par), borrowed(node_child))
    rings, tex_meta, texels, colours, mix = (borrowed(rings), borrowed(tex_meta), borrowed(texels), borrowed(colours),
                                             borrowed(mix))
    requests, request_slots, lods, queue = borrowed(requests), borrowed(request_slots), borrowed(lods), borrowed(queue)
    buckets, taps, weights = borrowed(buckets), borrowed(taps), borrowed(weights)
    direct, sizes = borrowed(direct), borrowed(sizes)
    sa, sb, sfp, sm = shade[0], shade[1], shade[2], shade[4]
    sizes[:] = 0
    count = 0
    for i in range(samples):
        if nodes[i] >= 0:
            count = _request_albedo(nodes[i], node_kind, node_par, node_child, rings, tex_meta, sa[i], sb[i],
                                    sfp[i], sm[i], 4 * i, colours, mix, requests, request_slots, count, direct, sizes)
    footprints, levels, lo_row, f_row = requests[_FOOTPRINT], requests[_LEVELS], lods[0], lods[1]
    for r in range(count):  # log2 of max(footprint, 1): level 0 alone at a footprint of at most one texel
        lod = min(log2(max(footprints[r], 1.0)), levels[r] - 1.0)
        lo_f = np.floor(lod)
        lo_row[r] = lo_f
        f_row[r] = np.float32(lod - lo_f)
    # the requests bucketed by texture and mip level (a counting sort), so that each bucket's lookups are planned
    # in one vectorized loop with its level's constants loop-invariant (:func:`_plan_bucket`)
    n_levels = tex_meta.shape[1]
    starts, cursor = buckets[0], buckets[1]
    starts[:] = 0
    for r in range(count):
        starts[request_slots[0, r] * n_levels + int(lo_row[r]) + 1] += 1
    for key in range(buckets.shape[1] - 1):
        starts[key + 1] += starts[key]
        cursor[key] = starts[key]
    for r in range(count):
        key = request_slots[0, r] * n_levels + int(lo_row[r])
        p = cursor[key]
        cursor[key] = p + 1
        slot, f = request_slots[1, r], np.float32(f_row[r])
        two = lo_row[r] + 1.0 < levels[r] and f != F0  # with f = 0 the blend is c * 1 + c2 * 0: c itself
        mix[1 + (slot >> 1 & 1), slot >> 2] = f if two else F0
        queue[0, p], queue[1, p], queue[2, p], queue[3, p] = requests[_S, r], requests[_T, r], f if two else F0, slot
    planned, textures = 0, sizes.shape[0]
    capacity = direct.shape[1] // textures
    for key in range(textures + buckets.shape[1] - 1):  # each texture's level-0 list, then each bucket
        listed = key < textures
        if listed:
            tex, lo, rows, start, end = key, 0, direct, key * capacity, key * capacity + sizes[key]
        else:
            tex, lo, rows = (key - textures) // n_levels, (key - textures) % n_levels, queue
            start, end = starts[key - textures], starts[key - textures + 1]
        for q in range(1 if listed else 2):  # level lo, then lo + 1 where it exists (slot -1 where unweighted)
            if end == start or (q == 1 and lo + 1 >= tex_meta[tex, 0, LEVELS]):
                break
            a, b = planned, planned + end - start
            _plan_bucket(level_constants(tex_meta, tex, lo + q), rows[0, start:end], rows[1, start:end],
                         rows[2, start:end], rows[-1, start:end], q == 1, taps[0, a:b], taps[1, a:b], taps[2, a:b],
                         taps[3, a:b], taps[4, a:b], weights[0, a:b], weights[1, a:b])
            planned = b
    look_up(texels, taps, weights, planned, colours)


@njit(cache=True, inline="always", error_model="numpy")
def _leaf_colour(colours, slot, f):
    """A material's colour from its slots: level ``lo``'s lookup, blended with level ``lo + 1``'s by ``f``."""
    r, g, b = colours[slot, 0], colours[slot, 1], colours[slot, 2]
    if f != F0:
        r2, g2, b2 = colours[slot + 1, 0], colours[slot + 1, 1], colours[slot + 1, 2]
        r, g, b = r * (F1 - f) + r2 * f, g * (F1 - f) + g2 * f, b * (F1 - f) + b2 * f
    return r, g, b


@njit(cache=True, inline="always", error_model="numpy")
def albedo_of(colours, mix, i):
    """Float32 RGB albedo of sub-ray ``i`` planned by :func:`albedo_row` once its lookups are done
    (:func:`look_up`): a blend's ``bottom * (1 - m) + top * m``, else the one material's colour."""
    r, g, b = _leaf_colour(colours, 4 * i, mix[1, i])
    m = mix[0, i]
    if not math.isnan(m):
        rt, gt, bt = _leaf_colour(colours, 4 * i + 2, mix[2, i])
        keep = F1 - m
        r, g, b = r * keep + rt * m, g * keep + gt * m, b * keep + bt * m
    return r, g, b
