"""Classifier metrics: properties over random probability vectors and logits, and every bad output."""

from __future__ import annotations

import math

import hypothesis.strategies as st
import numpy as np
import pytest
import torch
from hypothesis import assume, example, given, settings
from hypothesis.extra.numpy import arrays

from pytest_n2r.errors import InvalidArgument, InvalidType, MetricArgumentError, SUTOutputError
from pytest_n2r.metrics.classification import (
    class_invariance,
    cosine_similarity,
    is_probability_vector,
    l2_norm,
    probability_sum_tolerance,
    softmax,
)

logits = st.integers(2, 12).flatmap(
    lambda n: arrays(np.float64, n, elements=st.floats(-30, 30)))
logit_pairs = st.integers(2, 12).flatmap(
    lambda n: st.tuples(*[arrays(np.float64, n, elements=st.floats(-30, 30))] * 2))
ALL = [cosine_similarity(), l2_norm(), class_invariance(), class_invariance(top_k=2)]
LOGITS = [cosine_similarity(inputs="logits"), l2_norm(inputs="logits"), class_invariance(inputs="logits"),
          class_invariance(top_k=2, inputs="logits")]


def undefined_for_want_of_a_class(result, v) -> bool:
    """Whether ``result`` is undefined because ``v`` (the source) favours no class or ties at its top."""
    reason = result.details.get("reason", "")
    return (not result.valid) and (("is constant" in reason and v.min() == v.max())
                                   or ("tie" in reason and np.count_nonzero(v == v.max()) > 1))


@settings(max_examples=50)
@given(v=logits, as_probabilities=st.booleans())
def test_identical_outputs_score_the_ideal_unless_they_favour_no_class(v, as_probabilities):
    v = softmax(v) if as_probabilities else v
    for metric in ALL if as_probabilities else LOGITS:
        if getattr(metric, "top_k", 0) >= v.size:  # every class in the top-k: refused (test_top_k_must_be_...)
            continue
        result = metric(v, v.copy())
        if not result.valid:
            assert undefined_for_want_of_a_class(result, v), f"{metric!r} undefined for {v} without cause: {result}"
            continue
        assert result.score == pytest.approx(metric.ideal, abs=1e-12) and result.deviation < 1e-12, (metric, result)


@settings(max_examples=50)
@given(pair=logit_pairs, as_probabilities=st.booleans())
# found by a run with ten times the examples: softmaxed logits that favour different classes had a cosine of -2.2e-16
@example(pair=(np.array([17.1875, -21.0, 0.0]), np.array([-17.0, 21.0, 0.0])), as_probabilities=False)
def test_scores_stay_in_range_and_symmetric_metrics_are_symmetric(pair, as_probabilities):
    a, b = (softmax(pair[0]), softmax(pair[1])) if as_probabilities else pair
    inputs = "auto" if as_probabilities else "logits"
    cos, l2 = cosine_similarity(inputs)(a, b), l2_norm(inputs)(a, b)
    if a.min() == a.max() or b.min() == b.max():
        assert not cos.valid and not l2.valid, f"a constant output scored: {cos}, {l2}"
        return
    assert 0.0 <= cos.score <= 1.0 + 1e-12, cos  # probabilities (given or softmaxed) are non-negative
    assert 0.0 <= l2.score <= math.sqrt(2) + 1e-12, l2
    assert cos.score == pytest.approx(cosine_similarity(inputs)(b, a).score, abs=1e-12)
    assert l2.score == pytest.approx(l2_norm(inputs)(b, a).score, abs=1e-12)
    forward, backward = class_invariance(inputs=inputs)(a, b), class_invariance(inputs=inputs)(b, a)
    for result, source in ((forward, a), (backward, b)):
        assert result.valid or undefined_for_want_of_a_class(result, source) or "level with" in result.details[
            "reason"], f"class invariance undefined without a tie: {result}"
    if forward.valid and backward.valid:
        assert forward.score == backward.score in (0.0, 1.0), (forward, backward)  # top-1 equality is symmetric


