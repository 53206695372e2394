"""The SUT's outputs shared between relations: one call per SUT object and render, never across SUT objects,
never for a mutated image that changed a pixel, forgotten with the SUT."""

from __future__ import annotations

import gc
from dataclasses import dataclass, replace

import numpy as np
import pytest
from hypothesis import strategies as st

from pytest_n2r.relation import Relation, RelationFailure, RunSettings, check_relation
from pytest_n2r.relation.determinism import SUTNotDeterministic
from pytest_n2r.relation.sut_outputs import MISSING, SUTOutputs, output_bytes
from pytest_n2r.strategies import brightness, transforms
from pytest_n2r.strategies.pose_change import PoseChange
from tests.plugin.fakemetrics import AbsDifference
from tests.plugin.fakescene import PlaneScene, decode_ramp_x
from tests.relation.test_engine import _Invert

SETTINGS = RunSettings(examples=12, database=None, derandomize=True)


class CountingSUT:
    """The ramp's x coordinate at one pixel, counting its calls."""

    def __init__(self) -> None:
        self.calls = 0

    def __call__(self, rgb):
        self.calls += 1
        return float(decode_ramp_x(rgb)[36, 48])


def _verdicts(record):
    return [(e.view, e.status, e.deviation) for e in record.examples]


def test_relations_running_one_sut_share_its_outputs_and_keep_their_verdicts():
    scene = PlaneScene(texture="ramp")
    first = Relation.build(AbsDifference(), 255, transforms(yaw=5), examples=12)
    second = Relation.build(AbsDifference(), 255, transforms(yaw=8), examples=12)
    alone = [check_relation(scene, CountingSUT(), r, settings=SETTINGS, test_id=f"t{i}")
             for i, r in enumerate((first, second))]
    shared, sut = SUTOutputs(), CountingSUT()
    together = [check_relation(scene, sut, r, settings=SETTINGS, test_id=f"t{i}", sut_outputs=shared)
                for i, r in enumerate((first, second))]
    assert [_verdicts(r) for r in together] == [_verdicts(r) for r in alone]
    # the second relation draws from the same source views: their outputs come from the first one's calls
    assert together[1].sut_shared > alone[1].sut_shared
    assert sut.calls == sum(r.sut_calls for r in together) < sum(r.sut_calls for r in alone)


def test_another_sut_object_is_called_itself():
    scene = PlaneScene(texture="ramp")
    relation = Relation.build(AbsDifference(), 255, transforms(yaw=5), examples=12)
    shared, a, b = SUTOutputs(), CountingSUT(), CountingSUT()
    check_relation(scene, a, relation, settings=SETTINGS, sut_outputs=shared)
    check_relation(scene, b, relation, settings=SETTINGS, sut_outputs=shared)
    assert a.calls == b.calls > 0, "an equal SUT of another object shares nothing"


def test_a_mutated_image_always_runs_the_sut():
    scene = PlaneScene(texture="ramp")
    relation = Relation.build(AbsDifference(), 300, st.just(_Invert()), examples=5)
    shared, sut = SUTOutputs(), CountingSUT()
    record = check_relation(scene, sut, relation, settings=SETTINGS, sut_outputs=shared)
    again = check_relation(scene, sut, relation, settings=SETTINGS, sut_outputs=shared, test_id="again")
    accepted = len(record.valid_examples)
    views = len({e.view for e in record.examples})
    assert record.sut_calls == accepted + views, "the sources once each, every mutated follow-up"
    # the sources shared but the first, called again to check the SUT object still gives what it left
    assert again.sut_calls == accepted + 1 and again.sut_shared == accepted - 1, "the sources shared, mutations called"


class _Keep(_Invert):
    """A mutation that changes no pixel (as a patch of size zero does), copying the image."""

    name = "keep"

    def _apply(self, rgb):
        return rgb.copy()

    def describe(self):
        return "keep()"


def test_a_follow_up_with_its_sources_pixels_is_no_test_and_costs_no_sut_call():
    scene = PlaneScene(texture="ramp")
    relation = Relation.build(AbsDifference(), 300, st.just(_Keep()), examples=5)
    sut = CountingSUT()
    with pytest.raises(RelationFailure, match="nothing was tested") as info:
        check_relation(scene, sut, relation, settings=SETTINGS)
    record = info.value.record
    assert sut.calls == record.sut_calls == 0, "a pair of one image needs no SUT output"
    assert not record.valid_examples and record.undefined == len(record.examples) > 0, record.summary_line()


def test_outputs_are_forgotten_with_their_sut_and_capped():
    shared = SUTOutputs(max_outputs=3)

    def sut(rgb):
        return 0

    for key in "abcd":
        shared.put(sut, key, key.upper())
    assert len(shared) == 3 and shared.get(sut, "a") is MISSING and shared.get(sut, "d") == "D"
    del sut
    gc.collect()
    assert len(shared) == 0
    shared.put(len, "k", 1)  # a built-in takes no weak reference: held, and still told apart by identity
    assert shared.get(len, "k") == 1 and shared.get(abs, "k") is MISSING


