"""Every benchmark script keeps working: each one imports, and the cheap ones run on tiny inputs.

A benchmark publishes numbers in docs/; one that no longer runs (a renamed import, a changed API) would
leave those numbers unreproducible without anybody noticing.
"""

from __future__ import annotations

import importlib.util
import os
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest

ROOT = Path(__file__).resolve().parents[1]
SCRIPTS = sorted(p for p in (ROOT / "benchmarks").glob("*.py") if not p.name.startswith("_"))

#: Script -> (arguments for a run of a few seconds, a line fragment its output must contain, or a tuple of them).
SMOKE = {
    # 160x90: at 48x27 ORB (31-px borders) finds no keypoint, and a relation with nothing to compare fails
    "plugin_relation.py": (["--scene", "demo:object", "--examples", "3", "--size", "160x90"], "warm (disk) / cold"),
    "demo_render_speed.py": (["--poses", "1", "--size", "24x14"], "| object |"),
    # one relation that skips on the wall: the export, the caches and the table, without a cold kernel compile
    "main_job_compare.py": (["HEAD", "--warm", "1", "--", "-k", "test_cosine_similarity_tau1 and wall"],
                            "| HEAD ("),
    "demo_compare.py": (["HEAD", "--smoke"], "| object | HEAD"),
    "kernel_compile.py": (["--masks-only", "--collector", "off"], "with the cache the first process left"),
    "cold_timeline.py": (["HEAD", "--", "-k", "test_cosine_similarity_tau1 and wall"], "| pytest |"),
    "field_compare.py": (["demo:object", "HEAD", "--smoke"], "| HEAD ("),
    "mutations.py": (["--images", "8"], "LUT brightness is"),
    # one held-out view of the shipped twin, small: the placement analyses (a pose refined, 2×2 rays a pixel) and
    # the ceiling (the reference degraded; its points found again by each matching)
    "fidelity.py": (["demo:object-field", "--views", "1", "--size", "96", "--placement", "--ceiling"],
                    "with 2×2 rays a pixel:"),
    "render_speed.py": (["demo:object", "--smoke"], ("| 96×54 | adaptive=0 |", "| 96×54 | 1 |")),
    "render_settings.py": (["demo:object", "default", "t_stop=0.05 min_weight=0.03", "--smoke"],
                           "| t_stop=0.05 min_weight=0.03 |"),
    "splat_speed.py": (["--smoke"], "| 64×36 |"),
    "splat_compare.py": (["HEAD", "--smoke"], "| 64x36 | HEAD"),
    "splat_from_field.py": (["--smoke"], "| splats from the field |"),
    "render_fingerprint.py": (["--twins", "--steps", "4"], "| short-fit/file |"),
    "fit_profile.py": (["--capture", "wall", "--steps", "30", "--threads", "1", "--config", "resolutions=16,24",
                        "stage_fractions=0.5", "batch_rays=256"], "| 1 | all | 30 |"),
    # two small phone captures of the wall measured against their drawn gains (and the fox's, where ../shared is)
    "exposure.py": (["--scenes", "wall", "--size", "160", "--settings", "0.5:0.08", "0:0"], ("| wall | 0.5 : 0.08 |",
                                                                                            "| wall | 0 : 0 |")),
    # structure from motion at 160 px registers a few photos, or none (a row saying so): either way a table row
    "capture_poses.py": (["sfm", "--scenes", "wall", "--size", "160"], "| wall | 160 |"),
    # three draws of each ring: every turned photo found, whatever the steep rings give
    "upright_rings.py": (["--draws", "3", "--photos", "3", "8"], ("| 3 | 3 |", "turned photos found in 6 of 6 draws")),
    # the three fields of a tiny capture with shaken photos: every photo, the shaken left out, none shaken
    "shaken_photos.py": (["--scenes", "wall", "--size", "96", "--steps", "10", "--config", "resolutions=16,24",
                          "stage_fractions=0.5", "batch_rays=256"], ("| wall | shaken left out | 32 | 10 |",
                                                                     "wall: 10 photos shaken (10 of them fitted)")),
    # a tiny capture fitted plainly and corrected, scored with the share of each view the fitted photos did not see
    "phone_capture.py": (["--scenes", "wall", "--size", "96", "--steps", "10", "--config", "resolutions=16,24",
                          "stage_fractions=0.5", "batch_rays=256"],
                         ("| wall | plain | 10 |", "| wall | corrected | 10 |")),
    # a variant fitted with the per-photo appearance correction: the fit option a variant passes through
    "fit_budget.py": (["--scenes", "wall", "--size", "96", "--steps", "10", "--base", "default", "--variant", "tiny",
                       "resolutions=16,24", "stage_fractions=0.5", "batch_rays=256", "appearance=True"],
                      "| wall | tiny | 10 |"),
}


