"""Surface materials of the demo scenes: the albedo at a point of a surface's 2-D parametrization.

Convention
----------
Every primitive gives each hit point surface coordinates ``(a, b)`` in **scene units** (``a`` to the right
and ``b`` downwards as seen from outside the surface, for vertical faces) and the pixel footprint there in
scene units; a material turns them into an ``(N, 3)`` float32 albedo in ``[0, 1]``.
"""

from __future__ import annotations

from abc import ABC, abstractmethod
from collections.abc import Callable
from dataclasses import dataclass

import numpy as np

from .textures import Texture

__all__ = ["Material", "Flat", "Textured", "Poster", "Blend", "Radial"]


class Material(ABC):
    """Albedo as a function of surface coordinates."""

    @abstractmethod
    def albedo(self, a: np.ndarray, b: np.ndarray, footprint: np.ndarray) -> np.ndarray:
        """``(N, 3)`` float32 albedo at surface coordinates ``a, b`` (scene units, each ``(N,)``)."""

    @abstractmethod
    def describe(self) -> str:
        """A stable text form of every parameter (part of the scene's content hash)."""


@dataclass(frozen=True, eq=False)
class Flat(Material):
    """One colour everywhere."""

    colour: tuple[float, float, float]

    def albedo(self, a: np.ndarray, b: np.ndarray, footprint: np.ndarray) -> np.ndarray:
        return np.broadcast_to(np.asarray(self.colour, np.float32), (np.size(a), 3)).copy()

    def describe(self) -> str:
        return f"Flat{tuple(round(c, 6) for c in self.colour)}"


@dataclass(frozen=True, eq=False)
class Textured(Material):
    """A tiled texture, ``texels_per_unit`` texels per scene unit, shifted by ``offset`` (scene units)."""

    texture: Texture
    texels_per_unit: float
    offset: tuple[float, float] = (0.0, 0.0)

    def albedo(self, a: np.ndarray, b: np.ndarray, footprint: np.ndarray) -> np.ndarray:
        k = self.texels_per_unit
        return self.texture.sample((a - self.offset[0]) * k, (b - self.offset[1]) * k, footprint * k)

    def describe(self) -> str:
        return f"Textured({self.texture.digest()[:16]}, {self.texels_per_unit:.6g}, {self.offset})"


@dataclass(frozen=True, eq=False)
class Poster(Material):
    """A picture stretched over the rectangle ``rect = (a0, b0, a1, b1)``; ``base`` outside it."""

    base: Material
    picture: Texture
    rect: tuple[float, float, float, float]

    def albedo(self, a: np.ndarray, b: np.ndarray, footprint: np.ndarray) -> np.ndarray:
        out = self.base.albedo(a, b, footprint)
        a0, b0, a1, b1 = self.rect
        inside = np.nonzero((a >= a0) & (a <= a1) & (b >= b0) & (b <= b1))[0]
        if inside.size:
            h, w = self.picture.shape
            k = w / (a1 - a0)
            s = (a[inside] - a0) * k - 0.5
            t = (b[inside] - b0) * (h / (b1 - b0)) - 0.5
            out[inside] = self.picture.sample(s, t, footprint[inside] * k)
        return out

    def describe(self) -> str:
        return f"Poster({self.base.describe()}, {self.picture.digest()[:16]}, {self.rect})"


@dataclass(frozen=True, eq=False)
class Blend(Material):
    """``mask * top + (1 - mask) * bottom`` with ``mask(a, b)`` in ``[0, 1]`` (e.g. marine growth on stone).

    ``mask`` takes numpy arrays here and floats in the compiled renderer (:mod:`.mask_kernel` compiles it,
    with its sines and cosines inlined): write it with numpy ufuncs, ``math`` and compiled helpers only.
    """

    bottom: Material
    top: Material
    mask: Callable[[np.ndarray, np.ndarray], np.ndarray]
    mask_name: str

    def albedo(self, a: np.ndarray, b: np.ndarray, footprint: np.ndarray) -> np.ndarray:
        m = np.clip(self.mask(a, b), 0.0, 1.0).astype(np.float32)[:, None]
        return self.bottom.albedo(a, b, footprint) * (1 - m) + self.top.albedo(a, b, footprint) * m

    def describe(self) -> str:
        return f"Blend({self.bottom.describe()}, {self.top.describe()}, {self.mask_name}{_mask_code(self.mask)})"


def _mask_code(mask: Callable) -> str:
    """What names a mask's code beside its hand-written name in :meth:`Blend.describe` (and so in a scene's content
    hash and render keys): ``", <fingerprint>"`` of a user's mask, so that an edited mask function renders again
    under the same name; ``""`` for a mask of pytest-n2r's own demo package, whose source every render key
    already names (:data:`~pytest_n2r.scene.render_cache.RENDERING_CODE`), and whose hand-written name the
    shipped fitted twins' recipe digests depend on (:attr:`~pytest_n2r.demo.fitted.FittedRecipe.digest`: a
    fingerprint, which names bytecode and source bytes, would make them stale on every edit or Python version)."""
    import types

    fn = getattr(mask, "py_func", mask)  # a mask already compiled by numba: its Python function
    if not isinstance(fn, types.FunctionType) or (fn.__module__ or "").startswith(__package__ + "."):
        return ""  # not a plain function (a ufunc, which cannot change; compile_mask refuses the rest) or ours
    from .mask_kernel import mask_fingerprint

    # None: the mask cannot be named stably (its source is no file: typed at a prompt or exec'd; or it closes over
    # or defaults to something other than numbers and strings); its name is then all that tells it apart, as before
    fingerprint = mask_fingerprint(fn)
    return "" if fingerprint is None else f", {fingerprint}"


@dataclass(frozen=True, eq=False)
class Radial(Material):
    """Concentric rings about ``(0, 0)``: ``colours[i]`` out to ``radii[i]`` (a wheel's hub and tyre)."""

    radii: tuple[float, ...]
    colours: tuple[tuple[float, float, float], ...]
    outer: Material

    def albedo(self, a: np.ndarray, b: np.ndarray, footprint: np.ndarray) -> np.ndarray:
        out = self.outer.albedo(a, b, footprint)
        r = np.hypot(a, b)
        for radius, colour in sorted(zip(self.radii, self.colours), reverse=True):
            out[r <= radius] = colour
        return out

    def describe(self) -> str:
        return f"Radial({self.radii}, {self.colours}, {self.outer.describe()})"
