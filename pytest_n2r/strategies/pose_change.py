"""Pose changes: a transform τ that carries the units of its own translation, as a follow-up.

Convention
----------
- A :class:`PoseChange` is a :class:`~pytest_n2r.geometry.Transform` (angles in **degrees**, applied in
  the **source camera's frame**: ``c2w_tau = c2w @ T(tau)``) plus ``units``, what its ``x, y, z`` are
  measured in (:class:`~pytest_n2r.geometry.Units`; reference lengths by default). The units travel with
  the drawn value, so ``.map``, ``.filter`` and ``st.one_of`` over :func:`~pytest_n2r.strategies.transforms`
  keep them.
- A plain ``Transform`` used as a follow-up (a fixed ``transform=Transform(yaw=5)``, or a strategy that
  builds ``Transform`` values) is a pose change in reference lengths (:func:`as_follow_up`).
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass
from typing import TYPE_CHECKING, Any, ClassVar

from .._validation import check_choice
from ..errors import InvalidArgument, InvalidType
from ..geometry import Transform, Units
from .follow_up import FollowUp

if TYPE_CHECKING:
    import numpy as np

    from ..render.view import RenderedView
    from ..scene.base import Scene

__all__ = ["PoseChange", "as_follow_up"]


@dataclass(frozen=True, repr=False)
class PoseChange(Transform, FollowUp):
    """A pose transform τ whose translation is in ``units`` (the follow-up renders the moved camera).

    >>> tau = PoseChange(yaw=5.0, x=0.1, units="scene")
    >>> tau
    PoseChange(yaw=5.0, x=0.1, units='scene')
    >>> tau.describe(), tau.record_fields()["units"]
    ('yaw=+5.000°, x=+0.1 scene', 'scene')
    """

    units: Units = Units.REFERENCE
    moves_camera: ClassVar[bool] = True

    if TYPE_CHECKING:  # the generated __init__ as type checkers should read it: units by Units or by name
        def __init__(self, roll: float = 0.0, pitch: float = 0.0, yaw: float = 0.0, x: float = 0.0, y: float = 0.0,
                     z: float = 0.0, units: Units | str = Units.REFERENCE) -> None: ...

    def __post_init__(self) -> None:
        super().__post_init__()
        object.__setattr__(self, "units", check_choice("units", self.units, Units, "a unit"))

    @classmethod
    def of(cls, transform: Transform, units: Units | str = Units.REFERENCE) -> PoseChange:
        """``transform`` with its translation in ``units``."""
        return cls(**transform.as_dict(), units=check_choice("units", units, Units, "a unit"))

    @property
    def transform(self) -> Transform:
        """The plain transform (without units)."""
        return Transform(**self.as_dict())

    def then(self, other: Transform) -> PoseChange:
        """The single change equal to this one and then ``other`` (in the moved frame), in this change's ``units``:
        ``other`` is a change in the same units or a plain ``Transform`` (read in these units)."""
        if not isinstance(other, Transform):
            raise InvalidType(f"other={other!r} must be a pytest_n2r.Transform, not {type(other).__name__}")
        units = getattr(other, "units", self.units)
        if units is not self.units:
            raise InvalidArgument(f"cannot combine {self!r} (translation in {self.units.value!r} units) with "
                                  f"{other!r} (in {Units(units).value!r} units); express both in the same units")
        return PoseChange.of(self.transform.then(other), self.units)

    def inverse(self) -> PoseChange:
        """The change that undoes this one, in the same ``units``: ``tau.then(tau.inverse())`` is the identity."""
        return PoseChange.of(self.transform.inverse(), self.units)

    def check_scene(self, scene: Scene) -> None:
        """``units='metres'`` needs a scene with a known scale (else :class:`InvalidArgument`)."""
        scene.length_scale(self.units)

    def follow_view(self, source: RenderedView, scene: Scene,
                    render: Callable[[np.ndarray], RenderedView]) -> RenderedView:
        """The render of ``scene`` at the moved pose ``source.c2w @ T(tau)``, translation in scene units."""
        return render(self.apply(source.c2w, scene.length_scale(self.units)))

    def describe(self, units: str | None = None) -> str:
        """``yaw=+5.120°, x=+0.100 ref``: translations labelled with ``units`` (default: this change's own,
        ``ref`` for reference lengths)."""
        return super().describe(units or ("ref" if self.units is Units.REFERENCE else self.units.value))

    def record_fields(self) -> dict[str, Any]:
        return {"transform": self.as_dict(), "units": self.units.value}

    def explain(self, scene: Scene, note: str) -> list[str]:
        lines = [f"  transform:  {self.describe()}  ({note or 'minimal after shrinking'})"]
        if any((self.x, self.y, self.z)):
            scale = scene.length_scale(self.units)
            moved = [n for n in ("x", "y", "z") if getattr(self, n)]
            line = "              = " + ", ".join(f"{n}={getattr(self, n) * scale:+.4g}" for n in moved)
            line += " scene units"
            mpu = scene.metres_per_unit
            if mpu:
                line += " = " + ", ".join(f"{n}={getattr(self, n) * scale * mpu:+.3g}" for n in moved) + " m"
            lines.append(line)
        return lines

    def __repr__(self) -> str:
        parts = [f"{name}={getattr(self, name)!r}" for name in self.COMPONENTS if getattr(self, name) != 0.0]
        if self.units is not Units.REFERENCE:
            parts.append(f"units={self.units.value!r}")
        return f"PoseChange({', '.join(parts)})"


def as_follow_up(value: Any) -> FollowUp:
    """``value`` as a follow-up: a :class:`FollowUp` as it is, a plain ``Transform`` as a pose change in
    reference lengths; anything else is an error that names it."""
    if isinstance(value, FollowUp):
        return value
    if isinstance(value, Transform):
        return PoseChange.of(value)
    raise InvalidType(
        f"the relation's transform strategy drew {value!r} ({type(value).__name__}); expected a pose change "
        "(pytest_n2r.Transform, or a strategy such as transforms(yaw=10)) or an image mutation "
        "(a pytest_n2r.strategies.Mutation subclass)")
