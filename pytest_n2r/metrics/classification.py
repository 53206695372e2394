"""Classifier metrics: cosine similarity, L2 distance and class invariance of two output vectors.

SUT output: one vector of class scores, shape ``(C,)`` or a batch of one ``(1, C)`` (numpy, list or a
CPU/GPU tensor). Both outputs of a pair must have the same length ``C``.

What the scores mean depends on ``inputs``:

- ``"probabilities"``: the vectors are probability distributions (entries in [0, 1] summing to 1 within
  :func:`probability_sum_tolerance`: 1e-3, more for low-precision dtypes such as bfloat16); they are
  renormalized to sum 1. Anything else is a :class:`~pytest_n2r.errors.SUTOutputError`.
- ``"logits"``: the vectors are logits; both are turned into probabilities with a softmax first.
- ``"auto"`` (default): each vector is read on its own: every entry in [0, 1] → probabilities (renormalized,
  never softmaxed), which must then sum to 1 within the tolerance; an entry outside [0, 1] → logits
  (softmaxed). The two must read alike. A vector in [0, 1] that does not sum to 1, or a pair read one
  each way, is a :class:`~pytest_n2r.errors.SUTOutputError` saying which ``inputs`` to pass: a softmax of
  entries in [0, 1] is nearly uniform (they lie within a factor e of each other), so softmaxing probabilities
  made any two outputs look alike.
- ``"raw"``: the vectors are compared as given (e.g. embeddings); only :func:`cosine_similarity` and
  :func:`l2_norm` accept it.

Except with ``"raw"``, a constant output (all zeros, all equal logits, a uniform distribution; any output of
one class) favours no class: the pair is *undefined* (nothing to compare), never a perfect score. Class
invariance only looks at the ranking of the given scores, which no reading changes, and is undefined where
that ranking ties at the decisive place.

An empty or all-NaN output is no answer. No answer on both views is *undefined*; an answer on one view only
scores the worst end of the range (cosine 0, or -1 with ``"raw"``; L2 √2; class invariance 0), as a keypoint
metric scores 0 when only one view has points. ``l2_norm(inputs="raw")`` has no worst end: a
:class:`~pytest_n2r.errors.SUTOutputError`.
"""

from __future__ import annotations

from abc import abstractmethod
from typing import Any, Literal

import numpy as np

from ..errors import InvalidArgument, InvalidType, MetricArgumentError, MetricUndefined, SUTOutputError
from ._outputs import as_vector, float_eps
from .base import Metric, MetricResult

__all__ = [
    "CosineSimilarity",
    "L2Norm",
    "ClassInvariance",
    "cosine_similarity",
    "l2_norm",
    "class_invariance",
    "softmax",
    "is_probability_vector",
    "in_unit_range",
    "probability_sum_tolerance",
]

Inputs = Literal["auto", "probabilities", "logits", "raw"]
_INPUTS = ("auto", "probabilities", "logits", "raw")
#: The least tolerance on the sum of a probability vector (float32 outputs of 1000 classes drift up to 6e-7).
PROBABILITY_SUM_TOLERANCE = 1e-3
_FLOAT32_EPS = float(np.finfo(np.float32).eps)


def probability_sum_tolerance(n_classes: int, eps: float) -> float:
    """How far from 1 the sum of a probability vector of ``n_classes`` entries, stored in a dtype of machine
    epsilon ``eps``, may be: ``max(1e-3, 2 eps, n_classes eps(float32))``.

    Rounding each entry to the output dtype moves it by at most ``eps / 2`` of itself, so the sum by at most
    ``eps / 2`` whatever the length; the normalising sum, which torch (its accumulation type for float16 and
    bfloat16 is float32) and numpy (float16 sums included) accumulate in float32 or wider, adds at most about
    ``n_classes eps(float32) / 2``. Measured (2000 softmax outputs per case, of randn logits times 1, 3 or 10;
    ``|sum - 1|`` in float64; 10 to 10 000 classes): bfloat16 at most 2.9e-3 = 0.37 eps (torch in bfloat16,
    or float32 cast to it; 15-34 % of them stray past 1e-3); float16 3.5e-4 = 0.36 eps (torch), 6.9e-4 =
    0.73 eps (numpy, exp and division in float16); float32 5.9e-7 at 1000 classes, 3.0e-6 = 25 eps at 10 000.
    ``2 eps`` covers the worst of them (0.73 eps) 2.7 times over: 0.0156 for bfloat16, 0.00195 for float16;
    float32 and float64 get 1e-3 up to 8389 classes.
    """
    return max(PROBABILITY_SUM_TOLERANCE, 2.0 * eps, n_classes * _FLOAT32_EPS)


