"""A metamorphic relation: what to compare (metric, ``eps``), under which follow-up (transform or mutation),
on which source views, and when a follow-up view is a fair input (validity). :meth:`Relation.build`
checks every argument and names the bad one."""

from __future__ import annotations

from dataclasses import dataclass, field
from typing import Any

from hypothesis import strategies as st

from .._validation import check_range
from ..errors import InvalidArgument, InvalidType
from ..geometry import Transform
from ..metrics import Metric, resolve_metric
from ..render.size import RenderSize
from ..scene.splits import check_source_split
from ..strategies import PRESETS
from .validity import Validity

__all__ = ["Relation", "SEARCHES"]

SEARCHES = ("random", "targeted")


def _resolve_transform(transform: Any) -> st.SearchStrategy:
    if isinstance(transform, str):
        if transform not in PRESETS:
            raise InvalidArgument(f"transform={transform!r} is not a preset; presets: {', '.join(PRESETS)}")
        return PRESETS[transform]
    if isinstance(transform, Transform):
        return st.just(transform)
    if isinstance(transform, st.SearchStrategy):
        return transform
    raise InvalidType(
        f"transform={transform!r} must be a strategy such as transforms(yaw=10), a preset name ('tau1' to "
        f"'tau6'), a mutation strategy or a fixed Transform, not {type(transform).__name__}"
    )


@dataclass(frozen=True)
class Relation:
    """A metamorphic relation: ``metric`` deviation at most ``eps`` between the SUT's outputs on a source
    view and on its follow-up under ``transform``. ``examples``, ``size`` (``None``: the run's setting),
    ``search`` (``"random"`` or ``"targeted"``), the source ``views`` split (``"heldout"``, ``"train"``,
    ``"all"``), ``interpolate`` (sources between captured poses) and the ``validity`` thresholds.

    Build it with :meth:`build`, which validates every argument and names the bad one.
    """

    metric: Metric
    eps: float
    transform: st.SearchStrategy
    examples: int | None = None
    size: RenderSize | None = None
    search: str = "random"
    views: str = "heldout"
    interpolate: bool = False
    validity: Validity = field(default_factory=Validity)

    @classmethod
    def build(cls, metric: Metric | str, eps: float, transform: st.SearchStrategy[Any] | Transform | str, *,
              examples: int | None = None, size: RenderSize | str | int | tuple[int, int] | None = None,
              search: str = "random", views: str = "heldout", interpolate: bool = False,
              validity: Validity | None = None) -> Relation:
        """The relation of these arguments, each checked, with an error naming the bad one. The arguments are
        :func:`~pytest_n2r.metamorphic`'s (see its parameters); ``size`` may be anything
        :meth:`RenderSize.parse <pytest_n2r.render.size.RenderSize.parse>` reads."""
        metric = resolve_metric(metric)
        try:
            eps = check_range("eps", eps, 0.0)
        except InvalidType:
            raise InvalidType(f"eps={eps!r} must be a number >= 0 (the largest allowed deviation)") from None
        except InvalidArgument:
            raise InvalidArgument(
                f"eps={eps!r} must be a finite number >= 0 (the largest allowed deviation of "
                f"{metric.name} from its ideal {metric.ideal:g})"
            ) from None
        strategy = _resolve_transform(transform)
        if examples is not None and (isinstance(examples, bool) or not isinstance(examples, int) or examples < 1):
            raise InvalidArgument(f"examples={examples!r} must be a whole number >= 1")
        if search not in SEARCHES:
            raise InvalidArgument(f"search={search!r}; expected one of {SEARCHES}")
        check_source_split("views", views)
        if not isinstance(interpolate, bool):
            raise InvalidType(f"interpolate={interpolate!r} must be True or False")
        if validity is not None and not isinstance(validity, Validity):
            raise InvalidType(f"validity={validity!r} must be a pytest_n2r.Validity")
        return cls(metric, eps, strategy, examples, None if size is None else RenderSize.parse(size),
                   search, views, interpolate, validity or Validity())

    def describe(self) -> str:
        return f"{self.metric!r} within eps={self.eps:g} under {self.transform!r}"
