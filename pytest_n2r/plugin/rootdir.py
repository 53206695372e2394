"""Paths given to ``--n2r-*`` options that pytest took for test paths when it chose its rootdir and config file.

pytest picks its rootdir and config file before it loads plugins' options, from every argument its own options do
not consume that names an existing path: in ``--n2r-compare n2r-baseline.json`` the file counts as a test path, and
``pytest example_project --n2r-compare n2r-baseline.json`` run from the repository's root takes the root's config
instead of ``example_project``'s (other test ids, sizes and example counts: every relation "missing"). Written
``--n2r-compare=n2r-baseline.json`` the value is part of the option and pytest does not read it.

The check repeats pytest's first reading of the command line (its built-in options only) and its choice of rootdir
and config file without the values of pytest-n2r's path options; where that choice differs from the one pytest
made, the run stops. pytest's functions for both are internal: where they are not as expected, nothing is checked.
"""

from __future__ import annotations

import itertools
import os
import shlex
from collections.abc import Sequence
from pathlib import Path
from typing import Any

from .options import OPTIONS

__all__ = ["PATH_OPTIONS", "check_rootdir"]

#: The options whose value is a path (a scene may be a .n2r or .ply file).
PATH_OPTIONS = tuple(o.flag for o in OPTIONS if o.metavar in ("PATH", "DIR"))


def check_rootdir(invocation_args: Sequence[str], invocation_dir: Path, rootdir: Path,
                  inifile: Path | None) -> str | None:
    """The usage error when a path option written apart from its value (``--n2r-compare PATH``) changed the rootdir
    or config file pytest chose (``rootdir``, ``inifile``), naming the options, both choices and how to write them;
    ``None`` when it changed nothing (or pytest's internals could not be read)."""
    written_apart = [(option, value) for option, value in itertools.pairwise(invocation_args)
                     if option in PATH_OPTIONS and os.path.exists(invocation_dir / value)]
    if not written_apart:
        return None
    args = [*shlex.split(os.environ.get("PYTEST_ADDOPTS", "")), *invocation_args]
    early = _first_reading(args)
    if early is None or early.inifilename:  # -c names the config file: no argument moves it
        return None
    free = list(early.file_or_dir)
    misread = [(option, value) for option, value in written_apart if value in free]
    for _, value in misread:
        free.remove(value)
    expected = _setup(free, early, invocation_dir)
    if not misread or expected is None or expected == (rootdir, inifile):
        return None
    written = ", ".join(f"{option} {value}" for option, value in misread)
    fixed = " ".join(f"{option}={value}" for option, value in misread)
    return (f"pytest-n2r: {written}: pytest took the value for a test path when it chose its rootdir ({rootdir}) "
            f"and config file ({inifile or 'none'}), before it reads pytest-n2r's options; without it they are "
            f"{expected[0]} and {expected[1] or 'none'}, so this run may not use the config its tests expect; "
            f"write {fixed} (or give the config file with -c)")


def _first_reading(args: list[str]) -> Any:
    """pytest's reading of ``args`` with its built-in options only (as when it chose its rootdir), or ``None``."""
    try:
        from _pytest.config import get_config

        return get_config()._parser.parse_known_args(args)
    except Exception:  # noqa: BLE001 -- pytest's internals moved: nothing to compare with
        return None


def _setup(args: list[str], early: Any, invocation_dir: Path) -> tuple[Path, Path | None] | None:
    """The rootdir and config file pytest chooses for the free arguments ``args`` (its own ``determine_setup``),
    or ``None`` where this pytest's function takes other arguments."""
    import inspect

    try:
        from _pytest.config.findpaths import determine_setup

        known: dict[str, Any] = {  # what one pytest version's determine_setup or another's takes
            "inifile": None, "override_ini": getattr(early, "override_ini", None), "args": args,
            "rootdir_cmd_arg": getattr(early, "rootdir", None) or None, "invocation_dir": invocation_dir}
        accepted = inspect.signature(determine_setup).parameters
        root, ini, *_ = determine_setup(**{k: v for k, v in known.items() if k in accepted})
    except Exception:  # noqa: BLE001 -- pytest's internals moved: nothing to compare with
        return None
    return Path(root), None if ini is None else Path(ini)
