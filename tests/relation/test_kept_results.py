"""A keypoint metric's results kept in the render cache: a second session takes them instead of computing them,
only for the same metric, outputs and renders, and the records are the same."""

from __future__ import annotations

import json
import math

import cv2
import numpy as np
from hypothesis import strategies as st

from pytest_n2r.demo import load_demo
from pytest_n2r.metrics import repeatability
from pytest_n2r.metrics.base import MetricResult
from pytest_n2r.metrics.keypoints import Repeatability
from pytest_n2r.relation import Relation, RunSettings, check_relation
from pytest_n2r.relation.failure import SAME_PIXELS
from pytest_n2r.relation.floor import compare_exact
from pytest_n2r.relation.kept_results import output_digest, result_from_dict, result_key, result_to_dict
from pytest_n2r.render.size import RenderSize
from pytest_n2r.scene.render_cache import RenderCache
from pytest_n2r.strategies import brightness, noise_patch, transforms
from pytest_n2r.study import resolve_sut
from tests.plugin.fakescene import PlaneScene

SETTINGS = RunSettings(derandomize=True, database=None)


def corners(rgb: np.ndarray) -> np.ndarray:
    """A deterministic detector: the checkerboard's strongest corners, ``(N, 2)`` float32."""
    found = cv2.goodFeaturesToTrack(cv2.cvtColor(rgb, cv2.COLOR_RGB2GRAY), 40, 0.01, 3)
    return np.zeros((0, 2), np.float32) if found is None else found.reshape(-1, 2).astype(np.float32)


def _records(record):
    return [(e.view, e.status, e.reason, e.score, e.deviation) for e in record.examples]


def _counting(monkeypatch) -> list[int]:
    computed: list[int] = []
    original = Repeatability.compute
    monkeypatch.setattr(Repeatability, "compute", lambda self, *a: computed.append(1) or original(self, *a))
    return computed


def _second_session_computes_nothing(scene, relation, tmp_path, computed: list) -> None:
    """Check ``relation`` in two sessions sharing one render cache: the second computes no keypoint metric and
    gives the first one's records."""
    first = check_relation(scene, corners, relation, settings=SETTINGS, cache=RenderCache(tmp_path))
    assert computed and first.valid_examples, "the test needs evaluated examples"
    computed.clear()
    again = check_relation(scene, corners, relation, settings=SETTINGS, cache=RenderCache(tmp_path))
    assert computed == [] and _records(again) == _records(first)


def test_a_second_session_takes_the_keypoint_metrics_results_from_the_render_cache(tmp_path, monkeypatch):
    relation = Relation.build(repeatability(px=2), 0.9, transforms(yaw=3, x=0.05), examples=12)
    _second_session_computes_nothing(PlaneScene(), relation, tmp_path, _counting(monkeypatch))


def test_a_mutations_results_are_kept_under_its_source_render_and_its_pixels(tmp_path, monkeypatch):
    scene = PlaneScene()
    relation = Relation.build(repeatability(px=2), 0.9, brightness(max_levels=40), examples=10)
    computed = _counting(monkeypatch)
    _second_session_computes_nothing(scene, relation, tmp_path, computed)
    other = Relation.build(repeatability(px=2), 0.9, noise_patch(max_size=0.3, min_size=0.1), examples=5)
    check_relation(scene, corners, other, settings=SETTINGS, cache=RenderCache(tmp_path))
    assert computed, "other pixels: computed"


def test_other_outputs_or_another_metric_are_computed_again(tmp_path, monkeypatch):
    scene = PlaneScene()
    relation = Relation.build(repeatability(px=2), 0.9, transforms(yaw=3, x=0.05), examples=8)
    check_relation(scene, corners, relation, settings=SETTINGS, cache=RenderCache(tmp_path))
    computed = _counting(monkeypatch)
    shifted = check_relation(scene, lambda rgb: corners(rgb) + np.float32(0.5), relation, settings=SETTINGS,
                             cache=RenderCache(tmp_path))
    unchanged = sum(e.reason == SAME_PIXELS for e in shifted.examples)  # a pair of one image: nothing to compute
    assert len(computed) == len(shifted.examples) - shifted.rejected - unchanged > 0, (
        "new outputs: every result computed")
    computed.clear()
    wider = Relation.build(repeatability(px=3), 0.9, transforms(yaw=3, x=0.05), examples=8)
    check_relation(scene, corners, wider, settings=SETTINGS, cache=RenderCache(tmp_path))
    assert computed, "another tolerance is another metric"


