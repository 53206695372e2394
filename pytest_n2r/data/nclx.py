"""A HEIF photo's colours as its ``nclx`` box states them (ITU-T H.273 code points), written as the ICC profile a
colour-managed viewer applies, so that :func:`.colour.to_srgb` converts them as it converts an embedded profile.

Convention
----------
A HEIF photo states its colours with an ICC profile (an iPhone's Display P3) or with an ``nclx`` box: three code
points, the primaries (with libheif's chromaticities of them), the transfer curve and the YCbCr matrix (libheif
applies the matrix while decoding). When the file has both, the ICC profile is the one read. The ``nclx`` box becomes
an ICC v2 matrix/TRC profile: the primaries' RGB → XYZ matrix, adapted from the stated white to the profile
connection space's D50 with the Bradford transform (as ICC profiles are), and the transfer curve as a parametric
curve. The transfer codes of standard-range photos (BT.709 1, unspecified 2, BT.601 6, sRGB 13, BT.2020 14 and 15)
are read with the sRGB curve: a phone's standard-range photo is encoded for sRGB displays whichever of them it
states, as libheif's and libultrahdr's defaults take it; gamma 2.2 (4), gamma 2.8 (5) and linear (8) with their own
curve. BT.709 or unspecified primaries with one of those sRGB curves is sRGB itself: no profile, the pixels read as
stored. An HDR curve (PQ 16, HLG 18), which needs tone mapping, any other transfer code, or primaries that span no
colour space are warned of (:class:`~.colour.PhotoColourWarning`), and the pixels are taken as sRGB.
"""

from __future__ import annotations

import os
import struct
import warnings
from collections.abc import Mapping

import numpy as np

from .colour import PhotoColourWarning

__all__ = ["nclx_icc", "rgb_to_xyz", "bradford_adaptation"]

#: the profile connection space's white (ICC.1, D50) as XYZ
D50 = (0.9642, 1.0, 0.8249)
#: BT.709 / sRGB chromaticities (x, y): red, green, blue, white (D65)
SRGB_CHROMATICITIES = ((0.64, 0.33), (0.30, 0.60), (0.15, 0.06), (0.3127, 0.3290))
#: H.273 transfer codes of standard-range photos, read with the sRGB curve (see the module's *Convention*)
SRGB_CURVE_CODES = frozenset({1, 2, 6, 13, 14, 15})
#: H.273 transfer code → the parametric curve (ICC ``para`` function type, parameters) it is read with
_CURVES: dict[int, tuple[int, tuple[float, ...]]] = {
    **dict.fromkeys(SRGB_CURVE_CODES, (3, (2.4, 1 / 1.055, 0.055 / 1.055, 1 / 12.92, 0.04045))),
    4: (0, (2.2,)),
    5: (0, (2.8,)),
    8: (0, (1.0,)),
}
_HDR = {16: "PQ, SMPTE ST 2084", 18: "HLG, ARIB STD-B67"}
_BRADFORD = np.array([[0.8951, 0.2664, -0.1614], [-0.7502, 1.7135, 0.0367], [0.0389, -0.0685, 1.0296]])
_NAMES = ("red", "green", "blue", "white")


def rgb_to_xyz(chromaticities: tuple[tuple[float, float], ...]) -> np.ndarray:
    """The 3x3 matrix from linear RGB to XYZ of the primaries ``((x, y) red, green, blue, white)``, white at Y = 1.

    >>> np.round(rgb_to_xyz(SRGB_CHROMATICITIES)[1], 4)  # the luminance of sRGB's red, green, blue
    array([0.2126, 0.7152, 0.0722])
    """
    (xr, yr), (xg, yg), (xb, yb), white = chromaticities
    columns = np.array([[x / y, 1.0, (1 - x - y) / y] for x, y in ((xr, yr), (xg, yg), (xb, yb))]).T
    scale = np.linalg.solve(columns, _xyz(white))
    return columns * scale


def bradford_adaptation(source_white: np.ndarray, target_white: np.ndarray) -> np.ndarray:
    """The 3x3 Bradford chromatic adaptation of XYZ colours from ``source_white`` to ``target_white`` (both XYZ).

    >>> d65 = _xyz(SRGB_CHROMATICITIES[3])
    >>> np.allclose(bradford_adaptation(d65, np.array(D50)) @ d65, D50)
    True
    """
    cones = (_BRADFORD @ target_white) / (_BRADFORD @ source_white)
    return np.linalg.inv(_BRADFORD) @ np.diag(cones) @ _BRADFORD


