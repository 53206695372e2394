"""A render must not change the SUT's thread count.

numba's OpenMP threading layer (the splat renderer's parallel kernels, or a user scene's) sets the OpenMP thread
count of the calling thread each time it runs a kernel, and torch (built with OpenMP, as the CPU wheels are)
reads the same setting. A classifier that set ``torch.set_num_threads(1)`` for speed and reproducibility then
ran, after the first render of a fitted scene, with every core: measured on the example project under load
on 2 cores, its calls took several times as long, and a thread count can change a network's floating-point
results. :func:`threads_kept` puts torch's count back after a render.
"""

from __future__ import annotations

import sys
from collections.abc import Iterator
from contextlib import contextmanager

__all__ = ["threads_kept"]


@contextmanager
def threads_kept() -> Iterator[None]:
    """Run the block, then restore torch's intra-op thread count if the block changed it (nothing to do
    when torch is not loaded)."""
    torch = sys.modules.get("torch")
    before = torch.get_num_threads() if torch is not None else None
    try:
        yield
    finally:
        torch = sys.modules.get("torch")
        if torch is not None and before is not None and torch.get_num_threads() != before:
            torch.set_num_threads(before)
