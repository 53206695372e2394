"""The option registry (pytest_n2r.plugin.options): one entry per --n2r-* option, whose defaults are the
library's defaults, documented in the docs tables and shown by ``pytest --help`` through the entry point."""

from __future__ import annotations

import inspect
import re
from pathlib import Path

import pytest

from pytest_n2r import defaults
from pytest_n2r.plugin.options import OPTIONS, REPORT_OPTIONS, RUN_OPTIONS, Where, on_ci, option

#: pytest 9 reads ``pytest.toml`` and pyproject's ``[tool.pytest]`` (typed values); pytest 8 (the floor) reads only
#: ``[tool.pytest.ini_options]``
PYTEST_9 = pytest.mark.skipif(int(pytest.__version__.split(".")[0]) < 9,
                              reason="pytest.toml and [tool.pytest] are read from pytest 9 on")


def toml_table(name: str, table: str):
    """A (config file, table) parameter, skipped on pytest 8 where pytest 9 is needed to read it."""
    return pytest.param(name, table, marks=() if table == "[tool.pytest.ini_options]" else PYTEST_9)

DOCS = Path(__file__).resolve().parents[2] / "docs"


def _default_value(name: str):
    o = option(name)
    return o.parse(o.default, Where("default", Path.cwd(), Path.cwd()))


def test_every_option_is_declared_once_with_its_help():
    flags = [o.flag for o in OPTIONS]
    assert len(set(flags)) == len(flags), f"a flag is declared twice: {flags}"
    assert len({o.name for o in OPTIONS}) == len(OPTIONS)
    for o in OPTIONS:
        assert o.flag.startswith("--n2r-") and o.help_text.strip(), o
        assert o.ini is None or o.ini.startswith("n2r_"), o
        assert "{default}" in o.help or o.default is None, f"{o.flag}: help does not show its default {o.default!r}"
    assert set(RUN_OPTIONS) | set(REPORT_OPTIONS) == set(OPTIONS)


def test_the_plugin_defaults_are_the_library_defaults():
    from pytest_n2r.plugin.session import N2RSession
    from pytest_n2r.relation import RunSettings
    from pytest_n2r.report.compare import DEFAULT_FAIL_ON, compare_paired, parse_margin
    from pytest_n2r.scene.render_cache import RenderCache

    settings, session = RunSettings(), N2RSession()
    assert _default_value("examples") == settings.examples == defaults.EXAMPLES
    assert _default_value("timeout") == settings.timeout == defaults.TIMEOUT_S
    assert _default_value("cache_size") == RenderCache().disk_bytes == session.cache_bytes
    assert _default_value("render_scale") == session.render_scale
    assert _default_value("device") == session.device
    assert _default_value("compare_fail") == parse_margin(None) == inspect.signature(compare_paired).parameters[
        "margin"].default
    assert _default_value("compare_confidence") == inspect.signature(compare_paired).parameters["confidence"].default
    assert _default_value("compare_fail_on") == DEFAULT_FAIL_ON


@pytest.mark.parametrize("o", [o for o in OPTIONS if o.default is not None], ids=lambda o: o.flag)
def test_every_default_parses(o, tmp_path):
    assert o.parse(o.default, Where("default", tmp_path, tmp_path)) is not None


def _table_row(flag: str) -> str:
    for page in ("plugin.md", "reporting.md"):
        for line in (DOCS / page).read_text(encoding="utf-8").splitlines():
            if re.match(r"\|\s*`" + re.escape(flag) + r"[ `=]", line):
                return line
    raise AssertionError(f"{flag} has no row in the option tables of docs/plugin.md or docs/reporting.md")


@pytest.mark.parametrize("o", OPTIONS, ids=lambda o: o.flag)
def test_the_docs_tables_show_each_option_with_its_ini_key_and_default(o):
    row = _table_row(o.flag)
    if o.ini is not None:
        assert f"`{o.ini}`" in row, f"docs row of {o.flag} does not name its ini key {o.ini}:\n{row}"
    if o.default is not None:
        shown = o.default.replace(" ", "") in row.replace(" ", "")
        assert shown, f"docs row of {o.flag} does not show its default {o.default}:\n{row}"


