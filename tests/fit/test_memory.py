"""What a fit holds in memory: the stage estimate, the free memory, and the grid a fit moves to when the
wanted one would not fit (the fox's 30-step fit that moved an unpruned field to 384³ and was killed at 24 GB)."""

from __future__ import annotations

import warnings
from pathlib import Path

import numpy as np
import pytest
import torch

from pytest_n2r import host_memory as free_memory  # where the CPU reading lives (fit.free_memory asks it)
from pytest_n2r.errors import InvalidArgument
from pytest_n2r.field.config import FieldConfig
from pytest_n2r.field.grid import SceneField
from pytest_n2r.field.space import SceneSpace
from pytest_n2r.fit.free_memory import free_bytes
from pytest_n2r.fit.memory import (
    HEADROOM,
    GridChoice,
    GridMemoryLimit,
    choose_grid,
    fit_memory_bytes,
    memory_resolution,
    stage_bytes,
)

from .conftest import SHORT_CONFIG


def _field(resolution: int, occupied: np.ndarray | None = None, width_degree: int = 1, seed: int = 0) -> SceneField:
    """A sparse field of ``resolution``³ with random values on the vertices of ``occupied`` cells (all: None)."""
    field = SceneField.empty(SceneSpace((0.0, 0.0, 0.0), 1.0), resolution, width_degree, 0.01, 0.5, "cpu")
    if occupied is not None:
        field.occupancy = torch.as_tensor(occupied, dtype=torch.bool)
    field = field.compact()
    field.values = torch.randn(field.values.shape, generator=torch.Generator().manual_seed(seed))
    return field


def test_the_memory_ceiling_grows_with_memory_and_the_estimate_with_the_grid():
    sizes = [memory_resolution(gib * 2**30) for gib in (1, 4, 24)]
    assert sizes == sorted(sizes) and sizes[0] < sizes[-1]
    for r in sizes:
        assert fit_memory_bytes(r) <= max(gib * 2**30 for gib in (1, 4, 24))
    assert fit_memory_bytes(385) > fit_memory_bytes(384)
    assert fit_memory_bytes(384, occupied=0.2) > fit_memory_bytes(384, occupied=0.1)
    assert stage_bytes(384, 10**6, width=28) > stage_bytes(384, 10**6, width=13) > stage_bytes(384, 10**5)


@pytest.mark.parametrize("call, message", [
    (lambda: memory_resolution(0), "memory_bytes=0"),
    (lambda: memory_resolution(1000), "not even a 16³ grid"),
    (lambda: fit_memory_bytes(1), "resolution=1"),
    (lambda: fit_memory_bytes(64, occupied=0.0), "occupied=0.0"),
    (lambda: stage_bytes(64, -1), r"stored=-1: expected a vertex count in 0\.\.262144"),
    (lambda: stage_bytes(True, 0), "resolution=True"),
    (lambda: stage_bytes(64, 1, width=0), "width=0: expected float32 values a vertex >= 1"),
    (lambda: choose_grid(_field(16), 12, None), "wanted=12: expected a grid no coarser than the field's 16³"),
])
def test_bad_arguments_are_named(call, message):
    with pytest.raises(InvalidArgument, match=message):
        call()


def test_the_wanted_grid_where_it_fits_or_where_the_free_memory_is_unknown():
    field = _field(16)
    assert choose_grid(field, 48, None) == GridChoice(48, 48, stage_bytes(48, 48**3), None)
    plenty = 10 * stage_bytes(48, 48**3)
    choice = choose_grid(field, 48, plenty)
    assert choice.resolution == 48 and not choice.limited and choice.free == plenty


def test_a_grid_that_does_not_fit_gives_way_to_the_finest_that_does():
    field = _field(16)  # every cell occupied: upsampling stores every vertex of the finer grid
    free = int(stage_bytes(40, 40**3) / HEADROOM) + 1  # room for 40³, not for 41³ and above
    choice = choose_grid(field, 64, free)
    assert choice.limited and choice.resolution == 32, f"expected 32³ (16's multiple below 40), got {choice}"
    assert choice.needed == stage_bytes(64, 64**3) > HEADROOM * free
    assert "a 64³ grid would need" in choice.message() and "trained 32³ instead" in choice.message()
    stays = choose_grid(field, 64, stage_bytes(20, 20**3))
    assert stays.resolution == 16 and stays.limited, "nothing finer fits, so the field keeps its grid"