def softmax(logits: np.ndarray) -> np.ndarray:
    """Numerically stable softmax of a 1-D vector (subtracts the maximum first).

    >>> softmax(np.array([0.0, 0.0])).tolist()
    [0.5, 0.5]
    """
    z = np.exp(logits - logits.max())
    return z / z.sum()


def in_unit_range(v: np.ndarray, eps: float = float(np.finfo(np.float64).eps)) -> bool:
    """True when every entry is in [0, 1] within the rounding of a sum of ``v.size`` entries stored in a dtype of
    machine epsilon ``eps`` (``v.size * eps``: a probability computed as ``1 - sum(others)`` may round a little
    below 0). Anything further out is a score of its own, such as a logit.

    >>> in_unit_range(np.array([1.0, -2e-16, 2e-16])), in_unit_range(np.array([1.0, -1e-9, 1e-9]))
    (True, False)
    """
    tolerance = v.size * eps
    return bool(np.all(v >= -tolerance) and np.all(v <= 1.0 + tolerance))


def is_probability_vector(v: np.ndarray, eps: float = float(np.finfo(np.float64).eps)) -> bool:
    """True when all entries are in [0, 1] (within rounding: :func:`in_unit_range`) and they sum to 1 within
    :func:`probability_sum_tolerance` for a vector of this length stored in a dtype of machine epsilon ``eps``
    (float64's by default)."""
    return in_unit_range(v, eps) and abs(float(v.sum()) - 1.0) <= probability_sum_tolerance(v.size, eps)


def _describe(v: np.ndarray) -> str:
    return f"min {v.min():.4g}, max {v.max():.4g}, sum {v.sum():.6g}"


