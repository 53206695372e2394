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

from ..errors import N2RError

__all__ = ["CallTimeout", "TimeLimitReached", "time_limit"]


class CallTimeout(N2RError):
    """A render or SUT call ran longer than its limit (``--n2r-timeout``)."""


class TimeLimitReached(BaseException):
    """The escaping form of :class:`CallTimeout` (``time_limit(..., escape=True)``): not an ``Exception``,
    so neither the code under the limit (a SUT's ``except Exception``) nor Hypothesis (which would retry and
    shrink a failing example, several time-outs in a row) catches it; the caller turns it back into a
    :class:`CallTimeout` (:meth:`error`) once the search has stopped."""

    def error(self) -> CallTimeout:
        return CallTimeout(str(self))


class _Expired(BaseException):
    """Raised by the timer inside the block; ``except Exception`` in the timed code cannot swallow it."""


def _message(what: str, seconds: float) -> str:
    return (
        f"{what} did not finish within {seconds:g} s (--n2r-timeout / ini n2r_timeout); "
        "raise the limit if it is merely slow, or look for a hang"
    )


@contextmanager
def time_limit(seconds: float | None, what: str, *, escape: bool = False) -> Iterator[None]:
    """Raise :class:`CallTimeout` naming ``what`` when the block runs longer than ``seconds``
    (``None`` or 0: no limit), or :class:`TimeLimitReached` with ``escape=True``. Restores any timer set
    before (pytest-timeout's) when it ends."""
    if not seconds:
        yield
        return
    expired = TimeLimitReached if escape else CallTimeout
    usable = hasattr(signal, "setitimer") and threading.current_thread() is threading.main_thread()
    if not usable:
        start = time.perf_counter()
        yield
        if time.perf_counter() - start > seconds:
            raise expired(_message(what, seconds))
        return

    def on_alarm(signum, frame):
        raise _Expired

    previous_handler = signal.signal(signal.SIGALRM, on_alarm)
    previous_delay, _ = signal.getitimer(signal.ITIMER_REAL)
    start = time.monotonic()
    signal.setitimer(signal.ITIMER_REAL, seconds)
    try:
        yield
    except _Expired:
        raise expired(_message(what, seconds)) from None
    finally:
        signal.setitimer(signal.ITIMER_REAL, 0)
        signal.signal(signal.SIGALRM, previous_handler)
        if previous_delay:  # someone else's timer was running: give it back what is left of it
            left = previous_delay - (time.monotonic() - start)
            signal.setitimer(signal.ITIMER_REAL, max(left, 1e-3))
