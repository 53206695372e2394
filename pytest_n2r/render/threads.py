"""The render threads: a compiled kernel that releases the GIL, run over parts of its work on several threads.

numba's parallel loops (``parallel=True``, ``prange``) compile slowly: the scene field's marcher took 11.6 CPU s to
compile as a parallel loop and 3.3 s as a plain one (docs/performance-log.md, "The field renderer's kernels without
numba's parallel loops"), and a fresh checkout pays that on its first fitted render. So the field renderer's
kernels are plain ``nogil`` loops over a range of their work (``first``, ``last``), and :func:`run_parts` runs the
parts on this module's thread pool (:func:`run_balanced` where the work's cost is uneven: the rays); the exact demo
renderer runs its bands of rows on the same pool (:func:`render_pool`), and the splat renderer composites its tiles
dealt over it (:func:`run_dealt`). The training kernels (:mod:`pytest_n2r.fit.train_kernels`) keep numba's parallel
loops: run this way, a training step took 1.3x as long (the same page).

Convention
----------
- A kernel's work items (rays, rows) are independent: each writes only its own outputs. The result depends
  neither on the thread count nor on which thread runs which part.
- A render uses ``numba.get_num_threads()`` threads (``NUMBA_NUM_THREADS``, or ``numba.set_num_threads``), as
  numba's parallel loops would.
"""

from __future__ import annotations

import os
import threading
from collections.abc import Callable
from concurrent.futures import ThreadPoolExecutor, wait
from typing import Any

import numba

__all__ = ["render_pool", "run_balanced", "run_dealt", "run_parts"]

_POOL: tuple[int, ThreadPoolExecutor] | None = None


def render_pool() -> ThreadPoolExecutor:
    """The process's render threads (``numba.config.NUMBA_NUM_THREADS`` of them, which covers any thread count numba
    may be set to); a forked child gets its own (the parent's threads do not exist in it)."""
    global _POOL
    if _POOL is None or _POOL[0] != os.getpid():
        threads = numba.config.NUMBA_NUM_THREADS  # type: ignore[attr-defined]  # numba's config: set at run time
        _POOL = (os.getpid(), ThreadPoolExecutor(threads, thread_name_prefix="n2r-render"))
    return _POOL[1]