def _environment() -> dict[str, str]:
    env = dict(os.environ)
    env["PYTHONPATH"] = os.pathsep.join([str(ROOT), env.get("PYTHONPATH", "")])
    return env


def _import_benchmark(script: Path):
    """The benchmark module at ``script``, imported as a run imports it (the package and the script's folder first)."""
    spec = importlib.util.spec_from_file_location(f"_benchmark_{script.stem}", script)
    module = importlib.util.module_from_spec(spec)
    paths = [str(ROOT), str(ROOT / "benchmarks")]
    sys.path[:0] = paths
    try:
        spec.loader.exec_module(module)  # a script runs its work under `if __name__ == "__main__"` only
    finally:
        for path in paths:
            sys.path.remove(path)
    return module


@pytest.mark.parametrize("script", SCRIPTS, ids=[s.name for s in SCRIPTS])
def test_every_benchmark_imports_without_running(script: Path):
    module = _import_benchmark(script)
    assert callable(getattr(module, "main", None)), f"{script.name} has no main()"


def _object_view(index: int, size: int = 96):
    from pytest_n2r.demo import ground_truth
    from pytest_n2r.demo.rendered_capture import check_size

    scene = ground_truth("object")
    view = scene.views[index]
    return scene, view.c2w, check_size(size, view.camera)


def test_a_view_fitted_from_its_own_pose_has_nothing_unseen():
    scoring = _import_benchmark(ROOT / "benchmarks" / "_scoring.py")
    scene, c2w, camera = _object_view(0)
    view = scene.render(c2w, camera, ("rgb", "depth", "opacity"))
    unseen = scoring.FittedPhotos(scene, [(c2w, camera)]).unseen_mask(view)
    assert unseen.shape == view.opacity.shape and not unseen.any(), (
        f"{unseen.mean():.1%} of the view's own pixels counted unseen by a photo at its own pose")


def test_surface_hidden_from_the_fitted_photo_is_unseen_and_sky_never_is():
    """The object's near side, seen from the far side of its trajectory (view 24 of 48): in that photo's image but
    behind the object; a check by frame alone would count it seen (measured: 0.27 of the view unseen by frame,
    0.61 with the hidden surface)."""
    scoring = _import_benchmark(ROOT / "benchmarks" / "_scoring.py")
    from pytest_n2r.geometry import backproject, pixel_grid

    scene, c2w, camera = _object_view(0)
    _, far_c2w, far_camera = _object_view(24)
    view = scene.render(c2w, camera, ("rgb", "depth", "opacity"))
    fitted = scoring.FittedPhotos(scene, [(far_c2w, far_camera)])
    unseen = fitted.unseen_mask(view)
    solid = view.opacity >= 0.5
    points = backproject(pixel_grid(camera)[solid], view.depth[solid].astype(np.float64), camera, c2w)
    out_of_frame = float((~fitted.stack.sees(points)[0]).sum()) / solid.size
    assert not unseen[~solid].any(), "a pixel that hits no surface was counted unseen"
    assert unseen.mean() > out_of_frame + 0.2, (
        f"unseen {unseen.mean():.1%} against {out_of_frame:.1%} outside the far photo's frame: hidden surface missed")