@settings(max_examples=50)
@given(pair=logit_pairs, shift=st.floats(-50, 50))
def test_logits_are_read_through_a_softmax(pair, shift):
    a, b = pair
    assume(a.min() < a.max() and b.min() < b.max() and np.ptp(a + shift) > 0)
    # a softmax ignores a constant shift, so shifted logits are the same prediction
    shifted = l2_norm(inputs="logits")(a, a + shift)
    assert shifted.score < 1e-9, f"logits shifted by {shift} read as another prediction: {shifted}"
    assert l2_norm(inputs="logits")(a, b).score == pytest.approx(np.linalg.norm(softmax(a) - softmax(b)), abs=1e-12), (
        "logits were not compared through their softmax")
    rounding = a.size * np.finfo(np.float64).eps  # entries outside [0, 1] by rounding alone read as probabilities
    if np.any((a < -rounding) | (a > 1 + rounding)) and np.any((b < -rounding) | (b > 1 + rounding)):  # logits
        result = l2_norm()(a, b)
        assert result.details["inputs"] == "logits", f"auto read logits {a}, {b} as {result.details['inputs']}"
        assert result.score == l2_norm(inputs="logits")(a, b).score, "auto's logits reading differs from 'logits'"


def test_known_values():
    one_hot = np.eye(3)
    assert l2_norm()(one_hot[0], one_hot[1]).score == pytest.approx(math.sqrt(2))
    assert cosine_similarity()(one_hot[0], one_hot[1]).score == 0.0
    assert cosine_similarity(inputs="raw")([1.0, 0.0], [-1.0, 0.0]).score == -1.0
    assert cosine_similarity(inputs="raw")([3.0, 4.0], [6.0, 8.0]).score == pytest.approx(1.0)
    assert l2_norm(inputs="raw")([3.0, 4.0], [0.0, 0.0]).score == 5.0
    result = class_invariance(top_k=2)([0.1, 0.6, 0.3], [0.5, 0.1, 0.4])
    assert (result.score, result.details["source_class"], result.details["follow_classes"]) == (0.0, 1, [0, 2])


@pytest.mark.parametrize("empty", [[], np.zeros(0), np.full(5, np.nan), np.full((1, 3), np.nan), [np.nan, np.nan],
                                   [[np.nan, np.nan]], torch.full((3,), torch.nan)],
                         ids=["list", "array", "all-nan", "all-nan-batch", "all-nan-list", "all-nan-batch-list",
                              "all-nan-tensor"])
@pytest.mark.parametrize("metric", ALL, ids=repr)
def test_empty_or_all_nan_outputs_are_undefined_on_both_views_and_fail_on_one(metric, empty):
    """No answer on both views is undefined; an answer on one view only scores the worst end (as keypoints do)."""
    both = metric(empty, np.full(4, np.nan))
    assert not both.valid and math.isnan(both.deviation), f"no answer on either view was not undefined: {both}"
    assert both.details["reason"].startswith("the source output is "), both.details
    worst = {"cosine_similarity": 0.0, "l2_norm": math.sqrt(2), "class_invariance": 0.0}[metric.name]
    for a, b, which in ((empty, [0.2, 0.3, 0.5], "source"), ([0.2, 0.3, 0.5], empty, "follow-up")):
        result = metric(a, b)
        assert result.valid and result.score == worst and result.deviation == abs(worst - metric.ideal), (
            f"an answer on one view against no answer ({which}) did not score the worst end {worst}: {result}")
        assert result.details["reason"].startswith(f"the {which} output is "), result.details
        assert "answered on one view only" in result.details["reason"], result.details
    with pytest.raises(SUTOutputError, match="contains 1 NaN"):  # a partly NaN vector is a bug, not silence
        metric([np.nan, 0.5], [0.5, 0.5])


