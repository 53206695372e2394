"""``n2r fit``, ``n2r render`` and ``n2r info`` end to end on a 32×24 export of the demo object scene."""

from __future__ import annotations

import argparse
import contextlib
import io
import json
import os
import shutil
import signal
import sys
import zipfile
from pathlib import Path

import cv2
import numpy as np
import pytest

from pytest_n2r.cli.fit import parse_config_override, parse_duration, parse_durations
from pytest_n2r.cli.main import main
from pytest_n2r.errors import FitError
from pytest_n2r.geometry import Transform
from pytest_n2r.scene import load_scene, read_scene_file

from .conftest import TINY_CONFIG

#: ``--config`` flags giving :data:`TINY_CONFIG` (the fit test checks that they do).
TINY_FLAGS = ["--config", "resolutions=16,24", "--config", "stage_fractions=0.5", "--config", "batch_rays=256",
              "--config", "prune_every=10", "--config", "alpha_init=0.01"]


@pytest.fixture(scope="module")
def exported(tmp_path_factory) -> Path:
    """``n2r demo export object --size 32x24``: a transforms.json and its images."""
    out = tmp_path_factory.mktemp("export")
    assert main(["demo", "export", "object", "-o", str(out), "--size", "32x24"]) == 0
    return out / "transforms.json"


@pytest.fixture(scope="module")
def fitted(exported, tmp_path_factory) -> tuple[Path, str]:
    """``n2r fit`` of the export, 30 steps on the CPU; the scene file and what was printed."""
    path = tmp_path_factory.mktemp("fit") / "object.n2r"
    out = io.StringIO()  # capsys is function-scoped
    with contextlib.redirect_stdout(out):
        code = main(["fit", str(exported), "-o", str(path), "--downscale", "1", "--max-steps", "30", "--device", "cpu",
                     "--metres-per-unit", "1", "--eval-at", "0.001s", *TINY_FLAGS])
    assert code == 0, out.getvalue()
    return path, out.getvalue()


def test_fit_writes_a_complete_scene_and_prints_its_report(fitted, exported):
    path, printed = fitted
    scene = read_scene_file(path)
    report = scene.report
    assert report["complete"] is True and report["steps"] == 30 and report["device"] == "cpu"
    assert report["source"] == str(exported) and scene.config == TINY_CONFIG and scene.metres_per_unit == 1.0
    assert len(scene.views) == 48 and sum(v.split == "heldout" for v in scene.views) == 6
    assert all(v.image is not None for v in scene.views), "the photos were not stored"
    assert f"held out    PSNR {report['psnr']:.2f} dB" in printed, printed
    near = report["nearest_fitted"]
    assert (f"  nearest   fitted view {near['degrees']['median']:.1f}° and {near['distance']['median']:.3f} reference "
            f"lengths away (median; least {near['degrees']['min']:.1f}° and {near['distance']['min']:.3f})") in printed
    assert (f"training    PSNR {report['train_psnr']:.2f} dB, SSIM {report['train_ssim']:.4f} (mean of 8 training "
            "views") in printed, printed
    assert "complete: 30 steps" in printed and "images/object_008.png" in printed, printed
    [entry] = report["history"]
    # 0.001 s: any 30-step fit trains longer than that, however fast the machine (0.5 s was not always reached)
    assert entry["seconds"] == 0.001 and 0 < entry["step"] <= 30 and entry["psnr"] > 0, report["history"]
    assert f"after 0.001 s of training (step {entry['step']}): PSNR {entry['psnr']:.2f} dB" in printed, printed