def nclx_icc(nclx: Mapping[str, float] | None, path: str | os.PathLike) -> bytes | None:
    """The ICC profile (bytes) stating the colours ``nclx`` (pillow-heif's ``info["nclx_profile"]``) states, or
    ``None`` when they are sRGB, there is no ``nclx`` box, or it cannot be applied (warned of, naming ``path``): see
    the module's *Convention*."""
    if not nclx:
        return None
    transfer = int(nclx.get("transfer_characteristics", 2))
    if transfer not in _CURVES:
        why = (f"HDR colours (transfer {transfer}, {_HDR[transfer]}), which need tone mapping" if transfer in _HDR
               else f"transfer code {transfer}, which this reader does not convert")
        _warn(path, f"its nclx colour box states {why}")
        return None
    chromaticities = _chromaticities(nclx)
    if chromaticities == SRGB_CHROMATICITIES and transfer in SRGB_CURVE_CODES:
        return None
    try:
        matrix = rgb_to_xyz(chromaticities)
        if not np.all(np.isfinite(matrix)) or np.linalg.matrix_rank(matrix) < 3:
            raise np.linalg.LinAlgError("singular")
    except (np.linalg.LinAlgError, ZeroDivisionError):
        stated = ", ".join(f"{name} {xy}" for name, xy in zip(_NAMES, chromaticities))
        _warn(path, f"its nclx colour box states primaries that span no colour space ({stated})")
        return None
    white = _xyz(chromaticities[3])
    return _matrix_profile(bradford_adaptation(white, np.array(D50)) @ matrix, *_CURVES[transfer])


def _chromaticities(nclx: Mapping[str, float]) -> tuple[tuple[float, float], ...]:
    """The primaries' and white's ``(x, y)`` as libheif reports them, rounded to 4 places (stored as float32);
    sRGB's where libheif reports none (unspecified primaries: all zero)."""
    stated = tuple((round(float(nclx.get(f"color_primary_{name}_x", 0.0)), 4),
                    round(float(nclx.get(f"color_primary_{name}_y", 0.0)), 4)) for name in _NAMES)
    return SRGB_CHROMATICITIES if not any(x or y for x, y in stated) else stated


def _xyz(xy: tuple[float, float]) -> np.ndarray:
    """The XYZ, at Y = 1, of the chromaticity ``(x, y)``."""
    x, y = xy
    return np.array([x / y, 1.0, (1 - x - y) / y])


def _warn(path: str | os.PathLike, what: str) -> None:
    warnings.warn(f"image file {str(path)!r}: {what}; its pixels are taken as sRGB", PhotoColourWarning,
                  stacklevel=5)  # read_image's caller, as colour's warnings


def _matrix_profile(colourants: np.ndarray, function: int, parameters: tuple[float, ...]) -> bytes:
    """An ICC v2 RGB display profile: ``colourants`` (3x3, the D50-adapted XYZ of red, green, blue as columns) and
    one parametric curve (ICC ``para``, ``function`` type with ``parameters``) for all three channels."""
    def fixed(value: float) -> bytes:  # s15Fixed16Number
        return struct.pack(">i", round(value * 65536))

    def xyz(values) -> bytes:
        return b"XYZ \0\0\0\0" + b"".join(fixed(v) for v in values)

    text = b"nclx colours\0"
    curve = b"para\0\0\0\0" + struct.pack(">H2x", function) + b"".join(fixed(p) for p in parameters)
    tags = [(b"desc", b"desc\0\0\0\0" + struct.pack(">I", len(text)) + text + b"\0" * 78),
            (b"wtpt", xyz(D50)), (b"rXYZ", xyz(colourants[:, 0])), (b"gXYZ", xyz(colourants[:, 1])),
            (b"bXYZ", xyz(colourants[:, 2])), (b"rTRC", curve), (b"gTRC", curve), (b"bTRC", curve),
            (b"cprt", b"text\0\0\0\0no copyright\0")]
    table, data, start = b"", b"", 128 + 4 + 12 * len(tags)
    for signature, payload in tags:
        payload += b"\0" * (-len(payload) % 4)
        table += signature + struct.pack(">II", start + len(data), len(payload))
        data += payload
    body = struct.pack(">I", len(tags)) + table + data
    # size, CMM, version 2.1, display class, RGB data, XYZ connection space, date, signature, then flags to rendering
    # intent, the connection space's illuminant, creator, profile ID and reserved bytes
    header = (struct.pack(">I", 128 + len(body)) + b"\0" * 4 + bytes([2, 0x10, 0, 0]) + b"mntrRGB XYZ "
              + b"\0" * 12 + b"acsp" + b"\0" * 28 + b"".join(fixed(v) for v in D50) + b"\0" * 48)
    return header + body