@pytest.mark.parametrize("script", sorted(SMOKE), ids=sorted(SMOKE))
def test_cheap_benchmarks_run_on_tiny_inputs(script: str):
    args, expected = SMOKE[script]
    result = subprocess.run([sys.executable, str(ROOT / "benchmarks" / script), *args], cwd=ROOT,
                            env=_environment(), capture_output=True, text=True, timeout=300, check=False)
    assert result.returncode == 0, f"{script} {' '.join(args)} failed:\n{result.stdout}\n{result.stderr}"
    for fragment in expected if isinstance(expected, tuple) else (expected,):
        assert fragment in result.stdout, f"{script} printed no {fragment!r}:\n{result.stdout}"


def test_kernel_compile_reports_the_field_renderers_kernels():
    """The fitted twins' renderer compiles (docs/performance.md: its kernels' compile time is measured with this)."""
    args = ["--scene", "object-field", "--size", "16", "--collector", "off"]
    result = subprocess.run([sys.executable, str(ROOT / "benchmarks" / "kernel_compile.py"), *args], cwd=ROOT,
                            env=_environment(), capture_output=True, text=True, timeout=300, check=False)
    assert result.returncode == 0, f"kernel_compile.py {' '.join(args)} failed:\n{result.stdout}\n{result.stderr}"
    assert "| render_pixels | 1 |" in result.stdout, f"no compile of the field's kernel reported:\n{result.stdout}"


def test_kernel_compile_reports_the_training_kernels():
    args = ["--scene", "object", "--fit", "--collector", "off"]
    result = subprocess.run([sys.executable, str(ROOT / "benchmarks" / "kernel_compile.py"), *args], cwd=ROOT,
                            env=_environment(), capture_output=True, text=True, timeout=600, check=False)
    assert result.returncode == 0, f"kernel_compile.py {' '.join(args)} failed:\n{result.stdout}\n{result.stderr}"
    assert "| _composite_backward | 1 |" in result.stdout, f"no training kernel reported:\n{result.stdout}"


def test_capture_poses_perturb_fits_a_capture_with_a_turned_pose():
    """The other mode of capture_poses.py (SMOKE runs its structure from motion): a 5-step fit at 96 px."""
    args = ["perturb", "--size", "96", "--steps", "5", "--degrees", "10"]
    result = subprocess.run([sys.executable, str(ROOT / "benchmarks" / "capture_poses.py"), *args], cwd=ROOT,
                            env=_environment(), capture_output=True, text=True, timeout=300, check=False)
    assert result.returncode == 0, f"capture_poses.py {' '.join(args)} failed:\n{result.stdout}\n{result.stderr}"
    assert "| 10° |" in result.stdout, f"no turned photo reported:\n{result.stdout}"


@pytest.mark.parametrize("script, args", [
    ("fidelity.py", ["MISSING/fox.n2r"]),
    ("demo_accuracy.py", ["--scenes", "wall", "--fields", "MISSING"]),
    ("render_settings.py", ["MISSING/fox.n2r", "default"]),
], ids=["fidelity", "demo_accuracy", "render_settings"])
def test_a_missing_scene_file_is_a_usage_error_naming_it(script: str, args: list[str], tmp_path: Path):
    args = [a.replace("MISSING", str(tmp_path / "missing")) for a in args]
    result = subprocess.run([sys.executable, str(ROOT / "benchmarks" / script), *args], cwd=ROOT,
                            env=_environment(), capture_output=True, text=True, timeout=300, check=False)
    assert result.returncode == 2 and "Traceback" not in result.stderr, (
        f"{script} {' '.join(args)}: exit {result.returncode}, expected a usage error (2):\n{result.stderr}")
    assert str(tmp_path / "missing") in result.stderr, f"{script} did not name the missing file:\n{result.stderr}"