def test_render_writes_rgb_depth_and_opacity_as_the_scene_renders_them(fitted, tmp_path, capsys):
    path, _ = fitted
    out = tmp_path / "views" / "moved.png"
    code = main(["render", str(path), "--view", "images/object_003.png", "--transform", "yaw=10,x=0.1",
                 "--size", "64x48", "--depth", "--opacity", "--device", "cpu", "-o", str(out)])
    assert code == 0, capsys.readouterr().err
    scene = load_scene(path, device="cpu", images=False)
    view = scene.view(3)
    camera = view.camera.resized(64, 48)
    c2w = Transform(yaw=10, x=0.1).apply(view.c2w, scene.reference_length)
    want = scene.render(c2w, camera, ("rgb", "depth", "opacity"))
    rgb = cv2.imread(str(out), cv2.IMREAD_UNCHANGED)[:, :, ::-1]
    assert np.array_equal(rgb, want.rgb), "the PNG is not the scene's render (RGB order?)"
    assert np.array_equal(np.load(tmp_path / "views" / "moved.depth.npy"), want.depth)
    grey = cv2.imread(str(tmp_path / "views" / "moved.opacity.png"), cv2.IMREAD_UNCHANGED)
    assert grey.shape == (48, 64) and np.abs(grey / 255.0 - want.opacity).max() <= 0.5 / 255 + 1e-6
    assert cv2.imread(str(tmp_path / "views" / "moved.depth.png")).shape == (48, 64, 3)
    assert sorted(p.name for p in (tmp_path / "views").iterdir()) == \
        ["moved.depth.npy", "moved.depth.png", "moved.opacity.png", "moved.png"]


def test_render_errors_name_the_option(fitted, tmp_path, capsys):
    path, _ = fitted
    assert main(["render", str(path), "--transform", "spin=3", "-o", str(tmp_path / "x.png")]) == 2
    assert "--transform='spin=3': unknown component 'spin'" in capsys.readouterr().err
    assert main(["render", str(path), "--view", "99", "-o", str(tmp_path / "x.png")]) == 2
    assert "view=99 is out of range; scene 'object' has 48 views" in capsys.readouterr().err
    assert not (tmp_path / "x.png").exists()


def test_info_prints_the_summary_and_json(fitted, capsys):
    path, _ = fitted
    assert main(["info", str(path)]) == 0
    text = capsys.readouterr().out
    for words in ("views       48: 42 train, 6 held out; 48 photos stored", "1 m per scene unit",
                  "fit         complete: 30 steps"):
        assert words in text, f"{words!r} missing from n2r info:\n{text}"
    assert main(["info", str(path), "--json"]) == 0
    data = json.loads(capsys.readouterr().out)
    assert (data["views"], data["heldout_views"], data["file_bytes"]) == (48, 6, path.stat().st_size)
    assert data["report"]["steps"] == 30 and data["field"]["resolution"] == 24


def test_info_on_a_bad_file_is_an_error_naming_it(tmp_path, capsys):
    bad = tmp_path / "bad.n2r"
    bad.write_bytes(b"nope")
    assert main(["info", str(bad)]) == 2
    assert f"n2r info: error: {bad}: not a zip archive" in capsys.readouterr().err


# -- interruptions ------------------------------------------------------------------------------------------------
def interrupting_fit(monkeypatch, error: BaseException, after_checkpoints: int) -> list[int]:
    """Make ``fit`` raise ``error`` from its progress callback once ``after_checkpoints`` checkpoints were
    written (as Ctrl-C or a crash would, mid-training); returns the steps of the checkpoints written."""
    from pytest_n2r import fit as fitting

    real_fit = fitting.fit
    written: list[int] = []

    def fit(*args, progress, checkpoint, **kwargs):
        def save(result):
            checkpoint(result)
            written.append(result.report["steps"])

        def report(info):
            progress(info)
            if len(written) >= after_checkpoints:
                raise error

        return real_fit(*args, progress=report, checkpoint=save, **kwargs)

    monkeypatch.setattr(fitting, "fit", fit)
    return written


def run_fit(exported: Path, out: Path, every: str, steps: str = "100000") -> int:
    return main(["fit", str(exported), "-o", str(out), "--downscale", "1", "--max-steps", steps, "--device",
                 "cpu", "--checkpoint-every", every, *TINY_FLAGS])