def run_parts(kernel: Callable[..., Any], n: int, *args: Any) -> None:
    """``kernel(first, last, *args)`` over ``numba.get_num_threads()`` contiguous parts ``[first, last)`` that
    cover ``range(n)``, one a thread (the first on the calling thread), as numba's parallel loops split their
    work; ``kernel`` must release the GIL (``nogil=True``) to run beside the others. Contiguous, not dealt out in
    smaller pieces: on the fox field, rays dealt to the threads in chunks cost 7 % more work in all (each core's
    cache then holds the cells of the whole image instead of half of them; docs/performance-log.md, "The cells'
    occupancy as bits").

    >>> from numba import njit
    >>> import numpy as np
    >>> @njit(nogil=True)
    ... def square(first, last, x, out):
    ...     for i in range(first, last):
    ...         out[i] = x[i] * x[i]
    >>> x, out = np.arange(10.0), np.empty(10)
    >>> run_parts(square, 10, x, out)
    >>> out.tolist() == (x * x).tolist()
    True
    """
    threads = _thread_count(n)
    bounds = [n * i // threads for i in range(threads + 1)]
    _run(kernel, [(bounds[part], bounds[part + 1]) for part in range(threads)], args)


def run_balanced(kernel: Callable[..., Any], n: int, *args: Any, smallest: int = 256) -> None:
    """``kernel(first, last, *args)`` over ranges that cover ``range(n)``, on ``numba.get_num_threads()`` threads
    whose shares follow the work's cost: each thread starts on its own contiguous part, as :func:`run_parts`
    splits them, and runs it from its front a quarter of what is left at a time; a thread whose part is done
    takes, from the back of the part with the most left, a quarter of that. A range is at least ``smallest``
    items (the last of a part may be shorter). So each thread's items stay next to each other (a thread taking
    from its neighbour's back continues where its own part began), and the threads end within about one
    ``smallest`` range of each other. For the rays of a fitted field, whose cost differs across the image: with
    contiguous halves the threads of a 106 ms frame of the demo object's twin (320×180) waited 27 ms for each other,
    balanced 1 ms (docs/performance-log.md, "Rendering").

    >>> import numpy as np
    >>> hits = np.zeros(1000, dtype=np.int64)
    >>> def count(first, last, hits):  # a compiled kernel must release the GIL to run beside the others
    ...     hits[first:last] += 1
    >>> run_balanced(count, 1000, hits, smallest=16)
    >>> bool((hits == 1).all())  # every item once, whichever thread took it
    True
    """
    if smallest < 1:
        raise ValueError(f"smallest={smallest}: expected a range of at least 1 item")
    threads = _thread_count(n)
    if threads == 1:
        kernel(0, n, *args)
        return
    bounds = [n * i // threads for i in range(threads + 1)]
    left = [[bounds[part], bounds[part + 1]] for part in range(threads)]  # what is left of each part: [front, back)
    lock = threading.Lock()
    failed = False

    def take(part: int) -> tuple[int, int] | None:
        with lock:
            if failed:
                return None
            own = left[part]
            if own[0] < own[1]:
                first = own[0]
                own[0] = min(own[1], first + max(smallest, (own[1] - first) // 4))
                return first, own[0]
            other = max(left, key=lambda span: span[1] - span[0])
            if other[0] >= other[1]:
                return None
            last = other[1]
            other[1] = max(other[0], last - max(smallest, (last - other[0]) // 4))
            return other[1], last

    def work(part: int) -> None:
        nonlocal failed
        try:
            while (span := take(part)) is not None:
                kernel(*span, *args)
        except BaseException:
            failed = True  # the other threads take nothing more
            raise

    _run(work, [(part,) for part in range(threads)], ())


def run_dealt(kernel: Callable[..., Any], n: int, *args: Any) -> None:
    """``kernel(part, parts, *args)`` on ``parts = numba.get_num_threads()`` threads (at most ``n``), part ``p``
    taking the items ``p, p + parts, p + 2·parts, ...`` of ``range(n)``: dealt like cards, so that work listed
    busiest first shares out evenly (the splat renderer's tiles: at 480×270 the busiest of 40 holds 8-11 % of a
    frame's (tile, Gaussian) pairs, four times the mean).

    >>> from numba import njit
    >>> import numpy as np
    >>> @njit(nogil=True)
    ... def mark(part, parts, owner):
    ...     for i in range(part, owner.size, parts):
    ...         owner[i] = part
    >>> owner = np.full(7, -1)
    >>> run_dealt(mark, 7, owner)
    >>> sorted(set(owner.tolist())) == list(range(min(numba.get_num_threads(), 7)))
    True
    """
    parts = _thread_count(n)
    _run(kernel, [(part, parts) for part in range(parts)], args)


def _thread_count(n: int) -> int:
    """The threads a kernel over ``n`` items runs on: numba's thread count, at most ``n``, at least 1."""
    return max(1, min(numba.get_num_threads(), n))


def _run(kernel: Callable[..., Any], heads: list[tuple[int, ...]], args: tuple[Any, ...]) -> None:
    """``kernel(*head, *args)`` for each head, the first on the calling thread and the others on the render
    threads; returns once every call has ended, raising the first error among them."""
    if len(heads) == 1:
        kernel(*heads[0], *args)
        return
    others = [render_pool().submit(kernel, *head, *args) for head in heads[1:]]
    try:
        kernel(*heads[0], *args)  # the first part on the calling thread, which would wait otherwise
    finally:
        wait(others)  # no part still writing to the outputs once this returns, even after an error
    for part in others:
        part.result()
