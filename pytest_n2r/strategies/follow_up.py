"""The follow-up protocol: what turns the source view of a metamorphic relation into its follow-up view.

Two kinds implement it, and the relation engine, the example records and ``n2r study`` handle both
through this one interface (never by asking what a value is):

- a **pose change** (:class:`~pytest_n2r.strategies.pose_change.PoseChange`): the camera moves; the scene
  renders the follow-up at the moved pose, so it is a new render whose validity is checked
  (``moves_camera`` is true). It carries the units of its own translation;
- a **mutation** (:class:`~pytest_n2r.strategies.mutation.Mutation`): the source render's pixels change
  at the same pose (``moves_camera`` is false); depth and opacity are the source's.

To write a follow-up of your own, subclass one of the two (a mutation is a frozen dataclass with a
``name``, see :mod:`pytest_n2r.strategies.mutation`).
"""

from __future__ import annotations

from abc import ABC, abstractmethod
from collections.abc import Callable
from typing import TYPE_CHECKING, Any, ClassVar

if TYPE_CHECKING:
    import numpy as np

    from ..render.view import RenderedView
    from ..scene.base import Scene

__all__ = ["FollowUp"]


class FollowUp(ABC):
    """What makes the follow-up view from a source view (see the module docstring)."""

    #: True when the follow-up is a new render at a moved pose (checked for validity); False when it is
    #: the source render changed in place.
    moves_camera: ClassVar[bool]

    @abstractmethod
    def follow_view(self, source: RenderedView, scene: Scene,
                    render: Callable[[np.ndarray], RenderedView]) -> RenderedView:
        """The follow-up of ``source`` (the source render of ``scene``); ``render(c2w)`` renders ``scene`` at
        a camera-to-world pose with the source's camera and the outputs the follow-up needs."""

    def check_scene(self, scene: Scene) -> None:
        """Raise, naming what is wrong, when the follow-up cannot be made on ``scene`` at all (called before
        anything is rendered); nothing by default."""

    @abstractmethod
    def describe(self) -> str:
        """Words for reports and failure messages (``"yaw=+5.010°, x=+0.1 ref"``)."""

    @abstractmethod
    def record_fields(self) -> dict[str, Any]:
        """The follow-up's fields of an example record (:class:`~pytest_n2r.relation.record.ExampleRecord`):
        ``transform`` and ``units``, or ``transform=None`` and ``mutation``."""

    @abstractmethod
    def explain(self, scene: Scene, note: str) -> list[str]:
        """The lines a failure message gives the follow-up on ``scene``; ``note`` says how it was found."""

    def _repr_pretty_(self, printer: Any, cycle: bool) -> None:
        """Hypothesis's "Falsifying example" shows the ``repr`` (the constructor call), not every field."""
        printer.text(repr(self))
