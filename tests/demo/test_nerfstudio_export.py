"""An interrupted `n2r demo export` leaves a folder the same command knows as its own."""

from __future__ import annotations

import json

from pytest_n2r.cli.main import main
from pytest_n2r.demo import nerfstudio_export


def test_an_interrupted_export_is_finished_by_running_it_again(tmp_path, monkeypatch, capsys):
    """Ctrl-C after some images left images/ without transforms.json, the mark of an export, so the rerun refused
    ("the folder holds other files ... pass --force")."""
    out = tmp_path / "exp"
    write = nerfstudio_export.atomic_write_bytes
    images: list[str] = []

    def interrupted_after_two(path, data):
        if len(images) == 2:
            raise KeyboardInterrupt
        images.append(str(path))
        return write(path, data)

    monkeypatch.setattr(nerfstudio_export, "atomic_write_bytes", interrupted_after_two)
    assert main(["demo", "export", "wall", "-o", str(out), "--size", "32x18"]) == 130
    assert len(list((out / "images").iterdir())) == 2
    partial = json.loads((out / "transforms.json").read_text())
    assert partial["n2r_scene"] == "wall" and partial["n2r_complete"] is False and partial["frames"] == []
    monkeypatch.setattr(nerfstudio_export, "atomic_write_bytes", write)
    assert main(["demo", "export", "wall", "-o", str(out), "--size", "32x18"]) == 0, capsys.readouterr().err
    done = json.loads((out / "transforms.json").read_text())
    assert len(done["frames"]) == 48 and "n2r_complete" not in done
