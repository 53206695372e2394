"""Fitting a field to a small exact capture: it learns, it is reproducible, it stops on NaN, and it checks
its arguments."""

from __future__ import annotations

import dataclasses

import numpy as np
import pytest
import torch

from pytest_n2r.errors import FitError, InvalidArgument, InvalidType
from pytest_n2r.field.config import FieldConfig
from pytest_n2r.field.grid import SceneField
from pytest_n2r.fit import evaluate_views, fit
from pytest_n2r.fit import field_fit as fit_module

from .conftest import SHORT_CONFIG, SHORT_STEPS

#: Held-out PSNR of the short fit, measured (bit-reproducible on one machine); the test allows 1.5 dB less.
MEASURED_PSNR = 18.6
#: The field before any step (opacity 0.01 per sample, grey) scores 9.6 dB; a black image 7.4 dB.
MIN_GAIN_DB = 5.0


def mean_psnr(field: SceneField, views) -> float:
    return float(np.mean([row["psnr"] for row in evaluate_views(field, views)]))


@pytest.mark.slow
def test_a_short_fit_reaches_the_measured_heldout_psnr(short_fit, capture48):
    heldout = capture48.heldout_views
    psnr = short_fit.report["psnr"]
    assert short_fit.report["steps"] == SHORT_STEPS and len(short_fit.report["heldout"]) == len(heldout) == 6
    assert psnr >= MEASURED_PSNR - 1.5, f"held-out PSNR {psnr} dB after {SHORT_STEPS} steps; measured {MEASURED_PSNR}"
    space = short_fit.field.space
    empty = SceneField.empty(space, SHORT_CONFIG.resolutions[0], SHORT_CONFIG.sh_degree, SHORT_CONFIG.alpha_init,
                             SHORT_CONFIG.step_ratio)
    before = mean_psnr(empty, heldout)
    assert psnr >= before + MIN_GAIN_DB, f"the fit scores {psnr} dB, the unfitted field {before:.2f} dB"
    assert abs(mean_psnr(short_fit.field, heldout) - psnr) < 1e-2, "the report's PSNR is not the field's"
    assert np.isfinite(short_fit.field.values.numpy()).all(), "the fitted values hold NaN or Inf"


@pytest.mark.parametrize("random_background, expected", [(True, (0.5, 0.5, 0.5)), (False, (0.0, 0.0, 0.0))])
def test_a_fitted_field_renders_over_the_mean_of_its_training_backgrounds(capture48, random_background, expected):
    result = fit(capture48, SHORT_CONFIG.replace(random_background=random_background), max_steps=1, device="cpu")
    assert result.field.background == expected, (
        f"random_background={random_background}: the field renders over {result.field.background}, "
        f"the mean of the training backgrounds is {expected}")


@pytest.mark.slow
def test_a_fit_with_max_steps_is_reproducible_bit_for_bit(short_fit, capture48):
    again = fit(capture48, SHORT_CONFIG, max_steps=SHORT_STEPS, device="cpu")
    assert again.field.values.numpy().tobytes() == short_fit.field.values.numpy().tobytes(), (
        "two fits with the same config and max_steps gave different values")
    assert torch.equal(again.field.occupancy, short_fit.field.occupancy), "the two fits' occupancies differ"
    assert again.report["heldout"] == short_fit.report["heldout"], "the two fits' held-out scores differ"


@pytest.mark.filterwarnings("error::UserWarning")  # the error path itself must not warn
def test_a_nan_in_a_step_raises_fit_error_naming_the_step(capture48, monkeypatch):
    real_apply = fit_module.Composite.apply
    calls = []

    def poisoned(sub, *args):
        calls.append(None)
        if len(calls) == 4:  # the fourth step (step index 3)
            sub = sub.clone()
            sub[0, 0] = float("nan")
        return real_apply(sub, *args)

    monkeypatch.setattr(fit_module.Composite, "apply", poisoned)
    with pytest.raises(FitError, match=r"diverged at step 3\b") as info:
        fit(capture48, SHORT_CONFIG.replace(resolutions=(16,), stage_fractions=()), max_steps=10, device="cpu")
    assert "nan" in str(info.value).lower(), f"the error does not say what went wrong: {info.value}"
    assert len(calls) == 4, f"the fit went on for {len(calls) - 4} steps after the NaN"


