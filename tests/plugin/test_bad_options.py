"""The bad-input catalogue of the plugin's options (docs/reliability.md counts it): each is a usage error at
configure time naming the option and what is expected, never a traceback from a fixture."""

from __future__ import annotations

import json
import re
import zipfile
from pathlib import Path

import pytest

# imported here, not first inside an inner run: pytester drops what an inner run imported, and importing
# torch's extension modules a second time in one process crashes it
import pytest_n2r.plugin.session
import pytest_n2r.scene.loading  # noqa: F401

PLANE = "tests.plugin.fakescene:plane"

#: (id, command-line arguments with {placeholders}, regex of the usage error)
OPTION_CASES: list[tuple[str, list[str], str]] = [
    ("scene file missing", ["--n2r-scene", "{tmp}/nowhere.n2r"],
     r"--n2r-scene '.*nowhere\.n2r': no such file .*; expected a \.n2r scene file"),
    ("scene file is a text file", ["--n2r-scene", "{tmp}/notes.n2r"], r"notes\.n2r is not a scene file"),
    ("scene file with metres_per_unit -1", ["--n2r-scene", "{tmp}/bad-scale.n2r"],
     r"--n2r-scene / ini n2r_scenes .*bad-scale\.n2r: .*metres_per_unit=-1; expected a finite number > 0"),
    ("scene file with a field member bomb", ["--n2r-scene", "{tmp}/bomb.n2r"],
     r"bomb\.n2r: field\.safetensors is not a valid safetensors file"),
    ("unknown demo scene", ["--n2r-scene", "demo:castle"], r"'demo:castle': no such demo scene"),
    ("glob matching nothing", ["--n2r-scene", "{tmp}/*.nothing"], r"matched no file"),
    ("device tpu", ["--n2r-scene", PLANE, "--n2r-device", "tpu"],
     r"--n2r-device / ini n2r_device: device='tpu': expected 'auto', 'cpu' or 'cuda\[:N\]'"),
    ("device cuda:x", ["--n2r-scene", PLANE, "--n2r-device", "cuda:x"], r"device='cuda:x': expected 'auto', 'cpu'"),
    ("artifacts in a read-only place", ["--n2r-scene", PLANE, "--n2r-artifacts", "/proc/n2r-artifacts"],
     r"--n2r-artifacts / ini n2r_artifacts: /proc/n2r-artifacts: cannot write into /proc .*or 'none'"),
    ("artifacts under a file", ["--n2r-scene", PLANE, "--n2r-artifacts", "{tmp}/notes.n2r/arts"],
     r"--n2r-artifacts .*notes\.n2r is a file, not a folder"),
    ("cache in a read-only place", ["--n2r-scene", PLANE, "--n2r-cache-dir", "/proc/n2r-cache"],
     r"--n2r-cache-dir / ini n2r_cache_dir: /proc/n2r-cache: cannot write into /proc"),
    ("cache dir empty ($VAR unset)", ["--n2r-scene", PLANE, "--n2r-cache-dir="],
     r"--n2r-cache-dir / ini n2r_cache_dir: '' is empty; expected a folder path, or 'none'"),
    ("artifacts empty", ["--n2r-scene", PLANE, "--n2r-artifacts", ""],
     r"--n2r-artifacts / ini n2r_artifacts: '' is empty; expected a folder path, or 'none'"),
    ("artifacts blank", ["--n2r-scene", PLANE, "--n2r-artifacts", " "], r"--n2r-artifacts .*' ' is empty"),
    ("cache in a folder of the user's", ["--n2r-scene", PLANE, "--n2r-cache-dir", "{tmp}"],
     (r"--n2r-cache-dir / ini n2r_cache_dir: .* is not a pytest-n2r render cache \(no CACHEDIR\.TAG written by "
      r"pytest-n2r\) and holds bad-scale\.n2r, bomb\.n2r, good\.n2r and 2 more; choose a new or empty folder, "
      r"or 'none'")),
    ("cache size lots", ["--n2r-scene", PLANE, "--n2r-cache-size", "lots"], r"--n2r-cache-size / ini n2r_cache_size"),
    ("timeout abc", ["--n2r-scene", PLANE, "--n2r-timeout", "abc"], r"'abc' is not a number of seconds >= 0"),
    ("timeout -1", ["--n2r-scene", PLANE, "--n2r-timeout", "-1"], r"'-1' is not a number of seconds >= 0"),
    ("timeout nan", ["--n2r-scene", PLANE, "--n2r-timeout", "nan"], r"'nan' is not a number of seconds >= 0"),
    ("timeout inf", ["--n2r-scene", PLANE, "--n2r-timeout", "inf"],
     r"--n2r-timeout / ini n2r_timeout: 'inf' is not a number of seconds >= 0 and <= 86400 \(0: no limit\)"),
    ("timeout 1e12", ["--n2r-scene", PLANE, "--n2r-timeout", "1e12"],
     r"'1e12' is not a number of seconds >= 0 and <= 86400"),
    ("examples 0", ["--n2r-scene", PLANE, "--n2r-examples", "0"], r"'0' is not a whole number >= 1"),
    ("examples 2.5", ["--n2r-scene", PLANE, "--n2r-examples", "2.5"], r"'2\.5' is not a whole number >= 1"),
    ("size 0", ["--n2r-scene", PLANE, "--n2r-size", "0"], r"--n2r-size / ini n2r_size: .*must be in \[16, 16384\]"),
    ("size 2, a slip for 2x", ["--n2r-scene", PLANE, "--n2r-size", "2"],
     r"--n2r-size / ini n2r_size: n2r_size='2': longer side 2 must be in \[16, 16384\] pixels"),
    ("size abc", ["--n2r-scene", PLANE, "--n2r-size", "abc"], r"is not a render size"),
    ("render scale 2", ["--n2r-scene", PLANE, "--n2r-render-scale", "2"], r"'2' is not a fraction in \[0\.1, 1\]"),
    ("render scale nan", ["--n2r-scene", PLANE, "--n2r-render-scale", "nan"], r"'nan' is not a fraction"),
    ("derandomize maybe", ["--n2r-scene", PLANE, "--n2r-derandomize", "maybe"], r"'maybe'; expected auto, yes or no"),
    ("precompile auto", ["--n2r-scene", PLANE, "--n2r-precompile", "auto"],
     r"--n2r-precompile / ini n2r_precompile: 'auto'; expected yes or no"),
]


