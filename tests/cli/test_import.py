"""``n2r import``: ``--heldout-every 0`` holds none out, the held-out count it prints, the background and name
it records, and the documented splat sizes when the source is a fitted scene."""

from __future__ import annotations

from pytest_n2r.cli.main import main

from ..splats.make_data import DATA, FILES


def test_import_heldout_every_0_holds_none_out(tmp_path, capsys):
    from pytest_n2r.scene import load_scene

    out = tmp_path / "s.n2r"
    assert main(["import", str(DATA / FILES["object-sh0"][0]), "-o", str(out), "--heldout-every", "0"]) == 0, \
        capsys.readouterr().err
    assert "(0 held out)" in capsys.readouterr().err
    assert not any(v.split == "heldout" for v in load_scene(out).views)


def test_import_background_and_its_name_and_held_count(tmp_path, capsys):
    from pytest_n2r.scene import load_scene

    out = tmp_path / "named.n2r"
    assert main(["import", str(DATA / FILES["object-sh0"][0]), "-o", str(out), "--background", "1,1,1"]) == 0
    err = capsys.readouterr().err
    scene = load_scene(out)
    held = sum(v.split == "heldout" for v in scene.views)
    assert 0 < held < len(scene.views)
    assert f"{len(scene.views)} views ({held} held out)" in err, err
    assert tuple(scene.background) == (1.0, 1.0, 1.0) and scene.name == "named"


def test_import_of_a_fitted_scene_uses_the_documented_defaults(tmp_path, capsys):
    from pytest_n2r.demo.fitted import packaged_path
    from pytest_n2r.scene.splat_file import splat_info
    from pytest_n2r.scene.splat_from_field import DEFAULT_PATH, DEFAULT_SIZE

    out = tmp_path / "splats.n2r"
    assert main(["import", str(packaged_path("wall")), "-o", str(out)]) == 0, capsys.readouterr().err
    made = splat_info(out)["report"]["from_field"]
    assert (made["size"], made["path"]) == (DEFAULT_SIZE, DEFAULT_PATH) == (0.4, 0.8)