def test_pytest_help_lists_every_option_through_the_entry_point(pytester):
    result = pytester.runpytest_subprocess("--help")
    text = result.stdout.str()
    missing = [o.flag for o in OPTIONS if o.flag not in text] + [o.ini for o in OPTIONS if o.ini and o.ini not in text]
    assert not missing, f"`pytest --help` (plugin loaded from the pytest11 entry point) lacks {missing}"
    assert "(default: 50)" in text and "(default: 2GiB)" in text, "the help does not show the defaults"


def test_command_line_beats_ini_beats_default(pytester):
    pytester.makeini("[pytest]\nn2r_examples = 7\nn2r_timeout = 9\n")
    config = pytester.parseconfig("--n2r-examples", "3")
    assert option("examples").value(config) == 3  # command line over ini
    assert option("timeout").value(config) == 9  # ini over default
    assert option("size").value(config).longer == 480  # the default


TYPED_TOML = """
n2r_examples = 7
n2r_timeout = 0
n2r_derandomize = true
n2r_precompile = false
n2r_render_scale = 0.5
n2r_size = 120
n2r_scenes = "tests.plugin.fakescene:plane tests.plugin.fakescene:ramp"
"""


@pytest.mark.parametrize(("name", "table"), [toml_table("pyproject.toml", "[tool.pytest]"),
                                             toml_table("pytest.toml", "[pytest]"),
                                             toml_table("pyproject.toml", "[tool.pytest.ini_options]")])
def test_typed_values_of_a_toml_config_file_parse(pytester, name, table):
    pytester.makefile(".toml", **{name.removesuffix(".toml"): table + TYPED_TOML})
    config = pytester.parseconfig()
    got = {n: option(n).value(config) for n in ("examples", "timeout", "derandomize", "precompile", "render_scale")}
    assert got == {"examples": 7, "timeout": 0.0, "derandomize": True, "precompile": False, "render_scale": 0.5}, (
        f"{name} {table}: typed values parsed as {got}")
    assert option("size").value(config).longer == 120, f"{name} {table}: n2r_size = 120 is not a 120-pixel size"
    scenes = [spec.name for spec in option("scene").value(config)]
    assert scenes == ["plane", "ramp"], f"{name} {table}: n2r_scenes gave {scenes}"


@PYTEST_9
def test_a_bad_typed_value_of_a_toml_table_is_a_usage_error_naming_the_key(pytester):
    pytester.makepyprojecttoml("[tool.pytest]\nn2r_examples = 0\nn2r_timeout = 1e12\n")
    config = pytester.parseconfig()
    for name, expected in (("examples", "--n2r-examples / ini n2r_examples: '0' is not a whole number >= 1"),
                           ("timeout", ("--n2r-timeout / ini n2r_timeout: '1000000000000.0' is not a number of "
                                        "seconds >= 0 and <= 86400"))):
        with pytest.raises(pytest.UsageError) as caught:
            option(name).value(config)
        assert expected in str(caught.value), f"the usage error should say {expected!r}, not {caught.value}"


@PYTEST_9
def test_a_run_configured_with_typed_toml_values_runs(n2r_project):
    n2r_project.pytester.makepyprojecttoml(
        "[tool.pytest]\nn2r_examples = 7\nn2r_timeout = 0\nn2r_derandomize = true\n"
        'n2r_scenes = ["tests.plugin.fakescene:plane"]\n')
    n2r_project.write("""
@metamorphic(AbsDifference(), eps=255, transform=transforms(yaw=2))
def test_a(n2r_scene):
    return mean_colour
""")
    result = n2r_project.run()
    assert "INTERNALERROR" not in result.stdout.str() + result.stderr.str(), result.stderr.str()
    result.assert_outcomes(passed=1)
    assert "7 examples" in n2r_project.summary(result, "test_a[plane]"), "n2r_examples = 7 was not applied"