def test_a_replay_reuses_the_outputs_of_the_run_it_replays():
    """A regression gate's replay (the session's outputs passed on) runs the SUT on no render the relation
    already ran it on but one (the check that the SUT object still gives the outputs it left), and gives the same
    deviations as a replay that calls it on every render."""
    from pytest_n2r.relation import replay_relation

    scene = PlaneScene(texture="ramp")
    relation = Relation.build(AbsDifference(), 255, transforms(yaw=5), examples=12)
    shared, sut = SUTOutputs(), CountingSUT()
    run = check_relation(scene, sut, relation, settings=SETTINGS, sut_outputs=shared)
    calls = sut.calls
    replayed = replay_relation(scene, sut, relation, run.valid_examples, sut_outputs=shared)
    assert sut.calls == calls + 1 and replayed.sut_calls == 1, f"{sut.calls - calls} SUT calls on renders it had run on"
    alone = replay_relation(scene, CountingSUT(), relation, run.valid_examples)
    assert [e.deviation for e in replayed.replayed] == [e.deviation for e in alone.replayed]
    assert alone.sut_calls > 0


class CountingDifference(AbsDifference):
    """``AbsDifference`` counting its computations."""

    def __init__(self) -> None:
        self.computed = 0

    def compute(self, out_source, out_follow, source, follow):
        self.computed += 1
        return super().compute(out_source, out_follow, source, follow)


def test_a_replay_of_evaluated_examples_reuses_the_metric_results_of_the_same_objects():
    from pytest_n2r.relation import replay_relation
    from pytest_n2r.report import replay_candidates

    scene = PlaneScene(texture="ramp")
    metric, sut, shared = CountingDifference(), CountingSUT(), SUTOutputs()
    relation = Relation.build(metric, 255, transforms(yaw=5), examples=12)
    record = check_relation(scene, sut, relation, settings=SETTINGS, sut_outputs=shared)
    computed, calls = metric.computed, sut.calls
    examples = replay_candidates(record)
    replayed = replay_relation(scene, sut, relation, examples, settings=SETTINGS, sut_outputs=shared)
    assert [e.deviation for e in replayed.replayed] == [e.deviation for e in examples]
    assert (metric.computed, sut.calls) == (computed, calls + 1), (
        "the same objects on the same renders: nothing again but the check of the first kept output")
    pairs = len({(e.view, tuple(sorted(e.transform.items()))) for e in examples})  # a pair drawn twice: once
    other = CountingDifference()
    again = replay_relation(scene, sut, Relation.build(other, 255, transforms(yaw=5)), examples, settings=SETTINGS,
                            sut_outputs=shared)
    assert other.computed == pairs, "another metric object computes its own results"
    assert [e.deviation for e in again.replayed] == [e.deviation for e in examples]
    fresh = CountingSUT()
    replay_relation(scene, fresh, relation, examples, settings=SETTINGS, sut_outputs=shared)
    assert fresh.calls > 0 and metric.computed == computed + pairs, "another SUT object: computed anew"


def test_a_kept_result_is_only_returned_for_its_own_metric_object():
    shared = SUTOutputs()

    def sut(rgb):
        return 0

    first, second = AbsDifference(), AbsDifference()
    shared.put_result(sut, first, "s", "f", "result")
    assert shared.result(sut, first, "s", "f") == "result"
    assert shared.result(sut, second, "s", "f") is MISSING
    assert shared.result(sut, first, "f", "s") is MISSING


def test_a_replay_reuses_the_validity_verdicts_of_the_same_renders(monkeypatch):
    from pytest_n2r.relation import replay_relation
    from pytest_n2r.relation.validity import Validity
    from pytest_n2r.report import replay_candidates

    checks = []
    check = Validity.check
    monkeypatch.setattr(Validity, "check", lambda self, *a, **k: checks.append(a) or check(self, *a, **k))
    scene, sut, shared = PlaneScene(texture="ramp"), CountingSUT(), SUTOutputs()
    relation = Relation.build(AbsDifference(), 255, transforms(yaw=30, x=0.5), examples=12)
    record = check_relation(scene, sut, relation, settings=SETTINGS, sut_outputs=shared)
    checked, examples = len(checks), replay_candidates(record)
    replayed = replay_relation(scene, sut, relation, examples, settings=SETTINGS, sut_outputs=shared)
    assert len(checks) == checked > 0, "the same two renders under the same thresholds were judged again"
    alone = replay_relation(scene, sut, relation, examples, settings=SETTINGS)
    assert len(checks) > checked, "a replay without the session's kept verdicts judges its follow-ups"
    assert [(e.status, e.reason) for e in replayed.replayed] == [(e.status, e.reason) for e in alone.replayed]


