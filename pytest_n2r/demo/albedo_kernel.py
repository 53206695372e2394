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

__all__ = ["albedo_of", "bilinear", "look_up", "plan_albedo", "FLAT", "TEXTURED", "POSTER", "BLEND", "RADIAL", "F0",
           "F1", "META_COLUMNS"]

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
    r = x - period * math.floor(x * inverse)
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


@njit(cache=True, inline="always", error_model="numpy")
def bilinear_taps(tex_meta, tex, level, s, t):
    """Where a bilinear lookup like ``cv2.remap`` at level-0 texel coordinates ``(s, t)`` reads: the offsets
    of its four texels ``p00, p01, p10, p11`` in the texel array and its float32 weights ``alpha, beta``; the
    level's constants come from its row of ``tex_meta`` (no division)."""
    h, w = int(tex_meta[tex, level, HEIGHT]), int(tex_meta[tex, level, WIDTH])
    scale = tex_meta[tex, level, SCALE]
    s = (s + 0.5) * scale - 0.5
    t = (t + 0.5) * scale - 0.5
    clamp = tex_meta[tex, level, CLAMP] == 1.0
    if clamp:
        s, t = min(max(s, -1.0), tex_meta[tex, level, WIDTH]), min(max(t, -1.0), tex_meta[tex, level, HEIGHT])
    else:
        s = _mirror_period(s, tex_meta[tex, level, PERIOD_S], tex_meta[tex, level, INV_PERIOD_S])
        t = _mirror_period(t, tex_meta[tex, level, PERIOD_T], tex_meta[tex, level, INV_PERIOD_T])
    s32, t32 = np.float32(s), np.float32(t)
    x0 = int(np.float64(s32) + 1.0) - 1  # floor: both are >= -1 here, and +1 is exact in float64
    y0 = int(np.float64(t32) + 1.0) - 1
    alpha, beta = s32 - np.float32(x0), t32 - np.float32(y0)
    x1, y1 = x0 + 1, y0 + 1
    if clamp:
        x0, x1 = min(max(x0, 0), w - 1), min(max(x1, 0), w - 1)
        y0, y1 = min(max(y0, 0), h - 1), min(max(y1, 0), h - 1)
    else:
        x0, x1, y0, y1 = _reflect(x0, w), _reflect(x1, w), _reflect(y0, h), _reflect(y1, h)
    offset = int(tex_meta[tex, level, OFFSET])
    return (offset + (y0 * w + x0) * 3, offset + (y0 * w + x1) * 3, offset + (y1 * w + x0) * 3,
            offset + (y1 * w + x1) * 3, alpha, beta)


@njit(cache=True, inline="always", error_model="numpy")
def blend_taps(texels, r00, r01, r10, r11, alpha, beta):
    """The RGB of a bilinear lookup from its taps (:func:`bilinear_taps`): ``p00 + a (p01 - p00)`` by fused
    multiply-adds, as OpenCV's vector code."""
    return (_lerp2(texels[r00], texels[r01], texels[r10], texels[r11], alpha, beta),
            _lerp2(texels[r00 + 1], texels[r01 + 1], texels[r10 + 1], texels[r11 + 1], alpha, beta),
            _lerp2(texels[r00 + 2], texels[r01 + 2], texels[r10 + 2], texels[r11 + 2], alpha, beta))


@njit(cache=True, error_model="numpy")
def bilinear(tex_meta, texels, tex, level, s, t):
    """Bilinear lookup like ``cv2.remap`` (float32 maps, fused multiply-adds) at level-0 texel coordinates."""
    r00, r01, r10, r11, alpha, beta = bilinear_taps(tex_meta, tex, level, s, t)
    return blend_taps(texels, r00, r01, r10, r11, alpha, beta)


@njit(cache=True, error_model="numpy")
def _lerp2(p00, p01, p10, p11, alpha, beta):
    """One channel of the bilinear blend of four texels."""
    v0 = _fma32(alpha, p01 - p00, p00)
    v1 = _fma32(alpha, p11 - p10, p10)
    return _fma32(beta, v1 - v0, v0)