def kernel_wrapped_interrupt() -> SystemError:
    """Ctrl-C as numba reports it when the signal lands in a compiled kernel's call back into Python."""
    error = SystemError("CPUDispatcher(<function march_packed>) returned a result with an exception set")
    error.__cause__ = KeyboardInterrupt()
    return error


@pytest.mark.parametrize("interrupt", [KeyboardInterrupt, kernel_wrapped_interrupt], ids=["plain", "in-a-kernel"])
def test_ctrl_c_keeps_the_last_checkpoint_loadable(exported, tmp_path, monkeypatch, capsys, interrupt):
    written = interrupting_fit(monkeypatch, interrupt(), after_checkpoints=1)
    out = tmp_path / "object.n2r"
    assert run_fit(exported, out, "0.2") == 130
    err = capsys.readouterr().err
    assert written, "no checkpoint was written before the interrupt"
    assert f"interrupted; the last checkpoint (step {written[-1]}," in err and str(out) in err, err
    scene = load_scene(out, device="cpu")
    assert scene.report["complete"] is False and scene.report["steps"] == written[-1]
    view = scene.views[0]
    assert scene.render(view.c2w, view.camera).rgb.shape == (24, 32, 3)
    assert main(["info", str(out)]) == 0
    assert "checkpoint (the fit did not finish)" in capsys.readouterr().out


def test_ctrl_c_before_the_first_checkpoint_leaves_the_old_file(exported, tmp_path, monkeypatch, capsys):
    source = tmp_path / "capture"
    shutil.copytree(exported.parent, source)
    (source / "images" / "object_005.png").unlink()
    interrupting_fit(monkeypatch, KeyboardInterrupt(), after_checkpoints=0)
    out = tmp_path / "scenes" / "object.n2r"
    out.parent.mkdir()
    with zipfile.ZipFile(out, "w") as previous:  # what `n2r fit` may replace: a scene file (a zip with scene.json)
        previous.writestr("scene.json", "the previous scene")
    before = out.read_bytes()
    assert run_fit(source / "transforms.json", out, "100000") == 130
    err = capsys.readouterr().err
    assert "  skipped   " in err and "object_005.png" in err, \
        f"the missing photo is not listed:\n{err}"
    assert f"no checkpoint was written yet, so {out} was not touched" in err
    assert out.read_bytes() == before
    assert [p.name for p in out.parent.iterdir()] == ["object.n2r"], "temporary files were left behind"


@pytest.fixture
def interactive_ctrl_c():
    """Ctrl-C handled as in an interactive shell (Python's default handler) for the test, and what it was
    before restored after it: a background job, as CI may run the suite, starts with Ctrl-C ignored."""
    if sys.platform == "win32":
        pytest.skip("os.kill(pid, SIGINT) ends the process on Windows")
    previous = signal.signal(signal.SIGINT, signal.default_int_handler)
    yield
    signal.signal(signal.SIGINT, previous)


def press_ctrl_c(times: int = 1, seen: dict | None = None) -> bool:
    """Send this process ``times`` real SIGINTs; whether the first one returned without raising (also set as
    ``seen["deferred"]`` before the next press, which may raise)."""
    os.kill(os.getpid(), signal.SIGINT)
    if seen is not None:  # reached only when the first press raised nothing
        seen["deferred"] = True
    for _ in range(times - 1):
        os.kill(os.getpid(), signal.SIGINT)
    return True


