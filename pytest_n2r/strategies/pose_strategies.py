"""Families of pose changes and the Hypothesis strategy that draws them (``transforms``).

Convention
----------
- A drawn value is a :class:`~pytest_n2r.strategies.pose_change.PoseChange`: a
  :class:`~pytest_n2r.geometry.Transform` applied in the **source camera's frame** (``c2w_tau = c2w @
  T(tau)``, docs/conventions.md, "Transforms τ"), angles in **degrees**, carrying the ``units`` of its
  translation (reference lengths by default, so one bound means the same on every scene).
- A :class:`PoseChangeFamily` (bounds, units, look-at) is the one place pose changes are drawn from:
  :meth:`~PoseChangeFamily.strategy` for Hypothesis (never the identity, shrinking toward the smallest
  motion on a decimal grid, :mod:`.grid`: a failing example is the smallest motion that still breaks the
  system under test) and
  :meth:`~PoseChangeFamily.sample` for uniform draws from a seeded generator (``n2r study``).
"""

from __future__ import annotations

from collections.abc import Mapping
from dataclasses import dataclass, field
from typing import Any

import numpy as np
from hypothesis import strategies as st

from .._validation import check_choice
from ..errors import InvalidArgument, InvalidType
from ..geometry import Transform, Units
from ..geometry.look_at import look_at_transform
from .grid import AXES, Bound, check_bound, draw_motion
from .pose_change import PoseChange

__all__ = ["PoseChangeFamily", "transforms"]


@dataclass(frozen=True)
class PoseChangeFamily:
    """Pose changes with each component in its bound (``bounds``: component -> ``(lo, hi)``; a component
    that is not there is 0), translations in ``units``; with ``look_at`` the camera also turns toward the
    point one reference length ahead (:func:`~pytest_n2r.geometry.look_at.look_at_transform`), the
    ``pitch`` and ``yaw`` bounds then being extra rotation on top. Build one with :meth:`of`.
    """

    bounds: Mapping[str, Bound] = field(default_factory=dict)
    units: Units = Units.REFERENCE
    look_at: bool = False

    @classmethod
    def of(cls, roll: float | Bound = 0.0, pitch: float | Bound = 0.0, yaw: float | Bound = 0.0,
           x: float | Bound = 0.0, y: float | Bound = 0.0, z: float | Bound = 0.0,
           *, units: Units | str = Units.REFERENCE, look_at: bool = False) -> PoseChangeFamily:
        """The family of :func:`transforms` with these arguments, validated (errors name the argument)."""
        bounds = {}
        for name, value in zip(AXES, (roll, pitch, yaw, x, y, z)):
            lo, hi = check_bound(name, value)
            if (lo, hi) != (0.0, 0.0):
                bounds[name] = (lo, hi)
        units = check_choice("units", units, Units, "a unit")
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
        if not bounds:
            raise InvalidArgument(f"roll, pitch, yaw, x, y and z are all 0: every pose change would be the identity, "
                                  f"which tests nothing; give at least one of {', '.join(AXES)} a bound other than 0")
        return cls(bounds, units, look_at)

    def build(self, values: Mapping[str, float]) -> PoseChange:
        """The pose change with these component ``values`` (missing ones 0), look-at compensated if asked."""
        transform = look_at_transform(**values) if self.look_at else Transform(**values)
        return PoseChange.of(transform, self.units)

    def strategy(self) -> st.SearchStrategy[PoseChange]:
        """Hypothesis draws of this family; the ``repr`` is the :func:`transforms` call."""
        arguments: dict[str, Any] = dict(self.bounds)  # the bounds first, as the repr reads them
        if self.look_at:
            arguments["look_at"] = True
        if self.units is not Units.REFERENCE:
            arguments["units"] = self.units.value
        return _transforms(**arguments)

    def sample(self, rng: np.random.Generator) -> PoseChange:
        """A pose change drawn uniformly within the bounds from ``rng`` (one ``uniform`` draw per bounded
        component, in alphabetical order of the component names)."""
        return self.build({axis: float(rng.uniform(lo, hi)) for axis, (lo, hi) in sorted(self.bounds.items())})


def _transforms_impl(draw: Any, *, look_at: bool = False, units: str = "reference", **bounds: Bound) -> PoseChange:
    values = draw_motion(draw, bounds)  # never the identity: it compares a view with itself
    return PoseChangeFamily(bounds, Units(units), look_at).build(values)


_transforms_impl.__name__ = _transforms_impl.__qualname__ = "transforms"  # so the repr reads transforms(...)
_transforms = st.composite(_transforms_impl)


def transforms(
    roll: float | Bound = 0.0, pitch: float | Bound = 0.0, yaw: float | Bound = 0.0,
    x: float | Bound = 0.0, y: float | Bound = 0.0, z: float | Bound = 0.0,
    *, units: Units | str = Units.REFERENCE, look_at: bool = False,
) -> st.SearchStrategy[PoseChange]:
    """Pose changes τ with each component within its bound, never the identity; shrinks toward the smallest motion.

    Each bound is a number ``b`` (meaning ``-|b|..|b|``) or a pair ``(lo, hi)``. Angles are **degrees**
    (yaw about the camera's y axis, pitch about x, roll about the optical axis; +yaw turns right, +pitch
    tilts up), translations ``x, y, z`` are in ``units``: ``"reference"`` (fractions of the scene's
    reference length, the default), ``"scene"`` or ``"metres"``. +x moves right, +y **down**, +z forward.
    Each drawn :class:`~pytest_n2r.strategies.pose_change.PoseChange` (a ``Transform``) carries its
    ``units``, so they survive ``.map``, ``.filter`` and ``st.one_of`` (a ``.map`` that builds a new plain
    ``Transform`` means reference lengths).

    ``look_at=True`` adds the yaw and pitch that keep the scene point one reference length ahead on the
    optical axis at the image centre (the paper's design: moving the camera up tilts it down); the
    ``yaw`` / ``pitch`` bounds are then extra rotation on top of that compensation
    (:func:`~pytest_n2r.geometry.look_at.look_at_transform`).

    Shrinking: each component moves toward the point of its bound nearest 0 (0 itself when the bound
    contains it) on a decimal grid, so a reported counterexample is within one grid step of the
    smallest failing motion. No draw is the identity (it would compare a view with itself): when every
    component before it drew 0, the last bounded component (in the order roll, pitch, yaw, x, y, z) is drawn
    off 0, so the smallest draw is one grid step along it. At least one bound must be other than 0.

    >>> transforms(yaw=10, x=(-0.1, 0.2))
    transforms(x=(-0.1, 0.2), yaw=(-10.0, 10.0))
    """
    return PoseChangeFamily.of(roll, pitch, yaw, x, y, z, units=units, look_at=look_at).strategy()