class Reconfigurable:
    """One detector object that tests reconfigure: ``flip`` scales every output tenfold."""

    def __init__(self) -> None:
        self.flip = False

    def __call__(self, rgb):
        x = float(decode_ramp_x(rgb)[36, 48])
        return 10 * x if self.flip else x


@pytest.mark.parametrize("order", [(False, True), (True, False)], ids=["plain-then-flipped", "flipped-then-plain"])
def test_a_sut_object_reconfigured_between_tests_is_judged_by_its_own_outputs(order):
    """A session fixture's detector reconfigured by a parametrized test kept its identity: the second test was
    handed the first configuration's outputs (a false pass of a broken configuration, or a correct one failing
    "not deterministic"). Each verdict must be the one the test gets alone."""
    scene = PlaneScene(texture="ramp")
    relation = Relation.build(AbsDifference(), 0.3, transforms(yaw=5), examples=8)

    def run(flip, shared):
        sut = shared_sut if shared is not None else Reconfigurable()
        sut.flip = flip
        try:
            return _verdicts(check_relation(scene, sut, relation, settings=SETTINGS, test_id=f"t{flip}",
                                            sut_outputs=shared))
        except (RelationFailure, SUTNotDeterministic) as exc:
            return type(exc).__name__

    shared_sut, shared = Reconfigurable(), SUTOutputs()
    together = [run(flip, shared) for flip in order]
    alone = [run(flip, None) for flip in order]
    assert together == alone, f"with outputs shared: {together}; each alone: {alone}"


