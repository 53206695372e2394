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

__all__ = ["albedo", "bilinear", "FLAT", "TEXTURED", "POSTER", "BLEND", "RADIAL", "F0", "F1", "META_COLUMNS"]

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
def bilinear(tex_meta, texels, tex, level, s, t):
    """Bilinear lookup like ``cv2.remap`` (float32 maps, ``p00 + a (p01 - p00)`` by fused multiply-adds) at
    level-0 texel coordinates; the level's constants come from its row of ``tex_meta`` (no division)."""
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
    r00, r01 = offset + (y0 * w + x0) * 3, offset + (y0 * w + x1) * 3
    r10, r11 = offset + (y1 * w + x0) * 3, offset + (y1 * w + x1) * 3
    return (_lerp2(texels[r00], texels[r01], texels[r10], texels[r11], alpha, beta),
            _lerp2(texels[r00 + 1], texels[r01 + 1], texels[r10 + 1], texels[r11 + 1], alpha, beta),
            _lerp2(texels[r00 + 2], texels[r01 + 2], texels[r10 + 2], texels[r11 + 2], alpha, beta))


@njit(cache=True, error_model="numpy")
def _lerp2(p00, p01, p10, p11, alpha, beta):
    """One channel of the bilinear blend of four texels."""
    v0 = _fma32(alpha, p01 - p00, p00)
    v1 = _fma32(alpha, p11 - p10, p10)
    return _fma32(beta, v1 - v0, v0)


@njit(cache=True, error_model="numpy")
def _sample(tex_meta, texels, tex, s, t, footprint):
    """Trilinear mip-mapped colour at texel coordinates ``(s, t)`` (see :meth:`Texture.sample`)."""
    if not footprint > 1.0:  # level 0 alone (log2 of max(footprint, 1) is 0)
        return bilinear(tex_meta, texels, tex, 0, s, t)
    n_levels = int(tex_meta[tex, 0, LEVELS])
    lod = min(math.log2(footprint), n_levels - 1)
    lo = int(math.floor(lod))
    r, g, b = bilinear(tex_meta, texels, tex, lo, s, t)
    f = np.float32(lod - lo)
    if lo + 1 < n_levels and f != F0:  # with f = 0 the blend is c * 1 + c2 * 0: c itself
        r2, g2, b2 = bilinear(tex_meta, texels, tex, lo + 1, s, t)
        r, g, b = r * (F1 - f) + r2 * f, g * (F1 - f) + g2 * f, b * (F1 - f) + b2 * f
    return r, g, b


@njit(cache=True, inline="always", error_model="numpy")
def _leaf(node, node_kind, node_par, node_child, rings, tex_meta, texels, a, b, fp):
    """Albedo of a material without a blend (Flat, Textured, Poster, Radial), float32 RGB."""
    while True:
        kind = node_kind[node]
        if kind == FLAT:
            return np.float32(node_par[node, 0]), np.float32(node_par[node, 1]), np.float32(node_par[node, 2])
        if kind == TEXTURED:
            k = node_par[node, 1]
            return _sample(tex_meta, texels, int(node_par[node, 0]), (a - node_par[node, 2]) * k,
                           (b - node_par[node, 3]) * k, fp * k)
        if kind == POSTER:
            a0, b0, a1, b1 = node_par[node, 1], node_par[node, 2], node_par[node, 3], node_par[node, 4]
            if a >= a0 and a <= a1 and b >= b0 and b <= b1:
                tex = int(node_par[node, 0])
                h, w = tex_meta[tex, 0, HEIGHT], tex_meta[tex, 0, WIDTH]
                k = w / (a1 - a0)
                return _sample(tex_meta, texels, tex, (a - a0) * k - 0.5, (b - b0) * (h / (b1 - b0)) - 0.5, fp * k)
            node = node_child[node, 0]
            continue
        # radial: the smallest ring that holds the point, else the outer material
        r = math.hypot(a, b)
        ring = -1
        for i in range(int(node_par[node, 0]), int(node_par[node, 0]) + int(node_par[node, 1])):
            if r <= rings[i, 0]:
                ring = i
        if ring >= 0:
            return np.float32(rings[ring, 1]), np.float32(rings[ring, 2]), np.float32(rings[ring, 3])
        node = node_child[node, 0]


@njit(cache=True, inline="always", error_model="numpy")
def albedo(node, node_kind, node_par, node_child, rings, tex_meta, texels, a, b, fp, mask):
    """Albedo of a surface's material at ``(a, b)`` with footprint ``fp`` (scene units), float32 RGB: a blend's
    two materials mixed by its ``mask`` value there (only the one it shows where the mask is 0 or 1), else the
    material's own."""
    m = F0
    bottom, top = node, -1
    if node_kind[node] == BLEND:
        m = np.float32(min(max(mask, 0.0), 1.0))
        bottom, top = node_child[node, 0], node_child[node, 1]
        if m == F1:  # bottom * 0 + top * 1: exactly the top colour
            bottom, top, m = top, -1, F0
        elif m == F0:  # exactly the bottom colour
            top = -1
    r, g, b_ = F0, F0, F0
    for leaf in (bottom, top):  # one call site: the leaf's code is inlined once
        if leaf < 0:
            break
        lr, lg, lb = _leaf(leaf, node_kind, node_par, node_child, rings, tex_meta, texels, a, b, fp)
        if leaf == bottom:
            r, g, b_ = lr, lg, lb
        else:
            keep = F1 - m
            r, g, b_ = r * keep + lr * m, g * keep + lg * m, b_ * keep + lb * m
    return r, g, b_
