"""What a time budget chooses for a fit (:mod:`pytest_n2r.fit.budget`)."""

from __future__ import annotations

import math

import pytest
from hypothesis import given
from hypothesis import strategies as st

from pytest_n2r.errors import InvalidArgument
from pytest_n2r.field.config import SH_DEGREES, FieldConfig
from pytest_n2r.fit.budget import LONG_BUDGET_S, LONG_BUDGET_SH_DEGREE, budget_config


@pytest.mark.parametrize(("budget", "kwargs", "degree"), [
    (1200.0, {}, 2),
    (3600.0, {"fixed": {"resolutions", "seed"}}, 2),  # other settings given: the degree is still the budget's
    (1199.0, {}, 1),
    (None, {}, 1),
    (3600.0, {"fixed": {"sh_degree"}}, 1),
    (3600.0, {"max_steps": 20_000}, 1),
])
def test_the_default_degree_follows_a_long_time_budget(budget, kwargs, degree):
    chosen = budget_config(FieldConfig(), budget, **kwargs).sh_degree
    assert chosen == degree, f"budget {budget} s with {kwargs}: SH degree {chosen}, expected {degree}"


@given(budget=st.one_of(st.none(), st.floats(min_value=1e-3, max_value=1e6)), degree=st.sampled_from(SH_DEGREES),
       fixed=st.sampled_from([(), ("sh_degree",), ("resolutions",)]),
       max_steps=st.one_of(st.none(), st.integers(1, 10**6)))
def test_only_the_default_degree_changes_and_nothing_else(budget, degree, fixed, max_steps):
    config = FieldConfig(sh_degree=degree)
    chosen = budget_config(config, budget, max_steps=max_steps, fixed=fixed)
    if degree != FieldConfig().sh_degree or "sh_degree" in fixed or max_steps is not None:
        assert chosen == config, f"a degree {degree} config, fixed {fixed}, max_steps {max_steps} was changed"
    assert chosen.replace(sh_degree=degree) == config, "a setting other than the SH degree changed"


def test_the_threshold_is_inclusive():
    assert budget_config(FieldConfig(), LONG_BUDGET_S).sh_degree == LONG_BUDGET_SH_DEGREE
    assert budget_config(FieldConfig(), math.nextafter(LONG_BUDGET_S, 0.0)).sh_degree == FieldConfig().sh_degree


@pytest.mark.parametrize("budget", [0.0, -5.0, math.nan, math.inf])
def test_a_budget_that_is_not_seconds_is_refused(budget):
    with pytest.raises(InvalidArgument, match=r"time_budget_s=.*: expected a finite number of seconds > 0, or None"):
        budget_config(FieldConfig(), budget)
