"""FieldConfig: every bad value is refused naming the setting; the dict form round-trips."""

from __future__ import annotations

import json

import pytest

from pytest_n2r.errors import InvalidArgument
from pytest_n2r.field.config import LATER_SETTINGS, FieldConfig


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
