"""Rendering a scene field at a camera and pose: RGB, z-depth and opacity, deterministic and memory-bounded.

Two backends render the same lattice (:mod:`pytest_n2r.field.lattice`):

- ``"compiled"`` (CPU): one fused numba kernel per ray batch, with empty-space skipping and early ray
  termination (a ray stops once its transmittance is below ``t_stop``);
- ``"torch"`` (any device, the reference and the CUDA path): marches every lattice sample and composites
  with :mod:`pytest_n2r.field.query`; it never terminates early.

``backend="auto"`` takes ``compiled`` for a field on the CPU and ``torch`` on CUDA.
"""

from __future__ import annotations

import itertools
import math
from dataclasses import asdict, dataclass, replace

import cv2
import numpy as np
import torch

from .._validation import as_unit_rgb, check_array
from ..errors import InvalidArgument
from ..field.config import check_setting_types
from ..field.grid import SceneField
from ..field.lattice import grid_coords
from ..field.march import MarchGrid, dense_rays, march_dense
from ..field.query import composite, interpolate, sh_basis, shade, trilinear
from ..geometry import Camera
from .adaptive import sample_adaptively
from .block_reach import block_reach
from .cell_bits import kept_cells
from .field_kernels import bake_logits, colour_columns, pixel_rays, render_pixels, vertex_positions
from .ray_order import tiled_pixels
from .threads import run_balanced, run_parts

__all__ = ["RenderSettings", "FieldRenderer", "BACKENDS", "DENSE_MARCH_BUDGET", "RENDER_VERSION"]

BACKENDS = ("auto", "compiled", "torch")
#: Where a sample's view-dependent colour takes its direction from (see ``RenderSettings.colour_direction``).
COLOUR_DIRECTIONS = ("vertex", "ray")
#: Part of every fitted scene's content hash: bump it whenever the output for the same field and settings
#: changes (a kernel or lattice change), so render caches built by an older pytest-n2r are not reused.
RENDER_VERSION = 7  # 4: colour logits baked per frame, min_weight; 5: coarser tail; 6: adaptive sampling interpolates
#  the last split's edge pixels between agreeing ends; 7: and its centres (docs/performance-log.md, "Rendering")
#: Bytes the torch backend's dense march of one chunk of rays may take (:func:`~pytest_n2r.field.march.dense_rays`):
#: it lists every lattice slot of every ray before it keeps the occupied ones, up to 662 slots a ray of 128 bytes at
#: 224³, so the default 65 536 rays took up to 5.2 GiB (3 GiB measured on rays across the cube). 512 MiB leaves a 4 GB
#: GPU, the smallest the CUDA path is meant for, room for its CUDA context (a few hundred MB), the field (its row map
#: alone 0.23 GB at 384³) and the shading of the samples kept, and is still millions of lattice slots a chunk (6 335
#: rays at 224³, 3 685 at 384³), work enough to keep a GPU busy.
DENSE_MARCH_BUDGET = 512 << 20