@pytest.fixture
def decoys(pytester: pytest.Pytester, monkeypatch: pytest.MonkeyPatch) -> dict[str, str]:
    from pytest_n2r.field.config import FieldConfig
    from pytest_n2r.scene import save_scene

    from ..scene.conftest import random_field, tiny_views

    monkeypatch.setenv("PYTHONPATH", str(Path(__file__).resolve().parents[2]))
    tmp = pytester.path
    (tmp / "notes.n2r").write_text("my notes\n")
    good = save_scene(tmp / "good.n2r", random_field(), FieldConfig(), tiny_views(), {}, reference_length=3.0)
    for name, edit, replace in (("bad-scale.n2r", {"metres_per_unit": -1}, {}),
                                ("bomb.n2r", {}, {"field.safetensors": b"\0" * (50 * 2**20)})):
        with zipfile.ZipFile(good) as src, zipfile.ZipFile(tmp / name, "w", zipfile.ZIP_DEFLATED) as out:
            for member in src.namelist():
                payload = replace.get(member, src.read(member))
                if member == "scene.json":
                    payload = json.dumps({**json.loads(payload), **edit}).encode()
                out.writestr(member, payload)
    pytester.makepyfile(test_inner="def test_scene(n2r_scene):\n    pass\n")
    return {"tmp": str(tmp)}


@pytest.mark.parametrize(("args", "expected"), [c[1:] for c in OPTION_CASES], ids=[c[0] for c in OPTION_CASES])
def test_a_bad_option_is_a_usage_error_at_configure_time(args, expected, decoys, pytester):
    result = pytester.runpytest("-p", "no:cacheprovider", *(a.format(**decoys) for a in args))
    err = " ".join(result.stderr.str().split())
    assert result.ret == pytest.ExitCode.USAGE_ERROR, f"exit code {result.ret}:\n{result.stdout.str()}\n{err}"
    assert "Traceback" not in err and "Traceback" not in result.stdout.str(), err
    assert re.search(r"ERROR: pytest-n2r: " + ".*" + expected, err), f"expected /{expected}/ in:\n{err}"


def test_a_bad_ini_value_names_the_ini_key(decoys, pytester):
    pytester.makeini("[pytest]\nn2r_timeout = soon\n")
    result = pytester.runpytest("-p", "no:cacheprovider", "--n2r-scene", PLANE)
    assert result.ret == pytest.ExitCode.USAGE_ERROR
    assert "--n2r-timeout / ini n2r_timeout: 'soon' is not a number of seconds >= 0" in result.stderr.str()