@pytest.mark.parametrize("script, args", [
    ("field_fit.py", ["--steps", "1"]),
    ("fit_profile.py", ["--capture", "wall", "--steps", "1"]),
    ("phone_capture.py", ["--steps", "1"]),
], ids=["field_fit", "fit_profile", "phone_capture"])
def test_an_unknown_fit_setting_is_a_usage_error_naming_it(script: str, args: list[str]):
    result = subprocess.run([sys.executable, str(ROOT / "benchmarks" / script), *args, "--config", "nosuch=1"],
                            cwd=ROOT, env=_environment(), capture_output=True, text=True, timeout=300, check=False)
    assert result.returncode == 2 and "Traceback" not in result.stderr, (
        f"{script} --config nosuch=1: exit {result.returncode}, expected a usage error (2):\n{result.stderr}")
    assert "unknown setting 'nosuch'" in result.stderr, f"{script} did not name the setting:\n{result.stderr}"


@pytest.mark.parametrize("args, message", [
    (["--steps", "5", "--eval-at", "1m"], "--eval-at: scores at training times within --budget"),
    (["--budget", "10m", "--eval-at", "5m,10m"], "--eval-at 600 s: expected training times below --budget 600 s"),
], ids=["with-steps", "past-the-budget"])
def test_field_fit_refuses_scoring_times_it_would_not_reach(monkeypatch, capsys, args: list[str], message: str):
    module = _benchmark_module(monkeypatch, "field_fit")
    with pytest.raises(SystemExit) as exit_info:
        module.main(args)
    err = capsys.readouterr().err
    assert exit_info.value.code == 2 and message in err, f"field_fit.py {' '.join(args)}: exit {exit_info.value}: {err}"


def test_every_smoke_run_names_an_existing_script():
    missing = sorted(set(SMOKE) - {s.name for s in SCRIPTS})
    assert not missing, f"SMOKE names scripts that do not exist: {missing}"


def test_field_fit_refuses_a_budget_that_is_not_a_duration(monkeypatch, capsys):
    module = _benchmark_module(monkeypatch, "field_fit")
    with pytest.raises(SystemExit) as exit_info:
        module.main(["--budget", "abc"])
    err = capsys.readouterr().err
    assert exit_info.value.code == 2 and "argument --budget: 'abc' is not a duration" in err, (
        f"field_fit.py --budget abc: exit {exit_info.value}, expected a usage error naming it: {err}")


def _benchmark_module(monkeypatch, name: str):
    monkeypatch.syspath_prepend(str(ROOT / "benchmarks"))
    spec = importlib.util.spec_from_file_location(f"_{name}", ROOT / "benchmarks" / f"{name}.py")
    module = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(module)
    return module


def test_main_job_compare_reads_the_sessions_split_not_a_relations(monkeypatch):
    module = _benchmark_module(monkeypatch, "main_job_compare")
    relation = "PASSED t.py::x: 10 examples; time render 7.47 s / SUT 0.12 s / metric 0.14 s of 9.57 s"
    session = ("time 33.9 s since pytest loaded pytest-n2r: start-up and collection 2.1 s; fixtures 1.1 s; relations "
               "30.7 s = render 22.27 s / SUT 0.25 s / metric 0.32 s / validity 0.30 s / field floors 6.70 s / "
               "search and other 0.83 s; other tests 0.0 s")
    assert module._SPLIT.search(relation) is None, "a relation's own split was taken for the session's"
    assert module._SPLIT.search(session).groupdict() == {"render": "22.27", "sut": "0.25", "metric": "0.32",
                                                         "validity": "0.30", "floors": "6.70"}


