"""The render cache's files: stores that a concurrent clear or a broken disk cannot fail, and trimming that counts
decisions, floors and temporary files against the cap, runs as a session opens the cache and removes what a killed
writer left."""

from __future__ import annotations

import errno
import json
import os
import stat
import tempfile
import time
import warnings
from pathlib import Path

import numpy as np
import pytest

from pytest_n2r import Transform
from pytest_n2r.plugin.session import N2RSession
from pytest_n2r.scene.render_cache import RenderCache

from ..plugin.fakescene import PlaneScene


def _pose(scene, yaw=0.0):
    return Transform(yaw=yaw).apply(scene.views[0].c2w)


def _du(folder):
    """Bytes of every file under ``folder``, as ``du`` would count them (not the cache's own accounting)."""
    return sum(p.stat().st_size for p in folder.rglob("*") if p.is_file()) if folder.exists() else 0


def _held(folder):
    """Bytes of the cache's entries in ``folder``: renders, decisions and floors."""
    return sum(_du(folder / sub) for sub in ("renders", "decisions", "floors"))


def test_a_clear_under_a_store_does_not_fail_the_render(tmp_path, monkeypatch):
    """A concurrent ``--n2r-cache-clear`` removed ``renders/`` while an entry was written: the FileNotFoundError of
    the rename reached the relation, which reported the SUT as not deterministic."""
    scene = PlaneScene()
    cache = RenderCache(tmp_path)
    cache.render(scene, _pose(scene), scene.views[0].camera, "rgb")  # the directory tagged, renders/ made
    save, cleared = np.save, []

    def save_then_clear(f, arr, **kwargs):
        save(f, arr, **kwargs)
        if not cleared:
            cleared.append(RenderCache(tmp_path).clear())  # another process clears mid-write

    monkeypatch.setattr(np, "save", save_then_clear)
    view = cache.render(scene, _pose(scene, 1.0), scene.views[0].camera, "rgb")
    assert view.rgb is not None and cleared, "the render was not returned"
    assert len(list((tmp_path / "renders").glob("*/*.npy"))) == 1, "the store was not made again after the clear"


@pytest.mark.parametrize(("error", "stores"), [(OSError(errno.ENOSPC, "No space left on device"), 1),
                                               (PermissionError(errno.EACCES, "Permission denied"), 1),
                                               (FileNotFoundError(errno.ENOENT, "No such file or directory"), 16)])
def test_a_disk_that_cannot_store_is_said_once_and_storing_stops(tmp_path, monkeypatch, error, stores):
    """A full disk, no permission, or a folder that never stays: every store raised into its relation. Now the
    renders are returned, one warning names the folder and the error, and the cache stores nothing more."""
    scene = PlaneScene()
    cache = RenderCache(tmp_path)
    cache.render(scene, _pose(scene), scene.views[0].camera, "rgb")
    tries = []

    def broken(*args, **kwargs):
        tries.append(1)
        raise error

    monkeypatch.setattr(tempfile, "mkstemp", broken)
    with warnings.catch_warnings(record=True) as caught:
        warnings.simplefilter("always")
        for yaw in range(1, 13):
            assert cache.render(scene, _pose(scene, yaw), scene.views[0].camera, "rgb").rgb is not None
    said = [str(w.message) for w in caught]
    name = type(error).__name__
    assert said == [f"the render cache {str(tmp_path)!r} stores nothing more this session: {name}: {error}"], said
    assert len(tries) == stores, f"{len(tries)} tries to store after the cache stopped storing"


def test_a_scan_beside_a_clear_does_not_fail(tmp_path, monkeypatch):
    """``renders/`` removed while the cap's scan walked it: the scan's FileNotFoundError reached the relation."""
    scene = PlaneScene()
    cache = RenderCache(tmp_path)
    cache.render(scene, _pose(scene), scene.views[0].camera, "rgb")
    cache.disk_bytes = 1
    real = os.scandir  # the listing is taken, then the folder removed before the scan reads its entries

    def scandir_then_clear(path):
        found = list(real(path))
        if str(path).endswith("renders"):
            RenderCache(tmp_path).clear()
        return _Listing(found)

    monkeypatch.setattr(os, "scandir", scandir_then_clear)
    assert cache.trim() == 0 and cache.disk_usage() == 0


class _Listing(list):
    def __enter__(self):
        return self

    def __exit__(self, *exc):
        return False


