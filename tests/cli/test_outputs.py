"""Where a command writes: an existing empty folder is a fine output folder, ``OUT.PNG`` is a PNG, and neither a
dangling symbolic link nor a file that is not the command's own output is written over without ``--force``."""

from __future__ import annotations

from pytest_n2r.cli.main import main


def test_a_dangling_symlink_at_the_output_is_not_written_through(tmp_path, capsys):
    link = tmp_path / "out.png"
    link.symlink_to(tmp_path / "elsewhere" / "target.png")
    assert main(["render", "demo:wall", "--size", "32", "-o", str(link)]) == 2
    assert "exists and is not a PNG image" in capsys.readouterr().err
    assert link.is_symlink() and not (tmp_path / "elsewhere").exists()


def test_an_upper_case_png_suffix_is_a_png(tmp_path, capsys):
    assert main(["render", "demo:wall", "--size", "32", "-o", str(tmp_path / "OUT.PNG")]) == 0, capsys.readouterr().err
    assert (tmp_path / "OUT.PNG").read_bytes().startswith(b"\x89PNG")


# render.py -------------------------------------------------------------------------------------------------------


def test_an_empty_folder_is_a_valid_output_folder(tmp_path, capsys):
    empty = tmp_path / "export"
    empty.mkdir()
    assert main(["demo", "export", "object", "-o", str(empty), "--size", "32x24"]) == 0, capsys.readouterr().err
    assert (empty / "transforms.json").is_file()


def test_demo_build_does_not_replace_a_file_that_is_no_scene_without_force(tmp_path, monkeypatch, capsys):
    import pytest_n2r.demo.fitted

    def no_build(*_a, **_k):
        raise AssertionError("built over a file that is no scene")

    monkeypatch.setattr(pytest_n2r.demo.fitted, "build_fitted", no_build)
    (tmp_path / "object.n2r").write_text("my notes")
    assert main(["demo", "build", "object", "-o", str(tmp_path)]) == 2
    assert "exists and is not a .n2r scene file" in capsys.readouterr().err
    assert (tmp_path / "object.n2r").read_text() == "my notes"