@pytest.mark.parametrize("args", [["--n2r-cache-dir="], ["--n2r-cache-dir=", "--n2r-cache-clear"],
                                  ["--n2r-cache-dir=data", "--n2r-cache-clear"], ["--n2r-artifacts="]])
def test_a_cache_dir_that_is_the_project_or_a_folder_of_the_users_is_refused_and_left_alone(args, decoys, pytester):
    tmp = pytester.path
    (tmp / ".gitignore").write_text("build/\n")
    for folder in (tmp / "renders" / "ab", tmp / "decisions", tmp / "data" / "renders" / "cd"):
        folder.mkdir(parents=True)
        (folder / "mine.npy").write_bytes(b"the user's own")
    before = sorted(str(p.relative_to(tmp)) for p in tmp.rglob("*"))
    result = pytester.runpytest("-p", "no:cacheprovider", "--n2r-scene", PLANE, *args)
    assert result.ret == pytest.ExitCode.USAGE_ERROR, f"{args}: exit code {result.ret}\n{result.stdout.str()}"
    assert "Traceback" not in result.stderr.str(), result.stderr.str()
    assert (tmp / ".gitignore").read_text() == "build/\n", f"{args}: the project's .gitignore was overwritten"
    assert sorted(str(p.relative_to(tmp)) for p in tmp.rglob("*")) == before, f"{args}: files changed"


def test_a_scene_whose_field_does_not_load_fails_with_its_message_not_a_traceback(decoys, pytester):
    import safetensors.torch
    import torch

    from ..scene.conftest import random_field

    tensors = random_field().tensors()
    tensors["vertex_values"] = torch.full_like(tensors["vertex_values"], float("nan"))
    good = Path(decoys["tmp"]) / "good.n2r"
    broken = Path(decoys["tmp"]) / "broken.n2r"
    with zipfile.ZipFile(good) as src, zipfile.ZipFile(broken, "w") as out:
        for member in src.namelist():
            out.writestr(member, safetensors.torch.save(tensors) if member == "field.safetensors"
                         else src.read(member))
    result = pytester.runpytest("-p", "no:cacheprovider", "--n2r-scene", str(broken))
    result.assert_outcomes(errors=1)
    text = result.stdout.str()
    assert re.search(r"pytest-n2r: scene .*broken\.n2r: .*tensor 'vertex_values' holds NaN or Inf", text), text
    assert "Traceback" not in text and "read_scene_file" not in text, text


def test_failure_pictures_that_cannot_be_saved_do_not_hide_the_failure(n2r_project, monkeypatch):
    from pytest_n2r.relation import engine

    def unwritable(directory, *args):
        raise PermissionError(13, "Permission denied", str(directory))

    monkeypatch.setattr(engine, "save_pair", unwritable)
    n2r_project.write("""
@metamorphic(SameLabel(), eps=0.5, transform=transforms(yaw=20), examples=30)
def test_heading(n2r_scene):
    return heading_class
""")
    result = n2r_project.run("--n2r-scene", "tests.plugin.fakescene:ramp")
    result.assert_outcomes(failed=1)
    text = result.stdout.str()
    assert "metamorphic relation violated" in text and "transform:  yaw=" in text, text
    assert re.search(r"images:\s+not saved \(Permission denied: .*n2r-artifacts", text), text
    assert "PermissionError" not in text, text


def test_an_unwritable_default_folder_is_a_configuration_warning_pytest_filters(n2r_project, monkeypatch):
    """A read-only checkout: the default cache and artifacts folders warn and write nothing, as pytest's own cache
    does, through pytest's configuration warnings, so `-W error` makes them errors and `filterwarnings` hides them
    (a plain warnings.warn at configure time reached neither)."""
    from pytest_n2r.data import atomic

    real = atomic.unwritable_reason
    monkeypatch.setattr(atomic, "unwritable_reason", lambda path: "cannot write into it (Read-only file system)"
                        if Path(path).name in (".n2r-cache", "n2r-artifacts") else real(path))
    n2r_project.write("def test_scene(n2r_scene):\n    pass\n")
    result = n2r_project.run("--n2r-scene", PLANE)
    result.assert_outcomes(passed=1)
    warning = ("*PytestConfigWarning: pytest-n2r: the default folder *.n2r-cache: cannot write into it (Read-only "
               "file system): nothing is written there this run*")
    result.stdout.fnmatch_lines([warning])
    strict = n2r_project.run("--n2r-scene", PLANE, "-W", "error::pytest.PytestConfigWarning")
    assert strict.ret != 0 and "the default folder" in strict.stdout.str() + strict.stderr.str(), \
        "-W error did not turn the default folder's warning into an error"
