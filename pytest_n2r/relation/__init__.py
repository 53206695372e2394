"""The metamorphic relation engine: render a source and a follow-up view, run the SUT on both, compare.

One concept per module:

- :mod:`~pytest_n2r.relation.spec`: the :class:`Relation` (metric, ``eps``, follow-up, source views) and
  the checks of its arguments;
- :mod:`~pytest_n2r.relation.validity`: when a rendered follow-up view is a fair input (:class:`Validity`);
- :mod:`~pytest_n2r.relation.settings`: the run-wide defaults (:class:`RunSettings`);
- :mod:`~pytest_n2r.relation.engine`: one drawn or replayed example evaluated and counted;
- :mod:`~pytest_n2r.relation.search`: Hypothesis's survey and shrink passes (:func:`check_relation`) and
  exact replay (:func:`replay_relation`);
- :mod:`~pytest_n2r.relation.record`: what a run did: one :class:`ExampleRecord` per drawn example, in the
  run's :class:`RelationRecord` (what the plugin, baselines and reports read);
- :mod:`~pytest_n2r.relation.outputs`: checks of the SUT's outputs (:class:`SUTError`);
- :mod:`~pytest_n2r.relation.failure`: :class:`RelationFailure` and the messages of every verdict
  (:data:`MAX_UNDEFINED`);
- :mod:`~pytest_n2r.relation.determinism`: telling a non-deterministic SUT from an inconsistency;
- :mod:`~pytest_n2r.relation.floor`: the field floor beside a relation's result;
- :mod:`~pytest_n2r.relation.artifacts`: failure pictures, the two renders with the SUT's output drawn on them;
- :mod:`~pytest_n2r.relation.kept_results`: a metric's results kept in the render cache across sessions;
- :mod:`~pytest_n2r.relation.sut_outputs`: the SUT's outputs on rendered views, kept so that one SUT runs once
  on one render;
- :mod:`~pytest_n2r.relation.timeout`: the per-call time limit, so that a hung render or SUT fails its test.
"""

from .determinism import SUTNotDeterministic
from .failure import MAX_UNDEFINED, RelationFailure
from .outputs import SUTError
from .record import ExampleRecord, RelationRecord
from .search import check_relation, replay_relation
from .settings import RunSettings
from .spec import SEARCHES, Relation
from .validity import Validity

__all__ = ["Relation", "RunSettings", "RelationRecord", "ExampleRecord", "RelationFailure", "SUTError",
           "SUTNotDeterministic", "Validity", "check_relation", "replay_relation", "SEARCHES", "MAX_UNDEFINED"]