def test_an_answer_on_one_view_only_fails_raw_metrics_too():
    nan = np.full(4, np.nan)
    raw = cosine_similarity(inputs="raw")([1.0, -2.0, 0.5, 3.0], nan)
    assert (raw.valid, raw.score, raw.deviation) == (True, -1.0, 2.0), f"raw cosine not at its worst end -1: {raw}"
    with pytest.raises(SUTOutputError, match=r"l2_norm\(inputs='raw'\) is unbounded"):
        l2_norm(inputs="raw")(nan, [1.0, -2.0, 0.5, 3.0])
    with pytest.raises(AssertionError, match="deviates 1.0000"):  # a SUT broken on the follow-up fails at any eps < 1
        class_invariance().assert_within([0.1, 0.2, 0.7], nan[:3], eps=0.5)


def test_cosine_of_identical_outputs_deviates_exactly_zero():
    """1 - cos computed as |â - b̂|² / 2: identical outputs deviate 0, near-identical ones without cancellation."""
    rng = np.random.default_rng(0)
    for v in [np.array([0.1, 0.2, 0.7]), *(rng.standard_normal(1000) * 3 for _ in range(20))]:
        result = cosine_similarity()(v, v.copy())
        assert (result.score, result.deviation) == (1.0, 0.0), f"identical outputs deviate from the ideal: {result}"
    for _ in range(20):
        v = rng.standard_normal(512)
        raw = cosine_similarity(inputs="raw")(v, v.copy())
        assert (raw.score, raw.deviation) == (1.0, 0.0), f"identical raw embeddings deviate from the ideal: {raw}"
    cosine_similarity().assert_within(np.array([0.1, 0.2, 0.7]), np.array([0.1, 0.2, 0.7]), eps=0)
    a, b = np.array([1.0, 0.0]), np.array([1.0, 1e-9])  # 1 - cos = 5e-19, lost to cancellation in 1 - a·b
    near = cosine_similarity(inputs="raw")(a, b)
    assert near.deviation == pytest.approx(5e-19, rel=1e-6), f"a deviation of 5e-19 was lost to cancellation: {near}"


def test_top_k_must_be_less_than_the_number_of_classes():
    """With top_k = C every class is in the follow-up's top k: class invariance would score 1 whatever happened."""
    with pytest.raises(MetricArgumentError, match=r"top_k=3 must be less than the number of classes .* \(3\)"):
        class_invariance(top_k=3)([0.2, 0.7, 0.1], [0.9, 0.05, 0.05])
    for follow in ([0.5, 0.5], [np.nan, np.nan]):  # refused before a constant or missing output decides the pair
        with pytest.raises(InvalidArgument, match=r"top_k=2 must be less than the number of classes .* \(2\)"):
            class_invariance(top_k=2)([0.2, 0.8], follow)
    assert class_invariance(top_k=2)([0.2, 0.7, 0.1], [0.9, 0.01, 0.09]).score == 0.0, "top_k=2 of 3 not scored"


def test_zero_vectors_in_raw_mode():
    zero = np.zeros(4)
    both_zero = cosine_similarity(inputs="raw")(zero, zero)  # the SUT said nothing twice: not agreement
    assert not both_zero.valid and "both outputs are zero vectors" in both_zero.details["reason"]
    assert cosine_similarity(inputs="raw")(zero, np.ones(4)).score == 0.0
    with pytest.raises(SUTOutputError, match="source output is not a probability vector"):
        cosine_similarity(inputs="probabilities")(zero, zero)
    l2 = l2_norm(inputs="raw")(zero, zero)  # an embedding of zeros for every image passed every L2 relation
    assert not l2.valid and "both outputs are zero vectors" in l2.details["reason"], l2
    assert l2_norm(inputs="raw")(zero, np.ones(4)).score == 2.0


