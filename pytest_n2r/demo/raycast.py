"""Compiled ray casting of the exact demo scenes (numba): every pixel's rays, hits, shading and outputs in one
kernel that runs without the GIL.

The scene's primitives, materials and textures are flattened into arrays once (:func:`compile_scene`); the
kernel then follows the vectorized definitions of :mod:`.primitives`, :mod:`.materials` and
:mod:`.textures` operation for operation (the same float64 geometry, the same float32 colour arithmetic, the
bilinear lookup of OpenCV's ``remap`` with its 1/32-texel steps), so its images match theirs to within
rounding (tested against them, ``tests/demo/test_raycast.py``).

What makes it fast (measured in ``docs/performance.md``):

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
  (:func:`.borrow.borrowed`); scalar helpers are left to LLVM to inline (quicker to compile).
- No sine goes to the C library: a relief's waves and the blend masks (once per pixel row over all its
  sub-rays, :mod:`.mask_kernel`) take theirs from :mod:`.trig`'s inlined polynomials, in vectorized loops.

Threads take every n-th band of :data:`BAND` image rows, and each pixel depends only on its own band: results
do not depend on the thread count.

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
import platform
import warnings
from dataclasses import dataclass
from typing import Any

import numba
import numpy as np
from llvmlite import ir
from numba import njit, types
from numba.core.errors import NumbaExperimentalFeatureWarning
from numba.extending import intrinsic

from ..errors import InvalidArgument
from ..render.threads import render_pool
from .albedo_kernel import BLEND, F0, FLAT, META_COLUMNS, POSTER, RADIAL, TEXTURED, albedo_of, albedo_row
from .borrow import borrowed as _borrowed
from .mask_kernel import compile_mask, no_mask
from .materials import Blend, Flat, Material, Poster, Radial, Textured
from .primitives import T_MIN, Box, Cylinder, Disc, Group, Primitive, ReliefWall
from .relief_kernel import (
    HIT_ROWS,
    LANES,
    MODEL_ROWS,
    RELIEF_COLUMNS,
    SLOT,
    STATE_ROWS,
    SUM_ROWS,
    relief_at,
    relief_hits,
)
from .relief_rows import RELIEF_ROWS, relief_row
from .textures import Texture

__all__ = ["CompiledScene", "compile_scene"]

# primitive kinds
_DISC, _BOX, _CYLINDER, _RELIEF = 0, 1, 2, 3


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
        _cast_rays(o, d, self.groups, self.group_box, self.kinds, self.prims, self.waves, np.empty(LANES), everywhere,
                   t, which)
        return t, which

    def render(self, c2w: np.ndarray, fx: float, fy: float, cx: float, cy: float, height: int, width: int,
               supersample: int, far: float, outputs: tuple[str, ...]) -> dict[str, np.ndarray]:
        """The ``outputs`` (``rgb``, ``depth``, ``opacity``) of the pinhole view at pose ``c2w`` (see
        :mod:`.exact` for their definitions).

        The first render compiles (or loads) the kernel before the blend masks, on an empty image with
        placeholder masks of the same type: a process compiling the kernel leaves the masks to another process
        meanwhile (:mod:`pytest_n2r.plugin.precompile`, through numba's cache), and loads them afterwards."""
        view = (c2w, fx, fy, cx, cy)
        if "masks" not in self.__dict__:
            self._render_with(view, 0, 0, supersample, far, outputs, (no_mask,) * max(len(self.mask_functions), 1))
        return self._render_with(view, height, width, supersample, far, outputs, self.masks)

    def _render_with(self, view: tuple, height: int, width: int, supersample: int, far: float,
                     outputs: tuple[str, ...], masks: tuple) -> dict[str, np.ndarray]:
        """:meth:`render` with the compiled ``masks``; ``view`` is ``(c2w, fx, fy, cx, cy)``."""
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
                self.node_child, self.rings, masks, self.tex_meta, self.texels, self.shading,
                self.background, rgb, depth, opacity)
        threads = max(1, min(numba.get_num_threads(), -(-height // BAND)))
        rays = (int(supersample) + 1, int(supersample) * width)  # one pixel row's rays (see _render_kernel)
        samples = int(supersample) ** 2 * width  # one pixel row's supersampling rays (see _shading_inputs)
        reliefs = max(1, int(np.sum(self.kinds == _RELIEF)))
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
        out = {}
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
        self.rings: list[tuple[float, float, float, float]] = []
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


def _bounds(prim: Primitive) -> list[float]:
    """``lo, hi`` of an axis-aligned box that holds every hit of ``prim``."""
    if isinstance(prim, Disc):
        (x, y), r = prim.centre, prim.radius
        return [x - r, y - r, prim.height, x + r, y + r, prim.height]
    if isinstance(prim, Box):
        return [*prim.lo, *prim.hi]
    if isinstance(prim, Cylinder):
        half = [prim.radius] * 3
        half["xyz".index(prim.axis)] = prim.half_length
        return [c - h for c, h in zip(prim.centre, half)] + [c + h for c, h in zip(prim.centre, half)]
    x0, x1, z0, z1 = prim.extent  # ReliefWall
    return [x0, prim.y0 - prim.depth, z0, x1, prim.y0, z1]


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
        return _DISC, par, [b.material(prim.material)] * 6
    if isinstance(prim, Box):
        par[:6] = [*prim.lo, *prim.hi]
        faces = [b.material(prim._material(name)) for name in ("-x", "-y", "-z", "+x", "+y", "+z")]
        return _BOX, par, faces
    if isinstance(prim, Cylinder):
        par[:6] = [*prim.centre, "xyz".index(prim.axis), prim.radius, prim.half_length]
        return _CYLINDER, par, [b.material(prim.side), b.material(prim.cap)] + [0] * 4
    if isinstance(prim, ReliefWall):
        par[:RELIEF_COLUMNS] = [prim.y0, *prim.extent, prim.depth, prim.slope_bound, len(waves), len(prim._w),
                                prim.newton, prim.steps, prim.bisections, _curvature_bound(prim), b.reliefs,
                                _third_bound(prim)]
        b.reliefs += 1
        waves.extend(prim._w.astype(np.float32).tolist())
        return _RELIEF, par, [b.material(prim.material)] * 6
    raise InvalidArgument(f"primitive {type(prim).__name__} has no compiled form; expected one of Disc, Box, "
                          "Cylinder, ReliefWall")


def compile_scene(items: list[Primitive | Group], light: np.ndarray, ambient: float,
                  background: np.ndarray) -> CompiledScene:
    """Flatten a scene's primitives (groups keep their box), materials and textures into kernel tables."""
    b = _Builder()
    groups, boxes, kinds, prims, prim_mat, waves, bounds = [], [], [], [], [], [], []
    for item in items:
        children = item.children if isinstance(item, Group) else (item,)
        first = len(kinds)
        for prim in children:
            kind, par, faces = _primitive_row(prim, b, waves)
            kinds.append(kind)
            prims.append(par)
            prim_mat.append(faces)
        boxed = isinstance(item, Group)
        groups.append((first, len(kinds), int(boxed)))
        boxes.append([*item.lo, *item.hi] if boxed else [0.0] * 6)
        bounds.extend(_bounds(prim) for prim in children)
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


# -- geometry ------------------------------------------------------------------------------------------------


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
    """First hit of a capped :class:`Cylinder`, ``inf`` on a miss."""
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
    if kind == _RELIEF:
        slot = int(prims[row, SLOT])
        return reliefs[slot, 0, j], reliefs[slot, 1, j], reliefs[slot, 2, j], reliefs[slot, 3, j] != 0.0
    if kind == _DISC:
        t = _disc_hit(prims, row, ox, oy, oz, dx, dy, dz)
    elif kind == _BOX:
        t = _box_hit(prims, row, ox, oy, oz, ix, iy, iz)
    else:
        t = _cylinder_hit(prims, row, ox, oy, oz, dx, dy, dz)
    return t, 0.0, 0.0, False


@njit(cache=True, inline="always", error_model="numpy")
def _disc_hit(prims, row, ox, oy, oz, dx, dy, dz):
    """First hit of a :class:`Disc`, ``inf`` on a miss."""
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
    if kind == _DISC:
        for j in range(out.shape[0]):
            out[j] = _disc_hit(table, row, ox, oy, oz, dxs[j], dys[j], dzs[j])
    elif kind == _BOX:
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
        if groups[g, 2]:  # rays that miss the group's box skip its primitives (_BOX as a run-time value: numba
            # would compile _hits_along once more for a literal kind)
            _hits_along(groups[g, 2] * _BOX, group_box, g, ox, oy, oz, ds[0, g0:g1], ds[1, g0:g1], ds[2, g0:g1],
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
            relief = kinds[k] == _RELIEF
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
    pixel coordinates; groups and primitives whose screen rectangle (``rects``, :func:`screen_rects`) does not hold
    them are skipped."""
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
            if kinds[k] == _BOX and not inverse:
                ix, iy, iz, inverse = 1.0 / _opaque(dx), 1.0 / _opaque(dy), 1.0 / _opaque(dz), True
            t, gx, gz, have = _hit(kinds[k], prims, k, reliefs, j, ox, oy, oz, dx, dy, dz, ix, iy, iz)
            if t < best:
                best, which, best_gx, best_gz, best_have = t, k, gx, gz, have
    return best, which, best_gx, best_gz, best_have


@njit(cache=True, error_model="numpy")
def _cast_rays(o, d, groups, group_box, kinds, prims, waves, lanes, rects, t_out, which_out):
    """:meth:`CompiledScene.cast`: one ray at a time (each its own origin), serial (used for small batches)."""
    ds, no_guess, pixel = np.empty((3, 1)), np.full(1, math.nan), np.zeros(1)
    state, sums, spare = np.empty((STATE_ROWS, 1)), np.empty((SUM_ROWS, 1)), np.empty((SUM_ROWS, 1))
    reliefs, model = np.empty((_relief_count(kinds), HIT_ROWS, 1)), np.empty((MODEL_ROWS, 1))
    everywhere = rects[0]
    for r in range(o.shape[0]):
        ds[0, 0], ds[1, 0], ds[2, 0] = d[r, 0], d[r, 1], d[r, 2]
        for k in range(kinds.shape[0]):
            if kinds[k] == _RELIEF:
                relief_hits(prims, k, waves, lanes, o[r, 0], o[r, 1], o[r, 2], ds, no_guess, 1, pixel, 0.0,
                            everywhere, state, sums, spare, reliefs[int(prims[k, SLOT])], model, False)
        t_out[r], which_out[r], _, _, _ = _cast(groups, group_box, kinds, prims, reliefs, 0, rects, 0.0, 0.0,
                                                o[r, 0], o[r, 1], o[r, 2], d[r, 0], d[r, 1], d[r, 2])


@njit(cache=True, inline="always", error_model="numpy")
def _relief_count(kinds):
    """How many reliefs a scene has (at least 1: the size of the kernels' relief buffers)."""
    count = 0
    for k in range(kinds.shape[0]):
        count += kinds[k] == _RELIEF
    return max(count, 1)


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
    if kind == _DISC:
        return 0.0, 0.0, 1.0, x, y, 0
    if kind == _BOX:
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
    if kind == _CYLINDER:
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
def _cast_row(row, n, v, rows, c2w, camera, uss, xcs, rects, groups, group_box, kinds, prims, waves,
              lanes, rays, state, sums, spare, reliefs, ts, ks, gxs, gzs, haves):
    """Cast row ``row`` of a pixel row's rays (``row < n``: a sub-row of sub-pixel rays at image row ``v``;
    ``row == n``: the pixel centres) into ``ts, ks, gxs, gzs, haves[row]``: their directions, each relief's hits
    for all of them at once (:func:`.relief_rows.relief_row`: a centre's after the ``rows`` rows of centres above
    in this band, a sub-row's after its pixel row's centres), then each ray's nearest hit. Compiled apart from
    the kernel and called once per row of rays (the kernel's compile grows with each helper inlined into it); its
    helpers receive views of its arrays without reference counts, as the kernel's (:func:`_borrowed`)."""
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
        if kinds[k] == _RELIEF:
            relief_row(k, prims, waves, lanes, ox, oy, oz, ds, guesses, count, uss[table], v,
                       rects[groups.shape[0] + k], state, sums, spare, reliefs[int(prims[k, SLOT])], n, rows, centre)
    _nearest_hits(groups, group_box, kinds, prims, reliefs, rects, uss[table], v, ox, oy, oz, ds, count, row, ts, ks,
                  gxs, gzs, haves, spare)


@njit(cache=True, nogil=True, error_model="numpy")
def _render_kernel(first, step, scratch, scratch_int, shade, shade_int, lanes, rays, state, sums, spare, reliefs,
                   colours, taps, weights, mix, requests, request_slots, lods, queue, buckets, direct, sizes, c2w,
                   camera, n, rects, groups, group_box, kinds, prims, waves, prim_mat, node_kind, node_par, node_child,
                   rings, masks, tex_meta, texels, shading, background, rgb, depth, opacity):
    """Bands ``first, first + step, ...`` of :data:`BAND` image rows. Per pixel row: the rays through the pixel
    centres are cast first (the depth rays), then the ``n`` sub-rows of supersampling rays, then each pixel is
    shaded. Each row of rays is cast as a batch: a relief's hits first, for all the row's rays at once (a
    centre's root searched from the roots of the rows above, a sub-ray's from its pixel centre's hit, see
    :mod:`.relief_rows`), then the nearest hit of each ray."""
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
        relief = relief or kinds[k] == _RELIEF
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
    # one row of rays (see _cast_row): directions and the guesses of a relief's roots; a relief search's state;
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
                _cast_row(row, n, float(v) if centre else v + ((row + 0.5) / n - 0.5), above, c2w, camera, uss, xcs,
                          rects, groups, group_box, kinds, prims, waves, lanes, rays, state, sums, spare, reliefs, ts,
                          ks, gxs, gzs, haves)
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
