"""No `n2r` command fails because its output cannot be encoded: on an ASCII locale (``LC_ALL=C``) or a Windows
console (cp1252) a character the terminal cannot show is printed escaped (``\\xb3``), and a path as its bytes."""

from __future__ import annotations

import io
import json
import os
import subprocess
import sys
from pathlib import Path

import pytest

from pytest_n2r.cli.main import COMMANDS, main

WALL = Path(__file__).parents[2] / "pytest_n2r" / "demo" / "data" / "wall.n2r"

#: A true ASCII stdout: Python 3.11 turns its UTF-8 mode on in the C locale unless told not to.
ASCII = {"LC_ALL": "C", "PYTHONUTF8": "0", "PYTHONCOERCECLOCALE": "0"}
#: A Windows console's stdout, on this machine.
CP1252 = {"PYTHONIOENCODING": "cp1252"}
LATIN1 = {"PYTHONIOENCODING": "latin-1"}

N2R = "import sys; from pytest_n2r.cli.main import main; sys.exit(main(sys.argv[1:]))"


def _n2r(env: dict[str, str], *argv: str) -> subprocess.CompletedProcess:
    """``n2r ARGV`` in a fresh interpreter with ``env`` over the current environment; its output as bytes."""
    clean = {k: v for k, v in os.environ.items() if not k.startswith(("LC_", "PYTHONIOENCODING", "PYTHONUTF8"))}
    return subprocess.run([sys.executable, "-c", N2R, *argv], env={**clean, **env}, capture_output=True,
                          check=False, timeout=120)


def _failed(result: subprocess.CompletedProcess, what: str) -> str:
    return f"{what} exited {result.returncode}: {result.stderr.decode('ascii', 'backslashreplace')[-1500:]}"


def test_info_prints_what_the_terminal_cannot_show_escaped():
    """`n2r info wall.n2r` on an ASCII locale failed with UnicodeEncodeError on the `³` of `384³ grid` (and `n2r
    fit`, which prints the same summary after saving its scene, ended a fit of many minutes in a traceback)."""
    result = _n2r(ASCII, "info", str(WALL))
    assert result.returncode == 0, _failed(result, "n2r info")
    assert b"384\\xb3 grid" in result.stdout, f"expected `384\\xb3 grid` in: {result.stdout[:600]!r}"
    assert not result.stderr, f"n2r info wrote to stderr: {result.stderr!r}"


def test_info_on_a_strict_ascii_stdout_in_process(monkeypatch):
    """What `n2r fit` prints at the end is :func:`format_info`'s summary: printed through a strict ASCII stdout, the
    `³` is escaped instead of failing the command."""
    out = io.TextIOWrapper(io.BytesIO(), encoding="ascii", errors="strict", write_through=True)
    monkeypatch.setattr("sys.stdout", out)
    assert main(["info", str(WALL)]) == 0
    text = out.buffer.getvalue().decode("ascii")
    assert "384\\xb3 grid" in text, f"the `384³ grid` of the summary, escaped, is missing from: {text[:600]!r}"


_HELPS = """\
import json, sys
from pytest_n2r.cli.main import COMMANDS, main
codes = {}
for argv in [["--help"]] + [[name, "--help"] for name in COMMANDS]:
    try:
        main(argv)
        codes[" ".join(argv)] = "returned"
    except SystemExit as exc:
        codes[" ".join(argv)] = exc.code
    except Exception as exc:
        codes[" ".join(argv)] = repr(exc)
with open(sys.argv[1], "w", encoding="utf-8") as fh:
    json.dump(codes, fh)
"""


@pytest.mark.parametrize("env", [ASCII, CP1252, LATIN1], ids=["ascii", "cp1252", "latin-1"])
def test_every_help_prints(env, tmp_path):
    """`n2r fit --help` (`256³`) and `n2r study --help` (`τ0`) failed with UnicodeEncodeError on an ASCII locale, and
    `study --help` on a cp1252 or latin-1 stdout too."""
    clean = {k: v for k, v in os.environ.items() if not k.startswith(("LC_", "PYTHONIOENCODING", "PYTHONUTF8"))}
    codes_file = tmp_path / "codes.json"
    result = subprocess.run([sys.executable, "-c", _HELPS, str(codes_file)], env={**clean, **env},
                            capture_output=True, check=False, timeout=120)
    assert result.returncode == 0, _failed(result, "the helps")
    codes = json.loads(codes_file.read_text(encoding="utf-8"))
    failed = {argv: code for argv, code in codes.items() if code != 0}
    assert not failed, f"these helps did not exit 0: {failed}"
    assert len(codes) == len(COMMANDS) + 1, codes
    assert b"\\u03c40" in result.stdout, f"`n2r study --help` has no escaped `\\u03c40`: {result.stdout[-3000:]!r}"


def test_a_written_path_with_non_ascii_letters_is_printed_as_its_bytes(tmp_path):
    """`n2r render demo:wall -o 'd é/out é.png'` on an ASCII locale wrote the PNG, then failed printing its name:
    `printable` had turned the name's bytes (kept as lone surrogates) back into `é`, which ASCII cannot encode."""
    folder = tmp_path / "d é"
    folder.mkdir()
    out = folder / "out é.png"
    result = _n2r(ASCII, "render", "demo:wall", "--size", "32", "-o", str(out))
    assert result.returncode == 0, _failed(result, "n2r render")
    assert out.is_file(), "the PNG was not written"
    assert result.stdout == b"wrote       " + os.fsencode(out) + b"\n", f"expected the path's bytes: {result.stdout!r}"


def test_a_written_path_on_a_windows_console(tmp_path):
    """On a cp1252 stdout the path's `é` is cp1252's byte; a byte that is not UTF-8 in a name stays escaped."""
    folder = tmp_path / "d é"
    folder.mkdir()
    out = folder / "out é.png"
    result = _n2r(CP1252, "render", "demo:wall", "--size", "32", "-o", str(out))
    assert result.returncode == 0, _failed(result, "n2r render")
    assert result.stdout == f"wrote       {out}\n".encode("cp1252"), f"expected the path in cp1252: {result.stdout!r}"


@pytest.mark.parametrize(("encoding", "errors", "expected"), [
    ("ascii", "surrogateescape", b"a\xc3\xa9\\u03c4\xffb\\xb3"),  # the C locale's stdout: a name's bytes as they are
    ("cp1252", "strict", b"a\\xc3\\xa9\\u03c4\\xffb\xb3"),  # a Windows console: every byte escaped
    ("utf-8", "strict", "a\\xc3\\xa9τ\\xffb³".encode()),  # a UTF-8 terminal: only the surrogates escaped
])
def test_tolerant_streams_write_anything(encoding, errors, expected, monkeypatch):
    """The streams `n2r` sets up at its start write any text: surrogate-escaped bytes (a file name's) as those bytes
    where the stream takes them, else escaped, and any character its encoding lacks escaped."""
    from pytest_n2r.cli._output import tolerant_streams

    for name in ("stdout", "stderr"):
        monkeypatch.setattr(f"sys.{name}", io.TextIOWrapper(io.BytesIO(), encoding=encoding, errors=errors))
    with tolerant_streams():
        for stream in (sys.stdout, sys.stderr):
            stream.write("a\udcc3\udca9τ\udcffb³")
            stream.flush()
            assert stream.buffer.getvalue() == expected, f"{encoding}/{errors} wrote {stream.buffer.getvalue()!r}"
    assert (sys.stdout.errors, sys.stderr.errors) == (errors, errors), "the streams' own handlers were not given back"
