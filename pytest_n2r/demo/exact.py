"""An exact scene: ray casting against analytic surfaces, with Lambertian shading under a fixed light.

Convention
----------
- Poses and cameras follow :mod:`pytest_n2r.geometry` (camera-to-world, OpenCV axes, pixel centres at
  integer coordinates); the demo world is z-up, in scene units.
- ``rgb`` is the mean of ``supersample × supersample`` rays spread evenly over each pixel (antialiased);
  shading is ``albedo * (ambient + (1 - ambient) * max(0, n·l))`` with a fixed light direction ``l``, so
  a surface point has one colour from every viewpoint (a field can learn it view-independently).
- ``depth`` is the exact z-depth of the surface under the pixel **centre**; where that ray hits nothing,
  depth is the scene's ``far`` distance.
- ``opacity`` is the fraction of the pixel's supersampling rays that hit a surface (1 inside a surface,
  between 0 and 1 on silhouettes, 0 for open water or sky).

- Where two surfaces coincide (the object scene's wheel caps lie in the van's sides), which one a ray sees
  depends on rounding.

Two implementations of these definitions: the compiled kernel of :mod:`.raycast` renders (``render``,
``cast``); the vectorized numpy code of :mod:`.primitives`, :mod:`.materials` and :mod:`.textures`
(``render_reference``, ``cast_reference``) is the readable definition it is tested against. They agree to
one grey level, bit for bit in almost every pixel, except where surfaces coincide
(``tests/demo/test_raycast.py``, ``benchmarks/demo_render_speed.py``).
"""

from __future__ import annotations

import hashlib
import math
from collections.abc import Sequence
from typing import TYPE_CHECKING

import numpy as np

from .._validation import as_unit_rgb, check_array, check_int, check_positive, check_range
from ..errors import InvalidArgument
from ..geometry import Camera, camera_rays, pixel_grid
from ..scene.base import Scene, SceneView, hash_views
from .portable_math import norm3
from .primitives import T_MIN, Group, Primitive, primitive_bounds, slab_hits

if TYPE_CHECKING:  # the ray caster (numba and its kernels) is imported by the first render, not with the scene: a
    # run that takes every render from the cache compiles and loads none of it
    from .raycast import CompiledScene

__all__ = ["GroundTruthScene"]

#: Bump when the scene's definition changes what it renders (part of the content hash, so it also makes the
#: fitted twins stale). Kept at "1" by both compiled kernels: their images are those of the numpy definition,
#: to one grey level.
RENDERER_VERSION = "1"
#: The most rays per pixel along each axis (256 a pixel; the built-in scenes cast 2): more is a slip, not a setting.
MAX_SUPERSAMPLE = 16


def _check_group_box(scene: str, item: int, group: Group) -> None:
    """Raise unless ``group``'s box holds every child: then the box only spares the rays that miss all of them and
    changes no pixel, which the content hash relies on (it covers the children, not the box)."""
    lo, hi = np.asarray(group.lo, np.float64), np.asarray(group.hi, np.float64)
    for k, child in enumerate(group.children):
        bounds = np.asarray(primitive_bounds(child), np.float64).reshape(2, 3)
        if np.any(bounds[0] < lo) or np.any(bounds[1] > hi):
            raise InvalidArgument(
                f"GroundTruthScene {scene!r}: primitives[{item}] is a Group whose box lo={tuple(group.lo)}, "
                f"hi={tuple(group.hi)} does not hold its child {k} ({type(child).__name__}, from "
                f"{tuple(bounds[0].tolist())} to {tuple(bounds[1].tolist())}); expected a box around all its "
                "children (a box that clipped them would change pixels the content hash does not cover)")