@pytest.mark.parametrize("dtype", [np.float32, np.float64])
def test_probabilities_with_a_rounding_error_below_zero_are_read_as_probabilities(dtype):
    """``[1, -eps, eps]`` (a probability computed as ``1 - sum(others)``) read as logits: the softmax made two
    opposite one-hot predictions score a cosine of 0.69."""
    e = np.finfo(dtype).eps
    a, b = np.array([1.0, -e, e], dtype), np.array([-e, 1.0, e], dtype)
    cos, l2 = cosine_similarity()(a, b), l2_norm()(a, b)
    assert cos.details["inputs"] == "probabilities" and cos.score < 1e-6, cos
    assert l2.score == pytest.approx(np.sqrt(2), abs=1e-6), l2
    assert cosine_similarity(inputs="probabilities")(a, a).score == pytest.approx(1.0)
    assert cosine_similarity()([1.2, -0.2], [1.2, -0.2]).details["inputs"] == "logits", "far outside [0, 1]: logits"


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
    with pytest.raises(InvalidArgument, match=r"top_k=5 must be less than the number of classes .* \(3\)"):
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


# -- how "auto" reads class scores -----------------------------------------------------------------------------

def softmax_in(dtype: str, logits: torch.Tensor) -> torch.Tensor | np.ndarray:
    """A softmax the way a SUT may compute it in a low-precision ``dtype``."""
    if dtype == "numpy float16":  # exp, sum and division all in float16
        e = np.exp((logits - logits.max()).numpy().astype(np.float16))
        return e / e.sum()
    low = getattr(torch, dtype.split()[-1])
    return torch.softmax(logits.to(low), 0) if dtype.startswith("torch") else torch.softmax(logits, 0).to(low)


@settings(max_examples=80, deadline=None)
@given(seed=st.integers(0, 2**32 - 1), classes=st.sampled_from([2, 10, 100, 1000, 10000]), scale=st.floats(0.5, 12),
       dtype=st.sampled_from(["torch bfloat16", "cast bfloat16", "torch float16", "cast float16", "numpy float16",
                              "torch float32"]))
def test_low_precision_probabilities_are_read_as_probabilities_never_softmaxed(seed, classes, scale, dtype):
    """bfloat16 softmax outputs over 1000 classes sum to 1 within 2.9e-3, past the 1e-3 of float64 for 16 % of
    them: they were softmaxed a second time (nearly uniform), and two different predictions scored alike."""
    x = torch.randn(2, classes, generator=torch.Generator().manual_seed(seed), dtype=torch.float32) * scale
    a, b = softmax_in(dtype, x[0]), softmax_in(dtype, x[1])
    exact = [np.asarray(v.double() if isinstance(v, torch.Tensor) else v, np.float64) for v in (a, b)]
    assume(all(v.min() < v.max() for v in exact))  # a constant output is undefined: tested below
    exact = [v / v.sum() for v in exact]
    for metric, raw in ((cosine_similarity(), cosine_similarity(inputs="raw")), (l2_norm(), l2_norm(inputs="raw"))):
        result = metric(a, b)
        assert result.details["inputs"] == "probabilities", (
            f"{dtype} softmax outputs of {classes} classes summing to {[float(v.sum()) for v in exact]} were read "
            f"as {result.details['inputs']}")
        assert result.score == pytest.approx(raw(*exact).score, abs=1e-12), "not the renormalized vectors' score"


def test_two_confident_different_bfloat16_predictions_score_far_apart():
    """The reviewer's case: classes 1 and 2 predicted with 0.81 and 0.93, stored in bfloat16 (sums 0.99836 and
    1.00106): cosine 0.9994 and L2 0.001 when softmaxed again; they share almost nothing."""
    x = torch.randn(2, 1000, generator=torch.Generator().manual_seed(2))
    x[0, 1] += 8.0
    x[1, 2] += 8.0
    a, b = torch.softmax(x, 1).to(torch.bfloat16)
    sums = [float(v.double().sum()) for v in (a, b)]
    assert all(abs(s - 1.0) > 1e-3 for s in sums), f"the case needs sums past 1e-3 of 1: {sums}"
    cos, l2 = cosine_similarity()(a, b), l2_norm()(a, b)
    assert cos.score < 0.05 and l2.score > 1.0, f"different predictions scored alike: {cos}, {l2}"
    assert class_invariance()(a, b).score == 0.0


