"""The colour of a photo's pixels: an embedded ICC colour profile converted to sRGB, and transparency warned of.

Convention
----------
Every image leaves :mod:`.images` in sRGB. A photo that embeds an RGB ICC profile other than sRGB (an iPhone's
Display P3, a camera's Adobe RGB) is converted to sRGB with Little CMS (Pillow's :mod:`PIL.ImageCms`, perceptual
intent, which a matrix profile takes as relative colorimetric), after the pixels are 8-bit (a 16-bit photo is scaled
first). A profile whose conversion leaves every colour within one level of where it was (sRGB under whatever name)
changes nothing, so an sRGB photo is read bit for bit as before. A gray or CMYK profile is not applied (OpenCV turns
those pixels into RGB itself). A profile Little CMS cannot read is warned of (:class:`PhotoColourWarning`) and the
pixels are kept. A photo with transparent pixels is warned of too: its alpha is dropped and the colour stored under
transparent pixels (often the background a cut-out removed) is what is read.
"""

from __future__ import annotations

import functools
import io
import os
import warnings
from typing import TYPE_CHECKING

import numpy as np

if TYPE_CHECKING:
    import PIL.Image
    from PIL import ImageCms

__all__ = ["PhotoColourWarning", "has_alpha", "to_srgb", "warn_if_transparent", "transparent"]


class PhotoColourWarning(UserWarning):
    """A photo whose colours are read with a caveat: transparent pixels whose alpha is dropped, a colour profile
    that could not be read or applied (its pixels taken as sRGB)."""


def to_srgb(image: np.ndarray, icc: bytes | None, path: str | os.PathLike) -> np.ndarray:
    """The ``H x W x 3`` RGB uint8 ``image`` converted from the ICC profile ``icc`` to sRGB (see the module's
    *Convention*); ``image`` itself when there is no profile, it is sRGB, not RGB, or it cannot be read (warned of,
    naming ``path``)."""
    if not icc:
        return image
    from PIL import Image, ImageCms

    try:
        transform = _transform(bytes(icc))
    except (ImageCms.PyCMSError, OSError, ValueError, TypeError) as exc:
        warnings.warn(f"image file {str(path)!r}: its colour profile cannot be read ({exc}); its pixels are taken as "
                      "sRGB", PhotoColourWarning, stacklevel=3)
        return image
    if transform is None:
        return image
    return np.ascontiguousarray(np.asarray(ImageCms.applyTransform(Image.fromarray(image, "RGB"), transform)))


@functools.lru_cache(maxsize=8)
def _transform(icc: bytes) -> ImageCms.ImageCmsTransform | None:
    """Little CMS's transform from the RGB profile ``icc`` to sRGB, or ``None`` when there is nothing to do (not an
    RGB profile, or within one level of the identity on every colour of a 16-level grid)."""
    from PIL import Image, ImageCms

    source = ImageCms.ImageCmsProfile(io.BytesIO(icc))
    if source.profile.xcolor_space.strip() != "RGB":
        return None
    transform = ImageCms.buildTransform(source, _srgb(), "RGB", "RGB",
                                        renderingIntent=ImageCms.Intent.PERCEPTUAL)
    probe = np.stack(np.meshgrid(*[np.linspace(0, 255, 16, dtype=np.uint8)] * 3, indexing="ij"), -1).reshape(64, 64, 3)
    moved = np.asarray(ImageCms.applyTransform(Image.fromarray(probe, "RGB"), transform)).astype(np.int16)
    return None if np.abs(moved - probe).max() <= 1 else transform


@functools.lru_cache(maxsize=1)
def _srgb() -> ImageCms.ImageCmsProfile:
    from PIL import ImageCms

    return ImageCms.ImageCmsProfile(ImageCms.createProfile("sRGB"))


def has_alpha(im: PIL.Image.Image) -> bool:
    """Whether the Pillow image ``im`` (its header read, its pixels need not be) carries an alpha channel or a
    transparent colour or palette entry."""
    return im.mode in ("RGBA", "LA", "La", "RGBa", "PA") or "transparency" in im.info


def transparent(path: str | os.PathLike) -> bool:
    """Whether the image at ``path`` has a pixel that is not opaque, as Pillow reads it (an alpha channel or a
    transparent palette entry); ``False`` when Pillow cannot read it."""
    from PIL import Image, UnidentifiedImageError

    try:
        with Image.open(path) as im:
            if not has_alpha(im):
                return False
            return im.convert("RGBA").getchannel("A").getextrema()[0] < 255
    except (OSError, UnidentifiedImageError, ValueError, SyntaxError):
        return False


def warn_if_transparent(path: str | os.PathLike, alpha: np.ndarray | None = None) -> None:
    """Warn (:class:`PhotoColourWarning`, naming ``path``) when the photo has transparent pixels: ``alpha`` when
    given (the decoded alpha channel), else as :func:`transparent` reads the file."""
    if alpha is None:
        found = transparent(path)
    else:
        opaque = np.iinfo(alpha.dtype).max if alpha.dtype.kind in "iu" else 1.0
        found = bool((alpha < opaque).any())
    if found:
        warnings.warn(f"image file {str(path)!r} has transparent pixels: its alpha is dropped and the colour stored "
                      "under them is read (a cut-out's removed background may show)", PhotoColourWarning,
                      stacklevel=3)
