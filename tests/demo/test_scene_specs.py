"""Scene specs (pytest_n2r.demo.scene_specs): a damaged scene file is refused with the project's error."""

from __future__ import annotations

import io
import zipfile

import pytest

from pytest_n2r.demo.scene_specs import parse_scene_specs
from pytest_n2r.errors import InvalidArgument, SceneFileError


def test_a_scene_file_with_a_damaged_central_directory_is_a_scene_file_error(tmp_path):
    """zipfile.is_zipfile finds the end record, then ZipFile raised BadZipFile: an INTERNALERROR under
    --n2r-scene and a bare traceback from `n2r study`."""
    buffer = io.BytesIO()
    with zipfile.ZipFile(buffer, "w") as archive:
        archive.writestr("scene.json", "{}")
        archive.writestr("field.safetensors", b"x" * 100)
    data = bytearray(buffer.getvalue())
    at = data.rfind(b"PK\x01\x02")
    data[at:at + 4] = b"XXXX"  # the central directory damaged, its end record kept
    path = tmp_path / "bad.n2r"
    path.write_bytes(bytes(data))
    with pytest.raises(SceneFileError) as exc:
        parse_scene_specs([str(path)], tmp_path, "--n2r-scene")
    assert f"--n2r-scene {str(path)!r}: {path}: not a zip archive, or truncated" in str(exc.value), str(exc.value)


def _scene_file(path):
    """A zip archive with a ``scene.json``: all that parsing a spec opens."""
    path.parent.mkdir(parents=True, exist_ok=True)
    with zipfile.ZipFile(path, "w") as archive:
        archive.writestr("scene.json", "{}")
    return path


def test_two_scene_files_of_one_name_are_refused_and_one_named_twice_is_one_scene(tmp_path):
    """Test ids use the scene name: without the check a second ``wall.n2r`` from another folder would silently replace
    the first, and the session would test one scene where two were configured."""
    a, b = _scene_file(tmp_path / "a" / "wall.n2r"), _scene_file(tmp_path / "b" / "wall.n2r")
    with pytest.raises(InvalidArgument, match=r"--n2r-scene: two scenes are named 'wall' \(.*a.wall\.n2r and "
                                              r".*b.wall\.n2r\); test ids use the scene name"):
        parse_scene_specs([str(a), str(b)], tmp_path, "--n2r-scene")
    specs = parse_scene_specs([str(a), "a/wall.n2r"], tmp_path, "--n2r-scene")
    assert [(s.name, s.kind) for s in specs] == [("wall", "file")], specs


def test_a_splat_file_is_taken_whatever_the_case_of_its_suffix(tmp_path):
    """Windows tools write ``scene.PLY``: a 3DGS ply is known by its suffix in any case, not refused as "not a scene
    file" (its header is read when the scene loads)."""
    (tmp_path / "garden.PLY").write_bytes(b"ply\nformat binary_little_endian 1.0\nend_header\n")
    specs = parse_scene_specs(["garden.PLY"], tmp_path, "--n2r-scene")
    assert [(s.name, s.kind) for s in specs] == [("garden", "file")], specs
