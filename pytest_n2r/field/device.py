"""Which torch device a fit or a scene uses.

Conventions
-----------
- A device is named ``"auto"`` (CUDA where there is one, else the CPU), ``"cpu"``, ``"cuda"`` or ``"cuda:N"``
  (``N`` without leading zeros, as ``torch.device`` reads it), or given as a ``torch.device`` of type ``cpu`` or
  ``cuda``.
- :func:`check_device` checks a name without importing torch, but for a CUDA device, whose existence only torch
  can tell: a command that renders an exact scene or reads a scene file does not pay ``import torch`` (about 1 s)
  to check its ``--device``.
"""

from __future__ import annotations

import re
from typing import TYPE_CHECKING

from ..errors import InvalidArgument

if TYPE_CHECKING:
    import torch

__all__ = ["check_device", "resolve_device"]

_NAME = re.compile(r"auto|cpu(?::0)?|cuda(?::(?P<index>0|[1-9]\d*))?")  # the names torch.device takes, cpu:0 too


def check_device(device: str | torch.device) -> str:
    """The name of ``device``, checked: one of the names above, and a CUDA device this machine has (``"cuda:N"``
    needs at least N + 1 GPUs).

    >>> check_device("auto"), check_device("cpu")
    ('auto', 'cpu')
    >>> check_device("tpu")
    Traceback (most recent call last):
    ...
    pytest_n2r.errors.InvalidArgument: device='tpu': expected 'auto', 'cpu' or 'cuda[:N]'
    """
    name = str(device)
    match = _NAME.fullmatch(name)
    if match is None:
        raise InvalidArgument(f"device={device!r}: expected 'auto', 'cpu' or 'cuda[:N]'")
    if name.startswith("cuda"):
        import torch

        if not torch.cuda.is_available():
            raise InvalidArgument(f"device={device!r}: CUDA is not available on this machine; use 'auto' or 'cpu'")
        if match["index"] is not None and int(match["index"]) >= (count := torch.cuda.device_count()):
            raise InvalidArgument(f"device={device!r}: this machine has {count} CUDA device(s), 'cuda:0' to "
                                  f"'cuda:{count - 1}'")
    return name


def resolve_device(device: str | torch.device) -> torch.device:
    """The torch device ``device`` names (:func:`check_device`): ``"auto"`` → CUDA when available, else CPU."""
    import torch

    name = check_device(device)
    if name == "auto":
        return torch.device("cuda" if torch.cuda.is_available() else "cpu")
    return torch.device(name)
