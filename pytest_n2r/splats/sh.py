"""Real spherical harmonics as 3D Gaussian Splatting evaluates them (degree 0 to 3).

Convention
----------
- Coefficients of one Gaussian are ``(K, 3)``: ``K = (degree + 1)²`` basis functions, each with an R, G, B
  coefficient; coefficient 0 is the view-independent ("DC") term.
- The basis is evaluated at the unit direction **from the camera centre to the Gaussian's mean, in world
  axes** (``x, y, z`` below), with the constants and signs of the 3DGS reference code
  (``SH_C1 · (-y, z, -x)`` for degree 1, ...), and the colour is ``max(0, Σ_k basis_k · coeff_k + 0.5)``
  (no upper clamp; the renderer clips the composited pixel to ``[0, 1]``).
- A view-independent colour ``c`` in ``[0, 1]`` is stored as the DC coefficient ``(c - 0.5) / SH_C0``
  (:func:`rgb_to_sh`).
"""

from __future__ import annotations

import math

import numpy as np
from numba import njit

from .._validation import check_array
from ..errors import InvalidArgument

__all__ = [
    "MAX_DEGREE",
    "SH_C0",
    "SH_C1",
    "SH_C2",
    "SH_C3",
    "rgb_to_sh",
    "sh_count",
    "sh_degree_of",
    "view_colours",
]

#: Highest SH degree the .ply format (and the renderer) carries.
MAX_DEGREE = 3
SH_C0 = 0.28209479177387814
SH_C1 = 0.4886025119029199
SH_C2 = (1.0925484305920792, -1.0925484305920792, 0.31539156525252005, -1.0925484305920792, 0.5462742152960396)
SH_C3 = (-0.5900435899266435, 2.890611442640554, -0.4570457994644658, 0.3731763325901154, -0.4570457994644658,
         1.445305721320277, -0.5900435899266435)


def sh_count(degree: int) -> int:
    """Basis functions of SH ``degree``: ``(degree + 1)²``.

    >>> [sh_count(d) for d in range(4)]
    [1, 4, 9, 16]
    """
    return (degree + 1) ** 2


def sh_degree_of(count: int) -> int | None:
    """The degree with ``count`` basis functions, or ``None`` when no degree 0..3 has that many."""
    for degree in range(MAX_DEGREE + 1):
        if sh_count(degree) == count:
            return degree
    return None


def rgb_to_sh(rgb: np.ndarray) -> np.ndarray:
    """View-independent colours in ``[0, 1]`` (``(..., 3)``) → DC coefficients (``(..., 3)``).

    >>> float(rgb_to_sh(np.array([0.5, 0.5, 0.5]))[0])
    0.0
    """
    return (np.asarray(rgb, dtype=np.float64) - 0.5) / SH_C0


@njit(cache=True, inline="always")
def colour_of(sh, i, degree, x, y, z, channel):
    """The colour ``channel`` of Gaussian ``i`` (``sh`` is ``(N, K, 3)``) seen along the unit world
    direction ``(x, y, z)`` from the camera: ``max(0, Σ basis · coeff + 0.5)``."""
    c = SH_C0 * sh[i, 0, channel]
    if degree > 0:
        c += SH_C1 * (-y * sh[i, 1, channel] + z * sh[i, 2, channel] - x * sh[i, 3, channel])
        if degree > 1:
            xx, yy, zz = x * x, y * y, z * z
            c += (SH_C2[0] * x * y * sh[i, 4, channel] + SH_C2[1] * y * z * sh[i, 5, channel]
                  + SH_C2[2] * (2.0 * zz - xx - yy) * sh[i, 6, channel] + SH_C2[3] * x * z * sh[i, 7, channel]
                  + SH_C2[4] * (xx - yy) * sh[i, 8, channel])
            if degree > 2:
                c += (SH_C3[0] * y * (3.0 * xx - yy) * sh[i, 9, channel]
                      + SH_C3[1] * x * y * z * sh[i, 10, channel]
                      + SH_C3[2] * y * (4.0 * zz - xx - yy) * sh[i, 11, channel]
                      + SH_C3[3] * z * (2.0 * zz - 3.0 * xx - 3.0 * yy) * sh[i, 12, channel]
                      + SH_C3[4] * x * (4.0 * zz - xx - yy) * sh[i, 13, channel]
                      + SH_C3[5] * z * (xx - yy) * sh[i, 14, channel]
                      + SH_C3[6] * x * (xx - 3.0 * yy) * sh[i, 15, channel])
    return max(c + 0.5, 0.0)


@njit(cache=True)
def _view_colours(sh, directions, degree, out):
    for i in range(sh.shape[0]):
        x, y, z = directions[i, 0], directions[i, 1], directions[i, 2]
        n = math.sqrt(x * x + y * y + z * z)
        if n > 0.0:
            x, y, z = x / n, y / n, z / n
        for channel in range(3):
            out[i, channel] = colour_of(sh, i, degree, x, y, z, channel)


def view_colours(sh: np.ndarray, directions: np.ndarray) -> np.ndarray:
    """Colours ``(N, 3)`` (float64, ``>= 0``) of ``N`` Gaussians' coefficients ``sh`` ``(N, K, 3)`` seen along
    ``directions`` ``(N, 3)`` (world axes, camera → Gaussian; normalized here).

    >>> view_colours(np.zeros((1, 4, 3)), np.array([[0.0, 0.0, 1.0]]))
    array([[0.5, 0.5, 0.5]])
    """
    sh = check_array("sh", sh, "N K 3", dtype=np.float64)
    degree = sh_degree_of(sh.shape[1])
    if degree is None:
        raise InvalidArgument(f"sh has {sh.shape[1]} coefficients per channel; expected 1, 4, 9 or 16 (degree 0-3)")
    directions = check_array("directions", directions, "N 3", dtype=np.float64)
    if len(directions) != len(sh):
        raise InvalidArgument(f"directions has {len(directions)} rows; sh has {len(sh)}")
    out = np.empty((len(sh), 3))
    _view_colours(np.ascontiguousarray(sh), np.ascontiguousarray(directions), degree, out)
    return out