class _VectorMetric(Metric):
    """Parse the two outputs, check their lengths and that they favour some class, read them as ``inputs``
    says."""

    allowed_inputs: tuple[str, ...] = _INPUTS
    nan_means_no_output = True

    def check_classes(self, n_classes: int) -> None:
        """Raise if the metric's arguments do not suit a classifier of ``n_classes`` classes (known at call time)."""

    @property
    def worst(self) -> float:
        """The score of an answer on one view against none (empty or all NaN) on the other: the worst end of the
        range."""
        return 0.0

    def __init__(self, inputs: Inputs = "auto") -> None:
        if inputs not in self.allowed_inputs:
            raise InvalidArgument(f"inputs={inputs!r}; expected one of {self.allowed_inputs}")
        self.inputs = inputs

    def compute(self, out_source: Any, out_follow: Any, source: Any = None, follow: Any = None) -> MetricResult:
        vectors: list[np.ndarray | None] = []
        silent: list[str] = []
        for value, which in ((out_source, "source"), (out_follow, "follow-up")):
            try:
                vectors.append(as_vector(value, which))
            except MetricUndefined as exc:  # the SUT gave no answer on this view
                vectors.append(None)
                silent.append(str(exc))
        if len(silent) == 2:
            return MetricResult.undefined(self.name, f"{' and '.join(silent)} (nothing to compare)")
        a, b = vectors
        if a is None or b is None:  # an answer on one view only: a failure, as for keypoints on one side
            answer = next(v for v in vectors if v is not None)  # one of the two: none returned above
            self.check_classes(int(answer.size))
            answered = "follow-up" if a is None else "source"
            score = self.worst
            return MetricResult(self.name, score, self.deviation(score), {
                "reason": f"{silent[0]} but the {answered} output is not: the SUT answered on one view only",
                "classes": int(answer.size)})
        if a.shape != b.shape:
            raise SUTOutputError(
                f"source output has {a.size} classes but follow-up output has {b.size}; "
                "a classifier must return the same number of class scores for every image"
            )
        self.check_classes(int(a.size))
        eps = (float_eps(out_source), float_eps(out_follow))
        if self.inputs == "probabilities":
            for which, v, e in (("source", a, eps[0]), ("follow-up", b, eps[1])):
                if not is_probability_vector(v, e):
                    raise SUTOutputError(
                        f"{which} output is not a probability vector ({_describe(v)}; expected entries in [0, 1] "
                        f"(within {v.size * e:.3g}) summing to 1 within {probability_sum_tolerance(v.size, e):.3g}); "
                        "pass "
                        "inputs='logits' (or 'auto') if the SUT returns logits"
                    )
        if self.inputs != "raw":
            for which, v in (("source", a), ("follow-up", b)):
                if v.min() == v.max():  # a softmax or a renormalization makes it uniform: no class stands out
                    raw_hint = "; inputs='raw' compares the values as given" if "raw" in self.allowed_inputs else ""
                    return MetricResult.undefined(
                        self.name, f"the {which} output is constant (all {v.size} class scores are {v[0]:.6g}): "
                        f"it favours no class, so there is nothing to compare{raw_hint}", classes=int(v.size))
        return self._score(a, b, eps)

    def read(self, a: np.ndarray, b: np.ndarray, eps: tuple[float, float]) -> tuple[np.ndarray, np.ndarray, str]:
        """The two vectors as compared (probability vectors renormalized to sum 1, logits softmaxed, raw as
        given) and how they were read; ``eps``: machine epsilon of each output's dtype.

        ``"auto"`` reads a vector with every entry in [0, 1] as probabilities if it sums to 1 within
        :func:`probability_sum_tolerance`, and is a :class:`SUTOutputError` otherwise: its softmax would be
        nearly uniform (its entries all lie within a factor e of each other), and two such outputs would score
        alike whatever they said. A vector with an entry outside [0, 1] reads as probabilities when that is
        rounding (:func:`is_probability_vector`: ``[1, -2e-16, 2e-16]`` in float64, from ``1 - sum(others)``),
        else as logits. Probabilities are clipped to [0, 1] before they are renormalized. The two outputs must
        read alike (a classifier returns one kind of score), or it is a :class:`SUTOutputError`.
        """
        mode = self.inputs
        if mode == "auto":
            kinds: list[Literal["probabilities", "logits"]] = []
            for which, v, e in (("source", a, eps[0]), ("follow-up", b, eps[1])):
                unit = bool(np.all(v >= 0) and np.all(v <= 1))
                if unit and not is_probability_vector(v, e):
                    raise SUTOutputError(
                        f"{which} output has every entry in [0, 1] but does not sum to 1 within "
                        f"{probability_sum_tolerance(v.size, e):.3g} ({_describe(v)}): it is no probability "
                        "vector, and a softmax would flatten it to nearly uniform; pass inputs='logits' if the "
                        "SUT returns logits, or inputs='raw' to compare the values as given (e.g. independent "
                        "sigmoid scores)")
                kinds.append("probabilities" if unit or is_probability_vector(v, e) else "logits")
            if kinds[0] != kinds[1]:
                raise SUTOutputError(
                    f"source output reads as {kinds[0]} but follow-up output as {kinds[1]} (source "
                    f"{_describe(a)}; follow-up {_describe(b)}); a classifier returns one kind of score for every "
                    "image: pass inputs='logits' or inputs='probabilities' to say which")
            mode = kinds[0]
        if mode == "probabilities":
            a, b = (np.clip(v, 0.0, 1.0) for v in (a, b))
            a, b = a / a.sum(), b / b.sum()
        elif mode == "logits":
            a, b = softmax(a), softmax(b)
        return a, b, mode

    @abstractmethod
    def _score(self, a: np.ndarray, b: np.ndarray, eps: tuple[float, float]) -> MetricResult:
        """Score the two given vectors (``eps``: machine epsilon of each output's dtype)."""

    def _repr_inputs(self) -> str:
        return "" if self.inputs == "auto" else f"inputs={self.inputs!r}"


def _unit_max(v: np.ndarray) -> np.ndarray:
    """``v`` divided by its largest absolute entry (unchanged if zero): entries in [-1, 1], so squares neither
    overflow (1e200) nor underflow (1e-200)."""
    top = float(np.abs(v).max())
    return v / top if top > 0.0 else v


