"""Compiled ray casting of the exact demo scenes (numba): every pixel's rays, hits, shading and outputs in one
kernel that runs without the GIL.

The scene's primitives, materials and textures are flattened into arrays once (:func:`compile_scene`); the
kernel then follows the vectorized definitions of :mod:`.primitives`, :mod:`.materials` and
:mod:`.textures` operation for operation (the same float64 geometry, the same float32 colour arithmetic, the
bilinear lookup of OpenCV's ``remap`` with its 1/32-texel steps), so its images match theirs to within
rounding (tested against them, ``tests/demo/test_raycast.py``).

What makes it fast (measured in ``docs/performance-log.md``):

- Each row of rays (the pixel centres, then each sub-row of sub-pixel rays) is cast as a batch: first a
  relief's hits for all its rays at once, Newton's method in lockstep with the waves evaluated four rays to a
  vector (:mod:`.relief_kernel`), each centre's root searched from the roots of the rows above (extrapolated),
  each sub-ray's taken from the relief's second-order expansion at its pixel centre's hit where that is as
  accurate as a search (:mod:`.relief_rows`), then each ray's nearest hit over the primitives.
- Per-ray chains of divisions (the light and footprint of the shading inputs, a relief's brackets and Newton
  steps) run in loops compiled apart over a row's arrays, one array per row, which LLVM vectorizes.
- Each render projects the groups' and primitives' bounding boxes to pixel rectangles (:func:`screen_rects`):
  a ray tests only what may lie under its pixel.
- The hot helpers are inlined and receive views of the kernel's arrays without reference counts
  (:func:`pytest_n2r.render.borrow.borrowed`); scalar helpers are left to LLVM to inline (quicker to compile).
- No sine goes to the C library: a relief's waves and the blend masks (once per pixel row over all its
  sub-rays, :mod:`.mask_kernel`) take theirs from :mod:`.trig`'s inlined polynomials, in vectorized loops.

Threads take every n-th band of :data:`BAND` image rows, and each pixel depends only on its own band: results
do not depend on the thread count.

A fresh checkout compiles the ray caster in two halves that two processes can compile at once: the kernel (with
a row's albedo and shading) and a row's cast (:mod:`.row_cast`, a kernel piece under its own lock), which the
kernel calls through a function pointer. The kernel is compiled against a placeholder of the row cast's type, so
its compile needs nothing of the row cast's (``docs/performance-log.md``).

Convention
----------
- Rays, hits and surface coordinates as in :mod:`.primitives`; colours as in :mod:`.exact` (the mean of
  ``supersample²`` rays per pixel, rows of sub-pixel offsets outer, columns inner).
- A :class:`~.materials.Blend` mask is a function of scalars ``(a, b)`` written with numpy ufuncs, so the
  same function serves numpy arrays and the compiled kernel (which calls a compiled batch copy of it, see
  :mod:`.mask_kernel`).
"""

from __future__ import annotations

import functools
import math
import warnings
from dataclasses import dataclass
from typing import Any

import numba
import numpy as np
from numba import njit
from numba.core.errors import NumbaExperimentalFeatureWarning

from ..errors import InvalidArgument
from ..render.borrow import borrowed as _borrowed
from ..render.threads import render_pool
from .albedo_kernel import BLEND, F0, FLAT, META_COLUMNS, POSTER, RADIAL, TEXTURED, albedo_of, albedo_row
from .mask_kernel import compile_mask, no_mask
from .materials import Blend, Flat, Material, Poster, Radial, Textured
from .primitives import T_MIN, Box, Cylinder, Disc, Group, Primitive, ReliefWall, primitive_bounds
from .relief_kernel import LANES, RELIEF_COLUMNS, STATE_ROWS, SUM_ROWS, relief_at
from .relief_rows import RELIEF_ROWS
from .row_cast import BOX, CYLINDER, DISC, RELIEF, cast_rays, cast_row_kernel, no_cast_row
from .textures import Texture

__all__ = ["CompiledScene", "compile_scene"]