def pressing_ctrl_c(monkeypatch, presses: int, after_checkpoints: int) -> dict:
    """Make ``fit`` press Ctrl-C ``presses`` times from its progress callback, once, after ``after_checkpoints``
    checkpoints were written. Returns what happened, filled in as the fit runs: ``written`` (the steps of the
    checkpoints), ``at`` (the step of the presses) and ``deferred`` (the first press raised nothing)."""
    from pytest_n2r import fit as fitting

    real_fit = fitting.fit
    seen: dict = {"written": [], "at": None, "deferred": False}

    def fit(*args, progress, checkpoint, **kwargs):
        def save(result):
            checkpoint(result)
            seen["written"].append(result.report["steps"])

        def report(info):
            progress(info)
            if len(seen["written"]) >= after_checkpoints and seen["at"] is None:
                seen["at"] = info["step"]
                press_ctrl_c(presses, seen)

        return real_fit(*args, progress=report, checkpoint=save, **kwargs)

    monkeypatch.setattr(fitting, "fit", fit)
    return seen


#: Steps that a fit of the tiny export cannot finish before a press (a stop that is not read fails the test
#: instead of fitting on).
PRESSED_STEPS = "3000"


def fit_pressed(exported: Path, out: Path, seen: dict, capsys) -> str:
    """Run the fit that :func:`pressing_ctrl_c` presses Ctrl-C in, checkpointing every 0.2 s; checks that it
    exited 130 and that the first press was read between steps, and returns what it printed to stderr."""
    assert run_fit(exported, out, "0.2", steps=PRESSED_STEPS) == 130
    assert seen["deferred"], "the first Ctrl-C raised at once instead of being read between steps"
    return capsys.readouterr().err


@pytest.mark.usefixtures("interactive_ctrl_c")
def test_a_real_ctrl_c_after_a_checkpoint_saves_the_field_trained_so_far(exported, tmp_path, monkeypatch, capsys):
    seen = pressing_ctrl_c(monkeypatch, presses=1, after_checkpoints=1)
    out = tmp_path / "object.n2r"
    err = fit_pressed(exported, out, seen, capsys)
    assert f"Ctrl-C: stopping here, then evaluating and saving the field trained so far (Ctrl-C again to quit " \
           f"at once, keeping the checkpoint of step {seen['written'][-1]})" in err, err
    report = load_scene(out, device="cpu").report
    assert report["stopped"] is True and report["complete"] is True, \
        f"expected a finished file of a stopped fit: stopped={report['stopped']}, complete={report['complete']}"
    assert report["steps"] == seen["at"], f"pressed at step {seen['at']}, stopped at {report['steps']}"
    assert report["psnr"] is not None, "the stopped field was not evaluated on the held-out views"
    assert f"interrupted; the field at step {report['steps']} (" in err and str(out) in err, err
    assert signal.getsignal(signal.SIGINT) is signal.default_int_handler, "the Ctrl-C handler was not restored"
    assert main(["info", str(out)]) == 0
    assert "fit         stopped before the end of its budget: " in capsys.readouterr().out


@pytest.mark.usefixtures("interactive_ctrl_c")
def test_a_second_real_ctrl_c_quits_at_once_keeping_the_last_checkpoint(exported, tmp_path, monkeypatch, capsys):
    seen = pressing_ctrl_c(monkeypatch, presses=2, after_checkpoints=1)
    out = tmp_path / "object.n2r"
    err = fit_pressed(exported, out, seen, capsys)
    written = seen["written"]
    assert f"interrupted; the last checkpoint (step {written[-1]}," in err, err
    report = load_scene(out, device="cpu").report
    assert report["complete"] is False and report["steps"] == written[-1], \
        f"expected the last checkpoint (step {written[-1]}), found complete={report['complete']} at {report['steps']}"
    assert signal.getsignal(signal.SIGINT) is signal.default_int_handler, "the Ctrl-C handler was not restored"