def test_tolerance_follows_the_dtype_and_the_length():
    eps16, eps_bf16 = float(np.finfo(np.float16).eps), 2.0**-7
    assert probability_sum_tolerance(1000, float(np.finfo(np.float64).eps)) == 1e-3, "float64 should get the floor"
    assert probability_sum_tolerance(1000, eps16) == 2 * eps16, "float16 should get 2 eps"
    assert probability_sum_tolerance(1000, eps_bf16) == 2**-6, "bfloat16 should get 2 eps"
    assert probability_sum_tolerance(100_000, float(np.finfo(np.float32).eps)) == pytest.approx(0.0119, abs=1e-4), (
        "100 000 float32-accumulated classes should get C eps(float32)")
    almost = np.array([0.9, 0.1015])  # sums to 1.0015: bfloat16 rounding, not float64 rounding
    assert is_probability_vector(almost, eps_bf16), "a sum 1.5e-3 off is within bfloat16's tolerance"
    assert not is_probability_vector(almost), "a sum 1.5e-3 off is past float64's tolerance"
    reading = cosine_similarity()(torch.tensor(almost, dtype=torch.bfloat16), torch.tensor([0.2, 0.8]))
    assert reading.details["inputs"] == "probabilities", f"the tensor's bfloat16 dtype was not used: {reading}"
    with pytest.raises(SUTOutputError, match=r"source output has every entry in \[0, 1\] but does not sum to 1 "
                                             r"within 0\.001 \(min 0\.1015, max 0\.9, sum 1\.0015\)"):
        cosine_similarity()(almost, [0.2, 0.8])  # float64: the SUT did not round that much


@pytest.mark.parametrize("metric", [cosine_similarity(), l2_norm()], ids=repr)
def test_auto_never_softmaxes_scores_in_the_unit_range_and_reads_both_sides_alike(metric):
    """A softmax of entries in [0, 1] is nearly uniform, so any two such outputs looked alike: a vector in [0, 1]
    reads as probabilities or is an error, and a pair read one way each is an error naming both."""
    with pytest.raises(SUTOutputError, match=r"follow-up output has every entry in \[0, 1\] but does not sum to 1"
                                             r".*pass inputs='logits' if the SUT returns logits, or inputs='raw'"):
        metric([0.2, 0.8, 0.0], [0.9, 0.8, 0.1])  # independent sigmoid scores
    with pytest.raises(SUTOutputError, match=r"source output reads as probabilities but follow-up output as logits "
                                             r"\(source min 0\.2, max 0\.8, sum 1; follow-up min -1, max 2"):
        metric([0.2, 0.8], [2.0, -1.0])
    assert metric([0.2, 0.8], [0.3, 0.7]).details["inputs"] == "probabilities", "probability vectors misread"
    assert metric([2.0, -1.0], [0.5, 1.5]).details["inputs"] == "logits", "logits misread"
    assert type(metric)(inputs="logits")([0.2, 0.8], [2.0, -1.0]).valid, "the error's advice (inputs=) fails"


@pytest.mark.parametrize("inputs", ["auto", "logits"])
@pytest.mark.parametrize("metric", [cosine_similarity, l2_norm, class_invariance], ids=lambda f: f.__name__)
def test_outputs_that_favour_no_class_are_undefined_never_ideal(metric, inputs):
    """All zeros (no answer), equal logits or a uniform distribution say nothing about the class: zeros against
    zeros scored cosine 1, L2 0 and class invariance 1, and zeros against a one-hot vector cosine 0.9985."""
    zero, one_hot, uniform = np.zeros(1000), np.eye(1000)[7], np.full(1000, 1e-3)
    m = metric(inputs=inputs)
    cases = [(zero, zero, "source"), (zero, one_hot, "source"), (one_hot, zero, "follow-up"),
             (np.full(10, 3.0), np.arange(10.0), "source"), (one_hot, uniform, "follow-up"), ([0.4], [0.6], "source")]
    for a, b, which in cases:
        result = m(a, b)
        assert not result.valid and math.isnan(result.deviation), f"{m!r} scored a constant output: {result}"
        assert result.details["reason"].startswith(f"the {which} output is constant"), result.details
    assert not class_invariance(inputs="probabilities")(uniform, one_hot).valid, "a uniform distribution scored"


