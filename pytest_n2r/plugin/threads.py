"""Render threads under pytest-xdist: each of ``N`` workers renders with ``cores ÷ N`` threads (at least one),
so that ``-n 2`` on two cores does not run four render threads that take turns on two cores.

numba's threads (the exact demo scenes' ray casting, the scene field's and the splats' kernels) are what the
renderers use; the count is set through ``NUMBA_NUM_THREADS`` before numba is imported, or with
``numba.set_num_threads`` when it already is. A ``NUMBA_NUM_THREADS`` the user set is kept. The SUT's own
threads (torch, OpenCV) are the SUT's business and left alone: a thread count can change a network's
floating-point results. Renders do not depend on the thread count (each pixel is computed by one thread).
"""

from __future__ import annotations

import os
import sys
from collections.abc import MutableMapping

__all__ = ["render_threads", "share_cores"]


def _cores() -> int:
    try:
        return len(os.sched_getaffinity(0))
    except AttributeError:  # not on Linux
        return os.cpu_count() or 1


def render_threads(workers: int, cores: int | None = None) -> int:
    """Threads per worker when ``workers`` processes share ``cores`` (default: this process's CPUs).

    >>> render_threads(2, cores=2), render_threads(3, cores=8), render_threads(4, cores=2)
    (1, 2, 1)
    """
    return max(1, (cores if cores is not None else _cores()) // max(1, workers))


def share_cores(environ: MutableMapping[str, str] = os.environ) -> int | None:
    """In a pytest-xdist worker (``PYTEST_XDIST_WORKER_COUNT`` set): limit numba to this worker's share of the
    cores and return the thread count; ``None`` (nothing changed) outside xdist, with one worker, or when the
    user set ``NUMBA_NUM_THREADS``."""
    try:
        workers = int(environ.get("PYTEST_XDIST_WORKER_COUNT", "1"))
    except ValueError:
        return None
    if workers <= 1 or "NUMBA_NUM_THREADS" in environ:
        return None
    threads = render_threads(workers)
    numba = sys.modules.get("numba")
    if numba is None:
        environ["NUMBA_NUM_THREADS"] = str(threads)
    else:
        numba.set_num_threads(min(threads, numba.config.NUMBA_NUM_THREADS))
    return threads