def test_a_byte_budget_drops_the_least_recently_used_outputs():
    """An image output (an enhancer's, for ``ssim_metric()``) is MiBs: under the count cap alone a session kept
    gigabytes of them."""
    shared = SUTOutputs(max_bytes=8 * 2**20)

    def sut(rgb):
        return rgb

    image = 2**20  # bytes of each output: 1 MiB, within the share one output may take
    for key in "abcdefghij":
        shared.put(sut, key, np.zeros(image, np.uint8))
        shared.get(sut, "a")  # used again: the last to go
        assert shared.bytes <= shared.max_bytes
    kept = [key for key in "abcdefghij" if shared.get(sut, key) is not MISSING]
    assert kept == ["a", "d", "e", "f", "g", "h", "i", "j"] and shared.bytes == 8 * image, (kept, shared.bytes)
    shared.put(sut, "j", np.zeros(image // 2, np.uint8))  # put again under its key: the older bytes leave
    assert shared.bytes == 7 * image + image // 2
    shared.forget(sut)
    assert len(shared) == 0 and shared.bytes == 0
    shared.put(sut, "a", np.zeros(image, np.uint8))
    del sut  # forgotten with the SUT object: its bytes too
    gc.collect()
    assert len(shared) == 0 and shared.bytes == 0


def test_an_output_over_its_share_of_the_budget_is_not_kept_and_a_view_counts_its_array():
    shared = SUTOutputs(max_bytes=8 * 2**20)

    def sut(rgb):
        return rgb

    shared.put(sut, "small", np.zeros(100, np.float32))
    shared.put(sut, "large", np.zeros(2**20 + 1, np.uint8))  # over an eighth of the budget
    shared.put(sut, "view", np.zeros(2 * 2**20, np.uint8)[:10])  # holds its whole array
    assert shared.get(sut, "large") is MISSING and shared.get(sut, "view") is MISSING
    assert shared.get(sut, "small") is not MISSING and shared.bytes == output_bytes(np.zeros(100, np.float32))


def test_a_pil_image_output_counts_its_pixels():
    """An image SUT may return PIL images (the image metrics take them): measured as an object they were 360 bytes
    whatever their size, and escaped the byte budget."""
    from PIL import Image

    assert output_bytes(Image.new("RGB", (640, 480))) == 640 * 480 * 3
    assert output_bytes(Image.new("I;16", (64, 48))) == 64 * 48 * 2
    assert output_bytes(Image.new("F", (100, 100))) == 100 * 100 * 4, "a float image counted a byte a pixel"


def test_a_tensor_that_requires_grad_past_the_items_measured_is_detached_too():
    """A container is measured by its first items: a grad tensor after 40 plain ones was kept with its graph."""
    torch = pytest.importorskip("torch")
    weights = torch.ones(50, 50, requires_grad=True)
    shared = SUTOutputs()

    def sut(rgb):
        return rgb

    for output in ([torch.zeros(2)] * 40 + [(weights * 2).sum(0)],
                   {**{f"f{k}": torch.zeros(2) for k in range(20)}, "logits": (weights * 2).sum(0)}):
        shared.put(sut, "k", output)
        kept = shared.get(sut, "k")
        last = kept[-1] if isinstance(kept, list) else kept["logits"]
        assert last.grad_fn is None and not last.requires_grad, "a tensor past the measured items kept its graph"


def test_a_tensor_is_kept_detached_from_its_autograd_graph():
    """A classifier called without ``torch.no_grad``: its logits' graph holds every activation (74 MiB for a
    MobileNetV2), which the kept output kept alive."""
    torch = pytest.importorskip("torch")
    weight = torch.ones(3, requires_grad=True)
    logits = weight * torch.arange(3.0)
    shared = SUTOutputs()

    def sut(rgb):
        return logits

    shared.put(sut, "k", logits)
    shared.put(sut, "pair", (logits, {"scores": [logits]}))
    kept, (first, nested) = shared.get(sut, "k"), shared.get(sut, "pair")
    for tensor in (kept, first, nested["scores"][0]):
        assert tensor.grad_fn is None and not tensor.requires_grad and torch.equal(tensor, logits)
    assert logits.grad_fn is not None, "the SUT's own output is left as it was"
    assert shared.bytes == output_bytes(kept) + output_bytes(shared.get(sut, "pair")) > 0


def test_the_outputs_module_does_not_import_torch():
    import subprocess
    import sys

    code = ("import sys, numpy as np; from pytest_n2r.relation.sut_outputs import SUTOutputs; s = SUTOutputs(); "
            "s.put(len, 'k', [np.zeros(3), {'a': (1, 2.0)}]); assert s.bytes > 0; assert 'torch' not in sys.modules")
    subprocess.run([sys.executable, "-c", code], check=True)


def test_every_mutation_of_one_source_view_computes_its_own_metric_result():
    """Guards against keying a mutation's metric result by its source render alone (``follow_key or source_key``):
    every mutation of one view then shared one result in the session, so a noise_patch relation reported the
    first mutation's deviation for the later ones of the same view (.05 .1 .1 .05 .05, not .05 .1 .2 .175 .375)."""
    scene = PlaneScene(texture="ramp", n_views=2)
    metric, sut = CountingDifference(), CountingSUT()
    relation = Relation.build(metric, 300, brightness(max_levels=100), examples=10)
    record = check_relation(scene, sut, relation, settings=SETTINGS)
    accepted = record.valid_examples
    views = {e.view for e in accepted}
    pairs = {(e.view, tuple(sorted(e.mutation.items()))) for e in accepted}
    assert len(accepted) >= 8 and len(views) <= 2 < len(pairs), "the test needs several mutations of a view"
    assert metric.computed == len(pairs), (
        f"{metric.computed} metric results computed for {len(pairs)} different mutations: a result was reused "
        "for another mutation of the same view")
    deviations = {e.deviation for e in accepted}
    assert len(deviations) > len(views), f"mutations of {len(views)} views gave only deviations {sorted(deviations)}"


@dataclass(frozen=True, repr=False)
class _Painted(PoseChange):
    """A user's follow-up that renders the moved pose and then changes the picture (inverts it)."""

    def follow_view(self, source, scene, render):
        view = render(self.apply(source.c2w, scene.length_scale(self.units)))
        return replace(view, rgb=255 - view.rgb)


def test_a_follow_up_that_changes_its_render_runs_the_sut_on_its_own_picture():
    """Guards against keying the SUT output of a follow-up by the last render its follow_view made even when it
    returned another picture: a follow-up that renders and then adds noise was given the clean render's output."""
    scene = PlaneScene(texture="ramp")
    painted = transforms(yaw=5).map(lambda tau: _Painted.of(tau, tau.units))
    relation = Relation.build(AbsDifference(), 300, painted, examples=6)
    shared, sut = SUTOutputs(), CountingSUT()
    record = check_relation(scene, sut, relation, settings=SETTINGS, sut_outputs=shared)
    again = check_relation(scene, sut, relation, settings=SETTINGS, sut_outputs=shared)
    accepted = len(again.valid_examples)
    assert accepted > 0 and [e.transform for e in again.examples] == [e.transform for e in record.examples], (
        "the test needs the same follow-ups drawn again")
    assert again.sut_calls >= accepted, (
        f"{again.sut_calls} SUT calls for {accepted} changed follow-ups: the output on the clean render was reused")
    assert [e.deviation for e in again.valid_examples] == [e.deviation for e in record.valid_examples], (
        "another run of the same draws gave other deviations")


def test_a_kept_result_is_only_returned_for_its_own_source_render():
    """Guards against a metric result keyed by its follow-up render alone: the result of another source view's
    pair with the same follow-up was returned."""
    shared = SUTOutputs()

    def sut(rgb):
        return 0

    metric = AbsDifference()
    shared.put_result(sut, metric, "s", "f", "result")
    assert shared.result(sut, metric, "other source", "f") is MISSING, "the result of another source render returned"
