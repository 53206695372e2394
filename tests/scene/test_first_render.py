"""The first render of a renderer kind in a process holds a lock file: another process (an xdist worker, the
kernel helper) compiling the same kernels makes it wait, and later renders of the kind take no lock."""

from __future__ import annotations

import threading
import time

import numpy as np
import pytest

from pytest_n2r.scene import first_render as fr
from pytest_n2r.scene.render_cache import RenderCache
from tests.plugin.fakescene import PlaneScene

pytestmark = pytest.mark.skipif(fr.fcntl is None, reason="no fcntl: no lock files (each process compiles)")


@pytest.fixture(autouse=True)
def _fresh_process_state(monkeypatch):
    monkeypatch.setattr(fr, "_RENDERED", set())


def test_a_held_kind_is_not_claimed_twice(tmp_path):
    with fr.claim_kind(tmp_path, "k", wait=False) as first:
        with fr.claim_kind(tmp_path, "k", wait=False) as second:
            assert (first, second) == (True, False), "a second claim of a held kind must fail at once"
        with fr.claim_kind(tmp_path, "other", wait=False) as other:
            assert other, "kinds have separate locks"
    with fr.claim_kind(tmp_path, "k", wait=False) as again:
        assert again, "the lock must be free once its block ended"


def test_no_directory_means_no_lock():
    with fr.claim_kind(None, "k") as held:
        assert held is False


def _wait_while_held(directory, scene, kind, seconds, meanwhile=None) -> float:
    """Seconds ``first_render`` of ``scene`` (with ``meanwhile``) waited while another thread held ``kind``'s lock
    for ``seconds``."""
    ready = threading.Event()

    def hold():
        with fr.claim_kind(directory, kind, wait=False) as held:
            assert held
            ready.set()
            time.sleep(seconds)

    holder = threading.Thread(target=hold)
    holder.start()
    ready.wait()
    start = time.perf_counter()
    with fr.first_render(directory, scene, meanwhile):
        waited = time.perf_counter() - start
    holder.join()
    return waited


def test_the_first_render_waits_for_another_holder_and_later_ones_do_not(tmp_path):
    scene = PlaneScene(width=16, height=12)
    kind = fr.renderer_kind(scene)
    waited = _wait_while_held(tmp_path, scene, kind, 0.5)
    assert waited >= 0.4, f"the first render of {kind} went ahead after {waited:.2f} s while the lock was held"
    assert fr.rendered(kind)
    waited = _wait_while_held(tmp_path, scene, kind, 1.0)
    assert waited < 0.3, f"a later render of {kind} waited {waited:.2f} s for the lock it no longer needs"


def test_the_first_render_of_a_kind_runs_with_the_collector_off_and_turns_it_back_on(tmp_path):
    import gc

    scene = PlaneScene(width=16, height=12)
    seen = []
    for _ in range(2):
        with fr.first_render(tmp_path, scene):
            seen.append(gc.isenabled())
    assert seen == [False, True], f"collector on during the first and a later render: {seen}"
    assert gc.isenabled(), "the first render left the collector off"
    gc.disable()
    try:
        with pytest.raises(RuntimeError), fr.collector_paused():
            raise RuntimeError("compile failed")
        assert not gc.isenabled(), "collector_paused turned on a collector that was off before it"
    finally:
        gc.enable()
    with pytest.raises(RuntimeError), fr.collector_paused():
        raise RuntimeError("compile failed")
    assert gc.isenabled(), "a failed block left the collector off"


def test_a_failed_first_render_is_not_counted(tmp_path):
    scene = PlaneScene(width=16, height=12)
    with pytest.raises(RuntimeError), fr.first_render(tmp_path, scene):
        raise RuntimeError("compile failed")
    assert not fr.rendered(fr.renderer_kind(scene))


def test_the_render_cache_renders_the_first_of_a_kind_under_its_lock(tmp_path, monkeypatch):
    scene = PlaneScene(width=16, height=12)
    cache = RenderCache(tmp_path)
    seen = []
    cache.on_first_render = seen.append
    waited = []
    cache.while_waiting = waited.append
    claims = []
    claim = fr.claim_kind

    def spy(directory, kind, wait=True, meanwhile=None):
        claims.append((str(directory), kind))
        meanwhile()  # as if another process held the lock
        return claim(directory, kind, wait)

    monkeypatch.setattr(fr, "claim_kind", spy)
    view = scene.views[0]
    for dx in (0.0, 0.1):
        c2w = view.c2w.copy()
        c2w[0, 3] += dx
        cache.render(scene, c2w, view.camera, ("rgb", "depth"))
    assert claims == [(str(tmp_path), fr.renderer_kind(scene))], "exactly the first render takes the lock"
    assert seen == [scene], "on_first_render is called once, with the scene, before the cache's first render"
    assert waited == [scene], "the first render's wait for its lock does not call while_waiting with the scene"
    assert (tmp_path / "kernel-locks").is_dir()
    np.testing.assert_array_equal(cache.render(scene, view.c2w, view.camera).rgb,
                                  scene.render(view.c2w, view.camera).rgb)


