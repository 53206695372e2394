"""Which grids a fit prunes thin haze from: its last, or from the caller's last on where a finer grid for the end
was added (the grid before it then runs at the last grid's speed)."""

from __future__ import annotations

import pytest
import torch

from pytest_n2r.field.config import FieldConfig
from pytest_n2r.fit import field_fit
from pytest_n2r.fit.field_fit import _Trainer

CONFIG = FieldConfig(resolutions=(16, 24, 32), stage_fractions=(0.3, 0.6), batch_rays=256, prune_alpha=1e-3,
                     final_prune_alpha=0.08)


def thresholds_by_stage(trainer: _Trainer, monkeypatch: pytest.MonkeyPatch) -> list[float]:
    """The opacity threshold of one prune on each of the trainer's grids."""
    seen: list[float] = []
    real = field_fit.pruned_occupancy

    def spy(field, grid, row_map, cell_weight, threshold, *args):
        seen.append(threshold)
        return real(field, grid, row_map, cell_weight, threshold, *args)

    monkeypatch.setattr(field_fit, "pruned_occupancy", spy)
    for stage in range(len(trainer.config.resolutions)):
        if stage:
            trainer.refine()
        for _ in range(3):
            trainer.step(1.0)
        trainer.prune()
    return seen


@pytest.mark.parametrize(("haze_from", "expected"), [(None, [1e-3, 1e-3, 0.08]), (1, [1e-3, 0.08, 0.08])],
                         ids=["the last grid", "from the second"])
def test_thin_haze_is_pruned_from_the_stage_given(capture48, monkeypatch, haze_from, expected):
    trainer = _Trainer(capture48, CONFIG, torch.device("cpu"), haze_from=haze_from)
    seen = thresholds_by_stage(trainer, monkeypatch)
    assert seen == expected, f"haze_from={haze_from}: the grids were pruned at opacities {seen}, expected {expected}"


def test_a_fit_that_adds_a_finer_grid_prunes_haze_from_the_callers_last_grid(capture48, monkeypatch):
    made = []

    class Spy(_Trainer):
        def __init__(self, *args, **kwargs):
            super().__init__(*args, **kwargs)
            made.append(self)

    monkeypatch.setattr(field_fit, "_Trainer", Spy)
    given = CONFIG.replace(resolutions=(16, 24), stage_fractions=(0.5,))
    monkeypatch.setattr(field_fit, "detailed_config", lambda config, detail: CONFIG)  # as if the photos asked for 32³
    field_fit.fit(capture48, given, max_steps=2, device="cpu")
    assert [t.haze_from for t in made] == [1], (
        f"a fit whose ladder {given.resolutions} was extended to {CONFIG.resolutions} pruned haze from stage "
        f"{[t.haze_from for t in made]}, expected 1 (its caller's last grid)")
