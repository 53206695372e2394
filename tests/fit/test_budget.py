"""What a time budget chooses for a fit (:mod:`pytest_n2r.fit.budget`)."""

from __future__ import annotations

import math

import pytest
from hypothesis import given
from hypothesis import strategies as st

from pytest_n2r.errors import InvalidArgument
from pytest_n2r.field.config import SH_DEGREES, FieldConfig
from pytest_n2r.fit.budget import LONG_BUDGET_S, LONG_BUDGET_SH_DEGREE, budget_config


@given(budget=st.one_of(st.none(), st.floats(min_value=1e-3, max_value=1e6)), degree=st.sampled_from(SH_DEGREES),
       fixed=st.booleans())
def test_only_the_default_degree_changes_and_only_from_a_long_budget(budget, degree, fixed):
    config = FieldConfig(sh_degree=degree)
    chosen = budget_config(config, budget, fixed={"sh_degree"} if fixed else ())
    long = budget is not None and budget >= LONG_BUDGET_S
    expected = LONG_BUDGET_SH_DEGREE if long and not fixed and degree == FieldConfig().sh_degree else degree
    assert chosen.sh_degree == expected, f"budget {budget} s, degree {degree}, fixed {fixed}: got {chosen.sh_degree}"
    assert chosen.replace(sh_degree=degree) == config, "a setting other than the SH degree changed"


def test_the_threshold_is_inclusive():
    assert budget_config(FieldConfig(), LONG_BUDGET_S).sh_degree == LONG_BUDGET_SH_DEGREE
    assert budget_config(FieldConfig(), math.nextafter(LONG_BUDGET_S, 0.0)).sh_degree == FieldConfig().sh_degree


@pytest.mark.parametrize("budget", [0.0, -5.0, math.nan, math.inf])
def test_a_budget_that_is_not_seconds_is_refused(budget):
    with pytest.raises(InvalidArgument, match=r"time_budget_s=.*: expected seconds > 0, or None"):
        budget_config(FieldConfig(), budget)