# -- the session's helper (pytest_n2r.plugin.precompile) compiles the kinds the session reaches later ---------


def _job(tmp_path, scene_file, skip="nothing"):
    import sys

    return {"scenes": [["object", "file", str(scene_file)]], "skip": skip, "cache_dir": str(tmp_path),
            "device": "cpu", "render_scale": 1.0, "sys_path": list(sys.path)}


def test_the_helper_compiles_a_kind_nobody_holds_and_skips_held_ones(tmp_path, tiny_scene_file):
    from pytest_n2r.plugin.precompile import HELPER_KIND, run_job
    from pytest_n2r.scene.loading import load_scene

    kind = fr.renderer_kind(load_scene(tiny_scene_file, device="cpu"))
    assert run_job(_job(tmp_path, tiny_scene_file)) == [kind]
    assert run_job(_job(tmp_path, tiny_scene_file, skip=kind)) == [], "the session's own kind is skipped"
    with fr.claim_kind(tmp_path, kind, wait=False):
        assert run_job(_job(tmp_path, tiny_scene_file)) == [], "a kind another process compiles is skipped"
    with fr.claim_kind(tmp_path, HELPER_KIND, wait=False):
        assert run_job(_job(tmp_path, tiny_scene_file)) == [], "one helper per cache directory"


def test_a_session_starts_the_helper_on_its_first_render(tmp_path, tiny_scene_file):
    from functools import partial

    from pytest_n2r.plugin.precompile import start_for_session
    from pytest_n2r.plugin.scenes import SceneSpec
    from pytest_n2r.plugin.session import N2RSession

    session = N2RSession(cache_dir=tmp_path, device="cpu", render_scale=1.0,
                         planned=[SceneSpec("object", "file", str(tiny_scene_file))])
    session.on_first_render = partial(start_for_session, session)
    plane = PlaneScene(width=16, height=12)
    session.cache.render(plane, plane.views[0].c2w, plane.views[0].camera)
    helper = session.helper
    assert helper is not None, "a first render with a scene of another family planned starts the helper"
    assert helper.wait(timeout=120) == 0
    log = (tmp_path / "kernel-locks" / "precompile.log").read_text()
    assert "FieldScene" in log and "compiled" in log, log
    session.cache.render(plane, plane.views[1].c2w, plane.views[1].camera)
    assert session.helper is helper, "the helper starts once per session"
    session.close()
    assert session.helper is None


def test_a_piece_is_locked_under_the_directory_of_its_kernel_locks_and_nowhere_else(tmp_path):
    with fr.claim_piece("p") as outside:
        assert outside is False, "a piece claimed outside kernel_locks took a lock"
    with fr.kernel_locks(tmp_path), fr.claim_piece("p") as held:
        assert held, "a piece inside kernel_locks was not locked"
        with fr.claim_kind(tmp_path, "piece-p", wait=False) as other:
            assert other is False, "another process could claim a piece that is held"
    with fr.claim_kind(tmp_path, "piece-p", wait=False) as again:
        assert again, "the piece's lock must be free once its block ended"


def test_the_first_render_locks_its_pieces_under_its_directory(tmp_path):
    scene = PlaneScene(width=16, height=12)
    with fr.first_render(tmp_path, scene), fr.claim_piece("p") as held:
        assert held and (tmp_path / "kernel-locks" / "piece-p.lock").exists(), "the piece was not locked there"


def test_a_first_render_that_must_wait_works_meanwhile_once_and_one_that_need_not_does_not(tmp_path):
    scene = PlaneScene(width=16, height=12)
    kind = fr.renderer_kind(scene)
    calls: list[object] = []
    with fr.first_render(tmp_path, scene, meanwhile=lambda: calls.append(fr._DIRECTORY.get())):
        pass
    assert calls == [], "a first render that found the lock free worked meanwhile"
    fr._RENDERED.clear()
    _wait_while_held(tmp_path, scene, kind, 0.5, meanwhile=lambda: calls.append(fr._DIRECTORY.get()))
    assert calls == [tmp_path], f"meanwhile ran {len(calls)} times, or without the pieces' lock directory: {calls}"


def test_a_lock_file_is_never_created_through_a_link(tmp_path):
    locks = tmp_path / "kernel-locks"
    locks.mkdir()
    target = tmp_path / "elsewhere" / "made-by-the-lock"
    target.parent.mkdir()
    link = fr._lock_path(tmp_path, "k")
    link.symlink_to(target)
    with fr.claim_kind(tmp_path, "k", wait=False) as held:
        assert held
    assert not target.exists(), "the lock was created through a link planted in its place"
    assert link.is_file() and not link.is_symlink()
