"""Classifier metrics: properties over random probability vectors and logits, and every bad output."""

from __future__ import annotations

import math

import hypothesis.strategies as st
import numpy as np
import pytest
import torch
from hypothesis import given, settings
from hypothesis.extra.numpy import arrays

from pytest_n2r.errors import InvalidArgument, InvalidType, SUTOutputError
from pytest_n2r.metrics.classification import (
    class_invariance,
    cosine_similarity,
    is_probability_vector,
    l2_norm,
    softmax,
)

logits = st.integers(2, 12).flatmap(
    lambda n: arrays(np.float64, n, elements=st.floats(-30, 30)))
logit_pairs = st.integers(2, 12).flatmap(
    lambda n: st.tuples(*[arrays(np.float64, n, elements=st.floats(-30, 30))] * 2))
probability_pairs = logit_pairs.map(lambda ab: (softmax(ab[0]), softmax(ab[1])))
ALL = [cosine_similarity(), l2_norm(), class_invariance(), class_invariance(top_k=2)]


@settings(max_examples=50)
@given(v=logits, as_probabilities=st.booleans())
def test_identical_outputs_score_the_ideal(v, as_probabilities):
    v = softmax(v) if as_probabilities else v
    for metric in ALL:
        result = metric(v, v.copy())
        assert result.score == pytest.approx(metric.ideal, abs=1e-12) and result.deviation < 1e-12, (metric, result)


@settings(max_examples=50)
@given(pair=st.one_of(probability_pairs, logit_pairs))
def test_scores_stay_in_range_and_symmetric_metrics_are_symmetric(pair):
    a, b = pair
    cos, l2 = cosine_similarity()(a, b), l2_norm()(a, b)
    assert 0.0 <= cos.score <= 1.0 + 1e-12, cos  # probabilities (given or softmaxed) are non-negative
    assert 0.0 <= l2.score <= math.sqrt(2) + 1e-12, l2
    assert cos.score == pytest.approx(cosine_similarity()(b, a).score, abs=1e-12)
    assert l2.score == pytest.approx(l2_norm()(b, a).score, abs=1e-12)
    assert class_invariance()(a, b).score in (0.0, 1.0)
    assert class_invariance()(a, b).score == class_invariance()(b, a).score  # top-1 equality is symmetric


@settings(max_examples=50)
@given(pair=logit_pairs, shift=st.floats(-50, 50))
def test_logits_are_read_through_a_softmax(pair, shift):
    a, b = pair
    # a softmax ignores a constant shift, so shifted logits are the same prediction
    assert l2_norm(inputs="logits")(a, a + shift).score < 1e-9
    assert l2_norm()(a, b).score == pytest.approx(np.linalg.norm(softmax(a) - softmax(b)), abs=1e-12)
    assert l2_norm()(a, b).details["inputs"] in ("logits", "probabilities")


def test_known_values():
    one_hot = np.eye(3)
    assert l2_norm()(one_hot[0], one_hot[1]).score == pytest.approx(math.sqrt(2))
    assert cosine_similarity()(one_hot[0], one_hot[1]).score == 0.0
    assert cosine_similarity(inputs="raw")([1.0, 0.0], [-1.0, 0.0]).score == -1.0
    assert cosine_similarity(inputs="raw")([3.0, 4.0], [6.0, 8.0]).score == pytest.approx(1.0)
    assert l2_norm(inputs="raw")([3.0, 4.0], [0.0, 0.0]).score == 5.0
    result = class_invariance(top_k=2)([0.1, 0.6, 0.3], [0.5, 0.1, 0.4])
    assert (result.score, result.details["source_class"], result.details["follow_classes"]) == (0.0, 1, [0, 2])


def test_auto_treats_both_sides_alike():
    probabilities = np.array([0.2, 0.8])
    logits_ = np.array([2.0, -1.0])
    assert l2_norm()(probabilities, logits_).details["inputs"] == "logits"
    assert l2_norm()(probabilities, probabilities[::-1]).details["inputs"] == "probabilities"


@pytest.mark.parametrize("empty", [[], np.zeros(0), np.full(5, np.nan), np.full((1, 3), np.nan)],
                         ids=["list", "array", "all-nan", "all-nan-batch"])
@pytest.mark.parametrize("metric", ALL, ids=repr)
def test_empty_or_all_nan_outputs_are_undefined_never_ideal(metric, empty):
    """Nothing to compare is never a perfect score: the pair is undefined, with the reason."""
    for a, b, which in ((empty, [0.5, 0.5], "source"), ([0.5, 0.5], empty, "follow-up")):
        result = metric(a, b)
        assert not result.valid and math.isnan(result.deviation), (metric, a, b, result)
        assert result.details["reason"].startswith(f"the {which} output is "), result.details
    with pytest.raises(SUTOutputError, match="contains 1 NaN"):  # a partly NaN vector is a bug, not silence
        metric([np.nan, 0.5], [0.5, 0.5])


