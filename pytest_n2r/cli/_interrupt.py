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

SIGTERM (what ``timeout``, ``docker stop`` and a cancelled CI job send) is handled as Ctrl-C: within
:func:`sigterm_as_ctrl_c` (the whole of a command) it raises :class:`KeyboardInterrupt`, so every command's
Ctrl-C path (its clean-up, the fit's save of the field trained so far) serves it too; :func:`exit_status` then
says 143 (128 + 15), not Ctrl-C's 130.
"""

from __future__ import annotations

import contextlib
import signal
import threading
from collections.abc import Callable, Iterator

__all__ = ["interrupted", "first_ctrl_c_deferred", "sigterm_as_ctrl_c", "sigterm_kept_from_pycolmap", "exit_status",
           "interrupt_name"]

#: The signal that interrupted the command running (SIGINT, or SIGTERM once one arrived), read for the exit status
#: and the messages; set by the handlers below, reset when a command starts.
_received: list[int] = [signal.SIGINT]


def exit_status() -> int:
    """The exit status of a command interrupted by :data:`_received`: 130 for Ctrl-C, 143 for SIGTERM."""
    return 128 + int(_received[0])


def interrupt_name() -> str:
    """How messages name the interrupt: ``"Ctrl-C"`` or ``"SIGTERM"``."""
    return "SIGTERM" if _received[0] == signal.SIGTERM else "Ctrl-C"


def _in_main_thread() -> bool:
    return threading.current_thread() is threading.main_thread()


@contextlib.contextmanager
def sigterm_as_ctrl_c() -> Iterator[None]:
    """Within the block SIGTERM raises :class:`KeyboardInterrupt` (and :func:`exit_status` says 143), as Ctrl-C
    would; the previous handler is restored on leaving. Outside the main thread, or where SIGTERM is ignored (as a
    process started with it ignored keeps it), nothing is installed.

    >>> import os
    >>> with sigterm_as_ctrl_c():
    ...     try:
    ...         os.kill(os.getpid(), signal.SIGTERM)
    ...     except KeyboardInterrupt:
    ...         print(interrupt_name(), exit_status())
    SIGTERM 143
    >>> signal.getsignal(signal.SIGTERM) is signal.SIG_DFL
    True
    """
    _received[0] = signal.SIGINT
    if not _in_main_thread() or signal.getsignal(signal.SIGTERM) is signal.SIG_IGN:
        yield
        return

    def handle(signum: int, _frame: object) -> None:
        _received[0] = signum
        raise KeyboardInterrupt

    previous = signal.signal(signal.SIGTERM, handle)
    try:
        yield
    finally:
        signal.signal(signal.SIGTERM, previous if previous is not None else signal.SIG_DFL)


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


def sigterm_kept_from_pycolmap() -> None:
    """Import pycolmap (structure from motion) now, and give SIGTERM back to the handler Python had: its logging
    library takes SIGTERM over on import (to print a stack trace and die by the signal), which left the SfM's
    temporary folder behind. For the commands that may run structure from motion, before any work."""
    try:
        import pycolmap  # noqa: F401 - imported for its side effect on SIGTERM, undone below
    except ImportError:
        return
    handler = signal.getsignal(signal.SIGTERM)
    if _in_main_thread() and handler is not None:
        signal.signal(signal.SIGTERM, handler)


@contextlib.contextmanager
def first_ctrl_c_deferred() -> Iterator[Callable[[], bool]]:
    """Within the block the first Ctrl-C (SIGINT) or SIGTERM raises nothing and is only remembered: the callable
    yielded says whether it came, for a loop to ask between steps. Each later press raises :class:`KeyboardInterrupt`
    as usual (to quit at once). The previous handlers are restored on leaving. Python handles signals in its
    main thread only, and a process started with Ctrl-C ignored (``nohup``, a background job of a script)
    keeps ignoring it: in both cases nothing is installed for it.

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

    def handle(signum: int, _frame: object) -> None:
        nonlocal presses
        presses += 1
        if presses == 1 or signum == signal.SIGTERM:
            _received[0] = signum
        if presses > 1:
            raise KeyboardInterrupt

    # SIGTERM as Ctrl-C (the first remembered, a later one raising), each unless the process ignores it
    signals = [s for s in (signal.SIGINT, signal.SIGTERM) if signal.getsignal(s) is not signal.SIG_IGN]
    if not _in_main_thread():
        signals = []
    previous = {s: signal.getsignal(s) for s in signals}
    try:
        for s in signals:
            signal.signal(s, handle)
        yield pressed
    finally:
        for s, handler in previous.items():
            signal.signal(s, handler if handler is not None else signal.SIG_DFL)
