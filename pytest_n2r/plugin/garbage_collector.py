"""The cyclic garbage collector over a session: off during the start-up, the heap frozen after the first setup on
each scene, unfrozen after pytest's last collections.

Conventions
-----------
- Everything a session loads and keeps (imports, scenes, networks, compiled kernels) lives until its end and holds
  few cycles; the collector walking it in every full collection is time spent on nothing. Measured on the main job
  (docs/performance-log.md, 2 December): the collector's time 7.1 → 2.7 s of a cold run (the kernels' compilation
  makes many collections), 0.9 → 0.6 s of a warm one.
- Garbage is never frozen: :func:`freeze_after_setup` collects first, and freezes once a scene rather than at every
  test (a cycle that was unreachable when frozen would never be freed). A released scene's cycles frozen before stay
  frozen (some 17 MB of a fitted scene's 450): unfreezing would walk the whole heap at each change of scene.
- The heap is unfrozen at the session's very end (:func:`unfreeze`), after pytest's own cleanups. So pytest's last
  collections, which report an exception raised in a ``__del__`` (an "unraisable" one), do not collect what the
  session froze and later dropped: such an exception shows later, at the next full collection or at exit.
"""

from __future__ import annotations

import gc

import pytest

__all__ = ["freeze_after_setup", "pause", "rescan_scenes", "resume", "unfreeze"]

#: ids of the scenes after whose first setup since a scene was released the heap was frozen.
_FROZEN_SCENES = pytest.StashKey[set]()
#: True once the session froze the heap (:func:`freeze_after_setup`); :func:`unfreeze` unfreezes it.
_FROZEN = pytest.StashKey[bool]()
#: True while the collector is off for the session's start-up (:func:`pause`).
_PAUSED = pytest.StashKey[bool]()


def pause(config: pytest.Config) -> None:
    """Turn the collector off until the end of the first test's setup (:func:`freeze_after_setup`). The start-up
    (the engine's imports, the test modules', a network's in its fixture) allocates millions of objects that live for
    the session: in a warm main job 12 full collections walked them in 0.55-0.70 s of CPU, with the collector off
    during the start-up 5 took 0.37-0.45 s (docs/performance-log.md, 2 December). Not in a pytest-xdist controller
    (it runs no test), nor when the collector was off already; :func:`resume` turns it back on."""
    if gc.isenabled() and (hasattr(config, "workerinput") or getattr(config.option, "dist", "no") == "no"):
        gc.disable()
        config.stash[_PAUSED] = True


def resume(config: pytest.Config) -> bool:
    """Turn the collector back on if :func:`pause` turned it off; whether it did."""
    if not config.stash.get(_PAUSED, False):
        return False
    config.stash[_PAUSED] = False
    gc.enable()
    return True


def freeze_after_setup(item: pytest.Item) -> None:
    """After the setup of the first test on each scene (again after :func:`rescan_scenes`), and after the session's
    first setup when the start-up ran paused: collect, then move every object alive out of the collector's sight
    (:func:`gc.freeze`), then :func:`resume`. Resumed first, the collector's next allocation started a young
    collection of every object the start-up made (0.1 s in a warm main job)."""
    paused = item.config.stash.get(_PAUSED, False)
    scene = getattr(item, "funcargs", {}).get("n2r_scene")
    frozen = item.config.stash.setdefault(_FROZEN_SCENES, set())
    if new_scene := scene is not None and id(scene) not in frozen:
        frozen.add(id(scene))
    if new_scene or paused:
        gc.collect()
        gc.freeze()
        item.config.stash[_FROZEN] = True
    resume(item.config)


def rescan_scenes(config: pytest.Config) -> None:
    """After a scene's release: the next setup on any scene collects (the released scene's cycles) and freezes."""
    config.stash.get(_FROZEN_SCENES, set()).clear()


def unfreeze(config: pytest.Config) -> None:
    """Unfreeze what the session froze, so that a process running pytest again (``pytest.main``, pytester) can free
    it. Registered as the config's first cleanup, so it runs after pytest's own, whose five collections
    (``_pytest.unraisableexception``) then walk only what is not frozen: with the heap unfrozen before them they took
    0.95 s at the end of a warm main job (docs/performance.md, 7 December)."""
    if config.stash.get(_FROZEN, False):
        config.stash[_FROZEN] = False
        gc.unfreeze()
