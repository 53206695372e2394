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