def test_only_the_class_that_declares_a_result_version_is_kept():
    class Mine(Repeatability):  # a user's subclass may compute anything: never kept under its parent's version
        pass

    points = np.zeros((3, 2), np.float32)
    assert result_key(repeatability(), "a", "b", points, points) is not None
    assert result_key(Mine(), "a", "b", points, points) is None
    assert result_key(repeatability(), "a", "b", points, [cv2.KeyPoint(1, 2, 3)]) is not None, (
        "keypoint objects are named exactly: their result is kept")
    assert result_key(repeatability(), "a", "b", points, [object()]) is None
    assert result_key(repeatability(), "a", "b", points, points) != result_key(repeatability(), "a", "c", points,
                                                                              points)


def test_output_digests_name_values_types_and_shapes_exactly():
    a = np.arange(6, dtype=np.float32).reshape(3, 2)
    same = [a, a.copy(), np.asfortranarray(a)]
    assert len({output_digest(x) for x in same}) == 1
    others = [a.reshape(2, 3), a.astype(np.float64), a + np.float32(1e-6), a[:2], a.tolist(), tuple(a.tolist())]
    assert len({output_digest(x) for x in [a, *others]}) == 1 + len(others)
    assert output_digest({"points": a, "n": 3}) == output_digest({"n": 3, "points": a.copy()})
    assert output_digest(np.array([object()])) is None and output_digest({1: a}) is None


def test_keypoint_objects_are_named_by_every_field_wherever_they_sit():
    import cv2

    base = cv2.KeyPoint(1.5, 2.0, 7.0, 10.0, 0.25, 1, -1)
    fields = {"x": 1.5, "y": 2.0, "size": 7.0, "angle": 10.0, "response": 0.25, "octave": 1, "class_id": -1}
    edits = [dict(fields, **{name: value}) for name, value in
             [("x", 1.5000001), ("y", 3.0), ("size", 8.0), ("angle", 11.0), ("response", 0.5), ("octave", 2),
              ("class_id", 4)]]
    digests = {output_digest(([cv2.KeyPoint(**f)], np.zeros((1, 32), np.uint8))) for f in [fields, *edits]}
    assert len(digests) == 1 + len(edits) and None not in digests, "a keypoint field is missing from the digest"
    assert output_digest({"points": [base]}) == output_digest({"points": [cv2.KeyPoint(**fields)]})


def test_tensors_are_named_by_dtype_shape_and_values():
    import torch

    t = torch.arange(6, dtype=torch.float32).reshape(3, 2)
    assert output_digest(t) == output_digest(t.clone().requires_grad_()) == output_digest((t.T.contiguous().T,)[0])
    others = [t.double(), t.reshape(2, 3), t + 1e-6, t.numpy(), [t]]
    assert len({output_digest(x) for x in [t, *others]}) == 1 + len(others), "a tensor was confused with another"
    half = t.to(torch.bfloat16)
    assert output_digest(half) not in (None, output_digest(t)), "bfloat16: named by its values and its own dtype"
    assert output_digest(half) == output_digest(half.clone())


def test_a_class_of_ones_own_named_keypoint_is_not_named_by_six_fields():
    """Any class named KeyPoint with cv2's six fields was digested by those alone: a field of its own (here a
    descriptor) could differ under one digest, and a floor or kept result be reused for another output."""
    from dataclasses import dataclass

    @dataclass
    class KeyPoint:
        pt: tuple
        size: float = 1.0
        angle: float = 0.0
        response: float = 0.0
        octave: int = 0
        class_id: int = -1
        descriptor: bytes = b""

    assert output_digest([KeyPoint((1.0, 2.0), descriptor=b"a")]) is None