class GroundTruthScene(Scene):
    """An exact procedural scene (see the module *Convention*).

    Parameters
    ----------
    name:
        Short name (``"wall"``, ``"object"``).
    primitives:
        The analytic surfaces; a :class:`~pytest_n2r.demo.primitives.Group` is tested only by the rays
        that enter its bounding box (``self.primitives`` lists every surface, groups flattened).
    views:
        The capture trajectory (every 8th view held out).
    light:
        Direction towards the light, world frame: a finite, non-zero 3-vector (normalized here).
    ambient:
        Fraction of the albedo seen in shadow-facing regions, in ``[0, 1]``.
    background:
        RGB in ``[0, 1]`` of rays that hit nothing (open water, sky).
    far:
        z-depth reported where nothing is hit (scene units, > 0).
    supersample:
        Rays per pixel along each axis for ``rgb`` and ``opacity``: an int in ``[1, MAX_SUPERSAMPLE]``.
    reference_length:
        The median z-depth of the surface seen from the training views (scene units), the unit of the
        pose transforms' translations; ``None`` measures it by casting rays 64 pixels wide (the kernel's first
        use in a process compiles it: seconds). The built-in scenes give the measured value (a test checks
        it), so that a process that only reads renders from a cache casts no ray.
    """

    is_exact = True
    #: Keys the render cache (see :attr:`Scene.renderer_version`): "2" predicts relief roots from neighbouring
    #: rays, which moves a few pixels by one grey level and depths by about 1e-7 relative; "3" takes the relief's
    #: and the masks' sines from :mod:`.trig` (a pixel in a million by one grey level, depths by 2e-7 relative);
    #: "4" predicts relief roots from the rows of rays above in bands of rows (:mod:`.relief_kernel`: a few
    #: pixels in 100 000 by one grey level, depths by 1e-7 relative); "5" takes a sub-pixel ray's relief hit from
    #: the relief's second-order expansion at its pixel centre's hit (:mod:`.relief_rows`: 0.03 % of the wall's
    #: pixels by one grey level, depths by 2.3e-7 relative, opacity unchanged, ``demo_compare.py --poses 24``).
    renderer_version = "5"

    def __init__(
        self, name: str, primitives: Sequence[Primitive | Group], views: Sequence[SceneView], *,
        light: Sequence[float], ambient: float, background: Sequence[float], far: float,
        supersample: int = 2, metres_per_unit: float | None = 1.0, reference_length: float | None = None,
    ) -> None:
        self.name = name
        self._items = tuple(primitives)
        flat: list[Primitive] = []
        #: ``(box lo, box hi, members)`` of each group; a lone primitive's box is ``(None, None)``
        self._groups: list[tuple[np.ndarray | None, np.ndarray | None, list[int]]] = []
        for index, item in enumerate(primitives):
            if isinstance(item, Group):
                _check_group_box(name, index, item)
                start = len(flat)
                flat.extend(item.children)
                self._groups.append((np.asarray(item.lo, float), np.asarray(item.hi, float),
                                     list(range(start, len(flat)))))
            else:
                self._groups.append((None, None, [len(flat)]))
                flat.append(item)
        self.primitives = tuple(flat)
        self.views = tuple(views)
        direction = check_array("light", light, "3", dtype=np.float64)
        length = math.hypot(*direction)
        if not 1e-150 < length < 1e150:  # bounds within which norm3's sum of squares neither underflows nor overflows
            raise InvalidArgument(f"light={tuple(direction.tolist())} has length {length:g}; expected a non-zero "
                                  "3-vector towards the light (world frame), of length between 1e-150 and 1e150")
        self.light = direction / norm3(direction.tolist())  # the same bits on every machine: the content hash has them
        self.ambient = check_range("ambient", ambient, 0.0, 1.0)
        rgb = as_unit_rgb(background)
        if rgb is None:
            raise InvalidArgument(f"background={background!r}; expected an RGB triple of three values in [0, 1]")
        self.background = np.asarray(rgb, dtype=np.float32)
        self.far = check_positive("far", far)
        self.supersample = check_int("supersample", supersample, 1, MAX_SUPERSAMPLE)
        self.metres_per_unit = None if metres_per_unit is None else check_positive("metres_per_unit", metres_per_unit)
        self._hash: str | None = None
        self._compiled: CompiledScene | None = None
        self.reference_length = (self.median_train_depth() if reference_length is None
                                 else check_positive("reference_length", reference_length))

    # -- Scene interface -------------------------------------------------------------------------------
    @property
    def content_hash(self) -> str:
        if self._hash is None:
            h = hashlib.sha256(f"GroundTruthScene/{RENDERER_VERSION}/{self.name}".encode())
            for prim in self.primitives:
                h.update(prim.describe().encode())
            # grouping changes no pixel (each group's box holds its children: _check_group_box), but say so
            for lo, _, members in self._groups:
                h.update(f"{members}".encode() if lo is not None else b"")
            h.update(np.asarray([*self.light, self.ambient, *self.background, self.far, self.supersample]).tobytes())
            hash_views(h, self.views)
            self._hash = h.hexdigest()
        return self._hash

    @property
    def compiled(self) -> CompiledScene:
        """The scene's tables for the compiled kernel (built on first use)."""
        if self._compiled is None:
            from .raycast import compile_scene

            self._compiled = compile_scene(list(self._items), self.light, self.ambient, self.background)
        return self._compiled

    def compile_apart(self) -> bool:
        """The ray caster's row cast (:func:`~.row_cast.cast_row_kernel`) and the scene's blend masks
        (:attr:`~.raycast.CompiledScene.masks`), which a first render compiles after the kernel (or loads, when
        this ran meanwhile in another process)."""
        from .row_cast import cast_row_kernel

        cast_row_kernel()
        return bool(self.compiled.masks)  # a cached property, compiled on first use; never empty

    def _render(self, c2w: np.ndarray, camera: Camera, outputs: tuple[str, ...]) -> dict[str, np.ndarray]:
        return self.compiled.render(c2w, camera.fx, camera.fy, camera.cx, camera.cy, camera.height, camera.width,
                                    self.supersample, self.far, outputs)

    def cast(self, o: np.ndarray, d: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """Nearest hit of rays ``o + t d`` (``(N, 3)`` each): ``t`` (``inf`` on a miss) and the primitive index."""
        return self.compiled.cast(o, d)

    # -- the vectorized reference ------------------------------------------------------------------------
    def render_reference(self, c2w: np.ndarray, camera: Camera,
                         outputs: tuple[str, ...] = ("rgb", "depth", "opacity")) -> dict[str, np.ndarray]:
        """``outputs`` by the vectorized numpy definition (slow: the reference the compiled kernel is tested
        against)."""
        out: dict[str, np.ndarray] = {}
        h, w = camera.height, camera.width
        if "rgb" in outputs or "opacity" in outputs:
            n = self.supersample
            offsets = (np.arange(n) + 0.5) / n - 0.5
            grid = pixel_grid(camera)
            uv = np.stack(
                [grid + np.array([du, dv]) for dv in offsets for du in offsets], axis=2
            )  # H W S 2
            o, d = camera_rays(camera, c2w, uv.reshape(-1, 2))
            t, which = self.cast_reference(o, d)
            hit = np.isfinite(t)
            if "rgb" in outputs:
                footprint = t / (0.5 * (camera.fx + camera.fy) * n)
                colour = self.shade(o, d, t, which, footprint)
                mean = colour.reshape(h, w, n * n, 3).mean(axis=2)
                out["rgb"] = np.clip(np.rint(mean * 255.0), 0, 255).astype(np.uint8)
            if "opacity" in outputs:
                out["opacity"] = hit.reshape(h, w, n * n).mean(axis=2).astype(np.float32)
        if "depth" in outputs:
            o, d = camera_rays(camera, c2w)
            t, _ = self.cast_reference(o.reshape(-1, 3), d.reshape(-1, 3))
            out["depth"] = np.where(np.isfinite(t), t, self.far).reshape(h, w).astype(np.float32)
        return out

    def cast_reference(self, o: np.ndarray, d: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """:meth:`cast` by the vectorized numpy definition."""
        ts = np.full((len(self.primitives), len(o)), np.inf)
        for lo, hi, members in self._groups:
            if lo is None or hi is None:  # a lone primitive: both None
                ts[members[0]] = self.primitives[members[0]].intersect(o, d)
                continue
            t_near, t_far = slab_hits(o, d, lo, hi)
            sel = np.nonzero((t_near <= t_far) & (t_far > T_MIN))[0]
            if sel.size:
                for k in members:
                    ts[k, sel] = self.primitives[k].intersect(o[sel], d[sel])
        which = np.argmin(ts, axis=0)
        return ts[which, np.arange(len(o))], which

    def shade(
        self, o: np.ndarray, d: np.ndarray, t: np.ndarray, which: np.ndarray, footprint: np.ndarray
    ) -> np.ndarray:
        """Linear RGB ``(N, 3)`` float32 in ``[0, 1]`` of the hits ``t`` (``inf``: background).

        ``footprint`` is the ray's sample spacing at the hit, in scene units, before foreshortening.
        """
        colour = np.broadcast_to(self.background, (len(o), 3)).copy()
        for k, prim in enumerate(self.primitives):
            idx = np.nonzero((which == k) & np.isfinite(t))[0]
            if not idx.size:
                continue
            p = o[idx] + t[idx, None] * d[idx]
            normals, a, b, groups = prim.surface(p)
            unit = d[idx] / np.linalg.norm(d[idx], axis=1, keepdims=True)
            cos = np.abs(np.einsum("ij,ij->i", normals, unit))
            fp = footprint[idx] / np.maximum(cos, 0.2)
            albedo = np.empty((idx.size, 3), dtype=np.float32)
            for sel, material in groups:
                if sel.size:
                    albedo[sel] = material.albedo(a[sel], b[sel], fp[sel])
            lambert = np.clip(normals @ self.light, 0.0, 1.0)
            light = (self.ambient + (1.0 - self.ambient) * lambert).astype(np.float32)
            colour[idx] = albedo * light[:, None]
        return colour

    def coincident_pixels(self, c2w: np.ndarray, camera: Camera) -> np.ndarray:
        """``H x W`` bool: pixels with a supersampling ray whose two nearest surfaces lie at the same distance
        (to 1e-9, relative), where which one is seen depends on rounding (the object scene's wheel caps lie in
        the van's sides): there the compiled and the reference renders may differ by more than a grey level."""
        n = self.supersample
        offsets = (np.arange(n) + 0.5) / n - 0.5
        grid = pixel_grid(camera)
        uv = np.stack([grid + np.array([du, dv]) for dv in offsets for du in offsets], axis=2)
        o, d = camera_rays(camera, c2w, uv.reshape(-1, 2))
        ts = np.sort(np.stack([p.intersect(o, d) for p in self.primitives]), axis=0)
        with np.errstate(invalid="ignore"):  # inf - inf where a ray misses both
            tie = np.isfinite(ts[0]) & (np.abs(ts[1] - ts[0]) <= 1e-9 * ts[0])
        return tie.reshape(camera.height, camera.width, n * n).any(axis=2)

    # -- helpers -----------------------------------------------------------------------------------------
    def median_train_depth(self, size: int = 64) -> float:
        """Median z-depth of the surface seen from the training views, rendered ``size`` pixels wide."""
        depths = []
        for v in self.views:
            if v.split != "train":
                continue
            cam = v.camera.fit_within(size)
            o, d = camera_rays(cam, v.c2w)
            t, _ = self.cast(o.reshape(-1, 3), d.reshape(-1, 3))
            depths.append(t[np.isfinite(t)])
        hits = np.concatenate(depths) if depths else np.empty(0)
        return float(np.median(hits)) if hits.size else 1.0
