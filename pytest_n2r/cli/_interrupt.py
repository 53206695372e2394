"""Ctrl-C as the ``n2r`` commands see it: a :class:`KeyboardInterrupt`, one that compiled code wrapped, or
a press a long loop reads when it is ready.

Python raises :class:`KeyboardInterrupt` in whatever Python code runs when the signal arrives. When that is a
callback from a numba-compiled kernel (numba calls back into Python to rebuild some constants), the kernel
reports the failed callback as a :class:`SystemError` whose cause is the interrupt; a command that only
caught :class:`KeyboardInterrupt` printed that as a crash, with numba's traceback. :func:`interrupted`
looks through an exception's causes for the interrupt. Once (5 December, a fit under load) a first Ctrl-C
was not seen at all, the fit going on for minutes: an exception raised in such a callback can be dropped.
:func:`first_ctrl_c_deferred` raises nothing on the first press, so nothing can drop it: it is remembered
until the loop asks.
"""

from __future__ import annotations

import contextlib
import signal
import threading
from collections.abc import Callable, Iterator

__all__ = ["interrupted", "first_ctrl_c_deferred"]


def interrupted(exc: BaseException) -> bool:
    """Whether ``exc`` is a :class:`KeyboardInterrupt` or was raised while handling or because of one.

    >>> interrupted(KeyboardInterrupt())
    True
    >>> try:
    ...     try:
    ...         raise KeyboardInterrupt
    ...     except KeyboardInterrupt as cause:
    ...         raise SystemError("returned a result with an exception set") from cause
    ... except SystemError as wrapped:
    ...     interrupted(wrapped)
    True
    >>> interrupted(ValueError("a real error"))
    False
    """
    seen: set[int] = set()
    current: BaseException | None = exc
    while current is not None and id(current) not in seen:
        if isinstance(current, KeyboardInterrupt):
            return True
        seen.add(id(current))
        current = current.__cause__ or current.__context__
    return False


@contextlib.contextmanager
def first_ctrl_c_deferred() -> Iterator[Callable[[], bool]]:
    """Within the block the first Ctrl-C (SIGINT) raises nothing and is only remembered: the callable yielded
    says whether it came, for a loop to ask between steps. Each later press raises :class:`KeyboardInterrupt`
    as usual (to quit at once). The previous handler is restored on leaving. Python handles signals in its
    main thread only, and a process started with Ctrl-C ignored (``nohup``, a background job of a script)
    keeps ignoring it: in both cases nothing is installed and the callable stays false.

    >>> import os
    >>> previous = signal.signal(signal.SIGINT, signal.default_int_handler)  # as in an interactive shell
    >>> with first_ctrl_c_deferred() as pressed:
    ...     before = pressed()
    ...     os.kill(os.getpid(), signal.SIGINT)
    ...     after = pressed()
    >>> before, after, signal.getsignal(signal.SIGINT) is signal.default_int_handler
    (False, True, True)
    >>> _ = signal.signal(signal.SIGINT, previous)
    """
    presses = 0  # a plain count: the handler runs in the main thread, between Python instructions

    def pressed() -> bool:
        return presses > 0

    if threading.current_thread() is not threading.main_thread() or signal.getsignal(signal.SIGINT) is signal.SIG_IGN:
        yield pressed
        return

    def handle(_signum: int, _frame: object) -> None:
        nonlocal presses
        presses += 1
        if presses > 1:
            raise KeyboardInterrupt

    previous = signal.getsignal(signal.SIGINT)
    try:
        signal.signal(signal.SIGINT, handle)
        yield pressed
    finally:
        signal.signal(signal.SIGINT, previous if previous is not None else signal.SIG_DFL)
