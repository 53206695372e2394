"""A path option written apart from its value (``--n2r-compare PATH``) that changed pytest's rootdir or config file."""

from __future__ import annotations

import pytest


@pytest.fixture
def repository(pytester: pytest.Pytester) -> pytest.Pytester:
    """A repository whose root and whose project folder each hold a pytest config: the project's is the one its
    tests expect (a 32-pixel render size, the demo wall); the root's has no pytest-n2r key, so a report option is
    the only pytest-n2r option of a run that takes it (the check was skipped then)."""
    pytester.makepyprojecttoml('[tool.pytest.ini_options]\naddopts = "-ra"\n')  # no n2r_* key: only report options
    project = pytester.mkdir("project")
    (project / "pyproject.toml").write_text('[tool.pytest.ini_options]\nn2r_size = "32"\nn2r_scenes = ["demo:wall"]\n')
    (project / "test_inner.py").write_text("def test_scene(n2r_scene):\n    pass\n")
    (pytester.path / "report.json").write_text("{}")
    return pytester


@pytest.mark.parametrize("rootdir", [[], ["--rootdir", "project"]], ids=["", "--rootdir"])
def test_a_path_written_apart_that_moves_the_config_is_a_usage_error(repository, rootdir):
    """Run from the repository's root, ``project --n2r-json report.json`` (the file existing) had pytest choose the
    root's config: a gate then compared other test ids and sizes ("missing" everywhere) or recorded a baseline
    under the wrong config, silently. ``--rootdir`` moves the rootdir back but not the config file."""
    result = repository.runpytest("-p", "no:cacheprovider", "project", "--n2r-json", "report.json", *rootdir)
    err = " ".join(result.stderr.str().split())
    assert result.ret == pytest.ExitCode.USAGE_ERROR, f"exit code {result.ret}:\n{result.stdout.str()}\n{err}"
    project = repository.path / "project"
    assert ("ERROR: pytest-n2r: --n2r-json report.json: pytest took the value for a test path when it chose its "
            "rootdir") in err, err
    assert f"config file ({repository.path / 'pyproject.toml'})" in err, err
    assert f"without it they are {project} and {project / 'pyproject.toml'}" in err, err
    assert "write --n2r-json=report.json (or give the config file with -c)" in err, err


@pytest.mark.parametrize("args", [
    ["project", "--n2r-json=report.json"],  # the value is part of the option: pytest does not read it
    ["project", "--n2r-json", "new.json"],  # no such path: pytest skips it
    ["--n2r-json", "report.json"],  # no test path: the file's folder is where pytest looks anyway
    ["project", "--n2r-json", "report.json", "-c", "project/pyproject.toml"],  # the config file given
])
def test_a_path_that_moves_nothing_is_taken(repository, args):
    result = repository.runpytest("-p", "no:cacheprovider", *args)
    assert result.ret in (pytest.ExitCode.OK, pytest.ExitCode.NO_TESTS_COLLECTED), (
        f"exit code {result.ret} for {args}:\n{result.stdout.str()}\n{result.stderr.str()}")


def test_a_path_elsewhere_that_moves_where_pytest_looks_but_not_what_it_finds_is_taken(repository, tmp_path_factory):
    """A report file outside the repository moves the folder pytest starts its search from, yet pytest still finds
    ``project``'s config through the test path: nothing moved, nothing to refuse."""
    elsewhere = tmp_path_factory.mktemp("elsewhere") / "report.json"
    elsewhere.write_text("{}")
    result = repository.runpytest("-p", "no:cacheprovider", "project", "--n2r-json", str(elsewhere))
    assert result.ret == pytest.ExitCode.OK, f"exit code {result.ret}:\n{result.stdout.str()}\n{result.stderr.str()}"


def test_a_folder_option_written_apart_that_moves_the_config_is_a_usage_error(repository):
    """--n2r-artifacts DIR / --n2r-cache-dir DIR take a path as well as --n2r-json PATH does."""
    repository.mkdir("art")
    result = repository.runpytest("-p", "no:cacheprovider", "project", "--n2r-artifacts", "art")
    assert result.ret == pytest.ExitCode.USAGE_ERROR, result.stdout.str() + result.stderr.str()
    assert "write --n2r-artifacts=art" in " ".join(result.stderr.str().split())


def test_a_config_file_given_in_pytest_addopts_is_the_users_choice(repository, monkeypatch):
    """-c in PYTEST_ADDOPTS names the config file as on the command line: no path option moved it."""
    monkeypatch.setenv("PYTEST_ADDOPTS", "-c pyproject.toml")
    result = repository.runpytest("-p", "no:cacheprovider", "project", "--n2r-json", "report.json")
    assert result.ret != pytest.ExitCode.USAGE_ERROR, result.stdout.str() + result.stderr.str()