def test_a_sparse_field_is_sized_by_the_vertices_it_will_store_not_by_the_cube():
    occupied = np.zeros((15,) * 3, dtype=bool)
    occupied[7, 7, 7] = True
    sparse = _field(16, occupied)
    free = int(stage_bytes(64, 5000) / HEADROOM) + 1
    assert choose_grid(sparse, 64, free).resolution == 64, "one occupied cell fits where a full grid would not"
    assert choose_grid(_field(16), 64, free).resolution < 64


def test_the_chosen_grid_replaces_or_drops_its_stage_in_the_config():
    config = FieldConfig(resolutions=(48, 96, 256, 384), stage_fractions=(0.1, 0.35, 0.7))
    reduced = GridChoice(384, 320, 1, 1).applied_to(config, 3)
    assert reduced.resolutions == (48, 96, 256, 320) and reduced.stage_fractions == config.stage_fractions
    dropped = GridChoice(384, 256, 1, 1).applied_to(config, 3)
    assert dropped.resolutions == (48, 96, 256) and dropped.stage_fractions == (0.1, 0.35)
    middle = GridChoice(256, 96, 1, 1).applied_to(config, 2)
    assert middle.resolutions == (48, 96, 384) and middle.stage_fractions == (0.1, 0.7)


def test_a_fit_short_of_memory_trains_a_coarser_grid_and_says_so(capture48, monkeypatch, tmp_path):
    from pytest_n2r.cli.info import format_info
    from pytest_n2r.fit import fit
    from pytest_n2r.scene.file import read_scene_file, save_scene

    # room for a 32³ stage storing every vertex at SH degree 1, not for 64³ storing what the pruned field needs
    free = int(stage_bytes(32, 32**3) / HEADROOM) + 1
    monkeypatch.setattr("pytest_n2r.fit.field_fit.free_bytes", lambda device: free)
    with pytest.warns(GridMemoryLimit, match=r"at step 40, a 64³ grid would need .* instead") as caught:
        result = fit(capture48, SHORT_CONFIG.replace(resolutions=(16, 64)), max_steps=80, device="cpu")
    (limit,) = result.report["grid_limits"]
    trained = limit["trained"]
    assert limit["step"] == 40 and limit["wanted"] == 64 and 16 < trained < 64 and trained % 16 == 0, limit
    assert f"trained {trained}³ instead" in str(caught[0].message)
    assert result.field.resolution == trained and result.config.resolutions == (16, trained)
    assert np.isfinite(result.report["psnr"]), "the coarser field was not evaluated"
    path = save_scene(tmp_path / "limited.n2r", result.field, result.config, capture48, result.report, images=False)
    assert "  memory    at step 40, a 64³ grid would need" in format_info(read_scene_file(path, images=False))


def test_a_fit_with_no_memory_for_any_finer_grid_stays_on_its_own(capture48, monkeypatch):
    from pytest_n2r.fit import fit

    monkeypatch.setattr("pytest_n2r.fit.field_fit.free_bytes", lambda device: 1)
    with pytest.warns(GridMemoryLimit, match="trained 16³ instead"):
        result = fit(capture48, SHORT_CONFIG, max_steps=60, device="cpu")
    assert result.field.resolution == 16 and result.config.resolutions == (16,)
    assert result.config.stage_fractions == ()


def test_a_fit_with_memory_enough_reports_no_limit(short_fit):
    assert short_fit.report["grid_limits"] == [] and short_fit.field.resolution == 24


def test_a_middle_grid_that_does_not_fit_is_skipped_and_the_next_is_still_trained(capture48, monkeypatch):
    from pytest_n2r.fit import fit

    answers = iter([1, 10**12])  # no room at the move to 24³, plenty at the move to 32³
    monkeypatch.setattr("pytest_n2r.fit.field_fit.free_bytes", lambda device: next(answers))
    config = SHORT_CONFIG.replace(resolutions=(16, 24, 32), stage_fractions=(0.3, 0.6))
    with pytest.warns(GridMemoryLimit, match="at step 24, a 24³ grid would need .*: trained 16³ instead"):
        result = fit(capture48, config, max_steps=80, device="cpu")
    assert result.config.resolutions == (16, 32) and result.config.stage_fractions == (0.6,)
    assert result.field.resolution == 32, "the grid after the skipped one was not trained"
    assert [(r["wanted"], r["trained"]) for r in result.report["grid_limits"]] == [(24, 16)]
    assert set(result.report["step_ms"]) >= {"16", "32"} and "24" not in result.report["step_ms"], \
        f"the step phases name a grid that was not trained: {sorted(result.report['step_ms'])}"