@dataclass(frozen=True, eq=False)
class CompiledScene:
    """A scene's primitives, materials and textures as flat arrays for the kernels (see :func:`compile_scene`).

    ``groups`` rows: ``first, end`` primitive indices and ``has_box``; ``group_box`` rows ``lo, hi``.
    ``prims`` rows hold each primitive's parameters, ``prim_mat`` its material node per face slot.
    ``cull_boxes`` rows ``lo, hi``: each group's box (NaN without one), then each primitive's bounds; a render
    turns them into screen rectangles (:func:`screen_rects`) that rays outside skip.
    """

    groups: np.ndarray
    group_box: np.ndarray
    kinds: np.ndarray
    prims: np.ndarray
    waves: np.ndarray
    prim_mat: np.ndarray
    node_kind: np.ndarray
    node_par: np.ndarray
    node_child: np.ndarray
    rings: np.ndarray
    mask_functions: tuple
    tex_meta: np.ndarray
    texels: np.ndarray
    shading: np.ndarray
    background: np.ndarray
    cull_boxes: np.ndarray

    @functools.cached_property
    def masks(self) -> tuple:
        """The blend masks compiled for the render kernel (:func:`~.mask_kernel.compile_mask`), on the first
        render: casting rays needs none, and a process whose renders all come from a cache compiles none (a few
        seconds each, unless numba's cache has them)."""
        return tuple(compile_mask(fn) for fn in self.mask_functions) or (no_mask,)

    def cast(self, o: np.ndarray, d: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """Nearest hit of rays ``o + t d`` (``(N, 3)`` float64 each): ``t`` (``inf`` on a miss) and the index
        of the primitive hit (0 on a miss)."""
        o = np.ascontiguousarray(o, dtype=np.float64)
        d = np.ascontiguousarray(d, dtype=np.float64)
        t = np.empty(len(o))
        which = np.empty(len(o), dtype=np.int64)
        everywhere = np.tile(np.array([-math.inf, math.inf, -math.inf, math.inf]), (len(self.cull_boxes), 1))
        cast_rays(o, d, self.groups, self.group_box, self.kinds, self.prims, self.waves, np.empty(LANES), everywhere,
                   t, which)
        return t, which

    def render(self, c2w: np.ndarray, fx: float, fy: float, cx: float, cy: float, height: int, width: int,
               supersample: int, far: float, outputs: tuple[str, ...]) -> dict[str, np.ndarray]:
        """The ``outputs`` (``rgb``, ``depth``, ``opacity``) of the pinhole view at pose ``c2w`` (see
        :mod:`.exact` for their definitions).

        The first render compiles (or loads) the kernel before the blend masks and the row cast, on an empty
        image with placeholders of the same types: a process compiling the kernel leaves those pieces to another
        process meanwhile (:mod:`pytest_n2r.plugin.precompile`, through numba's cache), and then loads them or
        waits for them (:func:`~pytest_n2r.scene.first_render.claim_piece`)."""
        view = (c2w, fx, fy, cx, cy)
        if "masks" not in self.__dict__:
            self._render_with(view, 0, 0, supersample, far, outputs, (no_mask,) * max(len(self.mask_functions), 1),
                              no_cast_row())
        return self._render_with(view, height, width, supersample, far, outputs, self.masks, cast_row_kernel())

    def _render_with(self, view: tuple, height: int, width: int, supersample: int, far: float,
                     outputs: tuple[str, ...], masks: tuple, cast_row: Any) -> dict[str, np.ndarray]:
        """:meth:`render` with the compiled ``masks`` and row cast ``cast_row``; ``view`` is ``(c2w, fx, fy, cx,
        cy)``."""
        c2w, fx, fy, cx, cy = view
        want_rgb, want_depth, want_opacity = ("rgb" in outputs), ("depth" in outputs), ("opacity" in outputs)
        rgb = np.empty((height, width, 3) if want_rgb else (0, 0, 3), dtype=np.uint8)
        depth = np.empty((height, width) if want_depth else (0, 0), dtype=np.float32)
        opacity = np.empty((height, width) if want_opacity else (0, 0), dtype=np.float32)
        camera = np.array([fx, fy, cx, cy, far])
        c2w = np.ascontiguousarray(c2w, dtype=np.float64)
        rects = screen_rects(self.cull_boxes, c2w, fx, fy, cx, cy)
        args = (c2w, camera, int(supersample), rects, self.groups,
                self.group_box, self.kinds, self.prims, self.waves, self.prim_mat, self.node_kind, self.node_par,
                self.node_child, self.rings, masks, (cast_row,), self.tex_meta, self.texels, self.shading,
                self.background, rgb, depth, opacity)
        threads = max(1, min(numba.get_num_threads(), -(-height // BAND)))
        rays = (int(supersample) + 1, int(supersample) * width)  # one pixel row's rays (see _render_kernel)
        samples = int(supersample) ** 2 * width  # one pixel row's supersampling rays (see _shading_inputs)
        reliefs = max(1, int(np.sum(self.kinds == RELIEF)))
        scratch = [(np.empty((5, *rays)), np.empty((2, *rays), dtype=np.int64), np.empty((11, samples)),
                    np.empty((2, samples), dtype=np.int64), np.empty(LANES), np.empty((4, rays[1])),
                    np.empty((STATE_ROWS, rays[1])), np.empty((SUM_ROWS, rays[1])), np.empty((SUM_ROWS, rays[1])),
                    np.empty((reliefs, RELIEF_ROWS, rays[1])),
                    np.empty((4 * samples, 3), np.float32),
                    np.empty((5, 4 * samples), np.int64), np.empty((2, 4 * samples), np.float32),
                    np.empty((3, samples), np.float32), np.empty((4, 2 * samples)),
                    np.empty((2, 2 * samples), np.int64), np.empty((2, 2 * samples)), np.empty((4, 2 * samples)),
                    np.empty((2, self.tex_meta.shape[0] * self.tex_meta.shape[1] + 1), np.int64),
                    np.empty((3, self.tex_meta.shape[0] * 2 * samples)), np.empty(self.tex_meta.shape[0], np.int64))
                   for _ in range(threads)]
        with warnings.catch_warnings():  # masks are passed as first-class functions: numba calls it experimental
            warnings.simplefilter("ignore", NumbaExperimentalFeatureWarning)
            if threads <= 1:
                _render_kernel(0, 1, *scratch[0], *args)
            else:  # every thread-th band per thread: bands of sky and of wall interleave (the kernel drops the GIL)
                list(render_pool().map(lambda first: _render_kernel(first, threads, *scratch[first], *args),
                                       range(threads)))
        out: dict[str, np.ndarray] = {}
        if want_rgb:
            out["rgb"] = rgb
        if want_depth:
            out["depth"] = depth
        if want_opacity:
            out["opacity"] = opacity
        return out


# -- building the tables -------------------------------------------------------------------------------------


class _Builder:
    """Collects material nodes, rings, masks and texture mip levels while primitives are flattened."""

    def __init__(self) -> None:
        self.node_kind: list[int] = []
        self.node_par: list[list[float]] = []
        self.node_child: list[tuple[int, int]] = []
        self.rings: list[tuple[float, ...]] = []  # (radius, r, g, b)
        self.masks: list[Any] = []
        self.textures: dict[int, int] = {}
        self.texture_list: list[Texture] = []
        self.nodes: dict[int, int] = {}
        self.reliefs = 0

    def texture(self, tex: Texture) -> int:
        if id(tex) not in self.textures:
            self.textures[id(tex)] = len(self.texture_list)
            self.texture_list.append(tex)
        return self.textures[id(tex)]

    def mask(self, fn: Any) -> int:
        self.masks.append(fn)
        return len(self.masks) - 1

    def material(self, mat: Material, top: bool = True) -> int:
        key = id(mat)
        if key in self.nodes:
            return self.nodes[key]
        par: list[float] = [0.0] * 6
        child = (-1, -1)
        if isinstance(mat, Flat):
            kind = FLAT
            par[:3] = [float(np.float32(c)) for c in mat.colour]
        elif isinstance(mat, Textured):
            kind = TEXTURED
            par[:4] = [self.texture(mat.texture), mat.texels_per_unit, *mat.offset]
        elif isinstance(mat, Poster):
            kind = POSTER
            par[:5] = [self.texture(mat.picture), *mat.rect]
            child = (self.material(mat.base, top=False), -1)
        elif isinstance(mat, Blend):
            if not top:
                raise InvalidArgument("a Blend material must be a surface's own material, not inside another one "
                                      "(the compiled renderer blends once per hit)")
            kind = BLEND
            par[0] = self.mask(mat.mask)
            child = (self.material(mat.bottom, top=False), self.material(mat.top, top=False))
        elif isinstance(mat, Radial):
            kind = RADIAL
            rings = sorted(zip(mat.radii, mat.colours), reverse=True)  # as Radial.albedo: the last match wins
            par[:2] = [len(self.rings), len(rings)]
            self.rings.extend((r, *(float(np.float32(c)) for c in colour)) for r, colour in rings)
            child = (self.material(mat.outer, top=False), -1)
        else:
            raise InvalidArgument(f"material {type(mat).__name__} has no compiled form; expected one of Flat, "
                                  "Textured, Poster, Blend, Radial")
        self.node_kind.append(kind)
        self.node_par.append(par)
        self.node_child.append(child)
        self.nodes[key] = len(self.node_kind) - 1
        return self.nodes[key]

    def texture_tables(self) -> tuple[np.ndarray, np.ndarray]:
        """``tex_meta (T, L, META_COLUMNS)`` float64: per texture and mip level the columns named in
        :mod:`.albedo_kernel` (texel offset, size, scale, mirror periods and their inverses, wrap, level count),
        and all texels as one float32 array."""
        levels = max((len(t.levels) for t in self.texture_list), default=1)
        meta = np.zeros((max(len(self.texture_list), 1), levels, META_COLUMNS), dtype=np.float64)
        chunks, offset = [], 0
        for i, tex in enumerate(self.texture_list):
            for j, img in enumerate(tex.levels):
                h, w = img.shape[:2]
                meta[i, j] = (offset, h, w, 0.5 ** j, 2.0 * w, 2.0 * h, 1.0 / (2.0 * w), 1.0 / (2.0 * h),
                              0.0 if tex.wrap == "mirror" else 1.0, len(tex.levels))
                chunks.append(img.reshape(-1))
                offset += img.size
        texels = np.concatenate(chunks) if chunks else np.zeros(3, np.float32)
        return meta, np.ascontiguousarray(texels, dtype=np.float32)


def _curvature_bound(relief: ReliefWall) -> float:
    """A bound of the relief's Hessian norm, ``depth * sum |amp| (fx² + fz²)`` (1 / scene units): how fast its
    gradient can change along the surface."""
    w = relief._w
    return float(relief.depth * np.sum(np.abs(w[:, 0]) * (w[:, 1] ** 2 + w[:, 3] ** 2)))


def _third_bound(relief: ReliefWall) -> float:
    """A bound of the relief's third derivatives along any unit direction, ``depth * sum |amp| (fx² + fz²)^1.5``
    (1 / scene units²): the error of its second-order expansion (:func:`.relief_kernel.set_models`)."""
    w = relief._w
    return float(relief.depth * np.sum(np.abs(w[:, 0]) * (w[:, 1] ** 2 + w[:, 3] ** 2) ** 1.5))


#: Screen rectangles are widened by this many pixels (their corners' projections round, the rays' too).
_RECT_MARGIN = 1.0


def screen_rects(boxes: np.ndarray, c2w: np.ndarray, fx: float, fy: float, cx: float, cy: float) -> np.ndarray:
    """``(M, 4)`` pixel rectangles ``u_lo, u_hi, v_lo, v_hi`` that hold the projection of each box ``lo, hi``
    (rows of ``boxes (M, 6)``, world frame) seen from ``c2w``: a ray whose pixel coordinates lie outside a box's
    rectangle cannot hit anything inside the box. A row of NaN (no box) gets the whole plane; a box wholly at
    or behind the camera plane an empty rectangle.

    The rays that meet a box are the cone its corners span from the camera; their pixels, the cone's section by
    the plane ``z = 1`` (camera frame), are the convex hull of the projections of the corners in front of the
    camera plus the cone's directions along that plane, which combine a corner in front with one at or behind
    it (``z_i c_j - z_j c_i``): a side is unbounded where such a direction points out of it (a seabed that
    reaches behind the camera still ends at its far edge). The margin covers the rounding of both.

    >>> boxes = np.array([[-1.0, -1, 5, 1, 1, 6], [-10.0, 2, -10, 10, 2, 10], [-1.0, -1, -3, 1, 1, -2]])
    >>> screen_rects(boxes, np.eye(4), 100, 100, 0, 0).tolist()  # in front; a floor from behind; behind
    [[-21.0, 21.0, -21.0, 21.0], [-inf, inf, 19.0, inf], [inf, -inf, inf, -inf]]
    """
    rects = np.tile(np.array([-math.inf, math.inf, -math.inf, math.inf]), (len(boxes), 1))
    lo, hi = boxes[:, None, :3], boxes[:, None, 3:]
    pick = np.array([[i >> 2 & 1, i >> 1 & 1, i & 1] for i in range(8)], dtype=bool)  # 8 corners
    corners = np.where(pick[None], hi, lo)  # M 8 3
    cam = (corners - c2w[:3, 3]) @ c2w[:3, :3]  # world -> camera frame (R^T (p - o))
    z = cam[..., 2]
    boxed = np.all(np.isfinite(boxes), axis=1)
    front = z > 0.5 * T_MIN  # nearer the camera plane: at it (a direction along it); no ray hits so near
    some = boxed & front.any(axis=1)
    with np.errstate(divide="ignore", invalid="ignore", over="ignore"):
        u, v = fx * cam[..., 0] / z + cx, fy * cam[..., 1] / z + cy
    rects[some] = np.stack([np.where(front, u, math.inf).min(1) - _RECT_MARGIN,
                            np.where(front, u, -math.inf).max(1) + _RECT_MARGIN,
                            np.where(front, v, math.inf).min(1) - _RECT_MARGIN,
                            np.where(front, v, -math.inf).max(1) + _RECT_MARGIN], axis=1)[some]
    cross = some & ~front.all(axis=1)  # the directions along the plane z = 1 (a corner in front, one not) open sides
    if cross.any():
        c, f = cam[cross], front[cross]
        along = c[:, :, None, 2, None] * c[:, None, :, :2] - c[:, None, :, 2, None] * c[:, :, None, :2]  # i j 2
        pair = (f[:, :, None] & ~f[:, None, :])[..., None]
        slack = 1e-9 * np.abs(along).sum(axis=-1, keepdims=True)
        rects[np.flatnonzero(cross)[:, None], [0, 2]] = np.where(np.any(pair & (along < slack), axis=(1, 2)),
                                                                 -math.inf, rects[cross][:, [0, 2]])
        rects[np.flatnonzero(cross)[:, None], [1, 3]] = np.where(np.any(pair & (along > -slack), axis=(1, 2)),
                                                                 math.inf, rects[cross][:, [1, 3]])
    rects[boxed & ~front.any(axis=1)] = [math.inf, -math.inf, math.inf, -math.inf]
    return rects


def _primitive_row(prim: Primitive, b: _Builder, waves: list) -> tuple[int, list[float], list[int]]:
    """Kind, parameters and face materials of one primitive."""
    par = [0.0] * 16
    if isinstance(prim, Disc):
        par[:4] = [prim.height, prim.radius, *prim.centre]
        return DISC, par, [b.material(prim.material)] * 6
    if isinstance(prim, Box):
        par[:6] = [*prim.lo, *prim.hi]
        faces = [b.material(prim._material(name)) for name in ("-x", "-y", "-z", "+x", "+y", "+z")]
        return BOX, par, faces
    if isinstance(prim, Cylinder):
        par[:6] = [*prim.centre, "xyz".index(prim.axis), prim.radius, prim.half_length]
        return CYLINDER, par, [b.material(prim.side), b.material(prim.cap)] + [0] * 4
    if isinstance(prim, ReliefWall):
        par[:RELIEF_COLUMNS] = [prim.y0, *prim.extent, prim.depth, prim.slope_bound, len(waves), len(prim._w),
                                prim.newton, prim.steps, prim.bisections, _curvature_bound(prim), b.reliefs,
                                _third_bound(prim)]
        b.reliefs += 1
        waves.extend(prim._w.astype(np.float32).tolist())
        return RELIEF, par, [b.material(prim.material)] * 6
    raise InvalidArgument(f"primitive {type(prim).__name__} has no compiled form; expected one of Disc, Box, "
                          "Cylinder, ReliefWall")


def compile_scene(items: list[Primitive | Group], light: np.ndarray, ambient: float,
                  background: np.ndarray) -> CompiledScene:
    """Flatten a scene's primitives (groups keep their box), materials and textures into kernel tables."""
    b = _Builder()
    groups: list[tuple[int, int, int]] = []
    boxes: list[list[float]] = []
    kinds: list[int] = []
    prims: list[list[float]] = []
    prim_mat: list[list[int]] = []
    waves: list[list[float]] = []  # a relief's rows (amplitude, fx, px, fz, pz)
    bounds: list[list[float]] = []
    for item in items:
        children = item.children if isinstance(item, Group) else (item,)
        first = len(kinds)
        for prim in children:
            kind, par, faces = _primitive_row(prim, b, waves)
            kinds.append(kind)
            prims.append(par)
            prim_mat.append(faces)
        groups.append((first, len(kinds), int(isinstance(item, Group))))
        boxes.append([*item.lo, *item.hi] if isinstance(item, Group) else [0.0] * 6)
        bounds.extend(primitive_bounds(prim) for prim in children)
    tex_meta, texels = b.texture_tables()
    return CompiledScene(
        groups=np.asarray(groups, np.int64), group_box=np.asarray(boxes, np.float64),
        kinds=np.asarray(kinds, np.int64), prims=np.asarray(prims, np.float64),
        waves=np.asarray(waves or [[0.0] * 5], np.float32).reshape(-1, 5),
        prim_mat=np.asarray(prim_mat, np.int64), node_kind=np.asarray(b.node_kind or [0], np.int64),
        node_par=np.asarray(b.node_par or [[0.0] * 6], np.float64),
        node_child=np.asarray(b.node_child or [(-1, -1)], np.int64),
        rings=np.asarray(b.rings or [(0.0,) * 4], np.float64).reshape(-1, 4), mask_functions=tuple(b.masks),
        tex_meta=tex_meta, texels=texels,
        shading=np.array([*np.asarray(light, np.float64), float(ambient)]),
        background=np.asarray(background, np.float32),
        cull_boxes=np.asarray([box if boxed else [math.nan] * 6 for box, (_, _, boxed) in zip(boxes, groups)]
                              + bounds, np.float64).reshape(-1, 6),
    )


# -- surfaces ------------------------------------------------------------------------------------------------


@njit(cache=True, error_model="numpy")
def _cylinder_surface(prims, row, qx, qy, qz):
    """:func:`_surface` of a :class:`Cylinder` at ``q`` = the hit point less its centre (the axes by name, not by
    indexing a list: a list is a heap allocation per hit)."""
    k = int(prims[row, 3])  # (i, j, k) = the two cross axes and the axis
    qi, qj, qk = (qy, qz, qx) if k == 0 else ((qx, qz, qy) if k == 1 else (qx, qy, qz))
    radius, half = prims[row, 4], prims[row, 5]
    if abs(abs(qk) - half) < 1e-7 * max(1.0, half) and math.hypot(qi, qj) < radius * (1 - 1e-9):
        nk = 1.0 if qk > 0 else (-1.0 if qk < 0 else 0.0)
        return (nk if k == 0 else 0.0), (nk if k == 1 else 0.0), (nk if k == 2 else 0.0), qi, qj, 1
    ni, nj = qi / radius, qj / radius
    nx, ny, nz = (0.0, ni, nj) if k == 0 else ((ni, 0.0, nj) if k == 1 else (ni, nj, 0.0))
    return nx, ny, nz, math.atan2(qj, qi) * radius, qk, 0


@njit(cache=True, inline="always", error_model="numpy")
def _surface(kind, prims, row, waves, lanes, x, y, z, gx, gz, have):
    """Unit outward normal, surface coordinates ``(a, b)`` and face slot of a hit point (see
    :meth:`Primitive.surface`); a relief uses the gradient ``gx, gz`` its hit gave when it ``have`` one."""
    if kind == DISC:
        return 0.0, 0.0, 1.0, x, y, 0
    if kind == BOX:
        best, face = abs(x - prims[row, 0]), 0
        for f, dist in ((1, abs(y - prims[row, 1])), (2, abs(z - prims[row, 2])), (3, abs(x - prims[row, 3])),
                        (4, abs(y - prims[row, 4])), (5, abs(z - prims[row, 5]))):
            if dist < best:
                best, face = dist, f
        sign = 1.0 if face >= 3 else -1.0
        axis = face % 3
        if axis == 2:
            return 0.0, 0.0, sign, x, y, face
        if axis == 0:  # right = (-n_y, n_x, 0) seen from outside
            return sign, 0.0, 0.0, y * sign, -z, face
        return 0.0, sign, 0.0, -x * sign, -z, face
    if kind == CYLINDER:
        return _cylinder_surface(prims, row, x - prims[row, 0], y - prims[row, 1], z - prims[row, 2])
    if not have:
        _, gx, gz = relief_at(waves, lanes, int(prims[row, 7]), int(prims[row, 8]), prims[row, 5], x, z)
    norm = math.sqrt(gx * gx + 1.0 + gz * gz)
    return -gx / norm, -1.0 / norm, -gz / norm, x, -z, 0


# -- the image kernel ----------------------------------------------------------------------------------------


#: Image rows per band: a thread renders whole bands (every thread-th), and a relief's root search starts from
#: the roots of the rows of rays above it in the same band (so images do not depend on the thread count).
BAND = 16


@njit(cache=True, inline="always", error_model="numpy")
def _shading_inputs(v, n, width, ts, ks, gxs, gzs, haves, xcs, c2w, camera, shading, kinds, prims, waves, lanes,
                    prim_mat, node_kind, node_par, masks, shade, shade_int):
    """For each sub-ray ``i = row * n * width + j`` of pixel row ``v`` that hit: surface coordinates ``a, b``,
    footprint, light factor (:func:`_light_and_footprint`, per row of sub-rays) and material node (``shade[0:4,
    i]``, ``shade_int[0, i]``; node -1 on a miss), then every blend mask over all the sub-rays it covers in one
    call (``shade[4, i]``; a compiled mask is a vectorized loop over a batch, see :mod:`.mask_kernel`)."""
    fx, fy, cy = camera[0], camera[1], camera[3]
    ox, oy, oz = c2w[0, 3], c2w[1, 3], c2w[2, 3]
    lx, ly, lz, ambient = shading[0], shading[1], shading[2], shading[3]
    scale_fp = 0.5 * (fx + fy) * n
    sub = n * width
    sa, sb, sfp, slight, sm = shade[0], shade[1], shade[2], shade[3], shade[4]
    batch_a, batch_b, batch_m = shade[5], shade[6], shade[7]
    snx, sny, snz = shade[8], shade[9], shade[10]
    rotation = (c2w[0, 0], c2w[0, 1], c2w[0, 2], c2w[1, 0], c2w[1, 1], c2w[1, 2], c2w[2, 0], c2w[2, 1], c2w[2, 2])
    nodes, where = shade_int[0], shade_int[1]
    for sv in range(n):
        yc = (v + ((sv + 0.5) / n - 0.5) - cy) / fy
        for j in range(sub):
            i = sv * sub + j
            t, k = ts[sv, j], ks[sv, j]
            if not math.isfinite(t):
                nodes[i] = -1
                continue
            xc = xcs[0, j]
            dx = xc * c2w[0, 0] + yc * c2w[0, 1] + c2w[0, 2]
            dy = xc * c2w[1, 0] + yc * c2w[1, 1] + c2w[1, 2]
            dz = xc * c2w[2, 0] + yc * c2w[2, 1] + c2w[2, 2]
            x, y, z = ox + t * dx, oy + t * dy, oz + t * dz
            nx, ny, nz, a, b, face = _surface(kinds[k], prims, k, waves, lanes, x, y, z, gxs[sv, j], gzs[sv, j],
                                              haves[sv, j])
            sa[i], sb[i], snx[i], sny[i], snz[i] = a, b, nx, ny, nz
            nodes[i] = prim_mat[k, face]
        row = slice(sv * sub, sv * sub + sub)
        _light_and_footprint(rotation, yc, scale_fp, (lx, ly, lz, ambient), xcs[0], ts[sv], snx[row], sny[row],
                             snz[row], sfp[row], slight[row])
    for mask in range(len(masks)):
        count = 0
        for i in range(n * sub):
            node = nodes[i]
            if node >= 0 and node_kind[node] == BLEND and int(node_par[node, 0]) == mask:
                batch_a[count], batch_b[count], where[count] = sa[i], sb[i], i
                count += 1
        if count:
            masks[mask](batch_a, batch_b, batch_m, count)
            for c in range(count):
                sm[where[c]] = batch_m[c]


@njit(cache=True, nogil=True, error_model="numpy")
def _light_and_footprint(rotation, yc, scale, light, xcs, ts, nxs, nys, nzs, footprints, lights):
    """Footprint ``t / scale / max(|n . d / |d||, 0.2)`` (pixels) and light factor of the hits ``j`` of one row of
    sub-rays (``t = ts[j]``, ``inf`` on a miss: then anything) in camera-frame directions ``(xcs[j], yc, 1)``
    (``rotation``: camera to world, row-major) with unit normal ``nxs[j], nys[j], nzs[j]`` (``light``: direction
    and ambient), into ``footprints[j]``, ``lights[j]``. Compiled apart and called with each row as its own array,
    so that LLVM vectorizes the loop (its divisions and square root four rays to a vector; a ray's chain of them
    was latency-bound); where a normal lies along an axis, its zero terms add nothing to the dot product, bit for
    bit."""
    r00, r01, r02, r10, r11, r12, r20, r21, r22 = rotation
    lx, ly, lz, ambient = light
    for j in range(ts.shape[0]):
        xc, nx, ny, nz = xcs[j], nxs[j], nys[j], nzs[j]
        dx = xc * r00 + yc * r01 + r02
        dy = xc * r10 + yc * r11 + r12
        dz = xc * r20 + yc * r21 + r22
        norm = math.sqrt(dx * dx + dy * dy + dz * dz)
        cos = abs(nx * (dx / norm) + ny * (dy / norm) + nz * (dz / norm))
        footprints[j] = ts[j] / scale / max(cos, 0.2)
        lights[j] = ambient + (1.0 - ambient) * min(max(nx * lx + ny * ly + nz * lz, 0.0), 1.0)



@njit(cache=True, nogil=True, error_model="numpy")
def _render_kernel(first, step, scratch, scratch_int, shade, shade_int, lanes, rays, state, sums, spare, reliefs,
                   colours, taps, weights, mix, requests, request_slots, lods, queue, buckets, direct, sizes, c2w,
                   camera, n, rects, groups, group_box, kinds, prims, waves, prim_mat, node_kind, node_par, node_child,
                   rings, masks, cast_row, tex_meta, texels, shading, background, rgb, depth, opacity):
    """Bands ``first, first + step, ...`` of :data:`BAND` image rows. Per pixel row: the rays through the pixel
    centres are cast first (the depth rays), then the ``n`` sub-rows of supersampling rays, then each pixel is
    shaded. Each row of rays is cast as a batch: a relief's hits first, for all the row's rays at once (a
    centre's root searched from the roots of the rows above, a sub-ray's from its pixel centre's hit, see
    :mod:`.relief_rows`), then the nearest hit of each ray, by ``cast_row[0]``
    (:func:`.row_cast.cast_row_kernel`, or its placeholder while the kernel compiles)."""
    fx, cx, far = camera[0], camera[2], camera[4]
    rects, groups, group_box, kinds = _borrowed(rects), _borrowed(groups), _borrowed(group_box), _borrowed(kinds)
    prims, waves, prim_mat, node_kind = _borrowed(prims), _borrowed(waves), _borrowed(prim_mat), _borrowed(node_kind)
    node_par, node_child, rings = _borrowed(node_par), _borrowed(node_child), _borrowed(rings)
    tex_meta, texels, background = _borrowed(tex_meta), _borrowed(texels), _borrowed(background)
    height = max(rgb.shape[0], depth.shape[0], opacity.shape[0])
    width = max(rgb.shape[1], depth.shape[1], opacity.shape[1])
    want_colour = rgb.shape[0] > 0
    want_hits = want_colour or opacity.shape[0] > 0
    relief = False
    for k in range(kinds.shape[0]):
        relief = relief or kinds[k] == RELIEF
    inv_count = np.float32(n * n)
    sub = n * width
    # the rays of one pixel row, n rows of sub-pixel offsets then the pixel centres: t, dh/dx, dh/dz of a relief
    # and the primitive hit, whether the gradient is the hit's (in the caller's buffers: see _borrowed)
    ts, gxs, gzs = _borrowed(scratch[0]), _borrowed(scratch[1]), _borrowed(scratch[2])
    # each ray's pixel column and camera-frame x (row 0: the sub-rays, row n: the pixel centres), alike in every
    # pixel row: taken once, not per ray (a division and an integer division)
    uss, xcs = _borrowed(scratch[3]), _borrowed(scratch[4])
    for j in range(sub):
        u = j // n
        uss[0, j] = u + ((j - u * n + 0.5) / n - 0.5)
        xcs[0, j] = (uss[0, j] - cx) / fx
    for j in range(width):
        uss[n, j] = float(j)
        xcs[n, j] = (uss[n, j] - cx) / fx
    ks, haves = _borrowed(scratch_int[0]), _borrowed(scratch_int[1])
    # each sub-ray's surface coordinates, footprint, light, material and mask value (see _shading_inputs)
    shade, shade_int = _borrowed(shade), _borrowed(shade_int)
    slight, nodes = shade[3], shade_int[0]
    lanes = _borrowed(lanes)
    # one row of rays (see .row_cast): directions and the guesses of a relief's roots; a relief search's state;
    # per relief its hits, the roots of the rows above and the models at the centres' hits (see .relief_rows)
    rays, state, sums, spare, reliefs = (_borrowed(rays), _borrowed(state), _borrowed(sums), _borrowed(spare),
                                         _borrowed(reliefs))
    # each sub-ray's four colour slots and blend weights, the row's texture requests and lookups (see albedo_row)
    colours, taps, weights, mix = _borrowed(colours), _borrowed(taps), _borrowed(weights), _borrowed(mix)
    requests, request_slots, lods = _borrowed(requests), _borrowed(request_slots), _borrowed(lods)
    queue, buckets, direct, sizes = _borrowed(queue), _borrowed(buckets), _borrowed(direct), _borrowed(sizes)
    for band in range(first, (height + BAND - 1) // BAND, step):
        for v in range(band * BAND, min(height, band * BAND + BAND)):
            above = v - band * BAND  # pixel rows of this band above this one (their rays guess this row's roots)
            # the centres first (a relief's sub-ray hits come from them), where depth or a relief needs them
            for order in range(0 if depth.shape[0] > 0 or (want_hits and relief) else 1, n + 1 if want_hits else 1):
                row = n if order == 0 else order - 1
                centre = row == n
                cast_row[0](row, n, float(v) if centre else v + ((row + 0.5) / n - 0.5), above, c2w, camera, uss,
                            xcs, rects, groups, group_box, kinds, prims, waves, lanes, rays, state, sums, spare,
                            reliefs, ts, ks, gxs, gzs, haves)
            if depth.shape[0] > 0:
                for u in range(width):
                    depth[v, u] = np.float32(ts[n, u] if math.isfinite(ts[n, u]) else far)
            if not want_hits:
                continue
            if want_colour:
                _shading_inputs(v, n, width, ts, ks, gxs, gzs, haves, xcs, c2w, camera, shading, kinds, prims, waves,
                                lanes, prim_mat, node_kind, node_par, masks, shade, shade_int)
                albedo_row(n * sub, nodes, shade, node_kind, node_par, node_child, rings, tex_meta, texels, colours,
                           mix, requests, request_slots, lods, queue, buckets, direct, sizes, taps, weights)
            for u in range(width):
                hits = 0
                acc_r, acc_g, acc_b = F0, F0, F0
                for sv in range(n):
                    for su in range(n):
                        j = u * n + su
                        if not math.isfinite(ts[sv, j]):
                            cr, cg, cb = background[0], background[1], background[2]
                        else:
                            hits += 1
                            if not want_colour:
                                continue
                            i = sv * sub + j
                            cr, cg, cb = albedo_of(colours, mix, i)
                            light = np.float32(slight[i])
                            cr, cg, cb = cr * light, cg * light, cb * light
                        acc_r += cr
                        acc_g += cg
                        acc_b += cb
                if opacity.shape[0] > 0:
                    opacity[v, u] = np.float32(hits / (n * n))
                if want_colour:
                    for c, value in ((0, acc_r), (1, acc_g), (2, acc_b)):
                        level = np.rint(value / inv_count * np.float32(255.0))
                        rgb[v, u, c] = np.uint8(min(max(level, F0), np.float32(255.0)))