@dataclass(frozen=True)
class RenderSettings:
    """The render knobs (see docs/performance.md for what each costs and buys).

    - ``step_ratio``: sample spacing along a ray, in voxels of the field's grid (default: the training
      spacing; 1.0 measured on fox 1.4× faster for 0.28 dB less PSNR against the real photos, before adaptive
      sampling: docs/performance-log.md, "Run time against error");
    - ``shell_samples``: samples in the contracted outer shell (``None``: one per ``step_ratio`` voxels);
    - ``far``: how far beyond the unit cube rays go, in normalized units (the contracted shell reaches
      ``1 + shell·(1 - 1/(1+far))`` of the way to infinity);
    - ``t_stop``: early ray termination once transmittance is below this (compiled backend); the
      transmittance left shows the background, as at the far end (0.03 measured on fox 1.2× faster than
      1e-3 for 0.03 dB less PSNR against the real photos; 0.04 with ``min_weight=2e-2``, the defaults since 4
      December, took 1.086× less CPU than 0.03 with 1e-2 on the fox for 0.011 dB less against its held-out photos,
      1.04–1.19× on the demo twins for 0.009–0.028 dB against their exact scenes; keep it at or below ``adaptive``,
      or terminated rays' opacities split the sampler's cells: docs/performance-log.md, "Rendering");
    - ``tail``: transmittances (decreasing, in (0, 1)) below which a ray's samples get coarser: at each one
      crossed the ray takes every second lattice sample of the rest, each with the opacity of the length it
      stands for (compiled backend). A render moves by at most the transmittance at the first one crossed
      (what lies behind it adds at most that much); measured on the fox and the demo twins, far less
      (docs/performance-log.md, "Rendering"); ``()`` takes every lattice sample;
    - ``min_alpha``: cells whose densest corner gives less opacity per sample than this are skipped (1e-2
      was 1.1× faster on the fox for 0.001 dB, but it depends on the grid: a smooth field upsampled 16 → 31
      lost 18 dB to its thin cells, tests/field/test_grid.py, so the default stays 1e-4);
    - ``scale``: render at this fraction of the camera's width and height, then resize to the camera
      (bilinear; depth takes the nearest rendered pixel, so it never invents a depth between a surface and
      what is behind it). A fitted field has no more detail than its grid: on the fox, 0.5 rendered 4.0×
      faster for 0.26 dB less PSNR against the real photos, before adaptive sampling (docs/performance-log.md);
    - ``adaptive``: adaptive pixel sampling (:mod:`pytest_n2r.render.adaptive`): trace a coarse grid of
      pixels and interpolate each grid cell whose corners agree within this (colour and opacity in [0, 1];
      z-depth within ``adaptive_depth`` relatively), tracing the pixels of every other cell; 0 traces every
      pixel. The default 0.04 traced 45 % / 26 % / 13 % of the fox's pixels at 480×270 / 960×540 / 1080p
      and stayed within 0.08 dB of tracing every pixel against the photos and the demo twins' exact scenes
      (docs/performance-log.md);
    - ``adaptive_stride``: the spacing of the coarsest grid in pixels (a power of two), ``None``: by image
      size, the largest power of two not above ``min(width, height) / 135`` (2 at 480×270, 8 at 1920×1080);
    - ``colour_direction`` (compiled backend): ``"vertex"`` bakes every vertex's colour for the direction from
      the camera to it once a frame, so a sample interpolates 3 colour logits instead of 12 SH coefficients (27
      at degree 2); ``"ray"`` takes each sample's ray direction (exact, as the torch reference). The two differ
      by the angle a cell subtends from the camera: on the fox 65.8 dB apart, 0.000 dB against the photos;
    - ``min_weight`` (compiled backend): a sample is coloured only once its compositing weight, plus the weight
      carried from samples not coloured before it, reaches this; the carried weight takes the next colour, so
      each channel is off by at most the summed weight of the ray's samples lighter than this (0: colour every
      sample). 1e-2 skipped about half of the fox's samples' colours; 2e-2 (the default) was 1.02–1.10× faster
      again for 0.001–0.008 dB on the fox and the demo twins (docs/performance-log.md);
    - ``chunk_rays``: rays per batch (bounds memory at any image size); the torch backend takes fewer where its
      dense march of that many would take more than :data:`DENSE_MARCH_BUDGET` (the same picture, to float32
      rounding);
    - ``background``: RGB in [0, 1] shown by the transmittance a ray has left (``None``: the field's own,
      :attr:`~pytest_n2r.field.grid.SceneField.background`, the colour it was fitted over in expectation).
    """

    step_ratio: float = 0.5
    shell_samples: int | None = None
    far: float = 100.0
    t_stop: float = 4e-2
    tail: tuple[float, ...] = (0.3, 0.1)
    min_alpha: float = 1e-4
    scale: float = 1.0
    adaptive: float = 0.04
    adaptive_depth: float = 0.1
    adaptive_stride: int | None = None
    colour_direction: str = "vertex"
    min_weight: float = 2e-2
    chunk_rays: int = 1 << 16
    background: tuple[float, float, float] | None = None
    backend: str = "auto"

    def __post_init__(self) -> None:
        check_setting_types(self)  # a string, None or a bool where a number belongs is named, not a TypeError
        checks = {  # name: (accepted, what is expected)
            "step_ratio": (0.01 <= self.step_ratio <= 8.0, "a value in [0.01, 8]"),
            "far": (math.isfinite(self.far) and 0.0 < self.far <= 1e6, "a value in (0, 1e6]"),
            "t_stop": (0.0 <= self.t_stop < 1.0, "a value in [0, 1)"),
            "min_alpha": (0.0 <= self.min_alpha < 1.0, "a value in [0, 1)"),
            "scale": (0.1 <= self.scale <= 1.0, "a value in [0.1, 1]"),
            "adaptive": (0.0 <= self.adaptive <= 1.0, "a value in [0, 1] (0 traces every pixel)"),
            "adaptive_depth": (0.0 <= self.adaptive_depth <= 1.0, "a relative depth in [0, 1]"),
            "min_weight": (0.0 <= self.min_weight < 1.0, "a value in [0, 1) (0 colours every sample)"),
            "chunk_rays": (self.chunk_rays >= 1, "an int >= 1"),
        }
        for name, (ok, expected) in checks.items():
            if not ok:
                value = getattr(self, name)
                raise InvalidArgument(f"RenderSettings.{name}={value!r} is out of range; expected {expected}")
        if self.shell_samples is not None and not 1 <= self.shell_samples <= 4096:
            raise InvalidArgument(f"RenderSettings.shell_samples={self.shell_samples!r}: expected None or 1..4096")
        if self.adaptive_stride is not None and not (
                1 <= self.adaptive_stride <= 64 and self.adaptive_stride & (self.adaptive_stride - 1) == 0):
            raise InvalidArgument(f"RenderSettings.adaptive_stride={self.adaptive_stride!r}: expected None or a "
                                  "power of two in 1..64")
        tail = tuple(self.tail)
        if not all(0.0 < v < 1.0 for v in tail) or any(a <= b for a, b in itertools.pairwise(tail)):
            raise InvalidArgument(f"RenderSettings.tail={self.tail!r}: expected a decreasing tuple of transmittances "
                                  "in (0, 1), or () to take every lattice sample")
        object.__setattr__(self, "tail", tuple(float(v) for v in tail))
        if self.background is not None:
            bg = as_unit_rgb(self.background)
            if bg is None:
                raise InvalidArgument(f"RenderSettings.background={self.background!r}: expected None or three "
                                      "values in [0, 1]")
            object.__setattr__(self, "background", bg)
        if self.colour_direction not in COLOUR_DIRECTIONS:
            raise InvalidArgument(f"RenderSettings.colour_direction={self.colour_direction!r}: expected one of "
                                  f"{COLOUR_DIRECTIONS}")
        if self.backend not in BACKENDS:
            raise InvalidArgument(f"RenderSettings.backend={self.backend!r}: expected one of {BACKENDS}")

    def to_dict(self) -> dict:
        return asdict(self)

    def replace(self, **changes) -> RenderSettings:
        return replace(self, **changes)

    def backend_on(self, device: torch.device) -> str:
        """The backend these settings render with on ``device`` (``"auto"``: compiled on the CPU, torch
        elsewhere); :class:`InvalidArgument` for the compiled backend off the CPU."""
        backend = self.backend if self.backend != "auto" else ("compiled" if device.type == "cpu" else "torch")
        if backend == "compiled" and device.type != "cpu":
            raise InvalidArgument("backend='compiled' renders fields on the CPU only; use backend='torch' on CUDA")
        return backend

    def background_of(self, field: SceneField) -> tuple[float, float, float]:
        """The background a render of ``field`` is composited over: these settings', else the field's."""
        return self.background if self.background is not None else field.background


