"""Hypothesis strategies of pose transforms τ (camera motions in the source camera's frame).

Convention
----------
- Transforms are :class:`~pytest_n2r.geometry.Transform` values applied in the **source camera's frame**
  (``c2w_tau = c2w @ T(tau)``, design.md §2): angles in **degrees**, translations in ``units``
  (reference lengths by default, so one bound means the same on every scene).
- Every strategy shrinks toward the identity (no motion) on a decimal grid (:mod:`.grid`): a failing
  example is reported as the smallest motion that still breaks the system under test.
"""

from __future__ import annotations

from typing import Any

from hypothesis import strategies as st

from ..errors import InvalidArgument, InvalidType
from ..geometry import Transform, Units
from ..geometry.look_at import look_at_transform
from .grid import AXES, Bound, check_bound, draw_axis

__all__ = ["transforms", "transform_units"]


def _transforms_impl(draw: Any, *, look_at: bool = False, units: str = "reference", **bounds: Bound) -> Transform:
    values = {a: draw_axis(draw, *bounds[a]) if a in bounds else 0.0 for a in AXES}
    return look_at_transform(**values) if look_at else Transform(**values)


_transforms_impl.__name__ = _transforms_impl.__qualname__ = "transforms"  # so the repr reads transforms(...)
_transforms = st.composite(_transforms_impl)


def transforms(
    roll: float | Bound = 0.0, pitch: float | Bound = 0.0, yaw: float | Bound = 0.0,
    x: float | Bound = 0.0, y: float | Bound = 0.0, z: float | Bound = 0.0,
    *, units: Units | str = Units.REFERENCE, look_at: bool = False,
) -> st.SearchStrategy[Transform]:
    """Pose transforms τ with each component within its bound; shrinks toward the identity.

    Each bound is a number ``b`` (meaning ``-|b|..|b|``) or a pair ``(lo, hi)``. Angles are **degrees**
    (yaw about the camera's y axis, pitch about x, roll about the optical axis; +yaw turns right, +pitch
    tilts up), translations ``x, y, z`` are in ``units``: ``"reference"`` (fractions of the scene's
    reference length, the default), ``"scene"`` or ``"metres"``. +x moves right, +y **down**, +z forward.

    ``look_at=True`` adds the yaw and pitch that keep the scene point one reference length ahead on the
    optical axis at the image centre (the paper's design: moving the camera up tilts it down); the
    ``yaw`` / ``pitch`` bounds are then extra rotation on top of that compensation
    (:func:`~pytest_n2r.geometry.look_at.look_at_transform`).

    Shrinking: each component moves toward the point of its bound nearest 0 (0 itself when the bound
    contains it) on a decimal grid, so a reported counterexample is within one grid step of the
    smallest failing motion.

    >>> transforms(yaw=10, x=(-0.1, 0.2))
    transforms(x=(-0.1, 0.2), yaw=(-10.0, 10.0))
    """
    bounds = {}
    for name, value in zip(AXES, (roll, pitch, yaw, x, y, z)):
        lo, hi = check_bound(name, value)
        if (lo, hi) != (0.0, 0.0):
            bounds[name] = (lo, hi)
    try:
        units = Units(units)
    except ValueError:
        raise InvalidArgument(f"units={units!r} is not a unit; expected one of {[u.value for u in Units]}") from None
    if not isinstance(look_at, bool):
        raise InvalidType(f"look_at={look_at!r} must be True or False")
    if look_at and units is not Units.REFERENCE:
        raise InvalidArgument(
            f"look_at=True needs units='reference' (the look-at point is one reference length ahead); "
            f"got units={units.value!r}"
        )
    if look_at and "z" in bounds and bounds["z"][1] >= 0.9:
        raise InvalidArgument(
            f"z={bounds['z']!r} with look_at=True moves the camera up to the look-at point one reference "
            "length ahead; keep z below 0.9"
        )
    extra: dict[str, Any] = {}
    if look_at:
        extra["look_at"] = True
    if units is not Units.REFERENCE:
        extra["units"] = units.value
    strategy = _transforms(**bounds, **extra)
    strategy.n2r_units = units  # read by the relation engine through transform_units()
    strategy.n2r_bounds = dict(bounds)
    strategy.n2r_look_at = look_at
    return strategy


def transform_units(strategy: Any) -> Units:
    """The translation units of a :func:`transforms` strategy (reference lengths for anything else)."""
    return getattr(strategy, "n2r_units", Units.REFERENCE)