@pytest.mark.usefixtures("interactive_ctrl_c")
def test_a_second_ctrl_c_while_the_stopped_field_is_evaluated_keeps_the_checkpoint(exported, tmp_path, monkeypatch,
                                                                                   capsys):
    from pytest_n2r.fit import evaluate as evaluation

    seen = pressing_ctrl_c(monkeypatch, presses=1, after_checkpoints=1)
    real_evaluate = evaluation.evaluate_views

    def evaluate(*args, **kwargs):
        if seen["at"] is not None:  # the final evaluation of the stopped fit (evaluate.final_scores)
            press_ctrl_c()
        return real_evaluate(*args, **kwargs)

    monkeypatch.setattr(evaluation, "evaluate_views", evaluate)
    out = tmp_path / "object.n2r"
    err = fit_pressed(exported, out, seen, capsys)
    assert f"interrupted; the last checkpoint (step {seen['written'][-1]}," in err, err
    report = load_scene(out, device="cpu").report
    assert (report["complete"], report["steps"]) == (False, seen["written"][-1]), report
    assert signal.getsignal(signal.SIGINT) is signal.default_int_handler, "the Ctrl-C handler was not restored"


@pytest.mark.usefixtures("interactive_ctrl_c")
def test_a_ctrl_c_after_the_last_step_keeps_the_complete_field(exported, tmp_path, monkeypatch, capsys):
    from pytest_n2r.scene import file as scene_file

    real_save = scene_file.save_scene
    pressed = []

    def save(path, field, config, capture, report, **kwargs):
        if report["complete"] and not pressed:  # the final save of a fit that reached its steps
            pressed.append(press_ctrl_c())
        return real_save(path, field, config, capture, report, **kwargs)

    monkeypatch.setattr(scene_file, "save_scene", save)
    out = tmp_path / "object.n2r"
    assert run_fit(exported, out, "100000", steps="40") == 130
    assert pressed == [True], "the press during the final save was raised, not read"
    assert f"interrupted after training had ended; the complete field is saved in {out}" in capsys.readouterr().err
    report = load_scene(out, device="cpu").report
    assert (report["complete"], report["stopped"], report["steps"]) == (True, False, 40), report


@pytest.mark.usefixtures("interactive_ctrl_c")
def test_a_real_ctrl_c_before_the_first_checkpoint_leaves_the_output_untouched(exported, tmp_path, monkeypatch, capsys):
    seen = pressing_ctrl_c(monkeypatch, presses=1, after_checkpoints=0)
    out = tmp_path / "object.n2r"
    with zipfile.ZipFile(out, "w") as previous:  # what `n2r fit` may replace: a scene file (a zip with scene.json)
        previous.writestr("scene.json", "the previous scene")
    before = out.read_bytes()
    assert run_fit(exported, out, "100000", steps=PRESSED_STEPS) == 130
    assert seen["deferred"], "the first Ctrl-C raised at once instead of being read between steps"
    assert f"no checkpoint was written yet, so {out} was not touched" in capsys.readouterr().err
    assert out.read_bytes() == before
    assert [p.name for p in tmp_path.iterdir()] == ["object.n2r"], "temporary files were left behind"


@pytest.mark.usefixtures("interactive_ctrl_c")
def test_off_the_main_thread_ctrl_c_is_left_to_python():
    """Python runs signal handlers in its main thread only: elsewhere nothing is installed (and nothing fails)."""
    import threading

    from pytest_n2r.cli._interrupt import first_ctrl_c_deferred

    seen = []

    def body():
        with first_ctrl_c_deferred() as pressed:
            seen.append((pressed(), signal.getsignal(signal.SIGINT)))

    worker = threading.Thread(target=body)
    worker.start()
    worker.join()
    assert seen == [(False, signal.default_int_handler)], f"off the main thread: {seen}"


def test_a_process_started_with_ctrl_c_ignored_keeps_ignoring_it():
    """``nohup n2r fit …`` or a script's background job: Ctrl-C was ignored when the process started."""
    from pytest_n2r.cli._interrupt import first_ctrl_c_deferred

    previous = signal.signal(signal.SIGINT, signal.SIG_IGN)
    try:
        with first_ctrl_c_deferred() as pressed:
            during = signal.getsignal(signal.SIGINT)
            os.kill(os.getpid(), signal.SIGINT)
            seen = pressed()
    finally:
        signal.signal(signal.SIGINT, previous)
    assert (during, seen) == (signal.SIG_IGN, False), f"handler {during}, pressed {seen}: expected it left ignored"