def test_class_invariance_is_undefined_where_a_tie_decides():
    tied_source = class_invariance()([0.4, 0.4, 0.2], [0.1, 0.2, 0.7])
    assert not tied_source.valid, f"a tied source top-1 was scored (class 0 won by index): {tied_source}"
    assert "the source's top-1 is a tie between classes 0, 1" in tied_source.details["reason"], (
        f"the reason does not name the tie: {tied_source}")
    level = class_invariance()([0.2, 0.7, 0.1], [0.45, 0.45, 0.1])  # class 1 level with class 0 at the top
    assert not level.valid and "level with classes 0 across its top-1 boundary" in level.details["reason"], (
        f"a follow-up tie across the top-1 boundary was broken by index: {level}")
    both_in = class_invariance(top_k=2)([0.2, 0.7, 0.1], [0.45, 0.45, 0.1])  # the tie lies within the top 2
    assert both_in.valid and both_in.score == 1.0, f"a tie inside the top 2 decides nothing: {both_in}"
    below = class_invariance()([0.2, 0.7, 0.1], [0.8, 0.1, 0.1])  # tied, but below class 0 whatever the tie-break
    assert below.valid and below.score == 0.0, f"a tie below the top-1 decides nothing: {below}"
    ranks = class_invariance(top_k=2, inputs="logits")([0.0, -800.0, -900.0], [0.0, -800.0, -900.0])
    assert ranks.valid and ranks.score == 1.0, f"softmax underflow (0 and 0) is no tie of the logits: {ranks}"


# -- raw vectors of any magnitude ------------------------------------------------------------------------------

magnitudes = st.one_of(st.just(0.0), st.floats(1e-3, 1e3), st.floats(-1e3, -1e-3))
raw_pairs = st.integers(1, 8).flatmap(lambda n: st.tuples(*[arrays(np.float64, n, elements=magnitudes)] * 2))


@settings(max_examples=60)
@given(pair=raw_pairs, scales=st.tuples(st.integers(-300, 300), st.integers(-300, 300)))
def test_raw_cosine_is_scale_invariant_and_l2_scales_at_any_magnitude(pair, scales):
    """[1e200, 1e200] against itself scored cosine 0.0 (the squares overflowed), [1e-200, 2e-200] was called
    a zero vector (they underflowed), and [1e200, 0] was infinitely far from [-1e200, 0]."""
    a, b = pair
    sa, sb = 10.0 ** scales[0], 10.0 ** scales[1]
    cos, scaled = cosine_similarity(inputs="raw")(a, b), cosine_similarity(inputs="raw")(a * sa, b * sb)
    assert cos.valid == scaled.valid, f"scaling by {sa:g}, {sb:g} changed validity: {cos} vs {scaled}"
    if cos.valid:
        assert scaled.score == pytest.approx(cos.score, abs=1e-9), f"scaled by {sa:g}, {sb:g}: {scaled} vs {cos}"
    l2, plain = l2_norm(inputs="raw")(a * sa, b * sa), l2_norm(inputs="raw")(a, b)
    assert l2.valid == plain.valid == bool(np.any(a) or np.any(b)), f"only two zero vectors are undefined: {l2}"
    if plain.valid:
        assert l2.score == pytest.approx(sa * plain.score, rel=1e-9), f"L2 scaled by {sa:g}: {l2}"


