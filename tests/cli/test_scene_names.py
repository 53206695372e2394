"""`n2r render`, `n2r info` and `n2r study` take every scene name `--n2r-scene` takes (`demo:<name>`, its fitted
twin `demo:<name>-field`, `module:function`, a 3DGS `.ply`, a `.n2r` file), through the plugin's own resolver."""

from __future__ import annotations

import json
import subprocess
import sys
from pathlib import Path

import cv2
import numpy as np
import pytest

import pytest_n2r.demo.scene_specs
import pytest_n2r.plugin.scenes
from pytest_n2r.cli.main import main
from pytest_n2r.demo.fitted import packaged_path
from pytest_n2r.render.size import RenderSize

from ..splats.make_data import DATA, FILES

PLANE = "tests.plugin.fakescene:plane"
SPLAT_PLY = str(DATA / FILES["object-sh0"][0])


def _plugin_render(name: str, view: str, size: str) -> np.ndarray:
    """The RGB the plugin's scene ``name`` renders at captured view ``view``, ``size`` as ``--size`` takes it."""
    from pytest_n2r.plugin.scenes import load_scene_spec, parse_scene_specs

    (spec,) = parse_scene_specs([name], Path.cwd(), "--n2r-scene")
    scene = load_scene_spec(spec, "cpu")
    shown = scene.view(view)
    return scene.render(shown.c2w, RenderSize.parse(size).apply(shown.camera), ("rgb",)).rgb


def _png(path: Path) -> np.ndarray:
    image = cv2.imread(str(path), cv2.IMREAD_UNCHANGED)
    assert image is not None, f"{path} is not a readable image"
    return image[:, :, ::-1]


def test_the_plugin_and_the_command_line_share_one_resolver():
    for name in ("SceneSpec", "parse_scene_specs", "default_scene_specs", "load_scene_spec", "DEMO_PREFIX"):
        assert getattr(pytest_n2r.plugin.scenes, name) is getattr(pytest_n2r.demo.scene_specs, name), name


@pytest.mark.parametrize(("name", "view"), [("demo:wall", "wall_004.png"), ("demo:wall-field", "wall_004.png"),
                                            (PLANE, "view1"), (SPLAT_PLY, "1")])
def test_render_of_a_scene_name_writes_what_the_plugins_scene_renders(name, view, tmp_path, capsys):
    out = tmp_path / "out.png"
    assert main(["render", name, "--view", view, "--size", "48", "--device", "cpu", "-o", str(out)]) == 0, \
        capsys.readouterr().err
    rendered = _png(out)
    expected = _plugin_render(name, int(view) if view.isdigit() else view, "48")
    assert max(rendered.shape[:2]) == 48
    np.testing.assert_array_equal(rendered, expected)


def test_info_of_an_exact_demo_scene_prints_its_views_cameras_and_scale(capsys):
    assert main(["info", "demo:wall"]) == 0
    out = capsys.readouterr().out
    assert out.startswith("scene       demo:wall: GroundTruthScene 'wall', exact renders"), out
    assert "views       48: 42 train, 6 held out" in out and "  camera    480x270" in out, out
    assert main(["info", "demo:wall", "--json"]) == 0
    info = json.loads(capsys.readouterr().out)
    assert (info["scene"], info["kind"], info["exact"], info["views"]) == ("demo:wall", "demo", True, 48)


def test_info_of_a_fitted_demo_twin_is_the_summary_of_its_scene_file(capsys):
    assert main(["info", "demo:wall-field", "--json"]) == 0
    assert json.loads(capsys.readouterr().out)["path"] == str(packaged_path("wall"))


def test_info_of_module_function_and_of_a_ply(capsys):
    assert main(["info", PLANE]) == 0
    out = capsys.readouterr().out
    assert f"scene       {PLANE}: PlaneScene 'plane', renders not exact" in out and "views       4:" in out, out
    assert main(["info", SPLAT_PLY, "--json"]) == 0
    info = json.loads(capsys.readouterr().out)
    assert (info["kind"], info["type"], info["name"]) == ("file", "SplatScene", "point_cloud"), info


def test_module_function_is_imported_from_the_working_folder(tmp_path, monkeypatch, capsys, request):
    """As ``python -m`` does: a user's scene module beside them imports without PYTHONPATH."""
    request.addfinalizer(lambda: sys.modules.pop("n2r_my_scenes", None))
    (tmp_path / "n2r_my_scenes.py").write_text("from pytest_n2r.demo import ground_truth\n\n\n"
                                               "def wall():\n    return ground_truth('wall')\n")
    monkeypatch.chdir(tmp_path)
    monkeypatch.setattr(sys, "path", [p for p in sys.path if p not in ("", str(tmp_path))])
    assert main(["render", "n2r_my_scenes:wall", "--view", "wall_004.png", "--size", "32", "-o", "out.png"]) == 0, \
        capsys.readouterr().err
    np.testing.assert_array_equal(_png(tmp_path / "out.png"), _plugin_render("demo:wall", "wall_004.png", "32"))


@pytest.mark.parametrize("command", [["info"], ["render", "-o", "{tmp}/out.png"], ["study", "--sut", "orb", "-o",
                                                                                  "{tmp}/study"]])
def test_a_name_that_is_no_scene_lists_what_a_scene_may_be(command, tmp_path, capsys):
    argv = [command[0], "castle", *(a.format(tmp=tmp_path) for a in command[1:])]
    assert main(argv) == 2
    err = " ".join(capsys.readouterr().err.split())
    assert f"n2r {command[0]}: error: SCENE 'castle': no such file (" in err, err
    for form in ("a .n2r scene file", "a 3DGS .ply", "'demo:<name>' for a built-in demo scene",
                 "'module:function' returning a Scene"):
        assert form in err, err
    assert "-o castle" not in err and "writes one)" in err  # not the advice to write a scene file named castle
    assert not list(tmp_path.iterdir()), "a refused command wrote a file"


def test_the_command_line_imports_no_pytest_for_a_demo_scene(tmp_path):
    code = ("import sys\nfrom pytest_n2r.cli.main import main\n"
            f"assert main(['render', 'demo:object', '--size', '28', '-o', {str(tmp_path / 'o.png')!r}]) == 0\n"
            "assert main(['info', 'demo:object']) == 0\n"
            "bad = sorted(m for m in sys.modules if m.split('.')[0] in ('pytest', '_pytest'))\n"
            "assert not bad, bad\n")
    result = subprocess.run([sys.executable, "-c", code], check=False, capture_output=True, text=True, timeout=300)
    assert result.returncode == 0, result.stderr


def test_a_ply_without_cameras_is_summarized_and_refused_by_render_naming_why(tmp_path, capsys):
    """n2r info raised the relations' 'no reference length' advice before printing anything, and n2r render an
    IndexError from scene.views[0]."""
    lone = tmp_path / "lone" / "lone.ply"
    lone.parent.mkdir()
    lone.write_bytes(Path(SPLAT_PLY).read_bytes())  # no cameras.json or transforms.json beside it
    assert main(["info", str(lone)]) == 0
    out = capsys.readouterr().out
    assert "views       0: 0 train, 0 held out" in out and "no reference length (no cameras)" in out, out
    assert main(["render", str(lone), "-o", str(tmp_path / "x.png")]) != 0
    err = capsys.readouterr().err
    assert "has no views to render (no cameras were given" in err and not (tmp_path / "x.png").exists(), err
