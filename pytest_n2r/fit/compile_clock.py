"""The time numba spends compiling kernels during a fit, kept out of its training time.

A fresh installation compiles the training kernels during its first fit's first steps (14 s of a 2-minute fox fit
on the project's 2-core host, docs/performance-log.md, "A fresh installation's kernel compiles kept out of the
budget"); later fits load them from numba's on-disk cache in under a second. A time budget counts seconds of
training, so what a budget buys should not depend on whether that cache was filled: the fit measures its compiles
with a :class:`CompileClock`, takes them off its training time and reports them apart
(``report["compile_seconds"]``).

Convention
----------
- Seconds of wall time (``time.perf_counter``, numba's own event timer), as the fit's training time.
- A compile counts from numba's ``numba:compile`` start event to its end; the compiles of the functions it calls in
  turn lie inside it and are not counted again.
"""

from __future__ import annotations

from collections.abc import Iterator
from contextlib import contextmanager

from numba.core import event

__all__ = ["CompileClock"]

_COMPILE = "numba:compile"


class CompileClock:
    """Seconds numba spent compiling while :meth:`counting`, summed over every time it counted: ``seconds``, read
    at any time (also inside the block, for the compiles ended so far).

    Loading a kernel from numba's cache is not a compile and does not count. numba's listeners are process-wide:
    count around work that runs on one thread while no other thread compiles (a fit's training steps).

    >>> from numba import njit
    >>> clock = CompileClock()
    >>> with clock.counting():
    ...     njit(lambda x: x + 1)(1)
    2
    >>> clock.seconds > 0.0
    True
    """

    def __init__(self) -> None:
        self._ended = 0.0  # the blocks counted to their end
        self._listener: event.TimingListener | None = None

    @property
    def seconds(self) -> float:
        """Seconds of compiles counted so far."""
        listener = self._listener
        return self._ended + (listener.duration if listener is not None and listener.done else 0.0)

    @contextmanager
    def counting(self) -> Iterator[None]:
        """Count the compiles of the ``with`` block (also when it raises); not reentrant."""
        if self._listener is not None:
            raise RuntimeError("CompileClock.counting() is running already: a compile would count twice")
        self._listener = listener = event.TimingListener()
        event.register(_COMPILE, listener)
        try:
            yield
        finally:
            event.unregister(_COMPILE, listener)
            self._ended, self._listener = self.seconds, None