def test_a_session_trims_the_cache_as_it_opens_it(tmp_path):
    """Trimming ran only after one process wrote a tenth of the cap: 22 small sessions left 72 MiB under a 40 MiB
    cap. The session now trims as it opens the cache."""
    scene = PlaneScene()
    camera = scene.views[0].camera
    one = camera.width * camera.height * 3 + 128
    filler = RenderCache(tmp_path, disk_bytes=100 * one)
    for yaw in range(10):
        filler.render(scene, _pose(scene, yaw), camera, "rgb")
    assert _du(tmp_path / "renders") == 10 * one
    assert N2RSession(cache_dir=tmp_path, cache_bytes=5 * one).cache.disk_bytes == 5 * one
    assert _du(tmp_path / "renders") <= 4 * one, f"the session opened a cache of {_du(tmp_path)} bytes, cap {5 * one}"


def test_decisions_and_floors_count_in_the_cap_and_go_oldest_first(tmp_path):
    """3 000 kept results left 13 MB under a 1 MiB cap: decisions (and floors) were neither counted nor trimmed
    while the renders were under the cap (and a 90-byte decision takes a 4 KiB block)."""
    scene = PlaneScene()
    cache = RenderCache(tmp_path, disk_bytes=10**9)
    cache.render(scene, _pose(scene), scene.views[0].camera, "rgb")
    keys = [f"{i:064x}" for i in range(300)]
    for age, key in enumerate(keys):
        cache.put_decision(key, {"detail": "x" * 200})
        os.utime(cache._decision_path(key), (1000.0 + age, 1000.0 + age))
    (tmp_path / "floors").mkdir()
    for i in range(50):
        (tmp_path / "floors" / f"{i:032x}.json").write_text(json.dumps({"pad": "y" * 200}))
        os.utime(tmp_path / "floors" / f"{i:032x}.json", (500.0 + i, 500.0 + i))
    assert cache.decision(keys[0]) is not None  # a hit: recently used, kept by the trim
    renders, before = _du(tmp_path / "renders"), cache.disk_usage()
    cache.disk_bytes = before // 2
    cache.trim()
    assert cache.disk_usage() <= 0.8 * cache.disk_bytes and _held(tmp_path) <= cache.disk_bytes, (
        f"{cache.disk_usage()} bytes ({_held(tmp_path)} in files) left under a cap of {cache.disk_bytes}")
    assert not list((tmp_path / "floors").glob("*.json")), "the oldest entries, the floors, were not trimmed first"
    assert cache.decision(keys[0]) is not None and cache.decision(keys[-1]) is not None
    assert cache.decision(keys[1]) is None, "an old decision was kept while newer ones went"
    assert _du(tmp_path / "renders") == renders, "a render, newer than every decision but one, was evicted"


def test_clear_empties_the_floors_too(tmp_path):
    scene = PlaneScene()
    cache = RenderCache(tmp_path)
    cache.render(scene, _pose(scene), scene.views[0].camera, "rgb")
    (tmp_path / "floors").mkdir()
    (tmp_path / "floors" / "f.json").write_text("{}")
    cache.clear()
    assert not (tmp_path / "floors").exists(), "--n2r-cache-clear left the kept field floors"


def test_trimming_deletes_what_a_killed_writer_left_but_not_a_writers_fresh_file(tmp_path):
    """``.{name}.XXXX.tmp`` files of a killed writer were neither counted nor ever deleted."""
    scene = PlaneScene()
    cache = RenderCache(tmp_path)
    cache.render(scene, _pose(scene), scene.views[0].camera, "rgb")
    folder = next((tmp_path / "renders").iterdir())
    stale, fresh = folder / ".a.rgb.npy.k1ll.tmp", folder / ".b.rgb.npy.w1p.tmp"
    for path in (stale, fresh):
        path.write_bytes(b"\0" * 5000)
    old = time.time() - 3600
    os.utime(stale, (old, old))
    assert cache.disk_usage() >= 10_000, f"temporary files not counted: {cache.disk_usage()} bytes"
    assert cache.trim() >= 5000
    assert not stale.exists() and fresh.exists(), "a killed writer's file kept, or a concurrent writer's deleted"


def test_a_disk_that_cannot_store_fails_no_render_under_warnings_as_errors(tmp_path, monkeypatch, capsys):
    """With -W error (filterwarnings = error, common in projects) the cache's warning became an exception raised
    out of the store, into the relation: a full disk failed tests the docs say storing never fails."""
    scene = PlaneScene()
    cache = RenderCache(tmp_path)
    monkeypatch.setattr(tempfile, "mkstemp", lambda *a, **k: (_ for _ in ()).throw(OSError(28, "No space left")))
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        assert cache.render(scene, _pose(scene, 3), scene.views[0].camera, "rgb").rgb is not None
    assert "stores nothing more this session: OSError: [Errno 28] No space left" in capsys.readouterr().err


