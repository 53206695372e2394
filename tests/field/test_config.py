"""FieldConfig: every bad value is refused naming the setting (an initial opacity and sample spacing whose density
shift no scene file holds among them); the dict form round-trips."""

from __future__ import annotations

import json

import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from pytest_n2r.errors import InvalidArgument, SceneFileError
from pytest_n2r.field.config import LATER_SETTINGS, FieldConfig
from pytest_n2r.field.density import alpha_range, step_ratio_range
from pytest_n2r.field.grid import SceneField, check_field_metadata

from .fields import SPACE


@pytest.mark.parametrize("changes, message", [
    ({"resolutions": ()}, r"resolutions=\(\): expected increasing grid sizes in 8\.\.1024"),
    ({"resolutions": (32, 16), "stage_fractions": (0.5,)}, r"resolutions=\(32, 16\)"),
    ({"resolutions": (4,), "stage_fractions": ()}, r"resolutions=\(4,\)"),
    ({"resolutions": (16, 32), "stage_fractions": ()}, r"stage_fractions=\(\): expected 1 increasing fractions"),
    ({"stage_fractions": (0.35, 0.1)}, r"stage_fractions=\(0\.35, 0\.1\)"),
    ({"stage_fractions": (0.1, 1.0)}, r"in \(0, 1\)"),
    ({"shell": 0.0}, r"FieldConfig\.shell=0\.0: expected a finite number > 0"),
    ({"step_ratio": -1.0}, r"FieldConfig\.step_ratio=-1\.0"),
    ({"lr_density": float("nan")}, r"FieldConfig\.lr_density=nan"),
    ({"lr_color": "0.1"}, r"FieldConfig\.lr_color='0\.1'"),
    ({"alpha_init": 1.5}, r"alpha_init=1\.5"),
    ({"prune_alpha": 1.0}, r"prune_alpha=1\.0"),
    ({"prune_weight": 1.0}, r"prune_weight=1\.0"),
    ({"final_prune_alpha": 2.0}, r"FieldConfig\.final_prune_alpha=2\.0: expected a threshold in \[0, 1\)"),
    ({"distortion": -1e-3}, r"FieldConfig\.distortion=-0\.001: expected a finite number >= 0"),
    ({"random_background": 1}, r"FieldConfig\.random_background=1: expected True or False"),
    ({"sparsity": -0.1}, r"FieldConfig\.sparsity=-0\.1: expected a finite number >= 0"),
    ({"batch_rays": 0}, r"FieldConfig\.batch_rays=0: expected an integer >= 1"),
    ({"prune_every": 2.5}, r"FieldConfig\.prune_every=2\.5"),
    ({"prune_after": 0}, r"FieldConfig\.prune_after=0: expected an integer >= 1"),
    ({"sh_degree": 3}, r"FieldConfig\.sh_degree=3: expected 0, 1 or 2"),
])
def test_bad_values_are_refused_naming_the_setting(changes, message):
    with pytest.raises(InvalidArgument, match=message):
        FieldConfig(**changes)


def test_the_dict_form_round_trips_through_json():
    config = FieldConfig(resolutions=(16, 24, 40), stage_fractions=(0.2, 0.6), sh_degree=0, seed=7, sparsity=0.0)
    data = json.loads(json.dumps(config.to_dict()))
    assert FieldConfig.from_dict(data) == config, f"{data} does not rebuild {config}"
    assert data["resolutions"] == [16, 24, 40], "tuples are not stored as JSON lists"
    assert FieldConfig.from_dict({"seed": 3}) == FieldConfig(seed=3), "missing keys do not take the defaults"


def test_an_unknown_key_is_an_error_listing_the_known_ones():
    with pytest.raises(InvalidArgument, match=r"unknown keys \['learning_rate'\]; known: \[.*'lr_density'"):
        FieldConfig.from_dict({**FieldConfig().to_dict(), "learning_rate": 0.1})


def test_stages_follow_the_fractions():
    config = FieldConfig(resolutions=(16, 24, 40), stage_fractions=(0.2, 0.6))
    stages = [config.stage(p) for p in (0.0, 0.19, 0.2, 0.59, 0.6, 0.99)]
    assert stages == [0, 0, 1, 1, 2, 2], f"stage() at 0, .19, .2, .59, .6, .99 gave {stages}"


def test_settings_added_later_are_stored_only_where_they_differ_from_their_defaults():
    stored = FieldConfig().to_dict()
    assert not set(LATER_SETTINGS) & set(stored), f"{sorted(set(LATER_SETTINGS) & set(stored))} stored at defaults"
    changed = FieldConfig(max_pixels_per_voxel=0.0, detail_grid_max=512)
    assert changed.to_dict()["max_pixels_per_voxel"] == 0.0 and changed.to_dict()["detail_grid_max"] == 512
    assert FieldConfig.from_dict(changed.to_dict()) == changed
    assert FieldConfig.from_dict(stored) == FieldConfig()


