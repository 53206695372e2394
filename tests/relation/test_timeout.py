"""The per-call time limit of renders and SUT calls."""

from __future__ import annotations

import signal
import time

import pytest

from pytest_n2r.relation.timeout import CallTimeout, time_limit


def test_time_limit_interrupts_and_restores_the_previous_timer():
    previous = signal.signal(signal.SIGALRM, signal.SIG_IGN)
    try:
        start = time.perf_counter()
        with pytest.raises(CallTimeout, match="napping did not finish within 0.1 s"), time_limit(0.1, "napping"):
            time.sleep(5)
        assert time.perf_counter() - start < 2
        assert signal.getsignal(signal.SIGALRM) is signal.SIG_IGN
        with time_limit(None, "anything"):
            pass
    finally:
        signal.signal(signal.SIGALRM, previous)


class _OuterDeadline(Exception):
    """What the outer timer's handler (pytest-timeout's, say) raises."""


def _outer_timer(handler, delay: float):
    """Arm an outer ITIMER_REAL with ``handler``; returns a function that disarms it and restores the handler."""
    previous = signal.signal(signal.SIGALRM, handler)
    signal.setitimer(signal.ITIMER_REAL, delay)

    def undo() -> None:
        signal.setitimer(signal.ITIMER_REAL, 0)
        signal.signal(signal.SIGALRM, previous)

    return undo


def test_an_earlier_outer_deadline_is_not_pushed_back():
    def outer(signum, frame):
        raise _OuterDeadline("the outer deadline")

    undo = _outer_timer(outer, 0.2)
    try:
        start = time.perf_counter()
        with pytest.raises(_OuterDeadline), time_limit(10, "napping"):
            time.sleep(3)
        elapsed = time.perf_counter() - start
        assert elapsed < 1.5, f"the outer 0.2 s deadline fired after {elapsed:.1f} s: the 10 s limit pushed it back"
        assert signal.getsignal(signal.SIGALRM) is outer, "the outer handler was not restored"
    finally:
        undo()


def test_a_later_outer_deadline_gets_back_what_is_left_of_it():
    def outer(signum, frame):
        raise _OuterDeadline("the outer deadline")

    undo = _outer_timer(outer, 5.0)
    try:
        with pytest.raises(CallTimeout, match="napping did not finish within 0.1 s"), time_limit(0.1, "napping"):
            time.sleep(3)
        left, _ = signal.getitimer(signal.ITIMER_REAL)
        assert 3.0 < left < 5.0, f"the outer timer should have about 4.9 s left, not {left:.2f} s"
        assert signal.getsignal(signal.SIGALRM) is outer, "the outer handler was not restored"
    finally:
        undo()


def test_an_outer_handler_that_returns_leaves_the_limit_in_force():
    called = []
    undo = _outer_timer(lambda signum, frame: called.append(time.perf_counter()), 0.1)
    try:
        start = time.perf_counter()
        with pytest.raises(CallTimeout, match="napping did not finish within 0.6 s"), time_limit(0.6, "napping"):
            time.sleep(5)
        elapsed = time.perf_counter() - start
        assert len(called) == 1, f"the outer handler should have run once, at its deadline, not {len(called)} times"
        assert elapsed < 3, f"the 0.6 s limit stopped a 5 s nap only after {elapsed:.1f} s"
    finally:
        undo()


def test_nested_limits_each_name_their_own_call():
    with (pytest.raises(CallTimeout, match="the outer call did not finish within 0.2 s"),
          time_limit(0.2, "the outer call"), time_limit(10, "the inner call")):
        time.sleep(5)
    assert signal.getitimer(signal.ITIMER_REAL)[0] == 0, "a timer was left running"
