"""Which torch device a fit or a scene uses."""

from __future__ import annotations

import torch

from ..errors import InvalidArgument

__all__ = ["resolve_device"]


def resolve_device(device: str | torch.device) -> torch.device:
    """``"auto"`` → CUDA when available, else CPU; otherwise the device named, checked to exist (``"cuda:N"``
    needs at least N + 1 GPUs)."""
    if str(device) == "auto":
        return torch.device("cuda" if torch.cuda.is_available() else "cpu")
    try:
        dev = torch.device(device)
    except (RuntimeError, TypeError):
        raise InvalidArgument(f"device={device!r}: expected 'auto', 'cpu' or 'cuda[:N]'") from None
    if dev.type == "cuda" and not torch.cuda.is_available():
        raise InvalidArgument(f"device={device!r}: CUDA is not available on this machine; use 'auto' or 'cpu'")
    if dev.type not in ("cpu", "cuda"):
        raise InvalidArgument(f"device={device!r}: expected 'auto', 'cpu' or 'cuda[:N]'")
    if dev.type == "cuda" and dev.index is not None and dev.index >= (count := torch.cuda.device_count()):
        raise InvalidArgument(f"device={device!r}: this machine has {count} CUDA device(s), 'cuda:0' to "
                              f"'cuda:{count - 1}'")
    return dev
