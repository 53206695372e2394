"""Textures of the demo scenes: real photos that scikit-image ships, sampled with trilinear mip-mapping.

Convention
----------
- A texture is an ``H×W×3`` float32 image in linear ``[0, 1]`` RGB. Texture coordinates ``(s, t)`` are in
  **texels** (``s`` along columns, ``t`` along rows) with texel centres at integer coordinates, like pixels.
- ``wrap="mirror"`` tiles the photo by mirroring it (no seams); ``wrap="clamp"`` repeats the border texel
  (for a picture placed once, e.g. a poster).
- ``footprint`` is the size of the area one sample covers, in texels; the sampler picks the mip level
  ``log2(footprint)`` and interpolates between the two nearest levels, so distant, grazing surfaces are
  filtered instead of aliased.
- A texture of a bundled photo (:meth:`Texture.photo`) reads and processes the photo on first use of its
  texels; until then its :meth:`~Texture.digest` comes from the user cache (:func:`_photo_digest`), so a
  process that takes every render from the render cache reads no photo.
"""

from __future__ import annotations

import functools
import hashlib
import json
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any, Literal

import numpy as np

from ..data.atomic import atomic_write_text
from ..errors import InvalidArgument
from .user_cache import cache_dir

__all__ = ["Texture", "sample_photo"]

#: scikit-image sample images that ship inside the wheel (no download needed).
PHOTOS = ("brick", "gravel", "grass", "coffee", "astronaut", "chelsea", "rocket", "moon", "camera")


def sample_photo(name: str) -> np.ndarray:
    """A scikit-image sample photo as ``H×W×3`` float32 in ``[0, 1]`` (grey photos are repeated to RGB)."""
    if name not in PHOTOS:
        raise InvalidArgument(f"photo={name!r} is not a bundled sample; expected one of {PHOTOS}")
    from skimage import data

    image = np.asarray(getattr(data, name)())
    if image.ndim == 2:
        image = np.repeat(image[..., None], 3, axis=2)
    return np.ascontiguousarray(image[..., :3], dtype=np.float32) / 255.0


def _downsample(image: np.ndarray) -> np.ndarray:
    """Half the size with a 2×2 box filter (odd sizes drop the last row / column)."""
    h, w = image.shape[0] // 2 * 2, image.shape[1] // 2 * 2
    im = image[:h, :w]
    return 0.25 * (im[0::2, 0::2] + im[1::2, 0::2] + im[0::2, 1::2] + im[1::2, 1::2])


