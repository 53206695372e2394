"""`n2r study`'s --device and --size, checked before any scene is rendered."""

from __future__ import annotations

import pytest
import torch

import pytest_n2r.study
from pytest_n2r.cli.main import build_parser, main


@pytest.fixture
def no_study(monkeypatch):
    def ran(*_args: object, **_kw: object) -> None:
        raise AssertionError("the study ran: the arguments were not refused before the work")

    monkeypatch.setattr(pytest_n2r.study, "run_study", ran)


@pytest.mark.skipif(torch.cuda.is_available(), reason="needs a machine without CUDA")
def test_study_on_cuda_without_cuda_is_refused_as_render_refuses_it(tmp_path, capsys, no_study):
    """`n2r study --device cuda` without CUDA ran the exact demo scenes on the CPU (rc 0), where render refuses."""
    assert main(["study", "demo:wall", "--sut", "orb", "-o", str(tmp_path / "st"), "--device", "cuda"]) == 2
    assert "n2r study: error: device='cuda': CUDA is not available on this machine" in capsys.readouterr().err


def test_study_device_takes_cuda_n_and_shows_its_default():
    study = build_parser()._subparsers._group_actions[0].choices["study"]
    assert study.parse_args(["demo:wall", "--sut", "orb", "-o", "x", "--device", "cuda:1"]).device == "cuda:1"
    assert "auto, cpu or cuda[:N] (default: auto)" in " ".join(study.format_help().split())


def test_a_size_too_small_for_ssim_is_refused_before_rendering(tmp_path, capsys, no_study):
    """`--size 16` passed, and the study failed after rendering: a 16:9 view is 16x9 pixels, under SSIM's 11x11."""
    assert main(["study", "demo:wall", "--sut", "orb", "-o", str(tmp_path / "st"), "--size", "16"]) == 2
    err = capsys.readouterr().err
    assert ("n2r study: error: --size 16: view 'wall_000.png' of wall would render 16x9 pixels; the study scores "
            "renders with SSIM, which needs at least 11 pixels a side: --size 19 or more") in err, err


def test_a_scene_of_ones_own_that_renders_no_rgb_is_refused_naming_it(tmp_path, capsys, monkeypatch, no_study):
    """The probe a study tells imported SUTs' kinds with: a Scene whose ``_render`` returns no rgb is named, not
    handed to the SUT as None."""
    import pytest_n2r.demo.scene_specs
    from pytest_n2r.demo import ground_truth

    scene = ground_truth("wall")
    monkeypatch.setattr(scene, "_render", lambda c2w, camera, outputs: {})
    monkeypatch.setattr(pytest_n2r.demo.scene_specs, "load_scene_spec", lambda spec, device: scene)
    assert main(["study", "demo:wall", "--sut", "orb", "-o", str(tmp_path / "st")]) == 2
    assert "rendered nothing as 'rgb'; its _render must return every output it is asked for" in \
        capsys.readouterr().err