def test_a_kept_result_reads_back_exactly():
    results = [MetricResult("repeatability", 0.1 + 0.2, 1 - (0.1 + 0.2), {"n_source": 3, "coverage": 0.917}),
               MetricResult.undefined("repeatability", "nothing to compare", n_source=0, n_follow=0)]
    for result in results:
        back = result_from_dict(json.loads(json.dumps(result_to_dict(result), sort_keys=True)))
        assert (back.metric, back.valid, back.details) == (result.metric, result.valid, result.details)
        for x, y in ((back.score, result.score), (back.deviation, result.deviation)):
            assert x == y or (math.isnan(x) and math.isnan(y)), (x, y)
    assert result_to_dict(MetricResult("m", 1.0, 0.0, {"points": np.zeros(2)})) is None, "not plain: not kept"


def test_the_exact_replay_of_a_fitted_demo_scene_takes_the_kept_results(tmp_path, monkeypatch):
    scene, camera_of = load_demo("wall-field", "cpu"), lambda v: RenderSize.parse(160).apply(v.camera)
    orb = resolve_sut("orb", None).fn
    relation = Relation.build(repeatability(px=2), 0.9, transforms(yaw=2), examples=4, size="160")
    records = check_relation(scene, orb, relation, settings=SETTINGS).examples
    first = compare_exact(scene, orb, repeatability(px=2), records, camera_of, cache=RenderCache(tmp_path))
    assert first is not None and first.pairs, "the test needs replayed pairs"
    computed = _counting(monkeypatch)
    again = compare_exact(scene, orb, repeatability(px=2), records, camera_of, cache=RenderCache(tmp_path))
    assert computed == [] and again == first


def test_a_mutation_relation_is_replayed_on_the_exact_twin_too(tmp_path, monkeypatch):
    """Mutations were skipped as 'not replayable' (the line read 'exact vs fitted: no example replayed, not
    replayable 2'), though the exact source render mutated the same way is exactly their replay."""
    from pytest_n2r.strategies import Brightness

    scene, camera_of = load_demo("wall-field", "cpu"), lambda v: RenderSize.parse(160).apply(v.camera)
    orb = resolve_sut("orb", None).fn
    relation = Relation.build(repeatability(px=2), 0.9, st.integers(20, 60).map(Brightness), examples=3, size="160")
    records = check_relation(scene, orb, relation, settings=SETTINGS).examples
    first = compare_exact(scene, orb, repeatability(px=2), records, camera_of, cache=RenderCache(tmp_path))
    assert first is not None and first.n == len([r for r in records if r.valid]) and first.skipped == 0, first
    assert "same poses on exact renders" in first.describe(), first.describe()
    computed = _counting(monkeypatch)
    again = compare_exact(scene, orb, repeatability(px=2), records, camera_of, cache=RenderCache(tmp_path))
    assert computed == [] and again == first, "the mutated exact renders' results were not kept"


def test_a_result_key_names_the_follow_up_output():
    """Guards against a result key without the follow-up output's digest: a SUT change that altered only the
    follow-up outputs was handed the old session's result from the render cache."""
    points = np.zeros((3, 2), np.float32)
    moved = points + np.float32(1)
    assert result_key(repeatability(), "a", "b", points, points) != result_key(repeatability(), "a", "b", points,
                                                                              moved), (
        "other follow-up outputs, same result key")


def test_a_result_key_names_the_metrics_parameters():
    """Guards against a result key without the metric's repr: repeatability(px=3) was given px=2's results."""
    points = np.zeros((3, 2), np.float32)
    assert result_key(repeatability(px=2), "a", "b", points, points) != result_key(repeatability(px=3), "a", "b",
                                                                                  points, points), (
        "another tolerance, same result key")


def test_a_result_key_names_the_source_render():
    """Guards against a result key without the source render's key: a pair with another source view but the same
    follow-up render and outputs was given the other pair's result."""
    points = np.zeros((3, 2), np.float32)
    assert result_key(repeatability(), "c", "b", points, points) != result_key(repeatability(), "a", "b", points,
                                                                              points), (
        "another source render, same result key")