@njit(cache=True, inline="always", error_model="numpy")
def _tap(tex_meta, tex, level, s, t, slot, taps, weights, count):
    """Append the lookup of ``(s, t)`` in ``level`` to the batch (``taps`` rows: the four texel offsets and the
    result slot; ``weights``: alpha, beta) at ``count``; the new count."""
    taps[0, count], taps[1, count], taps[2, count], taps[3, count], weights[0, count], weights[1, count] = \
        bilinear_taps(tex_meta, tex, level, s, t)
    taps[4, count] = slot
    return count + 1


@njit(cache=True, inline="always", error_model="numpy")
def _plan_leaf(node, node_kind, node_par, node_child, rings, tex_meta, a, b, fp, slot, colours, taps, weights,
               count):
    """Plan the albedo of a material without a blend (Flat, Textured, Poster, Radial) at ``(a, b)``: a constant
    colour goes to ``colours[slot]``; a texture's trilinear mip-mapped sample (see :meth:`Texture.sample`)
    appends its one or two bilinear lookups (levels ``lo`` and ``lo + 1``, results to ``slot`` and
    ``slot + 1``). Returns the new lookup count and the weight of level ``lo + 1`` (0: one lookup)."""
    tex = -1
    s = t = k = 0.0
    while tex < 0:
        kind = node_kind[node]
        if kind == FLAT:
            colours[slot, 0], colours[slot, 1], colours[slot, 2] = (
                np.float32(node_par[node, 0]), np.float32(node_par[node, 1]), np.float32(node_par[node, 2]))
            return count, F0
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
                return count, F0
            node = node_child[node, 0]
    footprint = fp * k
    lo, f, levels = 0, F0, 1
    if footprint > 1.0:  # else level 0 alone (log2 of max(footprint, 1) is 0)
        n_levels = int(tex_meta[tex, 0, LEVELS])
        lod = min(math.log2(footprint), n_levels - 1)
        lo = int(math.floor(lod))
        f = np.float32(lod - lo)
        if lo + 1 < n_levels and f != F0:  # with f = 0 the blend is c * 1 + c2 * 0: c itself
            levels = 2
        else:
            f = F0
    for q in range(levels):  # one call site: the lookup's code is inlined once (compile time)
        count = _tap(tex_meta, tex, lo + q, s, t, slot + q, taps, weights, count)
    return count, f


@njit(cache=True, inline="always", error_model="numpy")
def plan_albedo(node, node_kind, node_par, node_child, rings, tex_meta, a, b, fp, mask, slot, colours, taps,
                weights, count, mix):
    """Plan the albedo of a surface's material at ``(a, b)`` with footprint ``fp`` (scene units) into the four
    colour slots from ``slot`` (two per material, see :func:`_plan_leaf`): a blend's two materials where its
    ``mask`` value is strictly between 0 and 1 (only the one it shows where it is 0 or 1), else the material's
    own. ``mix[0:3, i]`` (``i = slot // 4``) get the mask value (NaN: no second material) and each material's
    level weight; returns the new lookup count. :func:`albedo_of` turns the looked-up slots into the colour."""
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
        count, mix[1 + which, i] = _plan_leaf(leaf, node_kind, node_par, node_child, rings, tex_meta, a, b, fp,
                                              slot + 2 * which, colours, taps, weights, count)
    return count


@njit(cache=True, inline="always", error_model="numpy")
def look_up(texels, taps, weights, count, colours):
    """Every planned bilinear lookup, into its colour slot: one tight loop whose texel reads (cache misses
    on large textures) overlap."""
    for q in range(count):
        slot = taps[4, q]
        colours[slot, 0], colours[slot, 1], colours[slot, 2] = blend_taps(
            texels, taps[0, q], taps[1, q], taps[2, q], taps[3, q], weights[0, q], weights[1, q])


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
    """Float32 RGB albedo of sub-ray ``i`` planned by :func:`plan_albedo` once its lookups are done
    (:func:`look_up`): a blend's ``bottom * (1 - m) + top * m``, else the one material's colour."""
    r, g, b = _leaf_colour(colours, 4 * i, mix[1, i])
    m = mix[0, i]
    if not math.isnan(m):
        rt, gt, bt = _leaf_colour(colours, 4 * i + 2, mix[2, i])
        keep = F1 - m
        r, g, b = r * keep + rt * m, g * keep + gt * m, b * keep + bt * m
    return r, g, b
