"""numba's compiles during a fit: counted once each, never for a cached kernel, and kept out of its training time."""

from __future__ import annotations

import time

import numpy as np
import pytest
from numba import njit

from pytest_n2r.fit import field_fit as fit_module
from pytest_n2r.fit import fit
from pytest_n2r.fit.compile_clock import CompileClock

from .conftest import SHORT_CONFIG


def _fresh_kernel():
    """A kernel numba has not compiled (new function objects, no on-disk cache), calling another on first use."""

    @njit
    def inner(x):
        return x * 2.0 + 1.0

    @njit
    def outer(x):
        total = 0.0
        for i in range(x.shape[0]):
            total += inner(x[i])
        return total

    return outer


def test_a_compile_counts_once_with_the_compiles_it_sets_off_and_a_cached_kernel_not_at_all():
    clock, kernel = CompileClock(), _fresh_kernel()
    t0 = time.perf_counter()
    with clock.counting():
        assert kernel(np.ones(3)) == 9.0
        inside = clock.seconds
    wall = time.perf_counter() - t0
    # the inner function's compile lies inside the outer's: counted twice, the sum would pass the block's time
    assert 0.0 < inside == clock.seconds <= wall, f"{clock.seconds} s of compiles counted in a block of {wall} s"
    with clock.counting():
        kernel(np.ones(3))  # compiled: no compile event
    assert clock.seconds == inside, f"a compiled kernel's call counted {clock.seconds - inside} s"


def test_compiles_outside_the_block_do_not_count_and_a_raising_block_still_counts_its_own():
    clock = CompileClock()
    _fresh_kernel()(np.ones(2))
    assert clock.seconds == 0.0, f"a compile before the block counted {clock.seconds} s"
    with pytest.raises(ZeroDivisionError), clock.counting():
        _fresh_kernel()(np.ones(2))
        1 / 0  # noqa: B018 - the block ends by raising
    counted = clock.seconds
    assert counted > 0.0, "the compile of a block that raised was lost"
    _fresh_kernel()(np.ones(2))
    assert clock.seconds == counted, "the clock kept counting after its block raised"


def test_counting_twice_at_once_is_refused():
    clock = CompileClock()
    with clock.counting(), pytest.raises(RuntimeError, match=r"counting\(\) is running already"), \
            clock.counting():
        pass


@pytest.mark.slow
def test_a_fit_keeps_its_kernels_compiles_out_of_its_training_time_and_its_step_phases(capture48, monkeypatch):
    march = fit_module._Trainer.march

    def compiling_march(self, o, d):  # a compile inside every step's march phase, as a fresh installation's
        _fresh_kernel()(np.ones(2))
        return march(self, o, d)

    monkeypatch.setattr(fit_module._Trainer, "march", compiling_march)
    config = SHORT_CONFIG.replace(resolutions=(16,), stage_fractions=())
    t0 = time.perf_counter()
    result = fit(capture48, config, time_budget_s=1.0, device="cpu")
    wall = time.perf_counter() - t0
    report = result.report
    train, compiling, steps = report["train_seconds"], report["compile_seconds"], report["steps"]
    assert compiling > 0.0, "the fit counted no compile, though every step compiled a kernel"
    assert train >= 1.0 and train + compiling <= wall, (
        f"{steps} steps: {train} s of training and {compiling} s of compiles in {wall:.2f} s: the budget was not "
        "spent on training alone")
    phases_s = sum(report["step_ms"]["all"]["wall_ms"].values()) * steps / 1e3
    assert phases_s <= train + 0.01, f"the step phases sum to {phases_s:.3f} s of {train} s of training"


def test_n2r_info_says_how_long_a_fit_compiled_its_kernels_beside_its_training(short_fit, capture48, tmp_path):
    from pytest_n2r.cli.info import format_info
    from pytest_n2r.scene.file import read_scene_file, save_scene

    for compiling, shown in ((21.37, " (and 21.4 s compiling its kernels)"), (0.0, "")):
        report = {**short_fit.report, "train_seconds": 600.0, "compile_seconds": compiling}
        path = save_scene(tmp_path / f"c{compiling}.n2r", short_fit.field, short_fit.config, capture48, report,
                          images=False)
        line = next(line for line in format_info(read_scene_file(path, images=False)).splitlines()
                    if line.startswith("fit "))
        assert line.endswith(f"600.0 s of training{shown} on cpu ({short_fit.report['threads']} threads)"), line
