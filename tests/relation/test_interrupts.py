"""A test runner's outcome raised inside the search (pytest-timeout's ``Failed``, ``KeyboardInterrupt``) on one
example only: Hypothesis reports a ``FlakyFailure`` wrapping it, and the search raises it as itself."""

from __future__ import annotations

import numpy as np
import pytest

from pytest_n2r.metrics import cosine_similarity
from pytest_n2r.relation import Relation, RunSettings, check_relation
from pytest_n2r.strategies import transforms
from tests.plugin.fakescene import PlaneScene


@pytest.mark.parametrize("kind", [SystemExit, pytest.fail.Exception])  # the two Hypothesis replays
def test_a_base_exception_raised_once_is_raised_as_itself(kind: type[BaseException]) -> None:
    """pytest-timeout's signal method raised ``Failed`` in one example; Hypothesis's replay passed, so it raised a
    ``FlakyFailure`` holding an ``Exception`` wrapping it, and the search re-raised that wrapper (Hypothesis's private
    ``_WrappedBaseException``) with a note that it was neither the SUT nor the verdict: pytest's "Timeout" was lost."""
    calls = 0
    raised = kind("Timeout (>2.0s) from pytest-timeout.")

    def once(rgb: np.ndarray) -> np.ndarray:
        nonlocal calls
        calls += 1
        if calls == 3:
            raise raised
        return np.array([0.1, 0.2, 0.7])

    records = []
    relation = Relation.build(cosine_similarity(), 0.01, transforms(yaw=3))
    with pytest.raises(BaseException) as info:  # which one is the point
        check_relation(PlaneScene(), once, relation, test_id="interrupted", on_start=records.append,
                       settings=RunSettings(examples=10, database=None, derandomize=True))
    assert info.value is raised, f"expected the SUT's {kind.__name__} itself, got {info.value!r}"
    assert not getattr(info.value, "__notes__", None), info.value.__notes__
    assert records[0].message == f"{kind.__name__}: Timeout (>2.0s) from pytest-timeout.", records[0].message
