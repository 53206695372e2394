"""Metrics by name, for the plugin and for reports."""

from __future__ import annotations

import pytest

import pytest_n2r
from pytest_n2r.errors import InvalidArgument, InvalidType
from pytest_n2r.metrics import METRICS, Metric, repeatability, resolve_metric


def test_every_metric_is_registered_under_its_name_with_a_rebuildable_repr():
    assert set(METRICS) == {
        "cosine_similarity", "l2_norm", "class_invariance", "repeatability", "interest_point_spread", "ssim",
    }
    for name, cls in METRICS.items():
        metric = resolve_metric(name)
        assert isinstance(metric, cls) and metric.name == name
        rebuilt = eval(repr(metric), vars(pytest_n2r.metrics))
        assert repr(rebuilt) == repr(metric)


def test_resolve_passes_parameters_and_objects_through():
    assert resolve_metric("class_invariance", top_k=5).top_k == 5
    metric = repeatability(px=3)
    assert resolve_metric(metric) is metric


def test_resolve_errors_list_what_is_known():
    with pytest.raises(InvalidArgument, match="unknown metric 'repeat'; known: class_invariance, cosine_similarity"):
        resolve_metric("repeat")
    with pytest.raises(InvalidArgument, match=r"metric 'l2_norm' does not take \['px'\]"):
        resolve_metric("l2_norm", px=2)
    with pytest.raises(InvalidArgument, match="given with the metric object"):
        resolve_metric(repeatability(), px=2)
    with pytest.raises(InvalidType, match="must be a Metric or a metric name"):
        resolve_metric(3)
    with pytest.raises(InvalidArgument, match=r"px=0\.0 must be > 0"):
        resolve_metric("repeatability", px=0)


def test_top_level_exports():
    assert pytest_n2r.repeatability is repeatability
    for factory in ("cosine_similarity", "l2_norm", "class_invariance", "interest_point_spread", "ssim_metric"):
        assert getattr(pytest_n2r, factory) is getattr(pytest_n2r.metrics, factory), f"{factory} is not exported"
    assert issubclass(pytest_n2r.Metric, Metric) and pytest_n2r.Brightness(3).levels == 3


class _NoIdeal(Metric):
    name = "no_ideal"

    def compute(self, out_source, out_follow, source=None, follow=None):
        return self.result(0.0)


class _NoName(Metric):
    ideal = 1.0

    def compute(self, out_source, out_follow, source=None, follow=None):
        return self.result(1.0)


class _TextIdeal(_NoIdeal):
    ideal = "1"


@pytest.mark.parametrize(("metric", "match"), [
    (_NoIdeal(), r"metric _NoIdeal has ideal=None; expected a finite number on the class"),
    (_TextIdeal(), r"metric _TextIdeal has ideal='1'; expected a finite number"),
    (_NoName(), r"metric _NoName has name=None; expected a short string"),
])
def test_a_metric_of_ones_own_must_declare_its_name_and_ideal(metric, match):
    """A Metric subclass without ``ideal`` passed @metamorphic's checks and failed mid-run with a bare
    AttributeError from Metric.deviation."""
    with pytest.raises(InvalidType, match=match):
        resolve_metric(metric)
