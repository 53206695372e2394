"""The memory a fit may still allocate on its device: what the kernel, a container's cgroup or the CUDA driver
says is free (:func:`free_bytes`), read before each move to a finer grid (:mod:`.memory`).

Convention
----------
Bytes. On the CPU, :func:`pytest_n2r.host_memory.cpu_free_bytes` (``MemAvailable``, or a container's cgroup
headroom where that is less); on CUDA, the device's free memory plus what torch's cache holds unused.
"""

from __future__ import annotations

from typing import TYPE_CHECKING

from ..host_memory import cpu_free_bytes

if TYPE_CHECKING:
    import torch

__all__ = ["free_bytes"]


def free_bytes(device: torch.device) -> int | None:
    """The bytes a fit on ``device`` may still allocate: on CUDA the device's free memory plus what torch's
    cache holds unused; on the CPU :func:`~pytest_n2r.host_memory.cpu_free_bytes`. ``None`` where the system does
    not say (no guard is then applied)."""
    if device.type == "cuda":
        import torch

        free, _ = torch.cuda.mem_get_info(device)
        return int(free + torch.cuda.memory_reserved(device) - torch.cuda.memory_allocated(device))
    return cpu_free_bytes()
