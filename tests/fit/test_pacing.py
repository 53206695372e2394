"""A fit paced by its time budget grows a grid only once pruned, and only where its measured steps predict growing
and a step on the finer grid to fit in what the budget has left (pytest_n2r/fit/phases.py): on a 64×36 capture a
20 s budget once grew an unpruned 96³ grid to a 100 %-occupied 224³ one and trained 44.5 s."""

from __future__ import annotations

import pytest

from pytest_n2r.fit import fit
from pytest_n2r.fit.phases import BUDGET_OVERRUN, StepPhases, growth_fits, step_fits

from .conftest import SHORT_CONFIG


def _step_s(report: dict, grid: str) -> float:
    """The mean wall seconds of a step on ``grid``, growth and pruning left out (as StepPhases.step_seconds)."""
    ms = report["step_ms"][grid]["wall_ms"]
    return sum(v for phase, v in ms.items() if phase not in ("prune", "refine")) / 1e3


def test_growth_and_steps_are_allowed_by_their_predicted_cost():
    assert growth_fits(None, 32, 96, 0.0), "a grid with no timed step has nothing to predict from"
    assert growth_fits(0.1, 96, 224, 2 * 0.1 * (224 / 96) ** 3)
    assert not growth_fits(0.1, 96, 224, 2 * 0.1 * (224 / 96) ** 3 - 0.01)
    assert step_fits(0.3, 0.01, 600.0) and step_fits(None, 0.0, 1.0)
    assert step_fits(2.0, 0.0, 20.0) and not step_fits(2.0 + 1e-6, 0.0, 20.0), f"overrun {BUDGET_OVERRUN}"
    phases = StepPhases()
    phases.start(16)
    assert phases.step_seconds(16) is None and phases.step_seconds(24) is None
    phases.steps[16] += 2
    phases.lap("march")
    phases.lap("prune")
    assert phases.step_seconds(16) == pytest.approx(phases.seconds[16][1, 0] / 2), "prune counted as a step's"


@pytest.mark.slow
def test_a_budgeted_fit_grows_no_grid_before_pruning_it(capture48):
    # due at 1 % of 3 s (a step or two on 16³), growth waits for the first prune: step 40 (every 20 from step 25)
    config = SHORT_CONFIG.replace(stage_fractions=(0.01,))
    report = fit(capture48, config, time_budget_s=3.0, device="cpu").report
    steps = {grid: row["steps"] for grid, row in report["step_ms"].items()}
    if "24" in steps:
        assert steps["16"] >= 40, f"the 16³ grid grew after {steps['16']} steps, before its first prune at step 40"
    else:  # 40 steps and the growth they price (6.75 steps) left no room: only on a machine 20× slower than ours
        assert 46.75 * _step_s(report, "16") > 3.0, f"the 24³ grid never grew, its 16³ steps: {report['step_ms']}"


@pytest.mark.slow
def test_a_budgeted_fit_grows_no_grid_its_measured_steps_price_past_the_budget(capture48):
    # 16³ → 128³ multiplies the cells 512×: growing and a step there are priced at 1 024 steps on 16³ (~3 s)
    config = SHORT_CONFIG.replace(resolutions=(16, 128), stage_fractions=(0.01,))
    budget = 1.0
    report = fit(capture48, config, time_budget_s=budget, device="cpu").report
    predicted = 2 * _step_s(report, "16") * 8 ** 3
    grids = sorted(grid for grid in report["step_ms"] if grid != "all")
    if predicted > budget:
        assert grids == ["16"], (f"the fit grew to 128³ although its 16³ steps priced that at {predicted:.2f} s "
                                 f"of a {budget} s budget: grids {grids}, {report['train_seconds']} s of training")
    seconds, steps = report["train_seconds"], report["steps"]
    assert seconds < budget + max(10.0 * seconds / steps, 0.5), f"{steps} steps took {seconds} s: the budget overran"


def test_a_grids_step_time_leaves_out_its_growth():
    """Refining to a grid is charged to it, but is no step of it: counted in, its steps are priced too dear and the
    budget starts fewer of them and grows no further grid."""
    phases = StepPhases()
    phases.start(24)
    phases.steps[24] += 2
    phases.seconds[24][StepPhases.NAMES.index("refine"), 0] = 5.0
    phases.seconds[24][StepPhases.NAMES.index("march"), 0] = 0.2
    phases.seconds[24][StepPhases.NAMES.index("prune"), 0] = 3.0
    assert phases.step_seconds(24) == pytest.approx(0.1), (
        f"two steps of 0.1 s after a 5 s growth and a 3 s prune: {phases.step_seconds(24)} s a step")


def test_a_budgeted_fit_starts_no_step_priced_past_its_budget(capture48, monkeypatch):
    """Once a step is timed, a step predicted to end more than BUDGET_OVERRUN of the budget past it is not started:
    here every step is priced at a minute, so a 0.5 s budget takes the one step that was not yet priced."""
    monkeypatch.setattr(StepPhases, "step_seconds", lambda self, grid: 60.0 if self.steps.get(grid) else None)
    config = SHORT_CONFIG.replace(resolutions=(16,), stage_fractions=())
    report = fit(capture48, config, time_budget_s=0.5, device="cpu").report
    assert report["steps"] == 1, (f"a 0.5 s budget started {report['steps']} steps priced at 60 s each "
                                  f"({report['train_seconds']} s of training)")