def test_raw_extremes():
    big, tiny = np.array([1e200, 1e200]), np.array([1e-200, 2e-200])
    assert cosine_similarity(inputs="raw")(big, big).score == pytest.approx(1.0), "[1e200, 1e200] overflowed"
    assert cosine_similarity(inputs="raw")(tiny, tiny * 1e200).score == pytest.approx(1.0), "[1e-200, ..] underflowed"
    assert l2_norm(inputs="raw")([1e200, 0.0], [-1e200, 0.0]).score == pytest.approx(2e200), "L2 overflowed"
    assert not cosine_similarity(inputs="raw")(np.zeros(3), np.zeros(3)).valid, "true zero vectors have no direction"


def test_an_int_too_large_for_a_float_is_an_output_error_naming_it():
    """``[10**400, 1]`` escaped as a bare OverflowError from numpy."""
    with pytest.raises(SUTOutputError, match="source output holds a number too large for a float64"):
        cosine_similarity(inputs="raw")([10**400, 1], [1, 2])


@settings(max_examples=60)
@given(classes=st.integers(3, 2000), share=st.floats(0.0, 0.99), seed=st.integers(0, 2**16))
@example(classes=100, share=5e-15 / (100 * np.finfo(np.float64).eps), seed=0)
def test_probabilities_rounding_below_zero_by_up_to_their_length_are_read_as_probabilities(classes, share, seed):
    """The rounding allowed below 0 grows with the vector's length (``v.size * eps``: a probability computed as
    ``1 - sum(others)`` of many classes rounds by up to that much): with ``eps`` alone, a 100-class one-hot with a
    -5e-15 entry read as logits, and two different one-hots scored a cosine of 0.97 instead of 0."""
    eps = float(np.finfo(np.float64).eps)
    i, j, k = np.random.default_rng(seed).choice(classes, 3, replace=False)
    a, b = np.zeros(classes), np.zeros(classes)
    a[i], b[j] = 1.0, 1.0
    a[k] = b[k] = -share * classes * eps  # the rounding of 1 - sum(others), inside the documented bound
    cos = cosine_similarity()(a, b)
    assert cos.details.get("inputs") == "probabilities", f"a {classes}-class one-hot read as {cos.details}"
    assert cos.valid and cos.score == pytest.approx(0.0, abs=1e-12), (
        f"two different {classes}-class one-hots scored cosine {cos.score}, not 0")


@settings(max_examples=50)
@given(span=st.floats(1.0, 1e5), classes=st.integers(2, 20), seed=st.integers(0, 2**16))
def test_softmax_of_logits_spanning_more_than_exp_can_hold_is_finite(span, classes, seed):
    """exp overflows past 709: the softmax subtracts the largest logit first, so every exponent is <= 0. Subtracting
    the smallest one made a softmax of [1000, 0] NaN, and the metric reported a NaN score as valid."""
    logits_ = np.random.default_rng(seed).uniform(0.0, span, classes)
    logits_[0], logits_[1] = 0.0, span  # the span is reached
    p = softmax(logits_)
    assert np.all(np.isfinite(p)), f"softmax of logits spanning {span:g} is not finite: {p}"
    assert p.sum() == pytest.approx(1.0) and int(np.argmax(p)) == int(np.argmax(logits_)), p


def test_the_softmax_of_a_logit_far_above_the_others_is_one_hot():
    """softmax([1000, 0]) is [1, 0], and two such confident opposite predictions score cosine 0 (it was NaN with
    valid=True when the softmax subtracted the smallest logit)."""
    np.testing.assert_allclose(softmax(np.array([1000.0, 0.0])), [1.0, 0.0], atol=0.0,
                               err_msg="softmax([1000, 0]) is not [1, 0]")
    result = cosine_similarity(inputs="logits")([1000.0, 0.0], [0.0, 1000.0])
    assert result.valid and result.score == 0.0, f"opposite confident logits did not score cosine 0: {result}"
    assert cosine_similarity()([1000.0, 0.0, -1000.0], [1000.0, 0.0, -1000.0]).score == 1.0
