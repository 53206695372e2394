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


@pytest.mark.parametrize("weight", ["sparsity", "distortion"])
def test_each_prior_weight_adds_its_term_to_the_loss(capture48, weight):
    """The first step of two trainers that differ only in one prior's weight draws the same rays and renders the
    same colours: the losses differ by that prior. The sparsity prior is the mean opacity of a sample, which on the
    untrained field is ``alpha_init`` everywhere."""

    def first_step(value: float) -> tuple[float, float]:
        config = SHORT_CONFIG.replace(sparsity=0.0, distortion=0.0).replace(**{weight: value})
        return fit_module._Trainer(capture48, config, torch.device("cpu")).step(1.0)

    (plain, plain_psnr), (weighted, weighted_psnr) = first_step(0.0), first_step(1.0)
    assert weighted_psnr == plain_psnr, "the weight changed the rendered colours of the first step"
    assert weighted > plain + 1e-4, f"{weight}=1 left the loss at {weighted} (without it {plain}): the term is missing"
    if weight == "sparsity":
        assert weighted - plain == pytest.approx(SHORT_CONFIG.alpha_init, rel=0.02), (
            f"the sparsity term is {weighted - plain}, not the mean opacity of a sample ({SHORT_CONFIG.alpha_init})")


def test_the_learning_rate_decays_to_lr_final_ratio_over_the_fit(capture48, monkeypatch):
    """Step k of n steps runs at lr_final_ratio ** (k / n) of the configured rates."""
    scales = []
    real_step = fit_module._Trainer.step

    def spy(self, lr_scale):
        scales.append(lr_scale)
        return real_step(self, lr_scale)

    monkeypatch.setattr(fit_module._Trainer, "step", spy)
    config = SHORT_CONFIG.replace(resolutions=(16,), stage_fractions=(), lr_final_ratio=0.05)
    fit(capture48, config, max_steps=6, device="cpu")
    expected = [0.05 ** (k / 6) for k in range(6)]
    assert scales == pytest.approx(expected), f"learning-rate scales {scales}, expected {expected}"


def test_the_seed_draws_the_training_batches(capture48):
    config = SHORT_CONFIG.replace(resolutions=(16,), stage_fractions=())
    one, two = (fit(capture48, config.replace(seed=seed), max_steps=2, device="cpu") for seed in (1, 2))
    assert not torch.equal(one.field.values, two.field.values), "fits with seeds 1 and 2 gave the same field"


def test_the_history_scores_the_heldout_views(capture48, monkeypatch):
    """``report["history"]`` is held-out PSNR/SSIM during the fit: scored on the held-out photos, never the fitted."""
    scored = []
    real_evaluate = fit_module.evaluate_views

    def spy(field, views, *args, **kwargs):
        scored.append([v.name for v in views])
        return real_evaluate(field, views, *args, **kwargs)

    monkeypatch.setattr(fit_module, "evaluate_views", spy)
    config = SHORT_CONFIG.replace(resolutions=(16,), stage_fractions=())
    fit(capture48, config, max_steps=2, device="cpu", eval_at_s=(0.0,))
    heldout = [v.name for v in capture48.heldout_views]
    assert scored == [heldout], (f"the history scored {[len(names) for names in scored]} views, expected the "
                                 f"{len(heldout)} held-out; fitted ones among them: "
                                 f"{sorted({n for names in scored for n in names} - set(heldout))[:5]}")


def test_a_fit_ending_between_prunes_prunes_its_field_at_the_end(capture48, monkeypatch):
    """A fit ends wherever its budget, max_steps or stop() does, and its field is then pruned as at a prune (thin
    haze and cells the rays left empty dropped), not left as the last periodic prune and the steps since made it."""
    pruned = []
    real_prune = fit_module._Trainer.prune

    def spy(self):
        real_prune(self)
        pruned.append((self.steps, self.field.occupancy.clone()))

    monkeypatch.setattr(fit_module._Trainer, "prune", spy)
    config = SHORT_CONFIG.replace(resolutions=(16,), stage_fractions=(), prune_every=20, prune_after=20)
    result = fit(capture48, config, max_steps=30, device="cpu")
    assert [steps for steps, _ in pruned] == [20, 30], f"pruned after steps {[s for s, _ in pruned]}, not 20 and 30"
    assert torch.equal(result.field.occupancy, pruned[-1][1]), "the fitted field is not the one the last prune left"


def test_every_evaluation_due_is_recorded_when_it_falls_due(capture48):
    """Evaluations due by the same step are each recorded after it, none later or lost at the end of the fit."""
    config = SHORT_CONFIG.replace(resolutions=(16,), stage_fractions=())
    history = fit(capture48, config, max_steps=2, device="cpu", eval_at_s=(0.0, 0.0, 1e-9)).report["history"]
    assert [(h["seconds"], h["step"]) for h in history] == [(0.0, 1), (0.0, 1), (0.0, 1)], (
        f"three evaluations due after the first step were recorded as {history}")


def test_a_stop_ends_the_fit_there_and_the_report_says_whether_it_cut_the_fit_short(capture48):
    config = SHORT_CONFIG.replace(resolutions=(16,), stage_fractions=())
    asked = []

    def stop_after(steps: int):
        return lambda: asked.append(None) or len(asked) >= steps

    early = fit(capture48, config, max_steps=5, device="cpu", stop=stop_after(2)).report
    assert (early["steps"], early["stopped"]) == (2, True), (
        f"a stop after step 2 of 5: steps {early['steps']}, stopped {early['stopped']}")
    asked.clear()
    last = fit(capture48, config, max_steps=3, device="cpu", stop=stop_after(3)).report
    assert (last["steps"], last["stopped"]) == (3, False), (
        f"a stop after the last of 3 steps cut nothing short: steps {last['steps']}, stopped {last['stopped']}")