@pytest.mark.parametrize(("error", "code"), [(kernel_wrapped_interrupt, 130), (SystemError, None)])
def test_any_command_reads_a_kernel_wrapped_ctrl_c_as_an_interrupt_and_nothing_else(monkeypatch, capsys, error, code):
    from pytest_n2r.cli import info

    def run(args):
        raise error()

    monkeypatch.setattr(info, "run", run)
    if code is None:
        with pytest.raises(SystemError):
            main(["info", "any.n2r"])
        return
    assert main(["info", "any.n2r"]) == code
    assert capsys.readouterr().err == "n2r info: interrupted\n"


def test_a_crash_keeps_the_last_checkpoint_and_exits_with_the_error(exported, tmp_path, monkeypatch, capsys):
    written = interrupting_fit(monkeypatch, FitError("the fit diverged at step 7"), after_checkpoints=1)
    out = tmp_path / "object.n2r"
    assert run_fit(exported, out, "0.2") == 2
    err = capsys.readouterr().err
    assert f"the fit failed; the last checkpoint (step {written[-1]}," in err, err
    assert "n2r fit: error: the fit diverged at step 7" in err, err
    assert read_scene_file(out).report["steps"] == written[-1]


# -- argument parsing ----------------------------------------------------------------------------------------------
@pytest.mark.parametrize(("text", "seconds"), [("10m", 600.0), ("90s", 90.0), ("1h30m", 5400.0), ("1m30", 90.0),
                                               ("45", 45.0), ("0.5m", 30.0)])
def test_durations(text, seconds):
    assert parse_duration(text) == seconds


@pytest.mark.parametrize("text", ["", "ten", "10x", "0", "m"])
def test_bad_durations_say_what_is_expected(text):
    with pytest.raises(argparse.ArgumentTypeError,
                       match=r"is not a duration; expected e\.g\. 10m|expected a duration > 0"):
        parse_duration(text)


def test_eval_times_are_sorted_durations():
    assert parse_durations("6m,1m,3m") == (60.0, 180.0, 360.0)
    with pytest.raises(argparse.ArgumentTypeError, match=r"'' is not a duration"):
        parse_durations("1m,,3m")


def test_config_overrides_are_literals_and_bad_ones_are_named(exported, tmp_path, capsys):
    assert parse_config_override("resolutions=16,24") == ("resolutions", (16, 24))
    assert parse_config_override("lr_density=1e-2") == ("lr_density", 0.01)
    with pytest.raises(argparse.ArgumentTypeError, match=r"--config 'seed=__import__\(\"os\"\)'"):
        parse_config_override('seed=__import__("os")')
    out = tmp_path / "x.n2r"
    assert main(["fit", str(exported), "-o", str(out), "--max-steps", "1", "--config", "warp=2"]) == 2
    assert "unknown setting 'warp'" in capsys.readouterr().err and not out.exists()


