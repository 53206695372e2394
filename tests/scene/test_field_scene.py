"""FieldScene and load_scene: what the plugin renders, its content hash, and the fitted tiny scene."""

from __future__ import annotations

import numpy as np
import pytest

import pytest_n2r
from pytest_n2r.errors import InvalidArgument
from pytest_n2r.geometry import Transform
from pytest_n2r.plugin.scenes import SceneSpec, load_scene_spec
from pytest_n2r.render.field_render import FieldRenderer, RenderSettings
from pytest_n2r.scene import FieldScene, load_scene, save_scene

from .conftest import TINY_STEPS, random_field, tiny_views


@pytest.fixture
def scene_path(tmp_path):
    from pytest_n2r.field.config import FieldConfig

    return save_scene(tmp_path / "orbit.n2r", random_field(), FieldConfig(), tiny_views(), {"psnr": 20.0},
                      reference_length=3.0, metres_per_unit=0.5)


def test_load_scene_gives_the_views_photos_scale_and_report(scene_path):
    scene = load_scene(scene_path, device="cpu")
    assert isinstance(scene, FieldScene) and scene.name == "orbit" and scene.backend == "compiled"
    assert [v.name for v in scene.views] == [v.name for v in tiny_views()]
    assert all(v.image is not None and v.image.shape == (16, 20, 3) for v in scene.views)
    assert (scene.reference_length, scene.metres_per_unit, scene.report) == (3.0, 0.5, {"psnr": 20.0})
    assert scene.view("frame_002.png").index == 2
    assert all(v.image is None for v in load_scene(scene_path, device="cpu", images=False).views)


@pytest.mark.parametrize("sh_degree", [0, 2])
def test_a_scene_file_keeps_the_fields_sh_degree(tmp_path, sh_degree):
    """Every degree a field can have goes through a scene file: read back, the field has that degree, its colour
    columns, and renders as the field before saving does once its values are rounded to the file's float16."""
    from pytest_n2r.field.config import FieldConfig

    field = random_field(sh_degree=sh_degree, seed=4)
    path = save_scene(tmp_path / "degree.n2r", field, FieldConfig(sh_degree=sh_degree), tiny_views(), {},
                      reference_length=3.0)
    loaded = load_scene(path, device="cpu").field
    assert loaded.sh_degree == sh_degree and loaded.values.shape[1] == 1 + 3 * (sh_degree + 1) ** 2, (
        f"sh_degree={sh_degree}: read back as degree {loaded.sh_degree} with {loaded.values.shape[1]} columns")
    view = tiny_views()[1]
    want = FieldRenderer(loaded, RenderSettings()).render(view.c2w, view.camera, ("rgb",))["rgb"]
    field.values.copy_(field.values.half().float())
    got = FieldRenderer(field, RenderSettings()).render(view.c2w, view.camera, ("rgb",))["rgb"]
    diff = np.abs(got.astype(int) - want).max()
    assert diff <= 1, f"sh_degree={sh_degree}: the scene read back renders up to {diff} levels off the field saved"


def test_the_top_level_names_are_the_scene_package_ones():
    assert (pytest_n2r.load_scene, pytest_n2r.save_scene, pytest_n2r.FieldScene) == (load_scene, save_scene, FieldScene)


def test_render_goes_through_the_field_renderer_with_the_scene_settings(scene_path):
    settings = RenderSettings(step_ratio=1.0, t_stop=1e-2)
    scene = load_scene(scene_path, device="cpu", settings=settings)
    view = scene.views[1]
    got = scene.render(view.c2w, view.camera, ("depth", "opacity"))
    want = FieldRenderer(scene.file.field, settings).render(view.c2w, view.camera, ("depth", "opacity"))
    assert got.rgb is None, "rgb was rendered though not asked for"
    assert np.array_equal(got.depth, want["depth"]) and np.array_equal(got.opacity, want["opacity"])


