"""The render threads (render/threads.py): a kernel's parts cover its work exactly once, on the thread count numba
is set to, a part's error reaches the caller, and balanced parts follow the work's cost."""

from __future__ import annotations

import itertools
import threading
import time

import numba
import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st
from numba import njit

from pytest_n2r.render.threads import render_pool, run_balanced, run_dealt, run_parts


@njit(nogil=True)
def _count(first, last, hits):
    for i in range(first, last):
        hits[i] += 1


@njit(nogil=True)
def _count_dealt(part, parts, hits):
    for i in range(part, hits.size, parts):
        hits[i] += 1


@settings(max_examples=80, deadline=None)
@given(n=st.integers(0, 5000), count=st.integers(1, 8), runner=st.sampled_from(["parts", "dealt", "balanced"]),
       smallest=st.integers(1, 700))
def test_the_parts_cover_the_work_exactly_once(n, count, runner, smallest):
    before = numba.get_num_threads()
    numba.set_num_threads(min(count, numba.config.NUMBA_NUM_THREADS))
    try:
        hits = np.zeros(n, dtype=np.int64)
        if runner == "dealt":
            run_dealt(_count_dealt, n, hits)
        elif runner == "balanced":
            run_balanced(_count, n, hits, smallest=smallest)
        else:
            run_parts(_count, n, hits)
    finally:
        numba.set_num_threads(before)
    assert (hits == 1).all(), (
        f"run_{runner}, n={n}, {count} threads: items run {np.bincount(hits).tolist()} times (0, 1, 2...)")


def test_balanced_parts_hand_the_slow_parts_back_to_the_idle_thread_from_its_back():
    if numba.config.NUMBA_NUM_THREADS < 2:
        pytest.skip("numba has a single thread here")
    ran: list[tuple[str, int, int]] = []
    lock = threading.Lock()

    def slow_first_half(first: int, last: int) -> None:
        if first < 500:
            time.sleep(0.0005 * (last - first))  # 0.25 s for the first half, nothing for the second
        with lock:
            ran.append((threading.current_thread().name, first, last))

    before = numba.get_num_threads()
    caller = threading.current_thread().name
    try:
        numba.set_num_threads(2)
        run_balanced(slow_first_half, 1000, smallest=10)
    finally:
        numba.set_num_threads(before)
    short = [(first, last) for _, first, last in ran if last - first < 10]
    assert len(short) <= 2, f"ranges under smallest=10 items other than where a part's front meets its back: {short}"
    helped = sorted((first, last) for name, first, last in ran if name != caller and first < 500)
    assert helped, f"the idle thread took nothing of the slow half: {ran}"
    assert helped[-1][1] == 500 and all(a[1] == b[0] for a, b in itertools.pairwise(helped)), (
        f"the idle thread should take the slow half from its back, one span up to item 500: it took {helped}")
    mine = sum(last - first for name, first, last in ran if name == caller)
    assert mine < 500, f"the calling thread ran {mine} of the slow half's 500 items: nothing was handed over"


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


@pytest.mark.parametrize("runner", ["parts", "balanced"])
@pytest.mark.parametrize("failing", [0, 1])
def test_an_error_in_a_part_reaches_the_caller_after_every_part_ended(failing, runner):
    if numba.config.NUMBA_NUM_THREADS < 2:
        pytest.skip("numba has a single thread here")
    started: list[int] = []
    ended: list[int] = []

    def part(first: int, last: int) -> None:
        started.append(first)
        if first == 50 * failing:
            raise ValueError(f"part [{first}, {last}) failed")
        time.sleep(0.05)
        ended.append(first)

    before = numba.get_num_threads()
    try:
        numba.set_num_threads(2)
        with pytest.raises(ValueError, match=rf"part \[{50 * failing}, {50 * failing + 50}\) failed"):
            if runner == "balanced":  # ranges of 50: the parts run_parts makes; a range not started stays so
                run_balanced(part, 100, smallest=50)
            else:
                run_parts(part, 100)
        still_running = sorted(set(started) - set(ended) - {50 * failing})
    finally:
        numba.set_num_threads(before)
    assert not still_running, f"ranges {still_running} had not ended when the error was raised"
    if runner == "parts":
        assert ended == [50 * (1 - failing)], f"run_parts runs every part, even beside a failing one: {ended}"
    assert render_pool() is render_pool(), "the pool is made once per process"


def test_balanced_parts_reject_an_empty_smallest_range():
    with pytest.raises(ValueError, match="smallest=0: expected a range of at least 1 item"):
        run_balanced(_count, 10, np.zeros(10, dtype=np.int64), smallest=0)