def _entries(folder):
    return [p for sub in ("renders", "decisions") for p in (folder / sub).rglob("*") if p.is_file()]


@pytest.mark.parametrize("mask", [0o002, 0o027], ids=["umask 002", "umask 027"])
def test_entries_get_the_mode_open_gives_under_the_umask(tmp_path, mask, umask):
    """A cache shared between users (a CI cache restored by another uid, a group's project folder): its entries
    were 0o600 whatever the umask, so unreadable to the others."""
    scene = PlaneScene()
    umask(mask)
    cache = RenderCache(tmp_path)
    cache.render(scene, _pose(scene), scene.views[0].camera, ("rgb", "depth"))
    cache.put_decision("ab" + "0" * 62, {"valid": True})
    modes = {p.relative_to(tmp_path).as_posix(): oct(stat.S_IMODE(p.stat().st_mode)) for p in _entries(tmp_path)}
    assert len(modes) == 3 and set(modes.values()) == {oct(0o666 & ~mask)}, \
        f"under umask {oct(mask)} the entries got modes {modes}, expected {oct(0o666 & ~mask)}"


def _refused(monkeypatch, folder, *, read):
    """Deletions (and reads too, with ``read``) of the entries under ``folder`` fail with PermissionError, as for
    another user's 0o600 entry in a folder of theirs (chmod does not do it for root, who runs CI); the deletions
    tried are returned."""
    read_bytes, tried = Path.read_bytes, []

    def refuse(kind, original):
        def call(path, *args, **kwargs):
            if path.parent.parent.parent != folder or path.parent.parent.name not in ("renders", "decisions"):
                return original(path, *args, **kwargs)
            if kind == "unlink":
                tried.append(path)
            raise PermissionError(errno.EACCES, "Permission denied", str(path))
        return call

    monkeypatch.setattr(Path, "unlink", refuse("unlink", Path.unlink))
    if read:
        monkeypatch.setattr(Path, "read_bytes", refuse("read", read_bytes))
    return tried


def test_an_entry_we_may_not_read_is_a_miss_and_left_where_it_is(tmp_path, monkeypatch):
    """Another user's 0o600 entry: the PermissionError of its read, then of its deletion, failed the test."""
    scene, key = PlaneScene(), "cd" + "0" * 62
    RenderCache(tmp_path).render(scene, _pose(scene), scene.views[0].camera, "rgb")
    RenderCache(tmp_path).put_decision(key, {"valid": True})
    tried = _refused(monkeypatch, tmp_path, read=True)
    cache = RenderCache(tmp_path)
    assert cache.decision(key) is None, "a decision that cannot be read was not a miss"
    view = cache.render(scene, _pose(scene), scene.views[0].camera, "rgb")
    assert view.rgb is not None and scene.calls == 2, f"the unreadable entry was not rendered again ({scene.calls})"
    assert not tried, f"entries we may not read are not ours to delete, yet deleting {tried} was tried"
    assert len(_entries(tmp_path)) == 2, f"the entries are not all there: {_entries(tmp_path)}"


def test_a_damaged_entry_that_cannot_be_deleted_is_a_miss(tmp_path, monkeypatch):
    """A damaged entry in a folder we may not write: the PermissionError of its deletion failed the test."""
    scene, key = PlaneScene(), "ef" + "0" * 62
    RenderCache(tmp_path).render(scene, _pose(scene), scene.views[0].camera, "rgb")
    RenderCache(tmp_path).put_decision(key, {"valid": True})
    for entry in _entries(tmp_path):
        entry.write_bytes(entry.read_bytes()[:7])
    tried = _refused(monkeypatch, tmp_path, read=False)
    cache = RenderCache(tmp_path)
    assert cache.decision(key) is None, "a torn decision was read"
    view = cache.render(scene, _pose(scene), scene.views[0].camera, "rgb")
    assert view.rgb is not None and scene.calls == 2, f"the damaged entry was not rendered again ({scene.calls})"
    assert len(tried) == 2, f"the damaged entries were not both tried for deletion: {tried}"