class CosineSimilarity(_VectorMetric):
    """``a·b / (|a| |b|)``. Range [-1, 1] ([0, 1] for probabilities), ideal 1, deviation ``1 - score``, computed
    as ``|â - b̂|² / 2`` on the unit vectors: exactly 0 for identical outputs, without cancellation near 0.

    A zero vector has no direction: two zero vectors are *undefined* (the SUT said nothing either time,
    which is not agreement), a zero vector against a non-zero one scores 0 (they share nothing). Only
    ``inputs="raw"`` can get zero vectors to this point: in the other readings a constant output (all zeros
    included) favours no class and is undefined. Empty or all-NaN outputs: see the module notes. Each vector is
    scaled by its largest absolute entry first (the cosine does not change), so ``[1e200, 1e200]`` or
    ``[1e-200, 2e-200]`` score like ``[1, 1]`` and ``[1, 2]``.
    """

    name = "cosine_similarity"
    ideal = 1.0

    @property
    def worst(self) -> float:
        """-1 with ``inputs="raw"`` (opposite vectors), else 0 (the range of non-negative vectors is [0, 1])."""
        return -1.0 if self.inputs == "raw" else 0.0

    def _score(self, a: np.ndarray, b: np.ndarray, eps: tuple[float, float]) -> MetricResult:
        a, b, mode = self.read(a, b, eps)
        a, b = _unit_max(a), _unit_max(b)
        na, nb = float(np.linalg.norm(a)), float(np.linalg.norm(b))
        if na == 0.0 and nb == 0.0:
            return MetricResult.undefined(self.name, "both outputs are zero vectors (nothing to compare)",
                                          inputs=mode, classes=int(a.size))
        if na == 0.0 or nb == 0.0:
            return self.result(0.0, inputs=mode, classes=int(a.size))
        # 1 - cos = |â - b̂|² / 2 on unit vectors: exactly 0 for identical outputs, and no cancellation near 0; held
        # within the range, whose far end rounding can pass (two softmaxed logits favouring different classes, their
        # cosine about 1e-16, gave a score of -2.2e-16 from non-negative vectors)
        deviation = float(np.clip(0.5 * np.sum((a / na - b / nb) ** 2), 0.0, self.ideal - self.worst))
        score = 1.0 - deviation
        return MetricResult(self.name, score, deviation, {"inputs": mode, "classes": int(a.size)})

    def __repr__(self) -> str:
        return f"cosine_similarity({self._repr_inputs()})"


class L2Norm(_VectorMetric):
    """Euclidean distance ``|a - b|_2`` (not squared). Range [0, √2] for probability vectors (two
    different one-hot vectors), unbounded for ``"raw"`` (computed on the vectors scaled by their largest
    absolute entry, so ``[1e200, 0]`` and ``[-1e200, 0]`` are 2e200 apart, not infinitely); ideal 0,
    deviation = score. Two zero vectors (only ``"raw"`` gets them here) are *undefined*, as for the cosine: the
    SUT said nothing either time, which is not agreement."""

    name = "l2_norm"
    ideal = 0.0

    @property
    def worst(self) -> float:
        """√2 (two different one-hot vectors); ``inputs="raw"`` has no worst end: an error (see ``compute``)."""
        if self.inputs == "raw":
            raise SUTOutputError("one output is empty or all NaN and the other is not; l2_norm(inputs='raw') is "
                                 "unbounded, so an answer on one view only has no score")
        return float(np.sqrt(2.0))

    def _score(self, a: np.ndarray, b: np.ndarray, eps: tuple[float, float]) -> MetricResult:
        a, b, mode = self.read(a, b, eps)
        top = max(float(np.abs(a).max()), float(np.abs(b).max()))
        if top == 0.0:
            return MetricResult.undefined(self.name, "both outputs are zero vectors (nothing to compare)",
                                          inputs=mode, classes=int(a.size))
        distance = top * float(np.linalg.norm(a / top - b / top))
        return self.result(distance, inputs=mode, classes=int(a.size))

    def __repr__(self) -> str:
        return f"l2_norm({self._repr_inputs()})"


