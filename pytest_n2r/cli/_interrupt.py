"""Ctrl-C as the ``n2r`` commands see it: a :class:`KeyboardInterrupt`, or one that compiled code wrapped.

Python raises :class:`KeyboardInterrupt` in whatever Python code runs when the signal arrives. When that is a
callback from a numba-compiled kernel (numba calls back into Python to rebuild some constants), the kernel
reports the failed callback as a :class:`SystemError` whose cause is the interrupt; a command that only
caught :class:`KeyboardInterrupt` printed that as a crash, with numba's traceback. :func:`interrupted`
looks through an exception's causes for the interrupt.
"""

from __future__ import annotations

__all__ = ["interrupted"]


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