class _NaNGradient(torch.autograd.Function):
    """The identity whose gradient is NaN: a finite loss with a poisoned backward pass."""

    @staticmethod
    def forward(ctx, x: torch.Tensor) -> torch.Tensor:
        return x.clone()

    @staticmethod
    def backward(ctx, grad: torch.Tensor) -> torch.Tensor:
        return grad * float("nan")


def test_non_finite_gradients_raise_fit_error_naming_the_step(capture48, monkeypatch):
    real_apply = fit_module.Composite.apply
    calls = []

    def poisoned(*args):
        calls.append(None)
        rgb, *rest = real_apply(*args)
        return (_NaNGradient.apply(rgb) if len(calls) == 3 else rgb), *rest

    monkeypatch.setattr(fit_module.Composite, "apply", poisoned)
    with pytest.raises(FitError, match=r"diverged at step 2: non-finite gradients"):
        fit(capture48, SHORT_CONFIG.replace(resolutions=(16,), stage_fractions=()), max_steps=10, device="cpu")
    assert len(calls) == 3, f"the fit went on for {len(calls) - 3} steps after the NaN gradient"


@pytest.mark.parametrize("case, expected", [
    ("no images", ("capture 'demo:object' has no training view with an image: its 42 training views were loaded "
                   "without images; load it with images")),
    ("all held out", "capture 'demo:object' has no training view: all 48 of its views are held out"),
    ("no views", "capture 'demo:object' has no training view: it has no views"),
])
def test_a_capture_without_training_images_is_a_fit_error_saying_why(capture48, case, expected):
    """Held-out views used to be told to load their images, and no views at all to end in a bare ValueError."""
    views = {"no images": [dataclasses.replace(v, image=None) for v in capture48.views],
             "all held out": [dataclasses.replace(v, split="heldout") for v in capture48.views],
             "no views": []}[case]
    try:
        fit(dataclasses.replace(capture48, views=views), SHORT_CONFIG, max_steps=1, device="cpu")
    except FitError as error:
        assert str(error) == expected, f"{case}: the fit error does not say why there is nothing to train on: {error}"
    except Exception as error:  # noqa: BLE001 - what the fit raised instead is the finding
        pytest.fail(f"{case}: the fit raised {error!r}, not a FitError saying why there is nothing to train on")
    else:
        pytest.fail(f"{case}: the fit ran without a training view")


@pytest.mark.parametrize("kwargs, message", [
    ({}, "needs time_budget_s or max_steps"),
    ({"time_budget_s": -1}, r"time_budget_s=-1: expected a finite number of seconds > 0"),
    ({"time_budget_s": float("nan")}, r"time_budget_s=nan"),
    ({"time_budget_s": "10m"}, r"time_budget_s='10m': expected a finite number of seconds > 0, or None, not str"),
    ({"max_steps": 0}, r"max_steps=0: expected an integer >= 1"),
    ({"max_steps": 2.5}, r"max_steps=2.5: expected an integer"),
    ({"max_steps": True}, r"max_steps=True: expected an integer >= 1"),
    ({"max_steps": 1, "device": "tpu"}, r"device='tpu': expected 'auto', 'cpu' or 'cuda\[:N\]'"),
])
def test_bad_fit_arguments_are_named(capture48, kwargs, message):
    with pytest.raises((InvalidArgument, InvalidType), match=message):
        fit(capture48, SHORT_CONFIG, **kwargs)


@pytest.mark.skipif(torch.cuda.is_available(), reason="this machine has CUDA")
def test_cuda_without_cuda_is_named(capture48):
    with pytest.raises(InvalidArgument, match=r"device='cuda': CUDA is not available on this machine"):
        fit(capture48, SHORT_CONFIG, max_steps=1, device="cuda")


@pytest.mark.slow
def test_a_fit_with_a_short_prune_period_still_learns(capture48):
    """Pruning early and often (every 10 steps from step 10) must not empty a field that is still forming.
    (With the default alpha_init=1e-4, 30 steps of 256 rays are too few to show anything: 7.7 dB.)"""
    config = FieldConfig(resolutions=(16, 24), stage_fractions=(0.5,), batch_rays=256, prune_every=10,
                         prune_after=10, alpha_init=1e-2)
    result = fit(capture48, config, max_steps=30, device="cpu")
    occupied = result.report["field"]["occupied_fraction"]
    assert occupied > 0, f"the fit pruned every cell (prune_every=10, alpha_init={config.alpha_init})"
    assert result.report["psnr"] > 7.44 + 3.0, f"held-out PSNR {result.report['psnr']} dB: the fit learned nothing"