def test_the_cache_is_scanned_for_its_cap_only_once_it_may_be_near_it(tmp_path, monkeypatch):
    """A cold main job scanned its 4 360 entries 9 times (a scan every 64 MiB stored: 35-43 ms each, linear in the
    entries) though they held a quarter of the cap; the cap must still hold."""
    from pytest_n2r.scene import render_cache

    scans = []
    trim = render_cache.trim_entries
    monkeypatch.setattr(render_cache, "trim_entries", lambda *a, **k: (scans.append(1), trim(*a, **k))[1])
    scene = PlaneScene()
    camera = scene.views[0].camera
    one = camera.width * camera.height * 3 + 128
    cache = RenderCache(tmp_path, disk_bytes=40 * one, memory_bytes=0)  # a tenth of it: 4 renders
    for yaw in range(19):  # a scan after 5 renders (nothing known held yet), then none below half the cap
        cache.render(scene, _pose(scene, yaw), camera, "rgb")
    assert len(scans) == 1, f"{len(scans)} scans for 19 renders into a cap of 40 (one every 5 before)"
    for yaw in range(19, 120):
        cache.render(scene, _pose(scene, yaw), camera, "rgb")
    assert _du(tmp_path / "renders") <= 45 * one, f"the cap of 40 renders passed: {_du(tmp_path) / one:.1f} held"


def test_workers_storing_into_one_cache_keep_it_under_its_cap(tmp_path):
    """Each of pytest-xdist's workers counts only what it stores: four that each waited for half the cap before
    scanning again held twice the cap together."""
    scene = PlaneScene()
    camera = scene.views[0].camera
    one = camera.width * camera.height * 3 + 128
    RenderCache(tmp_path).render(scene, _pose(scene, -1), camera, "rgb")  # a cache folder an earlier run made
    workers = [RenderCache(tmp_path, disk_bytes=40 * one, memory_bytes=0, writers=4) for _ in range(4)]
    for cache in workers:
        cache.trim()  # as each session does when it opens the cache: each finds 1 render held
    peak = 0
    for yaw in range(120):
        workers[yaw % 4].render(scene, _pose(scene, yaw), camera, "rgb")
        peak = max(peak, _du(tmp_path / "renders"))
    # each checks after a tenth of the cap of its own (4 renders): four may pass the cap by that much each before one
    # scans (46 here, as before scans waited for half the cap; 73 when each counted only its own stores)
    assert peak <= 50 * one, f"four workers held {peak / one:.1f} renders under a cap of 40"


def _rendered(folder, count):
    """``count`` views of the plane rendered into a cache in ``folder`` (no cap to speak of); the scene, the camera
    and the bytes one view takes."""
    scene = PlaneScene()
    camera = scene.views[0].camera
    cache = RenderCache(folder, disk_bytes=10**9)
    for yaw in range(count):
        cache.render(scene, _pose(scene, yaw), camera, "rgb")
    return scene, camera, camera.width * camera.height * 3 + 128


def test_entries_dated_by_a_clock_ahead_go_first_and_the_ones_used_here_stay(tmp_path):
    """A cache CI restored from a machine whose clock ran a day ahead: its entries looked newer than the ones this
    session had just used, so each trim evicted the entries in use and kept the dead ones (and a temporary file
    dated tomorrow was no writer's, but stayed)."""
    from pytest_n2r.scene.cache_files import cache_entries, trim_entries

    scene, camera, one = _rendered(tmp_path, 20)
    now = time.time()
    restored = sorted(p for _, p, _, _ in cache_entries(tmp_path))
    for path in restored:
        os.utime(path, (now + 86400, now + 86400))  # written under a clock a day ahead
    leftover = restored[0].with_name(f".{restored[0].name}.abcd1234.tmp")
    leftover.write_bytes(b"x")
    os.utime(leftover, (now + 86400, now + 86400))
    used = RenderCache(tmp_path, disk_bytes=10**9)
    for yaw in range(20, 30):
        used.render(scene, _pose(scene, yaw), camera, "rgb")  # stored now, by this machine's clock
    trim_entries(tmp_path, 15 * one, now=time.time())
    left = {p for _, p, _, _ in cache_entries(tmp_path)}
    assert not leftover.exists(), "a temporary file dated by another clock was kept"
    assert len(left) == 10 and left.isdisjoint(restored), (
        f"{len(left & set(restored))} restored entries kept, {len(left - set(restored))} of the 10 stored here")


def test_an_entry_stored_during_the_trims_scan_is_the_newest_not_another_clocks(tmp_path):
    """A worker's store a moment after the trim read the time is dated after it: taken for another clock's, it went
    first, before an entry an hour old."""
    from pytest_n2r.scene.cache_files import cache_entries, trim_entries

    _, _, one = _rendered(tmp_path, 3)
    now = time.time()
    old, recent, during = sorted(p for _, p, _, _ in cache_entries(tmp_path))
    for path, when in ((old, now - 3600), (recent, now - 1), (during, now + 0.05)):
        os.utime(path, (when, when))
    trim_entries(tmp_path, 2 * one, now=now)  # 80 % of 2 renders: one stays
    assert [p for _, p, _, _ in cache_entries(tmp_path)] == [during], "not the newest entry kept"
