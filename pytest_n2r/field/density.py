"""The density's shift: a field's density is ``σ = softplus(raw + density_shift)`` per voxel (see
:mod:`~pytest_n2r.field.grid`), the shift set where a fit starts so that a raw density of 0 gives the opacity asked
for, and the shifts a scene file may hold.

Written once here for the field (:class:`~pytest_n2r.field.grid.SceneField`, which sets and reads the shift) and its
fit settings (:class:`~pytest_n2r.field.config.FieldConfig`, which refuses an ``alpha_init`` and ``step_ratio``
whose shift no scene file could hold before any training time is spent).
"""

from __future__ import annotations

import math

__all__ = ["MAX_DENSITY_SHIFT", "alpha_range", "density_shift_for", "step_ratio_range"]

#: The largest |density_shift| a scene file may hold: a fit's shift is -14.5..69 for alpha_init 1e-6..0.999
#: over steps of 0.1..2 voxels (-8.5 by default); beyond ±100, every sample is empty or opaque alike.
MAX_DENSITY_SHIFT = 100.0


def density_shift_for(alpha: float, step_ratio: float) -> float:
    """The shift that makes a raw density of 0 give opacity ``alpha`` (in (0, 1)) over one sample of ``step_ratio``
    voxels: ``softplus⁻¹(σ)`` of the density σ per voxel (``-inf`` where σ underflows to 0, ``inf`` where it
    overflows).

    >>> round(density_shift_for(1e-4, 0.5), 4)
    -8.517
    """
    sigma = -math.log1p(-alpha) / step_ratio
    if sigma == 0.0:  # softplus⁻¹(σ) → log σ → -inf as σ → 0
        return -math.inf
    return float(sigma + math.log(-math.expm1(-sigma)))  # softplus⁻¹(σ)


def _density_range() -> tuple[float, float]:
    """The densities per voxel whose ``softplus⁻¹`` lies within ±:data:`MAX_DENSITY_SHIFT`: their softplus."""
    return math.log1p(math.exp(-MAX_DENSITY_SHIFT)), math.log1p(math.exp(MAX_DENSITY_SHIFT))


def alpha_range(step_ratio: float) -> tuple[float, float]:
    """The opacities per sample of ``step_ratio`` voxels whose :func:`density_shift_for` lies within
    ±:data:`MAX_DENSITY_SHIFT`, ``(lowest, highest)``.

    >>> [f"{a:.3g}" for a in alpha_range(0.5)]
    ['1.86e-44', '1']
    """
    lowest, highest = _density_range()
    return -math.expm1(-lowest * step_ratio), -math.expm1(-highest * step_ratio)


def step_ratio_range(alpha: float) -> tuple[float, float]:
    """The sample spacings (voxels) at which opacity ``alpha`` per sample has a :func:`density_shift_for` within
    ±:data:`MAX_DENSITY_SHIFT`, ``(shortest, longest)``.

    >>> [f"{r:.3g}" for r in step_ratio_range(0.99)]
    ['0.0461', '1.24e+44']
    """
    lowest, highest = _density_range()
    optical_depth = -math.log1p(-alpha)  # σ · step_ratio
    return optical_depth / highest, optical_depth / lowest
