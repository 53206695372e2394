"""Scene specs (pytest_n2r.demo.scene_specs): a damaged scene file is refused with the project's error."""

from __future__ import annotations

import io
import zipfile

import pytest

from pytest_n2r.demo.scene_specs import parse_scene_specs
from pytest_n2r.errors import SceneFileError


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