@pytest.mark.slow
def test_the_final_prune_threshold_thins_the_finest_grid_without_losing_the_fit(short_fit, capture48):
    """On the finest grid cells below ``final_prune_alpha`` are dropped (measured: 51 % of cells stay
    occupied at the default 0.08, all of them at the coarse threshold), and the fit scores no worse for it."""
    coarse_only = fit(capture48, SHORT_CONFIG.replace(final_prune_alpha=SHORT_CONFIG.prune_alpha),
                      max_steps=SHORT_STEPS, device="cpu")
    thinned, kept = short_fit.report["field"]["occupied_fraction"], coarse_only.report["field"]["occupied_fraction"]
    assert thinned < 0.8 * kept, (f"final_prune_alpha={SHORT_CONFIG.final_prune_alpha} left {thinned:.0%} of "
                                  f"the cells occupied, against {kept:.0%} without it")
    assert short_fit.report["psnr"] >= coarse_only.report["psnr"] - 0.5, (
        f"thinning cost {coarse_only.report['psnr'] - short_fit.report['psnr']:.2f} dB of held-out PSNR")


def test_checkpoints_and_evaluations_come_when_asked(capture48):
    checkpoints = []
    config = SHORT_CONFIG.replace(resolutions=(16,), stage_fractions=())
    result = fit(capture48, config, max_steps=5, device="cpu", checkpoint=checkpoints.append,
                 checkpoint_every_s=0.0, eval_at_s=(0.0, 1e6))
    steps = [c.report["steps"] for c in checkpoints]
    assert steps == [1, 2, 3, 4, 5], f"checkpoint_every_s=0 gave checkpoints after steps {steps}; expected every step"
    last = checkpoints[-1].field
    assert last.values.numpy().tobytes() == result.field.values.numpy().tobytes(), \
        "the last checkpoint is not the final (quantized) field of a fit without a final prune"
    assert torch.equal(last.values, last.values.half().float()), "a checkpoint holds values float16 cannot store"
    history = result.report["history"]
    assert [h["seconds"] for h in history] == [0.0] and history[0]["step"] == 1, (
        f"eval_at_s=(0, 1e6) recorded {history}; expected one evaluation after the first step")
    assert np.isfinite(history[0]["psnr"]) and result.report["eval_seconds"] > 0


@pytest.mark.slow
def test_a_time_budget_stops_the_fit_after_the_step_that_spends_it(capture48):
    config = SHORT_CONFIG.replace(resolutions=(16,), stage_fractions=())
    result = fit(capture48, config, time_budget_s=1.0, device="cpu")
    steps, seconds = result.report["steps"], result.report["train_seconds"]
    assert steps >= 1 and seconds >= 1.0, f"a 1 s budget stopped after {steps} steps and {seconds} s"
    assert seconds < 1.0 + max(10.0 * seconds / steps, 0.5), f"{steps} steps took {seconds} s: the budget overran"


def test_the_report_says_where_each_grids_steps_spent_their_time(short_fit):
    step_ms = short_fit.report["step_ms"]
    assert set(step_ms) == {"16", "24", "all"}, f"expected one entry per grid and 'all', got {sorted(step_ms)}"
    assert step_ms["16"]["steps"] + step_ms["24"]["steps"] == step_ms["all"]["steps"] == SHORT_STEPS
    phases = ("rays", "march", "corners", "forward", "backward", "update", "prune", "refine")
    for grid, row in step_ms.items():
        for kind in ("wall_ms", "cpu_ms"):
            assert set(row[kind]) == set(phases), f"{grid} {kind}: {sorted(row[kind])}"
            assert all(ms >= 0 for ms in row[kind].values()), f"{grid} {kind}: {row[kind]}"
    assert step_ms["16"]["wall_ms"]["refine"] == 0 < step_ms["24"]["wall_ms"]["refine"], "refining is charged to 24³"
    assert step_ms["all"]["wall_ms"]["backward"] > 0 and step_ms["all"]["wall_ms"]["prune"] > 0
    # the phases cover the training time (the rest is the loop's own bookkeeping)
    total_s = sum(step_ms["all"]["wall_ms"].values()) * SHORT_STEPS / 1e3
    assert 0.8 * short_fit.report["train_seconds"] <= total_s <= short_fit.report["train_seconds"] + 0.01, \
        f"phases sum to {total_s:.3f} s of {short_fit.report['train_seconds']} s of training"