@pytest.mark.parametrize("alpha_init, step_ratio, shift, alphas, ratios", [
    (1e-60, 0.5, "-137.5", "[1.86e-44, 1]", "[1e-62, 2.69e-17]"),
    (0.99, 0.001, "4605", "[3.72e-47, 0.0952]", "[0.0461, 1.24e+44]"),
    (5e-324, 8.0, "-inf", "[2.98e-43, 1]", "[0, 1.33e-280]"),  # the density underflows to 0
])
def test_a_density_shift_no_scene_file_holds_is_refused_before_the_fit(alpha_init, step_ratio, shift, alphas, ratios):
    """The whole fit used to run and then have save_scene refuse its field.density_shift."""
    with pytest.raises(InvalidArgument) as info:
        FieldConfig(alpha_init=alpha_init, step_ratio=step_ratio)
    message = str(info.value)
    expected = (f"FieldConfig.alpha_init={alpha_init!r} with step_ratio={step_ratio!r} gives the field a density "
                f"shift of {shift}, beyond the ±100 a scene file holds (every sample would be empty or opaque "
                f"alike): at step_ratio={step_ratio!r}, alpha_init must be in {alphas}; at alpha_init={alpha_init!r}, "
                f"step_ratio in {ratios}")
    assert message == expected, f"the refusal does not name both settings and the combinations allowed: {message}"


@settings(max_examples=300, deadline=None)
@given(st.floats(1e-300, 1.0, exclude_max=True), st.floats(1e-6, 1e6))
def test_a_config_is_accepted_exactly_where_a_scene_file_holds_its_fields_shift(alpha_init, step_ratio):
    """The config's check is the scene file's, and the ranges a refusal names are the ones accepted."""
    field = SceneField.empty(SPACE, 4, 0, alpha_init, step_ratio)
    try:
        check_field_metadata(field.metadata(), "scene.n2r")
        saved = True
    except SceneFileError:
        saved = False
    try:
        FieldConfig(alpha_init=alpha_init, step_ratio=step_ratio)
        accepted = True
    except InvalidArgument:
        accepted = False
    assert accepted == saved, (f"alpha_init={alpha_init!r}, step_ratio={step_ratio!r} (density shift "
                               f"{field.density_shift!r}): the config is {'' if accepted else 'not '}accepted, the "
                               f"scene file {'would' if saved else 'would not'} hold the field")
    lowest, highest = alpha_range(step_ratio)
    inside = lowest * (1 + 1e-9) <= alpha_init <= highest * (1 - 1e-9)
    assert not inside or accepted, (f"alpha_init={alpha_init!r} lies in the range {lowest!r}..{highest!r} named for "
                                    f"step_ratio={step_ratio!r}, yet the config is refused")
    shortest, longest = step_ratio_range(alpha_init)
    inside = shortest * (1 + 1e-9) <= step_ratio <= longest * (1 - 1e-9)
    assert not inside or accepted, (f"step_ratio={step_ratio!r} lies in the range {shortest!r}..{longest!r} named for "
                                    f"alpha_init={alpha_init!r}, yet the config is refused")


@pytest.mark.parametrize("changes, message", [
    ({"detail_grid_max": 4}, r"FieldConfig\.detail_grid_max=4: expected a grid size in 8\.\.1024"),
    ({"detail_grid_max": 4096}, r"FieldConfig\.detail_grid_max=4096: expected a grid size in 8\.\.1024"),
    ({"lr_final_ratio": 0.0}, r"FieldConfig\.lr_final_ratio=0\.0: expected a finite number > 0"),
    ({"lr_final_ratio": -0.5}, r"FieldConfig\.lr_final_ratio=-0\.5: expected a finite number > 0"),
    ({"tv": float("inf")}, r"FieldConfig\.tv=inf: expected a finite number >= 0"),
    ({"tv_density": -2e-5}, r"FieldConfig\.tv_density=-2e-05: expected a finite number >= 0"),
    ({"max_pixels_per_voxel": -1.0}, r"FieldConfig\.max_pixels_per_voxel=-1\.0: expected a finite number >= 0"),
])
def test_every_range_checked_setting_is_refused_out_of_range_naming_it(changes, message):
    """The settings the table above leaves out: a detail grid the fit cannot build, a learning rate decaying to
    zero or below, a negative or infinite regularization weight, each refused before any training time is spent."""
    with pytest.raises(InvalidArgument, match=message):
        FieldConfig(**changes)