def test_capture_poses_scores_a_reconstruction_up_to_a_similarity_and_sets_turned_photos_apart(monkeypatch):
    from scipy.spatial.transform import Rotation

    module = _benchmark_module(monkeypatch, "capture_poses")
    rng = np.random.default_rng(0)
    truth = {}
    for k in range(12):
        c2w = np.eye(4)
        c2w[:3, :3] = Rotation.from_rotvec(rng.normal(0, 0.3, 3)).as_matrix()
        c2w[:3, 3] = [k * 0.5, rng.normal(0, 0.2), rng.normal(0, 0.2)]
        truth[f"p{k:02d}"] = c2w
    world = np.eye(4)  # a similarity of the world: what structure from motion is free to choose
    world[:3, :3] = Rotation.from_rotvec([0.4, -1.1, 2.0]).as_matrix() * 3.0
    world[:3, 3] = [1.0, -2.0, 0.5]
    estimated = {}
    for name, c2w in truth.items():
        est = world @ c2w
        est[:3, :3] /= 3.0
        estimated[name] = est
    right = module.score_poses(estimated, truth)
    assert right["consistent"] == 12 and right["others_rotation_deg"] is None, f"a right reconstruction: {right}"
    assert right["rotation_deg"][1] < 1e-5 and right["centre_pct"][1] < 1e-5, f"a right reconstruction: {right}"
    flip = Rotation.from_rotvec([0.0, 0.0, np.pi]).as_matrix()
    for name in ("p08", "p09", "p10", "p11"):  # turned half a turn about the world's z, centres moved
        estimated[name] = estimated[name].copy()
        estimated[name][:3, :3] = flip @ estimated[name][:3, :3]
        estimated[name][:3, 3] += [0.0, 5.0, 0.0]
    wrong = module.score_poses(estimated, truth)
    assert wrong["consistent"] == 8, f"four photos turned by 180° counted as consistent: {wrong}"
    assert wrong["rotation_deg"][1] < 1e-5 and wrong["centre_pct"][1] < 1e-5, f"the right eight scored: {wrong}"
    assert abs(wrong["others_rotation_deg"] - 180.0) < 1e-5, f"four photos turned by 180° scored: {wrong}"
    assert wrong["inconsistent"] == ["p08", "p09", "p10", "p11"] and right["inconsistent"] == [], wrong


class _Fitted(Exception):
    """Raised by a stand-in for ``fit``, carrying the config it was given."""


@pytest.mark.parametrize("args, fixed", [
    (["--budget", "20m"], {}),
    (["--budget", "40m", "--config", "sh_degree=1"], {"sh_degree": 1}),
    (["--budget", "10m"], {}),
    (["--steps", "5"], {}),
], ids=["long", "long-degree-given", "default", "steps"])
def test_field_fit_trains_what_n2r_fit_trains_for_the_budget(monkeypatch, tmp_path, args: list[str],
                                                              fixed: dict[str, int]):
    from types import SimpleNamespace

    from pytest_n2r.cli.fit import parse_duration
    from pytest_n2r.field.config import FieldConfig
    from pytest_n2r.fit.budget import LONG_BUDGET_S, budget_config

    module = _benchmark_module(monkeypatch, "field_fit")
    view = SimpleNamespace(image=np.zeros((9, 16, 3), np.float32))
    monkeypatch.setattr(module, "FOX", tmp_path)  # present, so the fit is reached without ../shared
    monkeypatch.setattr(module, "ingest", lambda *a, **k: SimpleNamespace(views=[view], train_views=[view],
                                                                          heldout_views=[]))

    def fake_fit(capture, config, **kwargs):
        raise _Fitted(config)

    monkeypatch.setattr(module, "fit", fake_fit)
    monkeypatch.setattr(module, "decide_appearance", lambda capture, appearance: (False, None))  # no photos here
    with pytest.raises(_Fitted) as fitted:
        module.main(args)
    steps = int(args[1]) if args[0] == "--steps" else None
    budget = None if steps is not None else parse_duration(args[1])
    expected = budget_config(FieldConfig().replace(**fixed), budget, max_steps=steps, fixed=set(fixed))
    long = budget is not None and budget >= LONG_BUDGET_S
    assert (expected != FieldConfig().replace(**fixed)) == long, f"{args}: the case does not test what it names"
    assert fitted.value.args[0] == expected, (
        f"field_fit.py {' '.join(args)} fitted {fitted.value.args[0]}, not what n2r fit trains: {expected}")
