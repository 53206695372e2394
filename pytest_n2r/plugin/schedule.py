"""The order of tests under pytest-xdist, so that the workers finish together.

Tests on fitted scenes are the slowest of a run (field renders, and the field kernels' compile in a fresh
checkout). In the order pytest collects them they can come last (the example project's four fitted-twin
relations did), and pytest-xdist hands tests out in chunks of consecutive ones: one worker then ran them
alone while the other waited. Under xdist pytest-n2r therefore

- moves the tests on fitted scenes (:data:`SLOW_FAMILIES`) to the front of every worker's collection, in
  their order (the same in every worker, as xdist requires), and
- hands tests out one at a time (xdist's ``--maxschedchunk 1``, unless given) in a session that uses
  pytest-n2r, so the slow tests spread over the workers first and the short ones fill in behind them.

A serial run keeps pytest's order. Loaded with the plugin (``pytest_plugins``), so ``-p no:n2r`` turns it off.
"""

from __future__ import annotations

from typing import Any

import pytest

from .options import is_used

#: Scene families (:func:`pytest_n2r.plugin.precompile.family`) whose renders take longest: fitted fields.
SLOW_FAMILIES = frozenset({"demo-field", "file.n2r"})


def _on_slow_scene(item: pytest.Item) -> bool:
    spec = getattr(getattr(item, "callspec", None), "params", {}).get("n2r_scene")
    if spec is None:  # before importing the engine: a suite that does not use pytest-n2r never loads it
        return False
    from .precompile import family

    return family(spec) in SLOW_FAMILIES


def pytest_configure(config: pytest.Config) -> None:
    """In the xdist controller of a session that uses pytest-n2r: tests handed out one at a time."""
    option = config.option
    if hasattr(config, "workerinput") or getattr(option, "dist", "no") == "no" or not is_used(config):
        return
    if hasattr(option, "maxschedchunk") and option.maxschedchunk is None:
        option.maxschedchunk = 1


@pytest.hookimpl(trylast=True)  # after pytest's own reordering by fixture scope
def pytest_collection_modifyitems(config: pytest.Config, items: list[Any]) -> None:
    """In an xdist worker: the tests on fitted scenes first (a stable sort: the rest keep their order)."""
    if hasattr(config, "workerinput"):
        items.sort(key=lambda item: not _on_slow_scene(item))
