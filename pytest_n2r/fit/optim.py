"""Adam on the rows of a grid that a step touches (lazy, like ``torch.optim.SparseAdam``).

A step of a voxel field reads a few hundred thousand of millions of vertices; updating only those rows keeps
the optimizer's cost proportional to the work of the step, not to the size of the grid.
"""

from __future__ import annotations

import torch

__all__ = ["RowAdam"]


class RowAdam:
    """Adam over ``values`` ``(rows, columns)`` with one learning rate per column."""

    def __init__(self, values: torch.Tensor, lrs: torch.Tensor, betas: tuple[float, float] = (0.9, 0.99),
                 eps: float = 1e-8):
        self.values, self.lrs = values, lrs.to(values.device)
        self.betas, self.eps = betas, eps
        self.m = torch.zeros_like(values)
        self.v = torch.zeros_like(values)
        self.t = 0

    @torch.no_grad()
    def keep(self, rows: torch.Tensor, values: torch.Tensor) -> None:
        """Go on with ``values``, the rows ``rows`` of the old ones (in that order): their moments come along,
        one at a time (each old tensor is let go before the next new one is made)."""
        self.values = values
        self.m = self.m[rows].contiguous()
        self.v = self.v[rows].contiguous()

    @torch.no_grad()
    def step(self, rows: torch.Tensor, grad: torch.Tensor, lr_scale: float = 1.0) -> None:
        """Apply the gradient ``grad`` ``(len(rows), columns)`` of the unique ``rows``."""
        b1, b2 = self.betas
        self.t += 1
        if self.values.device.type == "cpu":
            from .train_kernels import adam_rows

            adam_rows(self.values.numpy(), self.m.numpy(), self.v.numpy(), rows.numpy(), grad.numpy(),
                      (self.lrs * lr_scale).numpy(), b1, b2, self.eps, 1.0 - b1 ** self.t, 1.0 - b2 ** self.t)
            return
        m = self.m[rows].mul_(b1).add_(grad, alpha=1.0 - b1)
        v = self.v[rows].mul_(b2).addcmul_(grad, grad, value=1.0 - b2)
        self.m[rows], self.v[rows] = m, v
        denom = (v / (1.0 - b2 ** self.t)).sqrt_().add_(self.eps)
        self.values[rows] -= (self.lrs * (lr_scale / (1.0 - b1 ** self.t))) * m / denom