def test_a_result_key_names_the_numpy_version(monkeypatch):
    """Guards against a result key without NumPy's version: a kept keypoint-metric result was reused after a NumPy
    upgrade, whose arithmetic may give another result."""
    from pytest_n2r.relation import kept_results

    points = np.zeros((3, 2), np.float32)
    before = result_key(repeatability(), "a", "b", points, points)
    monkeypatch.setattr(kept_results.np, "__version__", "0.0.1-not-this-numpy")
    after = result_key(repeatability(), "a", "b", points, points)
    assert before is not None and after is not None, "the test needs kept results"
    assert before != after, "another NumPy version, same result key"


def test_an_arrays_dtype_is_named_by_its_digest_and_its_kept_result(tmp_path):
    """Guards against a digest without the array's dtype: int8 and uint8 SUT outputs with the same bytes had one
    digest, so a result kept for one was handed to the other."""
    from pytest_n2r.relation.kept_results import kept_result

    signed, unsigned = np.array([1, 2], np.int8), np.array([1, 2], np.uint8)
    assert signed.tobytes() == unsigned.tobytes(), "the test needs the same bytes"
    assert output_digest(signed) != output_digest(unsigned), "int8 and uint8 outputs with the same bytes, one digest"
    cache = RenderCache(tmp_path)
    first = MetricResult("repeatability", 0.25, 0.75, {})
    kept = kept_result(cache, repeatability(), "a", "b", signed, signed, lambda: first)
    assert kept is first, "the first session computes"
    other = MetricResult("repeatability", 0.5, 0.5, {})
    got = kept_result(RenderCache(tmp_path), repeatability(), "a", "b", unsigned, unsigned, lambda: other)
    assert got is other, f"the int8 outputs' kept result {got} was returned for uint8 outputs"


def test_a_follow_up_with_another_camera_pose_or_depth_has_no_repainted_key():
    """Guards against repainted_key without its guard: a follow-up rendered from another camera, pose or depth
    was keyed as the source render repainted, and so given the source's kept results."""
    from pytest_n2r.geometry import Camera
    from pytest_n2r.relation.kept_results import repainted_key
    from pytest_n2r.render.view import RenderedView

    camera = Camera(2, 1, 1, 1, 0.5, 0)
    rgb = np.zeros((1, 2, 3), np.uint8)
    source = RenderedView(camera, np.eye(4), rgb=rgb)
    assert repainted_key(source, "k", RenderedView(camera, np.eye(4), rgb=rgb + 1)) is not None, (
        "the test needs a repainted follow-up to have a key")
    moved = np.eye(4)
    moved[0, 3] = 0.5
    others = {"camera": RenderedView(Camera(2, 1, 2, 2, 0.5, 0), np.eye(4), rgb=rgb + 1),
              "pose": RenderedView(camera, moved, rgb=rgb + 1),
              "depth": RenderedView(camera, np.eye(4), rgb=rgb + 1, depth=np.ones((1, 2), np.float32))}
    for what, follow in others.items():
        assert repainted_key(source, "k", follow) is None, f"a follow-up with another {what} got a repainted key"


def test_a_valid_kept_result_with_a_nan_deviation_is_refused(tmp_path):
    """Guards against result_from_dict without its finiteness check: a planted or corrupted 'valid' result with a
    NaN deviation was read back and handed to the engine as a passing/failing test."""
    from pytest_n2r.relation.kept_results import kept_result

    planted = {"metric": "repeatability", "score": math.nan, "deviation": math.nan, "details": {}, "valid": True}
    try:
        back = result_from_dict(json.loads(json.dumps(planted)))
    except ValueError:
        back = None
    assert back is None, f"a valid kept result with a NaN deviation was accepted: {back}"
    points = np.zeros((3, 2), np.float32)
    cache = RenderCache(tmp_path)
    cache.put_decision(result_key(repeatability(), "a", "b", points, points), planted)
    fresh = MetricResult("repeatability", 0.25, 0.75, {})
    got = kept_result(RenderCache(tmp_path), repeatability(), "a", "b", points, points, lambda: fresh)
    assert got is fresh, f"the planted NaN 'valid' result was taken from the cache: {got}"