@dataclass(eq=False)
class Texture:
    """A mip-mapped RGB texture (see the module *Convention*)."""

    image: np.ndarray
    wrap: Literal["mirror", "clamp"] = "mirror"
    levels: list[np.ndarray] = field(init=False, repr=False)

    def __post_init__(self) -> None:
        if self.wrap not in ("mirror", "clamp"):
            raise InvalidArgument(f"wrap={self.wrap!r}; expected 'mirror' or 'clamp'")
        img = np.ascontiguousarray(self.image, dtype=np.float32)
        if img.ndim != 3 or img.shape[2] != 3:
            raise InvalidArgument(f"texture image must have shape (H, W, 3), got {img.shape}")
        self.image = img
        self.levels = [img]
        while min(self.levels[-1].shape[:2]) >= 8:
            self.levels.append(_downsample(self.levels[-1]))

    @classmethod
    def photo(
        cls, name: str, *, tint: tuple[float, float, float] = (1.0, 1.0, 1.0), gain: float = 1.0,
        contrast: float = 1.0, wrap: Literal["mirror", "clamp"] = "mirror", quarter_turns: int = 0,
    ) -> Texture:
        """A bundled photo turned by ``quarter_turns`` × 90° counter-clockwise, contrast-stretched about its
        mean, then multiplied by ``gain * tint`` (read and processed on first use of ``image`` or ``levels``)."""
        if name not in PHOTOS:
            raise InvalidArgument(f"photo={name!r} is not a bundled sample; expected one of {PHOTOS}")
        if wrap not in ("mirror", "clamp"):
            raise InvalidArgument(f"wrap={wrap!r}; expected 'mirror' or 'clamp'")
        texture = cls.__new__(cls)
        texture.wrap = wrap
        texture.__dict__["_recipe"] = (name, tint, gain, contrast, quarter_turns)  # not a field: read from __dict__
        return texture

    def __getattr__(self, name: str) -> Any:
        """A photo's ``image`` and ``levels``, built on first use (only called for attributes not set yet)."""
        recipe = self.__dict__.get("_recipe")
        if name not in ("image", "levels") or recipe is None or "image" in self.__dict__:
            raise AttributeError(f"{type(self).__name__!r} object has no attribute {name!r}")
        self.image = _photo_image(*recipe)
        self.__post_init__()
        return self.__dict__[name]

    @property
    def shape(self) -> tuple[int, int]:
        return self.image.shape[0], self.image.shape[1]

    def digest(self) -> str:
        """SHA-256 of the texels and the wrap mode (part of a scene's content hash); a photo's texels that
        were not read yet are not read for it when the user cache holds their digest (:func:`_photo_digest`)."""
        recipe = self.__dict__.get("_recipe")
        if recipe is not None and "image" not in self.__dict__:
            return _photo_digest(self, recipe)
        return _texel_digest(self.image, self.wrap)

    def _bilinear(self, level: int, s: np.ndarray, t: np.ndarray) -> np.ndarray:
        """Bilinear lookup in mip ``level`` at level-0 texel coordinates (OpenCV ``remap``, 1/32-texel steps)."""
        import cv2

        img = self.levels[level]
        h, w = img.shape[:2]
        scale = 0.5**level  # texel coordinates of level 0 -> this level (centres stay aligned)
        s = (s + 0.5) * scale - 0.5
        t = (t + 0.5) * scale - 0.5
        if self.wrap == "mirror":  # one mirrored period first, so float32 keeps sub-texel precision
            s, t = np.mod(s, 2 * w), np.mod(t, 2 * h)
            border = cv2.BORDER_REFLECT
        else:
            s, t = np.clip(s, -1, w), np.clip(t, -1, h)
            border = cv2.BORDER_REPLICATE
        n = s.size
        cols = 1024
        rows = -(-n // cols)
        map_x = np.zeros(rows * cols, np.float32)
        map_y = np.zeros(rows * cols, np.float32)
        map_x[:n], map_y[:n] = s, t
        out = cv2.remap(img, map_x.reshape(rows, cols), map_y.reshape(rows, cols), cv2.INTER_LINEAR, borderMode=border)
        return out.reshape(-1, 3)[:n]

    def sample(self, s: np.ndarray, t: np.ndarray, footprint: np.ndarray | float = 1.0) -> np.ndarray:
        """Colours ``(N, 3)`` float32 at texel coordinates ``(s, t)`` (each ``(N,)``), filtered to ``footprint``."""
        s = np.asarray(s, dtype=np.float64).ravel()
        t = np.asarray(t, dtype=np.float64).ravel()
        lod = np.log2(np.maximum(np.broadcast_to(np.asarray(footprint, np.float64), s.shape), 1.0))
        lod = np.minimum(lod, len(self.levels) - 1)
        lo = np.floor(lod).astype(np.int64)
        frac = (lod - lo).astype(np.float32)[:, None]
        out = np.zeros((s.size, 3), dtype=np.float32)
        for level in np.unique(lo):
            sel = np.nonzero(lo == level)[0]
            colour = self._bilinear(int(level), s[sel], t[sel])
            if level + 1 < len(self.levels):
                f = frac[sel]
                colour = colour * (1 - f) + self._bilinear(int(level) + 1, s[sel], t[sel]) * f
            out[sel] = colour
        return out


def _photo_image(name: str, tint: tuple[float, float, float], gain: float, contrast: float,
                 quarter_turns: int) -> np.ndarray:
    """The texels of :meth:`Texture.photo` with these arguments."""
    img = np.rot90(sample_photo(name), quarter_turns)
    mean = img.mean(axis=(0, 1), keepdims=True)
    return np.clip((mean + (img - mean) * contrast) * gain * np.asarray(tint, np.float32), 0.0, 1.0)


def _texel_digest(image: np.ndarray, wrap: str) -> str:
    """SHA-256 of ``image``'s texels and the ``wrap`` mode."""
    h = hashlib.sha256(wrap.encode())
    h.update(str(image.shape).encode())
    h.update(image.tobytes())
    return h.hexdigest()


@functools.cache
def _photo_file(name: str) -> Path | None:
    """The file scikit-image reads bundled photo ``name`` from, or ``None`` when it does not say (a private
    function of scikit-image: without it, every digest is taken from the texels)."""
    try:
        from skimage.data._fetchers import _fetch, registry

        (entry,) = [key for key in registry if key.rsplit(".", 1)[0] == f"data/{name}"]
        return Path(_fetch(entry)).resolve()
    except (ImportError, AttributeError, KeyError, ValueError, OSError):
        return None


@functools.cache
def _code_digest() -> str:
    """What else the texels depend on: this module's source and the numpy and scikit-image versions."""
    import skimage

    versions = f"{np.__version__}/{skimage.__version__}"  # type: ignore[attr-defined]  # skimage's stub lacks it
    return hashlib.sha256(Path(__file__).read_bytes() + versions.encode()).hexdigest()


def _photo_digest(texture: Texture, recipe: tuple[Any, ...]) -> str:
    """:meth:`Texture.digest` of a photo's texture whose texels were not read, from the user cache
    (``<cache dir>/texture-digests/``). An entry is keyed by the photo file's resolved path, size and
    modification time, the recipe and :func:`_code_digest`, so an edited photo or processing gets a new
    entry; a missing, unreadable or malformed entry is computed from the texels and written (atomically)."""
    photo = _photo_file(recipe[0])
    try:
        stat = photo.stat() if photo is not None else None
    except OSError:
        stat = None
    if stat is None:
        return _texel_digest(texture.image, texture.wrap)
    key = json.dumps([str(photo), stat.st_size, stat.st_mtime_ns, repr(recipe), texture.wrap, _code_digest()])
    path = cache_dir() / "texture-digests" / hashlib.sha256(key.encode()).hexdigest()
    try:
        digest = path.read_text()
        if len(digest) == 64 and all(c in "0123456789abcdef" for c in digest):
            return digest
    except (OSError, UnicodeDecodeError):
        pass
    digest = _texel_digest(texture.image, texture.wrap)
    try:
        atomic_write_text(path, digest)
    except OSError:
        pass  # a read-only cache: the digest is computed again next time
    return digest
