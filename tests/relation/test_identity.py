"""The run's identity (test, scene, relation) keys its database entries and seeds its draws: it must not
change between processes, so a memory address in a strategy's repr is left out of it."""

from __future__ import annotations

from pytest_n2r import Transform
from pytest_n2r.relation import Relation, RunSettings, check_relation
from pytest_n2r.relation.search import run_identity
from pytest_n2r.strategies import transforms
from tests.plugin.fakemetrics import AbsDifference
from tests.plugin.fakescene import PlaneScene


class Halve:
    """A callable object without a repr of its own: ``repr`` shows its memory address."""

    def __call__(self, tau: Transform) -> Transform:
        return Transform(yaw=tau.yaw / 2)


def _relation(examples: int = 8) -> Relation:
    return Relation.build(AbsDifference(), 255, transforms(yaw=4).map(Halve()), examples=examples)


def test_the_identity_leaves_out_memory_addresses():
    scene = PlaneScene()
    first, second = _relation(), _relation()
    assert " at 0x" in repr(first.transform), "the test needs a repr with a memory address"
    one, two = run_identity("t", scene, first), run_identity("t", scene, second)
    assert one == two, f"the run's identity holds a memory address, so it changes between processes: {one!r}"
    assert b" at 0x" not in one and b"Halve object" in one, one


def test_a_derandomized_run_draws_the_same_examples_with_another_instance_of_a_mapped_object():
    scene, settings = PlaneScene(), RunSettings(derandomize=True, database=None)
    relations = [_relation(), _relation()]  # both alive: their mapped objects sit at different addresses
    runs = [check_relation(scene, lambda rgb: 0.0, r, settings=settings, test_id="t") for r in relations]
    drawn = [[(e.view, e.transform) for e in run.examples] for run in runs]
    assert drawn[0] == drawn[1], ("a derandomized run drew other examples when the mapped object sat at another "
                                  f"address: {drawn[0][:3]} vs {drawn[1][:3]}")