@pytest.mark.parametrize("key", ["n2r_examples", "n2r_render_scale", "n2r_timeout", "n2r_cache_dir", "n2r_artifacts"])
@pytest.mark.parametrize(("name", "table"), [toml_table("pytest.toml", "[pytest]"),
                                             toml_table("pyproject.toml", "[tool.pytest]"),
                                             toml_table("pyproject.toml", "[tool.pytest.ini_options]")])
def test_a_list_for_a_one_value_option_in_a_toml_file_is_a_usage_error_naming_the_key(pytester, name, table, key):
    pytester.makefile(".toml", **{name.removesuffix(".toml"): f'{table}\n{key} = ["1"]\n'})
    pytester.makepyfile(test_inner="def test_nothing():\n    pass\n")
    result = pytester.runpytest("-p", "no:cacheprovider")
    err = result.stderr.str()
    assert result.ret == pytest.ExitCode.USAGE_ERROR, f"{name} {table} {key}: exit {result.ret}\n{result.stdout.str()}"
    assert "INTERNALERROR" not in err + result.stdout.str() and "Traceback" not in err, err
    flag = "--" + key.replace("_", "-")
    assert f"pytest-n2r: {flag} / ini {key}: ['1'] is a list; expected one value, not a list" in err, err


@pytest.mark.parametrize(("name", "table"), [toml_table("pytest.toml", "[pytest]"),
                                             toml_table("pyproject.toml", "[tool.pytest.ini_options]")])
def test_toml_false_for_a_folder_option_means_none_and_true_is_a_usage_error(pytester, name, table):
    stem = name.removesuffix(".toml")
    pytester.makefile(".toml", **{stem: f"{table}\nn2r_cache_dir = false\nn2r_artifacts = false\n"})
    config = pytester.parseconfig()
    assert option("cache_dir").value(config) is None and option("artifacts").value(config) is None
    assert not [p.name for p in pytester.path.iterdir() if p.name in ("no", "False")], "a folder named 'no' was made"
    pytester.makefile(".toml", **{stem: f"{table}\nn2r_artifacts = true\n"})
    with pytest.raises(pytest.UsageError, match=r"--n2r-artifacts / ini n2r_artifacts: true is not a folder; "
                                                r"expected a folder path, or 'none' \(or false\)"):
        option("artifacts").value(pytester.parseconfig())


@PYTEST_9
def test_an_empty_ini_folder_is_the_default_and_a_blank_one_a_usage_error(pytester):
    pytester.makefile(".toml", pytest='[pytest]\nn2r_cache_dir = ""\nn2r_artifacts = " "\n')
    config = pytester.parseconfig()
    assert option("cache_dir").value(config) == pytester.path / ".n2r-cache", "an empty value is not the default"
    with pytest.raises(pytest.UsageError, match=r"--n2r-artifacts / ini n2r_artifacts: ' ' is empty; expected a "
                                                r"folder path, or 'none'"):
        option("artifacts").value(config)
    assert not (pytester.path / " ").exists()


def test_a_gpu_index_the_machine_lacks_is_a_usage_error_at_the_start(pytester, monkeypatch):
    """``--n2r-device cuda:7`` on a one-GPU machine passed the start and failed every test's setup instead."""
    import torch

    monkeypatch.setattr(torch.cuda, "is_available", lambda: True)
    monkeypatch.setattr(torch.cuda, "device_count", lambda: 1)
    assert option("device").value(pytester.parseconfig("--n2r-device", "cuda:0")) == "cuda:0"
    with pytest.raises(pytest.UsageError, match=r"--n2r-device / ini n2r_device: device='cuda:7': this machine has 1 "
                                                r"CUDA device\(s\), 'cuda:0' to 'cuda:0'"):
        option("device").value(pytester.parseconfig("--n2r-device", "cuda:7"))


@pytest.mark.parametrize("value, expected", [("true", True), ("1", True), ("yes", True), ("woodpecker", True),
                                             ("false", False), ("False", False), ("0", False), ("no", False),
                                             ("", False), (" ", False), (None, False)])
