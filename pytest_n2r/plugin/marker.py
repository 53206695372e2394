"""``@metamorphic``: turn a test that returns a system under test into a metamorphic relation check.

The decorated test takes the ``n2r_scene`` fixture (and any other fixtures) and **returns the SUT**, a
callable ``rgb (H×W×3 uint8, RGB) -> output``. The plugin then renders source and follow-up views,
runs the SUT on both and compares them with the metric (see :mod:`pytest_n2r.relation`).

Arguments are validated when the module is imported; a bad one becomes a collection error that names
the test, not a failure in the middle of a run.
"""

from __future__ import annotations

from collections.abc import Callable
from typing import TYPE_CHECKING, Any, TypeVar

from ..errors import N2RError
from ..relation import Relation, Validity
from . import ERROR_ATTR, RELATION_ATTR, RELATION_MARKER

if TYPE_CHECKING:
    from hypothesis.strategies import SearchStrategy

    from ..geometry import Transform
    from ..metrics.base import Metric
    from ..render.size import RenderSize

__all__ = ["metamorphic"]

F = TypeVar("F", bound=Callable[..., Any])


def metamorphic(metric: Metric | str, eps: float, *, transform: SearchStrategy[Any] | Transform | str,
                examples: int | None = None, size: RenderSize | str | int | tuple[int, int] | None = None,
                search: str = "random", views: str = "heldout", interpolate: bool = False,
                validity: Validity | None = None) -> Callable[[F], F]:
    """Check that the SUT the test returns satisfies a metamorphic relation on ``n2r_scene``.

    Parameters
    ----------
    metric
        A :class:`~pytest_n2r.metrics.base.Metric` (``repeatability(px=2)``) or a metric's name.
    eps
        Largest allowed deviation of the metric from its ideal (>= 0).
    transform
        A strategy of transforms (``transforms(yaw=10, x=0.1)``), a preset name (``"tau1"`` ..
        ``"tau6"``), a fixed ``Transform`` or a strategy of image mutations.
    examples, size
        Hypothesis examples and render size (``"480x270"`` or the longer side); default: the
        ``--n2r-examples`` / ``--n2r-size`` options, then the ini file.
    search
        ``"random"``, or ``"targeted"`` to steer the search toward larger deviations.
    views, interpolate
        Source views: ``"heldout"`` (default), ``"train"`` or ``"all"``; ``interpolate=True`` draws poses
        between consecutive captured views.
    validity
        Thresholds that decide when a follow-up view is a fair input (:class:`~pytest_n2r.relation.Validity`).
    """
    try:
        relation: Relation | None = Relation.build(
            metric, eps, transform, examples=examples, size=size, search=search, views=views,
            interpolate=interpolate, validity=validity,
        )
        error = None
    except N2RError as exc:
        relation, error = None, f"@metamorphic(...): {exc}"

    def decorate(test: F) -> F:
        import inspect

        import pytest

        if isinstance(test, staticmethod):  # above @staticmethod: the function inside carries the relation
            return staticmethod(decorate(test.__func__))  # type: ignore[return-value]
        if isinstance(test, classmethod):
            name = getattr(test.__func__, "__name__", repr(test))
            setattr(test.__func__, ERROR_ATTR, f"@metamorphic(...): {name} is a classmethod, which pytest does not "
                                               "collect as a test; make it a plain method or a staticmethod")
            return test
        if getattr(test, ERROR_ATTR, None) is not None:  # the inner decorator's error stands
            return test
        if getattr(test, RELATION_ATTR, None) is not None:
            name = getattr(test, "__name__", repr(test))
            setattr(test, ERROR_ATTR, f"@metamorphic(...): {name} was given two relations (two @metamorphic "
                                      "decorators, or one function decorated twice); a test checks one relation (the "
                                      "second replaced the first): write a test for each")
            return test
        if error is None and (inspect.iscoroutinefunction(test) or inspect.isasyncgenfunction(test)):
            name = getattr(test, "__name__", repr(test))
            setattr(test, ERROR_ATTR, f"@metamorphic(...): {name} is async; a @metamorphic test returns the system "
                                      "under test at once, so it must be a plain def")
            return test
        if error is not None:
            setattr(test, ERROR_ATTR, error)
            return test
        setattr(test, RELATION_ATTR, relation)
        test = pytest.mark.usefixtures("n2r_scene")(test)
        return getattr(pytest.mark, RELATION_MARKER)(test)

    return decorate
