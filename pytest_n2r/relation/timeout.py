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
from typing import Any

from ..errors import CallTimeout

__all__ = ["CallTimeout", "TimeLimitReached", "time_limit"]


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
    (``None`` or 0: no limit), or :class:`TimeLimitReached` with ``escape=True``.

    A timer set before (pytest-timeout's, an enclosing limit's) keeps its deadline: when it expires first, its
    handler runs as if this limit were not there; else it gets back what is left of it when the block ends."""
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

    previous_handler = signal.getsignal(signal.SIGALRM)
    previous_delay, previous_interval = signal.getitimer(signal.ITIMER_REAL)
    start, ours = time.monotonic(), object()  # ``ours`` tells this limit's expiry from a nested one's
    outer_first = 0 < previous_delay < seconds
    handed_over = False

    def on_alarm(signum: int, frame: Any) -> None:
        nonlocal handed_over
        if not outer_first or handed_over:
            raise _Expired(ours)
        handed_over = True  # the earlier deadline is the outer timer's: its handler's turn
        signal.signal(signal.SIGALRM, _restorable(previous_handler))
        if callable(previous_handler):
            previous_handler(signum, frame)
        elif previous_handler == signal.SIG_DFL:
            signal.raise_signal(signum)  # what SIGALRM would have done without this limit: end the process
        signal.signal(signal.SIGALRM, on_alarm)  # the outer handler returned: this limit holds for the rest
        signal.setitimer(signal.ITIMER_REAL, max(seconds - (time.monotonic() - start), 1e-3))

    try:
        signal.signal(signal.SIGALRM, on_alarm)
        signal.setitimer(signal.ITIMER_REAL, previous_delay if outer_first else seconds)
        yield
    except _Expired as exc:
        if exc.args != (ours,):
            raise
        raise expired(_message(what, seconds)) from None
    finally:
        signal.setitimer(signal.ITIMER_REAL, 0)
        signal.signal(signal.SIGALRM, _restorable(previous_handler))
        if previous_delay and not handed_over:  # someone else's timer was running: give it back what is left
            left = previous_delay - (time.monotonic() - start)
            signal.setitimer(signal.ITIMER_REAL, max(left, 1e-3), previous_interval)
        elif handed_over and previous_interval:  # it expired meanwhile, and repeats
            signal.setitimer(signal.ITIMER_REAL, previous_interval, previous_interval)


def _restorable(handler: Any) -> Any:
    """A handler :func:`signal.signal` takes back: ``None`` (one installed outside Python) as the default."""
    return signal.SIG_DFL if handler is None else handler
