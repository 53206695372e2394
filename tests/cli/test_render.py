"""``n2r render``: the depth preview as its help describes it (turbo, warm near and cool far over the object's own
depth range, black off the object), and ``--units scene`` moves the camera in scene units."""

from __future__ import annotations

import cv2
import numpy as np

from pytest_n2r.cli.main import main


def test_the_depth_preview_is_black_off_the_object_and_warm_near(tmp_path, capsys):

    out = tmp_path / "v.png"
    assert main(["render", "demo:object", "--size", "96", "--depth", "--opacity", "--device", "cpu",
                 "-o", str(out)]) == 0, capsys.readouterr().err
    depth = np.load(tmp_path / "v.depth.npy")
    opacity = cv2.imread(str(tmp_path / "v.opacity.png"), cv2.IMREAD_UNCHANGED) / 255.0
    preview = cv2.imread(str(tmp_path / "v.depth.png"))[:, :, ::-1].astype(int)
    solid = opacity >= 0.5
    assert 0 < solid.sum() < solid.size, "the view should show the object and some background"
    assert (preview[~solid] == 0).all(), "background not black"
    d = np.where(solid, depth, np.nan)
    near, far = np.unravel_index(np.nanargmin(d), d.shape), np.unravel_index(np.nanargmax(d), d.shape)
    assert preview[near][0] > preview[near][2], f"nearest pixel {preview[near]} is not warm"
    assert preview[far][2] > preview[far][0], f"farthest pixel {preview[far]} is not cool"


def test_the_depth_previews_colour_range_is_that_of_the_object(tmp_path, capsys):
    """The 1st to 99th percentile of the solid pixels' depth span the colour map: the nearest solid pixel is its
    warm end, the farthest its cool end."""

    out = tmp_path / "v.png"
    assert main(["render", "demo:object", "--size", "96", "--depth", "--opacity", "--device", "cpu",
                 "-o", str(out)]) == 0, capsys.readouterr().err
    depth = np.load(tmp_path / "v.depth.npy")
    opacity = cv2.imread(str(tmp_path / "v.opacity.png"), cv2.IMREAD_UNCHANGED) / 255.0
    preview = cv2.imread(str(tmp_path / "v.depth.png"))[:, :, ::-1]
    turbo = cv2.applyColorMap(np.array([[0, 255]], dtype=np.uint8), cv2.COLORMAP_TURBO)[0, :, ::-1]
    d = np.where(opacity >= 0.5, depth, np.nan)
    near, far = np.unravel_index(np.nanargmin(d), d.shape), np.unravel_index(np.nanargmax(d), d.shape)
    assert (preview[near] == turbo[1]).all() and (preview[far] == turbo[0]).all(), (preview[near], preview[far])


def test_render_units_scene_moves_by_scene_units(tmp_path, capsys):

    from pytest_n2r.demo import ground_truth
    from pytest_n2r.geometry import Transform

    out = tmp_path / "v.png"
    assert main(["render", "demo:wall", "--view", "0", "--transform", "x=0.3", "--units", "scene", "--size", "48",
                 "-o", str(out)]) == 0, capsys.readouterr().err
    scene = ground_truth("wall")
    view = scene.view(0)
    want = scene.render(Transform(x=0.3).apply(view.c2w, 1.0), view.camera.fit_within(48), ("rgb",)).rgb
    assert np.array_equal(cv2.imread(str(out))[:, :, ::-1], want)


def test_a_scene_of_ones_own_that_leaves_out_an_asked_output_is_refused_naming_it(tmp_path, capsys, monkeypatch):
    """A Scene whose ``_render`` returns no depth though asked for it: an error naming SCENE and the output, not a
    traceback from the depth preview, and nothing written."""
    import pytest_n2r.demo.scene_specs
    from pytest_n2r.demo import ground_truth

    scene = ground_truth("wall")
    full = scene._render
    monkeypatch.setattr(scene, "_render", lambda c2w, camera, outputs: {
        name: image for name, image in full(c2w, camera, outputs).items() if name != "depth"})
    monkeypatch.setattr(pytest_n2r.demo.scene_specs, "load_scene_spec", lambda spec, device, images: scene)
    assert main(["render", "demo:wall", "--size", "32", "--depth", "-o", str(tmp_path / "v.png")]) == 2
    assert "rendered nothing as 'depth'; its _render must return every output it is asked for" in \
        capsys.readouterr().err
    assert not list(tmp_path.iterdir())


# import.py -------------------------------------------------------------------------------------------------------


def test_a_file_in_the_way_of_the_depth_array_is_not_written_over(tmp_path, capsys):
    """``--depth -o v.png`` also writes ``v.depth.npy``: a file of the user's there that is no NumPy array is left
    as it is and named, unless ``--force``."""
    notes = tmp_path / "v.depth.npy"
    notes.write_text("my notes")
    assert main(["render", "demo:wall", "--size", "32", "--depth", "-o", str(tmp_path / "v.png")]) == 2
    assert "v.depth.npy" in capsys.readouterr().err
    assert notes.read_text() == "my notes" and not (tmp_path / "v.png").exists()