class FieldRenderer:
    """Renders one field with fixed settings (the marching grid is prepared once).

    ``last_traced`` is the number of pixels the last render traced (the others were interpolated).
    """

    def __init__(self, field: SceneField, settings: RenderSettings | None = None):
        self.field = field
        self.settings = settings or RenderSettings()
        s = self.settings
        self.backend = s.backend_on(field.device)
        # the cells sampled; both also check that the field stores every corner of its occupied cells (the
        # compiled kernel reads them without a check)
        if self.backend == "compiled":  # in one compiled pass, with their bits (the same cells: tested)
            cells, self._bits = kept_cells(field, s.step_ratio, s.min_alpha)
            occupancy = torch.from_numpy(cells.view(np.bool_))
        else:
            occupancy = field.occupancy
            with torch.no_grad():
                alpha = field.occupied_cell_alpha(s.step_ratio)
            if s.min_alpha > 0:
                occupancy = occupancy.clone()
                occupancy[field.occupancy] = alpha >= s.min_alpha  # a mask takes its cells in nonzero() order
        self.grid = MarchGrid(occupancy, field.space.shell, s.step_ratio, s.shell_samples, s.far)
        #: Rays traced at a time: ``chunk_rays``, fewer on the torch backend where its dense march would take more
        #: than :data:`DENSE_MARCH_BUDGET`.
        self.chunk_rays = s.chunk_rays if self.backend == "compiled" else min(
            s.chunk_rays, dense_rays(self.grid, DENSE_MARCH_BUDGET))
        #: The background actually rendered over (the settings', else the field's).
        self.background = s.background_of(field)
        self.last_traced = 0
        self._tail = np.asarray(s.tail, dtype=np.float64)
        if self.backend == "compiled":
            self._values = np.ascontiguousarray(field.values.detach().cpu().numpy())
            self._density = np.ascontiguousarray(self._values[:, 0])
            self._rows = field.kernel_rows()
            self._reach = block_reach((self._bits != 0).any(axis=-1).astype(np.uint8))  # blocks with a cell sampled
            self._fixed_logits: np.ndarray | None = None
            # where each vertex's colour direction is taken from when a frame bakes its logits: a degree-0 field's
            # colour takes none (its logits are baked once)
            n_rows = self._values.shape[0] if field.sh_degree > 0 and s.colour_direction == "vertex" else 0
            self._position = np.empty((3, n_rows), dtype=np.float64)
            self._outer = np.empty(n_rows, dtype=np.bool_)
            # the colour coefficients by column for a frame's bake (a degree-0 field's: made for its one bake)
            self._colour = self._colour_columns() if n_rows else None
            if n_rows:
                vertex = field.row_vertices().numpy()
                run_parts(vertex_positions, n_rows, vertex, self.grid.resolution, self.grid.shell, self._position,
                          self._outer)

    def render(self, c2w: np.ndarray, camera: Camera, outputs: tuple[str, ...]) -> dict[str, np.ndarray]:
        """``outputs`` (from ``rgb``, ``depth``, ``opacity``) of ``camera`` at ``c2w`` (OpenCV axes, scene units):
        ``rgb`` H×W×3 uint8, ``depth`` H×W float32 z-depth, ``opacity`` H×W float32 in [0, 1]."""
        c2w = check_array("c2w", c2w, "4 4", dtype=np.float64)  # NaN/Inf would crash the compiled kernel
        scale = self.settings.scale
        if scale == 1.0:
            return self._render(c2w, camera, outputs)
        small = camera.resized(max(1, round(camera.width * scale)), max(1, round(camera.height * scale)))
        size = (camera.width, camera.height)
        interpolation = {"rgb": cv2.INTER_LINEAR, "opacity": cv2.INTER_LINEAR, "depth": cv2.INTER_NEAREST}
        return {name: cv2.resize(image, size, interpolation=interpolation[name])
                for name, image in self._render(c2w, small, outputs).items()}

    def _render(self, c2w: np.ndarray, camera: Camera, outputs: tuple[str, ...]) -> dict[str, np.ndarray]:
        h, w = camera.height, camera.width
        adaptive = self.settings.adaptive > 0 and self.stride(camera) > 1
        want_depth = adaptive or "depth" in outputs  # the adaptive sampler compares depths
        logits = self._bake_logits(c2w)

        def trace(want: np.ndarray, rgb: np.ndarray, depth: np.ndarray, opacity: np.ndarray) -> None:
            index = tiled_pixels(want, w)  # traced tile by tile (render/ray_order.py)
            for start in range(0, index.size, self.chunk_rays):
                self._trace_pixels(index[start:start + self.chunk_rays], camera, c2w, logits, want_depth, rgb, depth,
                                   opacity)

        if adaptive:
            rgb, depth, opacity, self.last_traced = sample_adaptively(
                trace, h, w, self.stride(camera), self.settings.adaptive, self.settings.adaptive_depth)
        else:
            rgb, depth, opacity = (np.empty((h * w, 3), dtype=np.float32), np.empty(h * w, dtype=np.float32),
                                   np.empty(h * w, dtype=np.float32))
            trace(np.ones(h * w, dtype=np.bool_), rgb, depth, opacity)
            self.last_traced = h * w
        out: dict[str, np.ndarray] = {}
        if "rgb" in outputs:
            scaled = np.multiply(rgb, np.float32(255.0))  # rounded and clipped in place: one temporary, not three
            np.clip(np.rint(scaled, out=scaled), 0, 255, out=scaled)
            out["rgb"] = scaled.astype(np.uint8).reshape(h, w, 3)
        if "depth" in outputs:
            out["depth"] = depth.reshape(h, w)
        if "opacity" in outputs:
            out["opacity"] = np.clip(opacity, 0.0, 1.0).reshape(h, w)
        return out

    def stride(self, camera: Camera) -> int:
        """The coarsest grid spacing of adaptive sampling at ``camera``'s size (pixels; 1: every pixel)."""
        if self.settings.adaptive_stride is not None:
            return self.settings.adaptive_stride
        return 1 << max(0, int(math.floor(math.log2(max(1.0, min(camera.width, camera.height) / 135.0)))))

    def _pixel_rays(self, index: np.ndarray, camera: Camera, c2w: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """Normalized float32 rays ``(o, d)`` through the pixels with flat indices ``index`` (compiled; the
        same arithmetic as ``normalize_rays(*camera_rays(...))``, tests/render/test_settings.py)."""
        o = np.empty((index.size, 3), dtype=np.float32)
        d = np.empty((index.size, 3), dtype=np.float32)
        run_parts(pixel_rays, index.size, np.ascontiguousarray(index, dtype=np.int64), camera.width,
                  *self._pinhole_rays(camera, c2w), o, d)
        return o, d

    def _pinhole_rays(self, camera: Camera, c2w: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray, float]:
        """What the compiled kernels make a camera's rays from: ``(pinhole, c2w, center, radius)``, ``pinhole`` the
        intrinsics ``fx, fy, cx, cy`` (pixels), ``center`` and ``radius`` the field's normalization (scene units)."""
        space = self.field.space
        return (np.array([camera.fx, camera.fy, camera.cx, camera.cy], dtype=np.float64), c2w,
                np.asarray(space.center, dtype=np.float64), float(space.radius))

    def _bake_logits(self, c2w: np.ndarray) -> np.ndarray:
        """The compiled kernel's per-frame colour logits for a camera at ``c2w`` (``(n_rows, 3)`` float32), or an
        empty array: colour from each ray's direction. A field without view-dependent colour (SH degree 0) has
        the same logits from every camera: baked on the first frame, kept for the others."""
        if self.backend != "compiled" or self.settings.colour_direction != "vertex":
            return np.zeros((0, 3), dtype=np.float32)
        if self._fixed_logits is not None:  # set for a degree-0 field only, below
            return self._fixed_logits
        space = self.field.space
        origin = (c2w[:3, 3] - np.asarray(space.center)) / space.radius
        colour = self._colour if self._colour is not None else self._colour_columns()
        logits = np.empty((self._values.shape[0], 3), dtype=np.float32)
        run_parts(bake_logits, self._values.shape[0], colour, self._position, self._outer, origin,
                  self.field.sh_degree, logits)
        if self.field.sh_degree == 0:
            self._fixed_logits = logits  # the kernel only reads it (a read-only array would compile it anew)
        return logits

    def _colour_columns(self) -> np.ndarray:
        """The field's SH colour coefficients by column, ``(3·n_sh, n_rows)`` in the values' dtype, what a frame's
        bake reads (:func:`~.field_kernels.colour_columns`)."""
        colour = np.empty((self._values.shape[1] - 1, self._values.shape[0]), dtype=self._values.dtype)
        run_parts(colour_columns, self._values.shape[0], self._values, colour)
        return colour

    def _trace_pixels(self, index: np.ndarray, camera: Camera, c2w: np.ndarray, logits: np.ndarray, want_depth: bool,
                      rgb: np.ndarray, depth: np.ndarray, opacity: np.ndarray) -> None:
        """Render the rays through the pixels ``index`` (flat) of ``camera`` at ``c2w`` into those pixels of the flat
        images ``rgb``, ``depth`` and ``opacity``. The compiled kernel makes each pixel's ray itself, as
        :meth:`_pixel_rays` would (one pass over the rays, no ray arrays)."""
        s, g, f = self.settings, self.grid, self.field
        if self.backend == "compiled":
            run_balanced(render_pixels, index.size, index, camera.width, *self._pinhole_rays(camera, c2w),
                         self._density, self._values, logits, self._rows, self._bits, self._reach, g.resolution,
                         g.shell, g.step, g.shell_samples, g.far, f.density_shift, g.step_ratio, f.sh_degree,
                         s.t_stop, self._tail, s.min_weight, np.asarray(self.background), want_depth, rgb, depth,
                         opacity)
            return
        o, d = self._pixel_rays(index, camera, c2w)
        with torch.no_grad():
            ot = torch.from_numpy(o).to(f.device)
            dt = torch.from_numpy(d).to(f.device)
            out = render_rays_torch(f, g, ot, dt, torch.tensor(self.background, device=f.device), want_depth)
        rgb[index] = out["rgb"].cpu().numpy()
        opacity[index] = out["opacity"].cpu().numpy()
        if want_depth:
            depth[index] = out["depth"].cpu().numpy()


def render_rays_torch(field: SceneField, grid: MarchGrid, o: torch.Tensor, d: torch.Tensor,
                      background: torch.Tensor, want_depth: bool,
                      marched: tuple[torch.Tensor, torch.Tensor, torch.Tensor] | None = None
                      ) -> dict[str, torch.Tensor]:
    """Render normalized rays with torch (differentiable in ``field.values``); ``marched`` may pass samples
    already marched as ``(ray_idx, t, offsets)``."""
    ray_idx, t, offsets = march_dense(o, d, grid) if marched is None else marched
    p = o[ray_idx] + t[:, None] * d[ray_idx]
    corners, weights = trilinear(grid_coords(p, grid.shell, field.resolution), field.resolution)
    rows = field.vertex_rows(corners)
    unit = d / d.norm(dim=-1, keepdim=True)
    basis = sh_basis(unit[ray_idx], field.sh_degree)
    alpha, rgb = shade(interpolate(field.values, rows, weights), basis, field.density_shift, grid.step_ratio)
    return composite(alpha, rgb, t, ray_idx, offsets, o.shape[0], background,
                     grid.t_far(o, d) if want_depth else None)
