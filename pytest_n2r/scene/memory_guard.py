"""The guard every reader of a scene file applies before decoding what a few bytes of its JSON may declare to be
gigabytes (a grid's resolution, a splat count, a photo's size): :func:`check_memory`.

Convention
----------
Bytes, against the memory free on the CPU (:func:`pytest_n2r.host_memory.cpu_free_bytes`: ``MemAvailable``, or a
container's cgroup headroom where that is less). Where the system does not say, nothing is refused. No torch here:
a splat scene is read without it.
"""

from __future__ import annotations

from ..errors import SceneFileError
from ..host_memory import cpu_free_bytes

__all__ = ["check_memory", "decode_failure"]


def check_memory(needed: int, source: str, what: str) -> None:
    """Refuse, with a :class:`SceneFileError` naming ``source`` and ``what`` (the field of ``scene.json`` that
    declares the size), to decode what would take ``needed`` bytes when the memory free is less: a small file
    may declare a huge grid, splat count or photo, and torch's or NumPy's allocator failure names nothing."""
    free = cpu_free_bytes()
    if free is not None and needed > free:
        raise SceneFileError(f"{source}: {what} would take about {needed / 2**30:.2f} GiB to decode, more than the "
                             f"{free / 2**30:.2f} GiB of memory free; the file is corrupt, or needs a larger machine")


def decode_failure(exc: MemoryError | RuntimeError, member: str, too_big: str, corrupt: str) -> SceneFileError:
    """The error of a member that raised ``exc`` while it was decoded (``member``: the file and member named):
    ``too_big`` says what did not fit where the allocator failed (a machine with less memory than estimated),
    ``corrupt`` what is wrong otherwise (torch's shape or dtype errors are RuntimeErrors too)."""
    out_of_memory = isinstance(exc, MemoryError) or "alloc" in str(exc).lower()
    return SceneFileError(f"{member} could not be decoded ({type(exc).__name__}: {str(exc)[:200]}); "
                          + (too_big if out_of_memory else corrupt))
