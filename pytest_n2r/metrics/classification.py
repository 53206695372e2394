"""Classifier metrics: cosine similarity, L2 distance and class invariance of two output vectors.

SUT output: one vector of class scores, shape ``(C,)`` or a batch of one ``(1, C)`` (numpy, list or a
CPU/GPU tensor). Both outputs of a pair must have the same length ``C``.

What the scores mean depends on ``inputs``:

- ``"probabilities"``: the vectors are probability distributions (non-negative, summing to 1 within
  ``1e-3``); anything else is a :class:`~pytest_n2r.errors.SUTOutputError`.
- ``"logits"``: the vectors are logits; both are turned into probabilities with a softmax first.
- ``"auto"`` (default): if **both** vectors are probability distributions they are used as they are,
  otherwise **both** are softmaxed (decided per pair, so the two sides are always treated alike).
- ``"raw"``: the vectors are compared as given (e.g. embeddings); only :func:`cosine_similarity` and
  :func:`l2_norm` accept it.

Class invariance only looks at the ranking of classes, which the softmax does not change.
"""

from __future__ import annotations

from abc import abstractmethod
from typing import Any, Literal

import numpy as np

from ..errors import InvalidArgument, InvalidType, MetricUndefined, SUTOutputError
from ._outputs import as_vector
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
]

Inputs = Literal["auto", "probabilities", "logits", "raw"]
_INPUTS = ("auto", "probabilities", "logits", "raw")
#: How far from 1 the sum of a probability vector may be (float32 outputs of 1000 classes drift ~1e-6).
PROBABILITY_SUM_TOLERANCE = 1e-3


def softmax(logits: np.ndarray) -> np.ndarray:
    """Numerically stable softmax of a 1-D vector (subtracts the maximum first).

    >>> softmax(np.array([0.0, 0.0])).tolist()
    [0.5, 0.5]
    """
    z = np.exp(logits - logits.max())
    return z / z.sum()


def is_probability_vector(v: np.ndarray) -> bool:
    """True when all entries are in [0, 1] and they sum to 1 within :data:`PROBABILITY_SUM_TOLERANCE`."""
    return bool(np.all(v >= 0) and np.all(v <= 1) and abs(float(v.sum()) - 1.0) <= PROBABILITY_SUM_TOLERANCE)


class _VectorMetric(Metric):
    """Parse the two outputs, check their lengths, convert them as ``inputs`` says."""

    allowed_inputs: tuple[str, ...] = _INPUTS
    nan_means_no_output = True

    def __init__(self, inputs: Inputs = "auto") -> None:
        if inputs not in self.allowed_inputs:
            raise InvalidArgument(f"inputs={inputs!r}; expected one of {self.allowed_inputs}")
        self.inputs = inputs

    def vectors(self, out_source: Any, out_follow: Any) -> tuple[np.ndarray, np.ndarray, str]:
        """The two outputs as comparable vectors, and how they were read (``probabilities``, ``logits``,
        ``raw``)."""
        a, b = as_vector(out_source, "source"), as_vector(out_follow, "follow-up")
        if a.shape != b.shape:
            raise SUTOutputError(
                f"source output has {a.size} classes but follow-up output has {b.size}; "
                "a classifier must return the same number of class scores for every image"
            )
        mode = self.inputs
        if mode == "auto":
            mode = "probabilities" if is_probability_vector(a) and is_probability_vector(b) else "logits"
        elif mode == "probabilities":
            for which, v in (("source", a), ("follow-up", b)):
                if not is_probability_vector(v):
                    raise SUTOutputError(
                        f"{which} output is not a probability vector (min {v.min():.4g}, max {v.max():.4g}, "
                        f"sum {v.sum():.6g}); pass inputs='logits' (or 'auto') if the SUT returns logits"
                    )
        if mode == "logits":
            a, b = softmax(a), softmax(b)
        return a, b, mode

    def compute(self, out_source: Any, out_follow: Any, source: Any = None, follow: Any = None) -> MetricResult:
        try:
            a, b, mode = self.vectors(out_source, out_follow)
        except MetricUndefined as exc:
            return MetricResult.undefined(self.name, str(exc))
        return self._score(a, b, mode)

    @abstractmethod
    def _score(self, a: np.ndarray, b: np.ndarray, mode: str) -> MetricResult:
        """Score two comparable vectors (read as ``mode``)."""

    def _repr_inputs(self) -> str:
        return "" if self.inputs == "auto" else f"inputs={self.inputs!r}"


class CosineSimilarity(_VectorMetric):
    """``a·b / (|a| |b|)``. Range [-1, 1] ([0, 1] for probabilities), ideal 1, deviation ``1 - score``.

    A zero vector has no direction: two zero vectors are *undefined* (the SUT said nothing either time,
    which is not agreement), a zero vector against a non-zero one scores 0 (they share nothing). Only
    ``inputs="raw"`` can produce zero vectors. Empty or all-NaN outputs are undefined for every vector
    metric (see :func:`~pytest_n2r.metrics._outputs.as_vector`).
    """

    name = "cosine_similarity"
    ideal = 1.0

    def _score(self, a: np.ndarray, b: np.ndarray, mode: str) -> MetricResult:
        na, nb = float(np.linalg.norm(a)), float(np.linalg.norm(b))
        if na == 0.0 and nb == 0.0:
            return MetricResult.undefined(self.name, "both outputs are zero vectors (nothing to compare)",
                                          inputs=mode, classes=int(a.size))
        if na == 0.0 or nb == 0.0:
            score = 0.0
        else:
            score = float(np.clip(np.dot(a / na, b / nb), -1.0, 1.0))
        return self.result(score, inputs=mode, classes=int(a.size))

    def __repr__(self) -> str:
        return f"cosine_similarity({self._repr_inputs()})"


class L2Norm(_VectorMetric):
    """Euclidean distance ``|a - b|_2`` (not squared). Range [0, √2] for probability vectors (two
    different one-hot vectors), unbounded for ``"raw"``; ideal 0, deviation = score."""

    name = "l2_norm"
    ideal = 0.0

    def _score(self, a: np.ndarray, b: np.ndarray, mode: str) -> MetricResult:
        return self.result(float(np.linalg.norm(a - b)), inputs=mode, classes=int(a.size))

    def __repr__(self) -> str:
        return f"l2_norm({self._repr_inputs()})"


class ClassInvariance(_VectorMetric):
    """1 when the source's top-1 class is among the follow-up's ``top_k`` classes, else 0.

    With ``top_k=1`` this is "the predicted class did not change". Ties are broken toward the lower
    class index (as ``numpy.argmax``). Range {0, 1}, ideal 1, deviation ``1 - score``.
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

    def _score(self, a: np.ndarray, b: np.ndarray, mode: str) -> MetricResult:
        if self.top_k > b.size:
            raise InvalidArgument(f"top_k={self.top_k} exceeds the {b.size} classes the classifier returns")
        source_class = int(np.argmax(a))
        follow_top = np.argsort(-b, kind="stable")[: self.top_k]
        score = 1.0 if source_class in follow_top else 0.0
        return self.result(score, inputs=mode, source_class=source_class,
                           follow_classes=[int(c) for c in follow_top])

    def __repr__(self) -> str:
        parts = [f"top_k={self.top_k}"] if self.top_k != 1 else []
        parts += [self._repr_inputs()] if self.inputs != "auto" else []
        return f"class_invariance({', '.join(parts)})"


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
