"""Render threads under pytest-xdist: each worker's share of the cores."""

from __future__ import annotations

import numba

from pytest_n2r.plugin.threads import render_threads, share_cores


def test_workers_share_the_cores_and_a_users_setting_is_kept(monkeypatch):
    assert render_threads(2, cores=2) == 1 and render_threads(2, cores=16) == 8 and render_threads(0, cores=4) == 4
    assert share_cores({}) is None, "outside pytest-xdist nothing changes"
    assert share_cores({"PYTEST_XDIST_WORKER_COUNT": "1"}) is None
    assert share_cores({"PYTEST_XDIST_WORKER_COUNT": "2", "NUMBA_NUM_THREADS": "3"}) is None, "the user's own"
    before = numba.get_num_threads()
    try:
        # numba is imported here, so the count is set in numba itself
        monkeypatch.setattr("pytest_n2r.plugin.threads._cores", lambda: 2 * before)
        assert share_cores({"PYTEST_XDIST_WORKER_COUNT": "2"}) == before == numba.get_num_threads()
        monkeypatch.setattr("pytest_n2r.plugin.threads._cores", lambda: 2)
        assert share_cores({"PYTEST_XDIST_WORKER_COUNT": "4"}) == 1 == numba.get_num_threads()
    finally:
        numba.set_num_threads(before)


def test_before_numba_is_imported_the_environment_sets_it(monkeypatch):
    monkeypatch.delitem(__import__("sys").modules, "numba")
    environ: dict[str, str] = {"PYTEST_XDIST_WORKER_COUNT": "2"}
    threads = share_cores(environ)
    assert environ["NUMBA_NUM_THREADS"] == str(threads) and threads >= 1
