"""The per-photo appearance correction of a fit (``fit(..., appearance=True)``): exposure and white balance."""

from __future__ import annotations

from collections.abc import Sequence

import torch

__all__ = ["APPEARANCE_LR", "Appearance"]


#: Adam learning rate of the per-photo log colour gains (``appearance=True``).
APPEARANCE_LR = 0.01


class Appearance:
    """Per training photo, a colour gain per channel (exposure and white balance) that multiplies the field's
    colour in the loss only. The gains are ``exp(a - mean(a))`` over the photos, so the field keeps the
    capture's average exposure and white balance, which is what it renders at every pose (a render never
    applies a gain: the correction cannot leak into new views)."""

    def __init__(self, names: Sequence[str], device: torch.device):
        self.names = list(names)
        self.log_gain = torch.zeros(len(self.names), 3, device=device, requires_grad=True)
        self.adam = torch.optim.Adam([self.log_gain], lr=APPEARANCE_LR)

    def gains(self) -> torch.Tensor:
        return torch.exp(self.log_gain - self.log_gain.mean(dim=0, keepdim=True))

    def step(self, lr_scale: float) -> None:
        for group in self.adam.param_groups:
            group["lr"] = APPEARANCE_LR * lr_scale
        self.adam.step()
        self.adam.zero_grad(set_to_none=True)

    def report(self) -> dict:
        gains = self.gains().detach().cpu().numpy()
        return {name: [round(float(x), 4) for x in g] for name, g in zip(self.names, gains)}