def test_ci_is_read_as_ci_services_and_users_set_it(monkeypatch, value, expected):
    """`CI=false` (how a user turns a CI-like environment's default off) derandomized the run: any value counted."""
    if value is None:
        monkeypatch.delenv("CI", raising=False)
    else:
        monkeypatch.setenv("CI", value)
    assert on_ci() is expected, f"CI={value!r} read as {'' if on_ci() else 'not '}on CI"


@pytest.mark.parametrize("origin", ["default", "--n2r-cache-dir"])
def test_an_unwritable_default_folder_writes_nothing_with_a_warning_a_chosen_one_refuses_the_run(
        monkeypatch, tmp_path, origin):
    """A read-only checkout refused every run (`--n2r-cache-dir ...: cannot write into ...`) though nobody had
    asked for a folder there; pytest's own cache only warns."""
    from pytest_n2r.data import atomic
    from pytest_n2r.errors import InvalidArgument
    from pytest_n2r.plugin.path_options import cache_folder, folder

    monkeypatch.setattr(atomic, "unwritable_reason",
                        lambda path: f"cannot write into {tmp_path} (Read-only file system)")
    where = Where(origin, tmp_path, tmp_path)
    for parse in (folder, cache_folder):
        if origin == "default":
            with pytest.warns(UserWarning, match=r"the default folder .*\.n2r-cache: cannot write into .*Read-only "
                                                 r"file system.*: nothing is written there this run"):
                assert parse(".n2r-cache", where) is None, f"{parse.__name__} kept an unwritable default folder"
        else:
            with pytest.raises(InvalidArgument, match=r"cannot write into .*choose a writable folder, or 'none'"):
                parse(".n2r-cache", where)


@pytest.mark.parametrize(("text", "expected"), [("yes", True), ("true", True), ("1", True),
                                                ("no", False), ("false", False), ("0", False)])
def test_every_switch_word_is_read(pytester, text, expected):
    """The help and errors promise yes/no, true/false, 1/0 for the switch options."""
    pytester.makeini(f"[pytest]\nn2r_derandomize = {text}\nn2r_precompile = {text}\n")
    config = pytester.parseconfig()
    assert option("derandomize").value(config) is expected
    assert option("precompile").value(config) is expected


def test_ini_scene_paths_are_taken_from_the_ini_files_folder_not_the_rootdir(pytester):
    """With --rootdir elsewhere, an ini entry is still relative to the ini file's folder."""
    project = pytester.mkdir("project")
    (project / "pytest.ini").write_text("[pytest]\nn2r_scenes = scenes/*.n2r\n")
    elsewhere = pytester.mkdir("elsewhere")
    config = pytester.parseconfig("-c", str(project / "pytest.ini"), "--rootdir", str(elsewhere))
    with pytest.raises(pytest.UsageError, match=r"matched no file \(relative to (?P<b>.*)\)") as info:
        option("scene").value(config)
    assert f"(relative to {project})" in str(info.value), str(info.value)


def test_a_tilde_in_a_folder_option_is_the_home_folder(pytester, monkeypatch, tmp_path):
    """--n2r-artifacts=~/art (after '=' no shell expands it) is the home folder's, not <rootdir>/~/art."""
    home = tmp_path / "home"
    home.mkdir()
    monkeypatch.setenv("HOME", str(home))
    config = pytester.parseconfig("--n2r-artifacts=~/art", "--n2r-cache-dir=~/cache")
    assert option("artifacts").value(config) == home / "art"
    assert option("cache_dir").value(config) == home / "cache"


@pytest.mark.parametrize("word", ["none", "None", "NONE"])
def test_none_in_any_case_writes_no_folder(pytester, word):
    """'None' turns a folder option off as 'none' does, rather than naming a folder None."""
    config = pytester.parseconfig(f"--n2r-artifacts={word}", f"--n2r-cache-dir={word}")
    assert option("artifacts").value(config) is None
    assert option("cache_dir").value(config) is None