@pytest.mark.parametrize(("flags", "degree", "finest", "pixels"), [
    (["--time-budget", "20m"], 2, 256, 6.0),
    (["--time-budget", "29m"], 2, 256, 6.0),
    (["--time-budget", "30m"], 2, 256, 3.5),
    (["--time-budget", "1h"], 2, 256, 3.5),
    (["--time-budget", "1h", "--config", "max_pixels_per_voxel=6"], 2, 256, 6.0),
    (["--time-budget", "1h", "--config", "max_pixels_per_voxel=0"], 2, 256, 0.0),
    (["--time-budget", "20m", "--config", "seed=1"], 2, 256, 6.0),
    (["--time-budget", "20m", "--config", "sh_degree=1"], 1, 256, 6.0),
    (["--time-budget", "20m", "--config", "resolutions=32,96,224"], 2, 224, 6.0),
    (["--time-budget", "20m", "--config", "stage_fractions=0.1,0.35"], 2, 224, 6.0),
    (["--time-budget", "19m"], 1, 224, 6.0),
    (["--max-steps", "100000"], 1, 224, 6.0),
    (["--max-steps", "100000", "--time-budget", "1h"], 1, 224, 6.0),
])
def test_a_long_budget_fits_degree_2_colour_and_finer_grids_unless_they_are_given(exported, tmp_path, monkeypatch,
                                                                                capsys, flags, degree, finest, pixels):
    from pytest_n2r import fit as fitting

    chosen = []

    def fit(capture, config, **kwargs):  # what the fit was asked for; then stop before any training
        chosen.append(config)
        raise KeyboardInterrupt

    monkeypatch.setattr(fitting, "fit", fit)
    assert main(["fit", str(exported), "-o", str(tmp_path / "x.n2r"), "--downscale", "1", "--device", "cpu",
                 *flags]) == 130
    err = capsys.readouterr().err
    asked = [(c.sh_degree, c.resolutions[-1], c.max_pixels_per_voxel) for c in chosen]
    assert asked == [(degree, finest, pixels)], f"{flags}: the fits asked for were {chosen}"
    said = "colour      SH degree 2: it fits better than 1 from a 20-minute budget on" in err
    assert said == (degree == 2), f"{flags}: the choice of degree was {'' if said else 'not '}printed:\n{err}"
    if degree == 2:
        assert "--config sh_degree=1 keeps 1" in err
    said = "grid        32³ → 96³ → 256³: a finer last grid fits better from a 20-minute budget on" in err
    assert said == (finest == 256), f"{flags}: the choice of grids was {'' if said else 'not '}printed:\n{err}"
    if finest == 256:
        assert "--config resolutions=32,96,224 keeps the default grids" in err, f"{flags}: no way back said:\n{err}"
    said = ("detail      a finer grid for the last 30 % where a voxel spans more than 3.5 of the photos' pixels, "
            "not 6: it fits better from a 30-minute budget on") in err
    assert said == (pixels == 3.5), f"{flags}: the detail grid's sizing was {'' if said else 'not '}printed:\n{err}"
    if pixels == 3.5:
        assert "--config max_pixels_per_voxel=6 keeps 6" in err, f"{flags}: no way back said:\n{err}"


def test_fit_help_states_the_budget_rules_the_fit_applies(capsys):
    """``n2r fit --help`` writes the budgets out (the parser must not import torch to read them): this holds the
    text to :mod:`pytest_n2r.fit.budget`'s constants, so moving a threshold cannot leave the help behind."""
    from pytest_n2r.field.config import FieldConfig
    from pytest_n2r.fit.budget import (
        FINE_BUDGET_PIXELS_PER_VOXEL,
        FINE_BUDGET_S,
        LONG_BUDGET_RESOLUTIONS,
        LONG_BUDGET_S,
        LONG_BUDGET_SH_DEGREE,
    )

    with pytest.raises(SystemExit):
        main(["fit", "--help"])
    text = " ".join(capsys.readouterr().out.split())
    for rule in (f"from {LONG_BUDGET_S / 60:g}m on", f"SH degree {LONG_BUDGET_SH_DEGREE}",
                 f"end on {LONG_BUDGET_RESOLUTIONS[-1]}³", f"from {FINE_BUDGET_S / 60:g}m on",
                 (f"more than {FINE_BUDGET_PIXELS_PER_VOXEL:g} of the photos' pixels, "
                  f"not {FieldConfig().max_pixels_per_voxel:g}")):
        assert rule in text, f"n2r fit --help does not say {rule!r}:\n{text}"


