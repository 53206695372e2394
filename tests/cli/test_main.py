"""`n2r`'s entry: a missing COMMAND, and the errors and paths it prints."""

from __future__ import annotations

import errno
import io
import sys

import pytest

import pytest_n2r.cli.info
from pytest_n2r.cli.main import main


def test_bare_n2r_is_a_usage_error(capsys):
    """`n2r` alone printed the help and exited 0, as if it had done something (argparse exits 2 on a usage error)."""
    with pytest.raises(SystemExit) as exit_:
        main([])
    assert exit_.value.code == 2
    err = capsys.readouterr().err
    assert err.startswith("usage: n2r") and "n2r: error: expected a COMMAND: poses, fit" in err, err


def test_an_error_writing_stdout_has_one_colon(monkeypatch, capsys):
    """`n2r info demo:wall > /dev/full` printed `n2r info: error:: No space left on device`."""

    def full(_args: object) -> int:
        raise OSError(errno.ENOSPC, "No space left on device")

    monkeypatch.setattr(pytest_n2r.cli.info, "run", full)
    assert main(["info", "demo:wall"]) == 1
    assert capsys.readouterr().err == "n2r info: error: No space left on device\n"


class StrictUTF8:
    """A stdout as PYTHONIOENCODING=utf-8 gives it: a lone surrogate (a file name's byte that is not UTF-8) fails."""

    def __init__(self) -> None:
        self.stream = io.TextIOWrapper(io.BytesIO(), encoding="utf-8", errors="strict", write_through=True)

    def text(self) -> str:
        return self.stream.buffer.getvalue().decode("utf-8")


def test_a_written_path_that_is_not_utf8_is_printed_escaped(tmp_path, monkeypatch):
    """`n2r render ... -o $'bad\\xff.png'` wrote the PNG, then failed with UnicodeEncodeError printing its name."""
    out, err = StrictUTF8(), StrictUTF8()
    monkeypatch.setattr("sys.stdout", out.stream)
    monkeypatch.setattr("sys.stderr", err.stream)
    bad = tmp_path / ("bad" + chr(0xDCFF) + ".png")  # the byte 0xff, as os.fsdecode keeps it
    assert main(["render", "demo:wall", "--size", "32", "-o", str(bad)]) == 0, err.text()
    assert bad.is_file()
    assert f"wrote       {tmp_path}/bad\\xff.png\n" in out.text()
    assert main(["render", "demo:wall", "-o", str(bad.with_suffix(".txt"))]) == 2  # an error naming the path
    assert f"-o {tmp_path}/bad\\xff.txt: expected a PNG image" in err.text()


@pytest.mark.parametrize("argv", [["info", "demo:wall"], ["render", "demo:wall", "--size", "32", "-o", "{tmp}/w.png"]])
def test_commands_on_an_exact_scene_do_not_import_torch(argv, tmp_path):
    """`n2r info demo:wall` imported torch for an isinstance check and `n2r render demo:wall` to check `--device
    auto`: about 1.5 s of each command's 0.5 and 1.1 s."""
    import subprocess
    import sys

    argv = [a.replace("{tmp}", str(tmp_path)) for a in argv]
    code = ("import sys; from pytest_n2r.cli.main import main; code = main(sys.argv[1:]); "
            "assert code == 0, code; assert 'torch' not in sys.modules, 'torch was imported'")
    result = subprocess.run([sys.executable, "-c", code, *argv], check=False, capture_output=True, text=True)
    assert result.returncode == 0, f"n2r {' '.join(argv)}: {result.stderr[-2000:]}"


def test_python_dash_m_runs_n2r_where_its_script_is_not_on_path():
    """`pip install --user` puts the `n2r` script where PATH may not look: `python -m pytest_n2r.cli` had no
    __main__ to run."""
    import subprocess
    import sys

    result = subprocess.run([sys.executable, "-m", "pytest_n2r.cli", "--version"], check=False, capture_output=True,
                            text=True)
    assert result.returncode == 0 and result.stdout.startswith("pytest-n2r "), (result.stdout, result.stderr)


def test_a_reader_that_left_is_exit_141_and_nothing_printed(monkeypatch, capsys):
    """`n2r info demo:wall | head -0`: the shell's 141 (128 + SIGPIPE), no error line."""
    def gone(_args):
        raise BrokenPipeError(32, "Broken pipe")
    monkeypatch.setattr(pytest_n2r.cli.info, "run", gone)
    monkeypatch.setattr(sys, "stdout", sys.stdout)  # main() replaces it with os.devnull; put it back after
    assert main(["info", "demo:wall"]) == 141
    assert capsys.readouterr().err == ""


def test_out_of_memory_is_exit_1_with_a_hint(monkeypatch, capsys):
    def big(_args):
        raise MemoryError
    monkeypatch.setattr(pytest_n2r.cli.info, "run", big)
    assert main(["info", "demo:wall"]) == 1
    assert capsys.readouterr().err == "n2r info: error: out of memory (a smaller --size or --downscale needs less)\n"


def test_an_os_error_on_a_file_names_the_file(monkeypatch, capsys):
    def vanished(_args):
        raise FileNotFoundError(2, "No such file or directory", "/gone/x.n2r")
    monkeypatch.setattr(pytest_n2r.cli.info, "run", vanished)
    assert main(["info", "demo:wall"]) == 1
    assert capsys.readouterr().err == "n2r info: error: /gone/x.n2r: No such file or directory\n"
