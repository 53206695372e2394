"""Paths given to ``--n2r-*`` options that pytest took for test paths when it chose its rootdir.

pytest picks its rootdir and config file before it loads plugins' options, from every argument that does not start
with ``-`` and names an existing path: in ``--n2r-compare n2r-baseline.json`` the file counts as a test path, and
``pytest example_project --n2r-compare n2r-baseline.json`` run from the repository's root takes the root's config
instead of ``example_project``'s (other test ids, sizes and example counts: every relation "missing"). Written
``--n2r-compare=n2r-baseline.json`` the value is part of the option and pytest does not read it.
"""

from __future__ import annotations

import itertools
import os
from collections.abc import Sequence
from pathlib import Path

__all__ = ["PATH_OPTIONS", "misread_paths", "check_rootdir"]

#: The options whose value is a path (a scene may be a .n2r or .ply file).
PATH_OPTIONS = ("--n2r-compare", "--n2r-save-baseline", "--n2r-json", "--n2r-report", "--n2r-scene",
                "--n2r-cache-dir", "--n2r-artifacts")


def _folders(args: Sequence[str], invocation_dir: Path) -> list[Path]:
    """The folders of the existing paths among ``args`` (a file's folder; a node id's file), as pytest reads its
    arguments when it looks for its rootdir."""
    folders = []
    for arg in args:
        path = invocation_dir / arg.split("::")[0]
        if not arg.startswith("-") and os.path.exists(path):
            folders.append((path if path.is_dir() else path.parent).resolve())
    return folders


def _ancestor(folders: list[Path], invocation_dir: Path) -> Path:
    """The folder pytest starts its search for a config file in: the common ancestor of ``folders``."""
    return Path(os.path.commonpath(folders)) if folders else invocation_dir.resolve()


def misread_paths(invocation_args: Sequence[str], test_args: Sequence[str],
                  invocation_dir: Path) -> list[tuple[str, str]]:
    """``(option, value)`` for each path option written apart from its existing value (``--n2r-compare PATH``) when
    that value moved the folder pytest searched for its config from, given the test paths ``test_args``.

    >>> import tempfile
    >>> here = Path(tempfile.mkdtemp()); (here / "tests").mkdir(); (here / "b.json").write_text("{}")
    2
    >>> misread_paths(["tests", "--n2r-compare", "b.json"], ["tests"], here)
    [('--n2r-compare', 'b.json')]
    >>> misread_paths(["tests", "--n2r-compare=b.json"], ["tests"], here)
    []
    >>> misread_paths(["--n2r-compare", "b.json"], [], here)  # no test path: the file's folder is pytest's
    []
    """
    values = [(option, value) for option, value in itertools.pairwise(invocation_args)
              if option in PATH_OPTIONS]
    misread = [(option, value) for option, value in values if _folders([value], invocation_dir)]
    if not misread:
        return []
    tests = _folders(test_args, invocation_dir)
    with_values = tests + _folders([value for _, value in misread], invocation_dir)
    if _ancestor(with_values, invocation_dir) == _ancestor(tests, invocation_dir):
        return []
    return misread


def check_rootdir(invocation_args: Sequence[str], test_args: Sequence[str], invocation_dir: Path,
                  rootdir: Path, inifile: Path | None) -> str | None:
    """The usage error for a path option written apart from its value when that moved pytest's rootdir or config
    file (``rootdir`` and ``inifile`` are what pytest chose; ``test_args`` its test paths): naming the options,
    what pytest chose and would have chosen, and how to write them; ``None`` when nothing moved."""
    misread = misread_paths(invocation_args, test_args, invocation_dir)
    if not misread:
        return None
    expected = _setup_without(test_args, invocation_dir)
    if expected is not None and expected == (rootdir, inifile):
        return None  # the value moved where pytest looked, not what it found
    written = ", ".join(f"{option} {value}" for option, value in misread)
    fixed = " ".join(f"{option}={value}" for option, value in misread)
    instead = "" if expected is None else f" instead of {expected[0]} and {expected[1] or 'none'}"
    return (f"pytest-n2r: {written}: pytest took the value for a test path when it chose its rootdir ({rootdir}) "
            f"and config file ({inifile or 'none'}){instead}, before it reads pytest-n2r's options, so this run "
            f"may not use the config its tests expect; write {fixed} (or give --rootdir)")


def _setup_without(test_args: Sequence[str], invocation_dir: Path) -> tuple[Path, Path | None] | None:
    """The rootdir and config file pytest chooses for ``test_args`` alone (its own ``determine_setup``), or ``None``
    where this pytest's function takes other arguments."""
    import inspect

    try:
        from _pytest.config.findpaths import determine_setup

        known = {"inifile": None, "override_ini": None, "args": list(test_args), "rootdir_cmd_arg": None,
                 "invocation_dir": invocation_dir}
        accepted = inspect.signature(determine_setup).parameters
        root, ini, *_ = determine_setup(**{k: v for k, v in known.items() if k in accepted})
    except Exception:  # noqa: BLE001 -- pytest's internals moved: the ancestors alone decide
        return None
    return Path(root), None if ini is None else Path(ini)