class ClassInvariance(_VectorMetric):
    """1 when the source's top-1 class is among the follow-up's ``top_k`` classes, else 0. ``top_k`` must be less
    than the number of classes, if two or more (an :class:`~pytest_n2r.errors.InvalidArgument` at call time).

    With ``top_k=1`` this is "the predicted class did not change". Only the ranking of the given scores counts
    (a softmax or a renormalization does not change it), so ``inputs`` only decides whether outputs that are
    not probability vectors are an error (``"probabilities"``). Ties are never broken by class index: the
    pair is *undefined* when the source's top-1 is a tie (there is no predicted class), or when the follow-up
    scores the source class level with others across its ``top_k`` boundary (whether it is among the top
    ``top_k`` would depend on the tie-break). Range {0, 1}, ideal 1, deviation ``1 - score``.
    """

    name = "class_invariance"
    ideal = 1.0
    allowed_inputs = ("auto", "probabilities", "logits")

    def __init__(self, top_k: int = 1, inputs: Inputs = "auto") -> None:
        if isinstance(top_k, bool) or not isinstance(top_k, (int, np.integer)):
            raise InvalidType(f"top_k={top_k!r} must be an int, not {type(top_k).__name__}")
        if top_k < 1:
            raise InvalidArgument(f"top_k={top_k!r} must be >= 1")
        self.top_k = int(top_k)
        super().__init__(inputs)

    def check_classes(self, n_classes: int) -> None:
        if 1 < n_classes <= self.top_k:  # every class among the top k: 1 whatever (one class is constant: undefined)
            raise MetricArgumentError(f"top_k={self.top_k} must be less than the number of classes the classifier "
                                      f"returns ({n_classes}): with top_k >= {n_classes} every class is in the top-k")

    def _score(self, a: np.ndarray, b: np.ndarray, eps: tuple[float, float]) -> MetricResult:
        top = np.flatnonzero(a == a.max())
        if len(top) > 1:
            return MetricResult.undefined(
                self.name, f"the source's top-1 is a tie between classes {_listed(top)}: there is no predicted "
                "class to keep", source_classes=[int(c) for c in top[:10]])
        source_class = int(top[0])
        follow_top = np.argsort(-b, kind="stable")[: self.top_k]
        above = int(np.count_nonzero(b > b[source_class]))
        level = np.flatnonzero(b == b[source_class])
        if above < self.top_k < above + len(level):
            return MetricResult.undefined(
                self.name, f"the follow-up scores the source class {source_class} level with classes "
                f"{_listed(level[level != source_class])} across its top-{self.top_k} boundary: whether it is "
                "among them depends on how the tie is broken", source_class=source_class)
        score = 1.0 if above < self.top_k else 0.0
        return self.result(score, source_class=source_class, follow_classes=[int(c) for c in follow_top])

    def __repr__(self) -> str:
        parts = [f"top_k={self.top_k}"] if self.top_k != 1 else []
        parts += [self._repr_inputs()] if self.inputs != "auto" else []
        return f"class_invariance({', '.join(parts)})"


def _listed(classes: np.ndarray, most: int = 10) -> str:
    """Class indices for a message: ``0, 3, 7`` (the first ``most`` and how many more)."""
    shown = ", ".join(str(int(c)) for c in classes[:most])
    return shown + (f" and {len(classes) - most} more" if len(classes) > most else "")


def cosine_similarity(inputs: Inputs = "auto") -> CosineSimilarity:
    """Cosine similarity of the two output vectors (see :class:`CosineSimilarity` and the module notes).

    >>> cosine_similarity()([0.9, 0.1], [0.9, 0.1]).score
    1.0
    """
    return CosineSimilarity(inputs)


def l2_norm(inputs: Inputs = "auto") -> L2Norm:
    """Euclidean distance of the two output vectors (see :class:`L2Norm` and the module notes).

    >>> round(l2_norm()([1.0, 0.0], [0.0, 1.0]).score, 6)     # two different one-hot vectors: √2
    1.414214
    """
    return L2Norm(inputs)


def class_invariance(top_k: int = 1, inputs: Inputs = "auto") -> ClassInvariance:
    """Whether the predicted class survives the transform (see :class:`ClassInvariance`).

    >>> class_invariance()([0.1, 0.7, 0.2], [0.2, 0.3, 0.5]).score
    0.0
    >>> class_invariance(top_k=2)([0.1, 0.7, 0.2], [0.2, 0.3, 0.5]).score
    1.0
    """
    return ClassInvariance(top_k, inputs)
