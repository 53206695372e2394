"""A per-call time limit, so a hung render or SUT fails its test instead of stalling the whole run.

In the main thread of a POSIX process the limit is a ``SIGALRM`` timer that raises :class:`CallTimeout`
inside the running call (the way pytest-timeout's ``signal`` method works). A call stuck inside C code
that never returns to Python is interrupted when it next does. Elsewhere (worker threads, Windows) the
limit is checked when the call returns: it reports a slow call but cannot stop a hang.
"""

from __future__ import annotations

import signal
import threading
import time
from collections.abc import Iterator
from contextlib import contextmanager

from .errors import N2RError

__all__ = ["CallTimeout", "time_limit"]


class CallTimeout(N2RError):
    """A render or SUT call ran longer than its limit (``--n2r-timeout``)."""


def _message(what: str, seconds: float) -> str:
    return (
        f"{what} did not finish within {seconds:g} s (--n2r-timeout / ini n2r_timeout); "
        "raise the limit if it is merely slow, or look for a hang"
    )


@contextmanager
def time_limit(seconds: float | None, what: str) -> Iterator[None]:
    """Raise :class:`CallTimeout` naming ``what`` when the block runs longer than ``seconds``
    (``None`` or 0: no limit). Restores any timer set before (pytest-timeout's) when it ends."""
    if not seconds:
        yield
        return
    usable = hasattr(signal, "setitimer") and threading.current_thread() is threading.main_thread()
    if not usable:
        start = time.perf_counter()
        yield
        if time.perf_counter() - start > seconds:
            raise CallTimeout(_message(what, seconds))
        return

    def on_alarm(signum, frame):  # noqa: ARG001 - signal handler signature
        raise CallTimeout(_message(what, seconds))

    previous_handler = signal.signal(signal.SIGALRM, on_alarm)
    previous_delay, _ = signal.getitimer(signal.ITIMER_REAL)
    start = time.monotonic()
    signal.setitimer(signal.ITIMER_REAL, seconds)
    try:
        yield
    finally:
        signal.setitimer(signal.ITIMER_REAL, 0)
        signal.signal(signal.SIGALRM, previous_handler)
        if previous_delay:  # someone else's timer was running: give it back what is left of it
            left = previous_delay - (time.monotonic() - start)
            signal.setitimer(signal.ITIMER_REAL, max(left, 1e-3))