def test_zero_vectors_in_raw_mode():
    zero = np.zeros(4)
    both_zero = cosine_similarity(inputs="raw")(zero, zero)  # the SUT said nothing twice: not agreement
    assert not both_zero.valid and "both outputs are zero vectors" in both_zero.details["reason"]
    assert cosine_similarity(inputs="raw")(zero, np.ones(4)).score == 0.0
    assert cosine_similarity(inputs="logits")(zero, zero).score == pytest.approx(1.0)  # uniform distributions
    with pytest.raises(SUTOutputError, match="source output is not a probability vector"):
        cosine_similarity(inputs="probabilities")(zero, zero)


def test_accepts_keras_batches_and_tensors():
    v = np.array([[0.1, 0.7, 0.2]], dtype=np.float32)
    t = torch.tensor([0.1, 0.7, 0.2], requires_grad=True)
    assert class_invariance()(v, t).score == 1.0
    assert l2_norm()(v, t * 1).score < 1e-7
    assert class_invariance()(t.detach().to(torch.bfloat16), v).score == 1.0


@pytest.mark.parametrize(
    ("source", "follow", "error", "match"),
    [
        ([0.5, 0.5], [0.2, 0.3, 0.5], SUTOutputError, "source output has 2 classes but follow-up output has 3"),
        ([0.5, 0.5], [np.nan, 0.5], SUTOutputError, "follow-up output contains 1 NaN values"),
        ([np.inf, 0.5], [0.5, 0.5], SUTOutputError, "source output contains 1 infinite values"),
        (None, [0.5, 0.5], SUTOutputError, "source output is None; expected a 1-D vector"),
        (np.zeros((2, 3)), [0.5, 0.5], SUTOutputError, r"source output has shape \(2, 3\); expected a 1-D vector"),
        ([0.5, 0.5], {"cat": 1}, SUTOutputError, "follow-up output of type dict is not numeric"),
        ([0.5, 0.5], np.array([0.5 + 1j, 0.5]), SUTOutputError, "follow-up output is complex"),
        ([0.5, 0.5], [[0.5], [0.5, 0.2]], SUTOutputError, "follow-up output of type list is not numeric"),
    ],
)
def test_bad_outputs_name_the_output(source, follow, error, match):
    for metric in ALL:
        with pytest.raises(error, match=match):
            metric(source, follow)
    assert issubclass(SUTOutputError, InvalidType)  # a TypeError, as callers expect of wrong types


def test_bad_arguments():
    with pytest.raises(InvalidArgument, match=r"inputs='prob'; expected one of \('auto', 'probabilities'"):
        l2_norm(inputs="prob")
    with pytest.raises(InvalidArgument, match="inputs='raw'; expected one of"):
        class_invariance(inputs="raw")
    with pytest.raises(InvalidArgument, match="top_k=0 must be >= 1"):
        class_invariance(top_k=0)
    with pytest.raises(InvalidType, match="top_k=1.5 must be an int"):
        class_invariance(top_k=1.5)
    with pytest.raises(InvalidArgument, match="top_k=5 exceeds the 3 classes"):
        class_invariance(top_k=5)([0.2, 0.3, 0.5], [0.2, 0.3, 0.5])


def test_reprs_rebuild_the_call():
    assert repr(class_invariance(top_k=3, inputs="logits")) == "class_invariance(top_k=3, inputs='logits')"
    assert repr(cosine_similarity()) == "cosine_similarity()"
    assert repr(l2_norm(inputs="raw")) == "l2_norm(inputs='raw')"


def test_probability_vector_check():
    assert is_probability_vector(np.array([0.25, 0.75]))
    assert not is_probability_vector(np.array([0.5, 0.6]))
    assert not is_probability_vector(np.array([1.5, -0.5]))


def test_assert_within_message_has_score_deviation_and_eps():
    with pytest.raises(AssertionError,
                       match=r"l2_norm\(\): score 1\.4142 deviates 1\.4142 from the ideal 0, more than eps=0\.5"):
        l2_norm().assert_within([1.0, 0.0], [0.0, 1.0], eps=0.5)


@pytest.mark.skipif(not torch.cuda.is_available(), reason="no CUDA device on this machine")
def test_accepts_cuda_tensors():
    v = torch.tensor([0.1, 0.7, 0.2], device="cuda")
    assert class_invariance()(v, v.cpu()).score == 1.0
    assert l2_norm()(v, v).score == 0.0
