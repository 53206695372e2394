"""A metric's ``repr`` is the same in every run: baselines compare metrics by it (``changed-metric``), and the
field floor and kept results are keyed by it."""

from __future__ import annotations

import json
import os
import re
import subprocess
import sys

import numpy as np

from pytest_n2r.metrics import METRICS, interest_point_spread, repeatability
from pytest_n2r.metrics.base import Metric

from ..conftest import REPO_ROOT


def _norm(v):
    return v


class Scaled(Metric):
    """A user's metric without a ``__repr__`` of its own."""

    name = "scaled"
    ideal = 0.0

    def __init__(self, scale: float = 1.0, weights=None, normalize=_norm) -> None:
        self.scale, self.weights, self.normalize = scale, weights, normalize
        self._calls = 0  # private state: not part of the metric's identity

    def compute(self, out_source, out_follow, source=None, follow=None):
        self._calls += 1
        return self.result(abs(float(out_source) - float(out_follow)) * self.scale)


def test_a_users_metric_reprs_as_its_class_and_parameters_without_an_address():
    metric = Scaled(2.0, weights=np.arange(2000.0))
    text = repr(metric)
    assert not re.search(r"0x[0-9a-f]+", text), f"the repr holds a memory address, new every run: {text}"
    assert text.startswith("Scaled(normalize=tests.metrics.test_metric_repr._norm, scale=2.0, weights=array(["), text
    assert "..." not in text, f"a long array was elided, so two metrics of other weights read alike: {text[:200]}"
    assert "_calls" not in text, f"private state is not a parameter: {text[:200]}"
    assert repr(Scaled(2.0, weights=np.arange(2000.0))) == text, "two equal metrics must repr alike"
    other = np.arange(2000.0)
    other[1000] = -1
    assert repr(Scaled(2.0, weights=other)) != text, "metrics of other parameters must repr apart"
    metric(1.0, 2.0)
    assert repr(metric) == text, "evaluating the metric changed its repr"


def test_the_built_in_metrics_keep_their_own_reprs():
    """The committed example baseline names its metrics by these strings: a change would read as changed-metric."""
    baseline = json.loads((REPO_ROOT / "example_project" / "tests" / "gate-baseline.json").read_text())
    recorded = {rel["metric"] for rel in baseline["relations"].values()}
    current = {repr(repeatability(px=3.0)), repr(interest_point_spread())}
    assert recorded == current, f"the example baseline's metrics {recorded} differ from today's reprs {current}"
    for name, cls in METRICS.items():
        assert cls.__repr__ is not Metric.__repr__, f"{name} lost its own repr"


def test_a_set_attribute_reprs_in_the_same_order_in_every_process():
    """A set of strings iterates in the order of their hashes, which PYTHONHASHSEED changes from run to run."""
    code = ("from tests.metrics.test_metric_repr import Scaled; "
            "print(repr(Scaled(weights={'orb', 'sift', 'akaze', 'brisk', 'kaze'})))")
    texts = {subprocess.run([sys.executable, "-c", code], cwd=REPO_ROOT, capture_output=True, text=True, check=True,
                            env={**os.environ, "PYTHONPATH": str(REPO_ROOT), "PYTHONHASHSEED": str(seed)}).stdout
             for seed in range(4)}
    assert len(texts) == 1, f"the repr changed with the hash seed: {sorted(texts)}"
    assert "weights={'akaze', 'brisk', 'kaze', 'orb', 'sift'}" in texts.pop(), "the set's items are not sorted"