def test_a_ladder_repeating_a_grid_size_still_fits(capture48):
    from pytest_n2r.fit import fit

    config = SHORT_CONFIG.replace(resolutions=(16, 16, 24), stage_fractions=(0.3, 0.6))
    result = fit(capture48, config, max_steps=40, device="cpu")
    assert result.field.resolution == 24 and result.report["grid_limits"] == []


@pytest.mark.parametrize("room, added", [(10**12, 32), (None, None)], ids=["trained", "no room"])
def test_the_report_names_an_added_grid_only_where_it_was_trained(capture48, monkeypatch, room, added):
    from pytest_n2r.fit import fit

    ladder = SHORT_CONFIG.replace(resolutions=(16, 24, 32), stage_fractions=(0.5, 0.7))  # as a detail grid adds
    monkeypatch.setattr("pytest_n2r.fit.field_fit.detailed_config", lambda config, detail: ladder)
    answers = iter([10**12, room or 1])
    monkeypatch.setattr("pytest_n2r.fit.field_fit.free_bytes", lambda device: next(answers))
    checkpoints = []
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", GridMemoryLimit)
        result = fit(capture48, SHORT_CONFIG, max_steps=80, device="cpu", checkpoint=checkpoints.append,
                     checkpoint_every_s=0.0)
    assert result.report["detail"]["grid_added"] == added, result.report["detail"]
    assert checkpoints[-1].report["grid_limits"] == result.report["grid_limits"], \
        "a checkpoint after the limit does not carry it"
    assert checkpoints[-1].config == result.config


def test_the_free_memory_is_the_tighter_of_the_kernels_and_the_cgroups(monkeypatch):
    monkeypatch.setattr(free_memory, "_meminfo_available", lambda: 8 << 30)
    monkeypatch.setattr(free_memory, "_cgroup_free", lambda: 3 << 30)
    assert free_bytes(torch.device("cpu")) == 3 << 30
    monkeypatch.setattr(free_memory, "_cgroup_free", lambda: None)
    assert free_bytes(torch.device("cpu")) == 8 << 30
    monkeypatch.setattr(free_memory, "_meminfo_available", lambda: None)
    assert free_bytes(torch.device("cpu")) is None


def _cgroup_tree(tmp_path: Path, lines: str, files: dict[str, str]) -> None:
    (tmp_path / "proc").mkdir()
    (tmp_path / "proc" / "cgroup").write_text(lines)
    for name, text in files.items():
        path = tmp_path / "sys" / name
        path.parent.mkdir(parents=True, exist_ok=True)
        path.write_text(text)


@pytest.mark.parametrize("lines, files, expected", [
    # cgroup v2: a container limited to 8 GiB using 5 GiB, 1 GiB of it reclaimable file cache
    ("0::/docker/abc\n", {"docker/abc/memory.max": str(8 << 30), "docker/abc/memory.current": str(5 << 30),
                          "docker/abc/memory.stat": f"anon 1\ninactive_file {1 << 30}\n", "memory.max": "max\n",
                          "memory.current": "123\n"}, 4 << 30),
    # cgroup v1: the parent's limit is the tighter one
    ("4:memory:/a/b\n3:cpu:/\n", {"memory/a/b/memory.limit_in_bytes": str(16 << 30),
                                   "memory/a/b/memory.usage_in_bytes": str(2 << 30),
                                   "memory/a/memory.limit_in_bytes": str(6 << 30),
                                   "memory/a/memory.usage_in_bytes": str(3 << 30)}, 3 << 30),
    ("0::/\n", {"memory.max": "max\n", "memory.current": "5\n"}, None),  # no limit
    ("garbage\n\n0::/\n", {"memory.max": "100\n", "memory.current": "40\n"}, 60),  # lines not of the form skipped
    ("0::/not/mounted/here\n", {"memory.max": str(1 << 30), "memory.current": "0\n"}, 1 << 30),  # no such folder
])
def test_a_containers_memory_limit_is_read_from_its_cgroup(tmp_path, monkeypatch, lines, files, expected):
    _cgroup_tree(tmp_path, lines, files)
    monkeypatch.setattr(free_memory, "_PROC_CGROUP", tmp_path / "proc" / "cgroup")
    monkeypatch.setattr(free_memory, "_CGROUP_ROOT", tmp_path / "sys")
    assert free_memory._cgroup_free() == expected


def test_the_free_memory_of_this_machine_is_known_and_positive():
    free = free_bytes(torch.device("cpu"))
    if free is None:
        pytest.skip("this system reports no free memory (no /proc/meminfo, no cgroup)")
    assert 0 < free < 2**50, f"free memory {free} bytes is not plausible"