def test_a_fit_short_of_memory_says_so_above_the_bar_and_in_the_report(exported, tmp_path, monkeypatch, capsys):
    monkeypatch.setattr("pytest_n2r.fit.field_fit.free_bytes", lambda device: 1)  # no room for any finer grid
    path = tmp_path / "small.n2r"
    assert main(["fit", str(exported), "-o", str(path), "--downscale", "1", "--max-steps", "30", "--device", "cpu",
                 *TINY_FLAGS]) == 0
    out, err = capsys.readouterr()
    assert "n2r fit: memory: at step 15, a 24³ grid would need" in err and "trained 16³ instead" in err, err
    assert "GridMemoryLimit" not in err, f"the warning was shown with its source line:\n{err}"
    assert "  memory    at step 15, a 24³ grid would need" in out, out
    scene = read_scene_file(path, images=False)
    assert scene.config.resolutions == (16,) and scene.report["grid_limits"][0]["trained"] == 16


def test_an_output_that_cannot_be_written_is_refused_before_fitting(exported, tmp_path, capsys):
    assert main(["fit", str(exported), "-o", str(tmp_path), "--max-steps", "1"]) == 2
    err = capsys.readouterr().err
    assert f"-o {tmp_path}: is a folder; expected the path of a .n2r scene file" in err, err
    assert "ingested" not in err, "the capture was ingested before the output was checked"


def test_every_setting_can_be_given_including_those_stored_only_when_changed():
    from pytest_n2r.cli.fit import build_config
    from pytest_n2r.field.config import LATER_SETTINGS, FieldConfig

    config = build_config([("max_pixels_per_voxel", 0.0), ("detail_grid_max", 512)])
    assert (config.max_pixels_per_voxel, config.detail_grid_max) == (0.0, 512), config
    for name in LATER_SETTINGS:  # their defaults are accepted too (an override that changes nothing)
        assert build_config([(name, getattr(FieldConfig(), name))]) == FieldConfig(), name


def test_fit_without_a_budget_trains_ten_minutes(exported, tmp_path, monkeypatch, capsys):
    """``n2r fit`` given neither ``--time-budget`` nor ``--max-steps`` trains for the documented 10 minutes."""
    from pytest_n2r import fit as fitting

    asked = {}

    def fit(*args, time_budget_s, max_steps, **kwargs):
        asked.update(time_budget_s=time_budget_s, max_steps=max_steps)
        raise FitError("stopped by the test")

    monkeypatch.setattr(fitting, "fit", fit)
    assert main(["fit", str(exported), "-o", str(tmp_path / "x.n2r"), "--downscale", "1", "--device", "cpu"]) == 2
    assert asked == {"time_budget_s": 600.0, "max_steps": None}, asked
    assert "stopped by the test" in capsys.readouterr().err


def test_fit_prints_each_photo_size_of_a_mixed_capture(tmp_path, monkeypatch, capsys):
    """A capture of landscape and portrait photos: ``n2r fit`` names both sizes and their counts, not one size."""
    from pytest_n2r import fit as fitting

    assert main(["demo", "export", "object", "-o", str(tmp_path / "cap"), "--size", "32x24"]) == 0
    path = tmp_path / "cap" / "transforms.json"
    meta = json.loads(path.read_text())
    frame = meta["frames"][0]  # turned to portrait: the photo and its camera
    photo = path.parent / frame["file_path"]
    cv2.imwrite(str(photo), cv2.rotate(cv2.imread(str(photo)), cv2.ROTATE_90_CLOCKWISE))
    frame.update(w=24, h=32, fl_x=meta["fl_y"], fl_y=meta["fl_x"], cx=meta["cy"], cy=meta["cx"])
    path.write_text(json.dumps(meta))

    def fit(*args, **kwargs):
        raise FitError("stopped by the test")

    monkeypatch.setattr(fitting, "fit", fit)
    assert main(["fit", str(path.parent), "-o", str(tmp_path / "x.n2r"), "--downscale", "1", "--max-steps", "1"]) == 2
    ingested = next(line for line in capsys.readouterr().err.splitlines() if line.startswith("ingested"))
    count = len(meta["frames"])
    assert f"32x24 ({count - 1} views), 24x32 (1 views)" in ingested, ingested
