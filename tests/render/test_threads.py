"""The render threads (render/threads.py): a kernel's parts cover its work exactly once, on the thread count numba
is set to, and a part's error reaches the caller."""

from __future__ import annotations

import threading
import time

import numba
import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st
from numba import njit

from pytest_n2r.render.threads import render_pool, run_dealt, run_parts


@njit(nogil=True)
def _count(first, last, hits):
    for i in range(first, last):
        hits[i] += 1


@njit(nogil=True)
def _count_dealt(part, parts, hits):
    for i in range(part, hits.size, parts):
        hits[i] += 1


@settings(max_examples=60, deadline=None)
@given(n=st.integers(0, 5000), count=st.integers(1, 8), dealt=st.booleans())
def test_the_parts_cover_the_work_exactly_once(n, count, dealt):
    before = numba.get_num_threads()
    numba.set_num_threads(min(count, numba.config.NUMBA_NUM_THREADS))
    try:
        hits = np.zeros(n, dtype=np.int64)
        if dealt:
            run_dealt(_count_dealt, n, hits)
        else:
            run_parts(_count, n, hits)
    finally:
        numba.set_num_threads(before)
    runner = "run_dealt" if dealt else "run_parts"
    assert (hits == 1).all(), (
        f"{runner}, n={n}, {count} threads: items run {np.bincount(hits).tolist()} times (0, 1, 2...)")


def test_dealt_parts_take_every_parts_th_item_on_the_set_thread_count():
    if numba.config.NUMBA_NUM_THREADS < 2:
        pytest.skip("numba has a single thread here")
    heads: list[tuple[int, int]] = []
    lock = threading.Lock()

    def record(part: int, parts: int) -> None:
        with lock:
            heads.append((part, parts))

    before = numba.get_num_threads()
    try:
        numba.set_num_threads(2)
        run_dealt(record, 5)
        assert sorted(heads) == [(0, 2), (1, 2)], f"two threads, 5 items: parts {heads}, expected (0, 2), (1, 2)"
        heads.clear()
        run_dealt(record, 1)
        assert heads == [(0, 1)], f"two threads, one item: parts {heads}, expected the one part (0, 1)"
    finally:
        numba.set_num_threads(before)


def test_a_render_uses_the_thread_count_numba_is_set_to():
    if numba.config.NUMBA_NUM_THREADS < 2:
        pytest.skip("numba has a single thread here")
    seen: list[str] = []
    lock = threading.Lock()

    def record(first: int, last: int) -> None:
        with lock:
            seen.append(threading.current_thread().name)

    before = numba.get_num_threads()
    caller = threading.current_thread().name
    try:
        numba.set_num_threads(1)
        run_parts(record, 1000)
        assert seen == [caller], f"one thread set: the parts ran on {seen}"
        seen.clear()
        numba.set_num_threads(2)
        run_parts(record, 1000)
        assert sorted(seen) == [caller, seen[1]] and seen[1].startswith("n2r-render"), (
            f"two threads set: the parts ran on {seen}, expected the caller and one render thread")
    finally:
        numba.set_num_threads(before)


@pytest.mark.parametrize("failing", [0, 1])
def test_an_error_in_a_part_reaches_the_caller_after_every_part_ended(failing):
    if numba.config.NUMBA_NUM_THREADS < 2:
        pytest.skip("numba has a single thread here")
    ended: list[int] = []

    def part(first: int, last: int) -> None:
        if first == 50 * failing:
            raise ValueError(f"part [{first}, {last}) failed")
        time.sleep(0.05)
        ended.append(first)

    before = numba.get_num_threads()
    try:
        numba.set_num_threads(2)
        with pytest.raises(ValueError, match=rf"part \[{50 * failing}, {50 * failing + 50}\) failed"):
            run_parts(part, 100)
    finally:
        numba.set_num_threads(before)
    assert ended == [50 * (1 - failing)], f"the other part had not ended when the error was raised: {ended}"
    assert render_pool() is render_pool(), "the pool is made once per process"
