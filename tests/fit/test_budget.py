"""What a time budget chooses for a fit (:mod:`pytest_n2r.fit.budget`)."""

from __future__ import annotations

import math

import pytest
from hypothesis import given
from hypothesis import strategies as st

from pytest_n2r.errors import InvalidArgument, InvalidType
from pytest_n2r.field.config import SH_DEGREES, FieldConfig
from pytest_n2r.fit.budget import (
    FINE_BUDGET_PIXELS_PER_VOXEL,
    FINE_BUDGET_S,
    LONG_BUDGET_RESOLUTIONS,
    LONG_BUDGET_S,
    LONG_BUDGET_SH_DEGREE,
    budget_config,
)

DEFAULT = FieldConfig()
LONG = (LONG_BUDGET_SH_DEGREE, LONG_BUDGET_RESOLUTIONS)
SHORT = (DEFAULT.sh_degree, DEFAULT.resolutions)


@pytest.mark.parametrize(("budget", "kwargs", "chosen"), [
    (1200.0, {}, LONG),
    (3600.0, {"fixed": {"seed", "tv"}}, LONG),  # other settings given: the budget still chooses these two
    (3600.0, {"fixed": {"resolutions"}}, (LONG_BUDGET_SH_DEGREE, DEFAULT.resolutions)),
    (3600.0, {"fixed": {"stage_fractions"}}, (LONG_BUDGET_SH_DEGREE, DEFAULT.resolutions)),
    (3600.0, {"fixed": {"sh_degree"}}, (DEFAULT.sh_degree, LONG_BUDGET_RESOLUTIONS)),
    (3600.0, {"fixed": {"sh_degree", "resolutions"}}, SHORT),
    (1199.0, {}, SHORT),
    (None, {}, SHORT),
    (3600.0, {"max_steps": 20_000}, SHORT),
])
def test_the_default_degree_and_grids_follow_a_long_time_budget(budget, kwargs, chosen):
    config = budget_config(DEFAULT, budget, **kwargs)
    got = (config.sh_degree, config.resolutions)
    assert got == chosen, f"budget {budget} s with {kwargs}: SH degree and grids {got}, expected {chosen}"
    assert config.stage_fractions == DEFAULT.stage_fractions, config.stage_fractions


@given(budget=st.one_of(st.none(), st.floats(min_value=1e-3, max_value=1e6)), degree=st.sampled_from(SH_DEGREES),
       ladder=st.sampled_from([(DEFAULT.resolutions, DEFAULT.stage_fractions), (DEFAULT.resolutions, (0.2, 0.5)),
                               ((48, 96, 192), DEFAULT.stage_fractions), ((32, 64, 128, 320), (0.1, 0.3, 0.6))]),
       pixels=st.sampled_from([DEFAULT.max_pixels_per_voxel, 0.0, 2.0]),
       fixed=st.sets(st.sampled_from(["sh_degree", "resolutions", "stage_fractions", "max_pixels_per_voxel", "tv"])),
       max_steps=st.one_of(st.none(), st.integers(1, 10**6)))
def test_only_default_settings_not_given_change_and_nothing_else(budget, degree, ladder, pixels, fixed, max_steps):
    (ladder, fractions), default_ladder = ladder, (DEFAULT.resolutions, DEFAULT.stage_fractions)
    config = FieldConfig(sh_degree=degree, resolutions=ladder, stage_fractions=fractions, max_pixels_per_voxel=pixels)
    chosen = budget_config(config, budget, max_steps=max_steps, fixed=fixed)
    short = budget is None or budget < LONG_BUDGET_S or max_steps is not None
    if short or budget < FINE_BUDGET_S or pixels != DEFAULT.max_pixels_per_voxel or "max_pixels_per_voxel" in fixed:
        assert chosen.max_pixels_per_voxel == pixels, f"{pixels} px a voxel, fixed {fixed}, budget {budget}: changed"
    else:
        assert chosen.max_pixels_per_voxel == FINE_BUDGET_PIXELS_PER_VOXEL, f"budget {budget} s, fixed {fixed}: kept"
    if short or degree != DEFAULT.sh_degree or "sh_degree" in fixed:
        assert chosen.sh_degree == degree, f"a degree {degree} config, fixed {fixed}, budget {budget} was changed"
    else:
        assert chosen.sh_degree == LONG_BUDGET_SH_DEGREE, f"budget {budget} s, fixed {fixed}: degree {degree} kept"
    if short or (ladder, fractions) != default_ladder or {"resolutions", "stage_fractions"} & fixed:
        assert chosen.resolutions == ladder, f"grids {ladder} at {fractions}, fixed {fixed}, budget {budget}: {chosen}"
    else:
        assert chosen.resolutions == LONG_BUDGET_RESOLUTIONS, f"budget {budget} s, fixed {fixed}: grids {ladder} kept"
    unchosen = chosen.replace(sh_degree=degree, resolutions=ladder, max_pixels_per_voxel=pixels)
    assert unchosen == config, "a setting not the budget's changed"


def test_the_thresholds_are_inclusive():
    long = DEFAULT.replace(sh_degree=LONG_BUDGET_SH_DEGREE, resolutions=LONG_BUDGET_RESOLUTIONS)
    assert budget_config(DEFAULT, LONG_BUDGET_S) == long
    assert budget_config(DEFAULT, math.nextafter(LONG_BUDGET_S, 0.0)) == DEFAULT
    assert budget_config(DEFAULT, FINE_BUDGET_S) == long.replace(max_pixels_per_voxel=FINE_BUDGET_PIXELS_PER_VOXEL)
    assert budget_config(DEFAULT, math.nextafter(FINE_BUDGET_S, 0.0)) == long


@pytest.mark.parametrize("budget", [0.0, -5.0, math.nan, math.inf, "10m", True])
def test_a_budget_that_is_not_seconds_is_refused(budget):
    expected = r"time_budget_s=.*: expected a finite number of seconds > 0, or None"
    with pytest.raises((InvalidArgument, InvalidType), match=expected):
        budget_config(FieldConfig(), budget)