def test_the_content_hash_follows_the_field_and_the_settings(scene_path, tmp_path):
    from pytest_n2r.field.config import FieldConfig

    scene = load_scene(scene_path, device="cpu")
    assert load_scene(scene_path, device="cpu").content_hash == scene.content_hash, "same file, different hash"
    coarser = scene.with_settings(RenderSettings(step_ratio=1.0))
    assert coarser.settings.step_ratio == 1.0 and coarser.field is not None and coarser.name == scene.name
    assert coarser.content_hash != scene.content_hash, "other render settings kept the hash"
    assert scene.with_settings(RenderSettings()).content_hash == scene.content_hash
    other = save_scene(tmp_path / "other.n2r", random_field(seed=3), FieldConfig(), tiny_views(), {"psnr": 20.0},
                       reference_length=3.0, metres_per_unit=0.5)
    assert load_scene(other, device="cpu").content_hash != scene.content_hash, "another field kept the hash"


def test_the_torch_backends_hash_names_torch_and_its_kernels_and_the_compiled_ones_does_not(scene_path, monkeypatch):
    """The torch backend's pixels differ in their last bits between torch versions, CPU kernels and GPUs (one
    opacity pixel in four views between torch's AVX-512 and AVX2 kernels): a render cache shared by CI runners must
    not hand one runner's pictures to another; the compiled backend's renders are the same bits everywhere."""
    import torch

    by_torch = load_scene(scene_path, device="cpu").with_settings(RenderSettings(backend="torch"))
    compiled = load_scene(scene_path, device="cpu")
    before = by_torch.content_hash, compiled.content_hash
    monkeypatch.setattr(torch, "__version__", "2.99.0+another")
    again = (by_torch.with_settings(RenderSettings(backend="torch")).content_hash,
             load_scene(scene_path, device="cpu").content_hash)  # auto is the torch backend on a GPU machine
    assert again[0] != before[0], "a torch backend's renders were keyed without torch's version"
    assert again[1] == before[1], "the compiled backend's key moved with torch's version"
    other = "AVX2" if torch.backends.cpu.get_cpu_capability() != "AVX2" else "AVX512"  # this host's, and another
    monkeypatch.setattr(torch.backends.cpu, "get_cpu_capability", lambda: other)
    on_other = by_torch.with_settings(RenderSettings(backend="torch")).content_hash
    assert on_other != again[0], "torch's AVX2 and AVX-512 kernels' renders shared a key"


def test_pair_moves_by_metres_when_the_scale_is_known(scene_path):
    scene = load_scene(scene_path, device="cpu")
    source, follow = scene.pair(1, Transform(x=1.0), units="metres")
    moved = np.linalg.inv(source.c2w) @ follow.c2w
    np.testing.assert_allclose(moved[:3, 3], [2.0, 0.0, 0.0], atol=1e-12,
                               err_msg="1 m at 0.5 m per scene unit must move 2 scene units along x")


def test_a_bad_device_is_named(scene_path):
    with pytest.raises(InvalidArgument, match=r"device='tpu'"):
        load_scene(scene_path, device="tpu")


def test_the_session_loads_a_scene_file_spec(scene_path):
    scene = load_scene_spec(SceneSpec("orbit", "file", str(scene_path)), device="cpu")
    assert isinstance(scene, FieldScene) and len(scene.views) == 4


def test_the_tiny_fit_round_trips_with_its_report(tiny_scene_file, tiny_fit, tiny_capture):
    scene = load_scene(tiny_scene_file, device="cpu")
    assert scene.report["steps"] == TINY_STEPS and scene.report["heldout"] == tiny_fit.report["heldout"]
    assert scene.reference_length == tiny_capture.reference_length and scene.metres_per_unit == 1.0
    assert [v.split for v in scene.views] == [v.split for v in tiny_capture.views]
    view = scene.views[0]
    want = FieldRenderer(tiny_fit.field).render(view.c2w, view.camera, ("rgb", "opacity"))
    got = scene.render(view.c2w, view.camera, ("rgb", "opacity"))
    assert np.array_equal(got.rgb, want["rgb"]) and np.array_equal(got.opacity, want["opacity"]), \
        "the fitted field renders differently after saving and loading"


def test_splat_settings_for_a_fitted_field_are_refused_by_type(tmp_path):
    from pytest_n2r.errors import InvalidType
    from pytest_n2r.render.splat_render import SplatSettings

    with pytest.raises(InvalidType, match="holds a fitted field"):
        load_scene(tmp_path / "scene.n2r", settings=SplatSettings())
