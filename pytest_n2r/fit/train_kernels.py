"""Compiled CPU kernels of a training step (numba): sample corners, unique rows, the samples interpolated, shaded
and composited with their gradient, and the row-sparse Adam update.

They replace the torch ops that dominate a CPU step (``torch.unique``, the serial scatter in the backward of
an index, Adam over fancy-indexed rows) and agree with them (tests check against torch autograd).
"""

from __future__ import annotations

import math

import numpy as np
import torch
from numba import njit, prange

from ..field.kernels import cell_of, grid_coords_xyz, thread_ranges, vertex_row
from ..field.lattice import lattice_counts

__all__ = ["sample_corners", "lattice_positions", "scatter_max", "RowIndex", "Composite", "adam_rows"]


@njit(cache=True, parallel=True)
def _sample_corners(o, d, t, ray_idx, shell, res, vertex_rows, rows, weights, cells):
    rr = res * res
    nc = res - 1
    for i in prange(t.shape[0]):
        r = ray_idx[i]
        ti = np.float64(t[i])
        gx, gy, gz = grid_coords_xyz(o[r, 0] + ti * d[r, 0], o[r, 1] + ti * d[r, 1], o[r, 2] + ti * d[r, 2], shell, res)
        ci, cj, ck = cell_of(gx, res), cell_of(gy, res), cell_of(gz, res)
        fx, fy, fz = gx - ci, gy - cj, gz - ck
        base = (ci * res + cj) * res + ck
        cells[i] = (ci * nc + cj) * nc + ck
        for c in range(8):
            rows[i, c] = vertex_row(vertex_rows, base + (c >> 2) * rr + ((c >> 1) & 1) * res + (c & 1))
            weights[i, c] = (fx if c & 4 else 1.0 - fx) * (fy if c & 2 else 1.0 - fy) * (fz if c & 1 else 1.0 - fz)


def sample_corners(o: np.ndarray, d: np.ndarray, t: np.ndarray, ray_idx: np.ndarray, shell: float,
                   resolution: int, vertex_rows: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """The 8 corner rows ``(N, 8)`` int64 and trilinear weights ``(N, 8)`` float32 of packed samples (same
    corner order as :func:`pytest_n2r.field.query.trilinear`), and each sample's flat cell index ``(N,)``.
    ``vertex_rows`` maps a flat vertex index to its row (empty: a dense field, the row is the index; -1: not
    stored, the corner of a sample whose float32 ``t`` rounded into an unoccupied neighbour of the cell it was
    marched in: :class:`RowIndex` and :class:`Composite` count it as zeros and give it no row)."""
    rows = np.empty((t.shape[0], 8), dtype=np.int64)
    weights = np.empty((t.shape[0], 8), dtype=np.float32)
    cells = np.empty(t.shape[0], dtype=np.int64)
    _sample_corners(o, d, t, ray_idx, shell, resolution, vertex_rows, rows, weights, cells)
    return rows, weights, cells


@njit(cache=True, parallel=True)
def _positions(t, ray_idx, t0, dt, n_inner, ts, du, step, out):
    for i in prange(t.shape[0]):
        r = ray_idx[i]
        ti = np.float64(t[i])
        index = (ti - t0[r]) / dt[r] if ti < ts[r] else n_inner[r] + (1.0 / ts[r] - 1.0 / ti) / du[r]
        out[i] = step * index


def lattice_positions(o: torch.Tensor, d: torch.Tensor, t: torch.Tensor, ray_idx: torch.Tensor, step: float,
                      shell_samples: int, far: float) -> torch.Tensor:
    """:func:`pytest_n2r.field.lattice.lattice_position` compiled (CPU; the same operations in the same
    order, so the same float64 bits): each packed sample's position along its ray in contracted units."""
    counts = lattice_counts(o.double(), d.double(), step, shell_samples, far)
    t0, dt, n_inner, ts, du = (x.contiguous().numpy() for x in counts)
    out = np.empty(t.shape[0])
    _positions(t.numpy(), ray_idx.numpy(), t0, dt, n_inner, ts, du, step, out)
    return torch.from_numpy(out)


@njit(cache=True)
def scatter_max(cells, values, out):
    """``out[cells[i]] = max(out[cells[i]], values[i])`` (the largest compositing weight seen per cell)."""
    for i in range(cells.shape[0]):
        out[cells[i]] = max(out[cells[i]], values[i])


@njit(cache=True)
def _unique_rows(rows, slot, stamp, tag, unique, inverse):
    flat = rows.reshape(-1)
    for i in range(flat.shape[0]):
        if flat[i] >= 0:  # -1, a vertex the field does not store, has no row (indexing wraps to the last one)
            stamp[flat[i]] = tag
    n = 0
    for r in range(stamp.shape[0]):  # one pass over every row: the distinct ones come out ascending
        if stamp[r] == tag:
            slot[r] = n
            unique[n] = r
            n += 1
    inv = inverse.reshape(-1)
    for i in range(flat.shape[0]):
        inv[i] = slot[flat[i]] if flat[i] >= 0 else -1
    return n


class RowIndex:
    """Scratch space to find the distinct rows of a step without sorting (``stamp`` avoids clearing).

    The rows come out ascending, so the step's gather of their values and its Adam update walk the grid's
    arrays in memory order (measured on the fox at 160³, one thread: Adam 66 -> 18 ms, the gather and this
    pass 71 -> 31 ms, the interpolation, whose corners are then further apart, 93 -> 133 ms; 15 % off the
    step)."""

    def __init__(self, n_rows: int):
        self.slot = np.zeros(n_rows, dtype=np.int32)
        self.stamp = np.zeros(n_rows, dtype=np.int32)
        self.tag = 0

    def unique(self, rows: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """``(unique, inverse)``: the distinct rows in ascending order, and ``rows`` as indices into them (a row
        of -1, a vertex not stored, is left out of ``unique`` and stays -1 in ``inverse``)."""
        self.tag += 1
        unique = np.empty(rows.size, dtype=np.int64)
        inverse = np.empty(rows.shape, dtype=np.int64)
        n = _unique_rows(rows, self.slot, self.stamp, self.tag, unique, inverse)
        return unique[:n], inverse


@njit(cache=True, parallel=True)
def adam_rows(values, m, v, rows, grad, lrs, b1, b2, eps, bias1, bias2):
    """Adam on ``values[rows]`` in place (``bias1``/``bias2``: the bias corrections ``1 - β^t``)."""
    for i in prange(rows.shape[0]):
        r = rows[i]
        for f in range(values.shape[1]):
            g = grad[i, f]
            mi = b1 * m[r, f] + (1.0 - b1) * g
            vi = b2 * v[r, f] + (1.0 - b2) * g * g
            m[r, f] = mi
            v[r, f] = vi
            values[r, f] -= lrs[f] * (mi / bias1) / (math.sqrt(vi / bias2) + eps)


@njit(cache=True, inline="always")
def _corner_values(sub, inverse, weights, basis, i, r, v, out):
    """Sample ``i`` (on ray ``r``) from its 8 corners: its values interpolated into the scratch row ``v`` (float64
    sums over the corners' float32 values; a corner of row -1, not stored, counts as zeros), then ``out[i, 0]`` its
    raw density and ``out[i, 1 + ch]`` its colour logits along the ray's SH ``basis``."""
    v[:] = 0.0
    for c in range(8):
        row = inverse[i, c]
        if row < 0:
            continue
        w = np.float64(weights[i, c])
        for f in range(v.shape[0]):
            v[f] += w * sub[row, f]
    lr = lg = lb = 0.0
    for l in range(basis.shape[1]):
        lr += basis[r, l] * v[1 + l * 3]
        lg += basis[r, l] * v[2 + l * 3]
        lb += basis[r, l] * v[3 + l * 3]
    out[i, 0], out[i, 1], out[i, 2], out[i, 3] = v[0], lr, lg, lb


@njit(cache=True, inline="always")
def _sample(raw, i, density_shift, step_ratio, alpha_max, col):
    """Sample ``i``'s opacity (capped at ``alpha_max``) and its derivative by the raw density, from its raw values
    (:func:`_corner_values`); its colour goes to ``col``."""
    x = raw[i, 0] + density_shift
    sigma = x if x > 20.0 else math.log1p(math.exp(x))
    alpha = 1.0 - math.exp(-sigma * step_ratio)
    d_alpha = step_ratio * (1.0 - alpha) / (1.0 + math.exp(-x))
    if alpha > alpha_max:
        alpha, d_alpha = alpha_max, 0.0
    for ch in range(3):
        col[ch] = 1.0 / (1.0 + math.exp(-raw[i, 1 + ch]))
    return alpha, d_alpha


@njit(cache=True, parallel=True)
def _composite_forward(sub, inverse, weights, basis, offsets, s, delta, density_shift, step_ratio, alpha_max,
                       background, rgb, alpha_sum, dist, weight, raw):
    for r in prange(offsets.shape[0] - 1):
        col = np.empty(3)
        v = np.empty(sub.shape[1])
        trans = 1.0
        acc = np.zeros(3)
        a_sum = 0.0
        w_before = s_before = pairs = squares = 0.0  # running sums of weights and of weight · position
        for i in range(offsets[r], offsets[r + 1]):
            _corner_values(sub, inverse, weights, basis, i, r, v, raw)
            alpha, _ = _sample(raw, i, density_shift, step_ratio, alpha_max, col)
            w = trans * alpha
            weight[i] = w
            for ch in range(3):
                acc[ch] += w * col[ch]
            a_sum += alpha
            pairs += w * (s[i] * w_before - s_before)
            squares += w * w
            w_before += w
            s_before += w * s[i]
            trans *= 1.0 - alpha
        for ch in range(3):
            rgb[r, ch] = acc[ch] + trans * background[r, ch]
        alpha_sum[r] = a_sum
        dist[r] = 2.0 * pairs + squares * delta / 3.0


@njit(cache=True, parallel=True)
def _composite_backward(raw, offsets, s, delta, density_shift, step_ratio, alpha_max, rgb, weight,
                        grad_rgb, grad_alpha, grad_dist, grad_weight, grad_raw):
    for r in prange(offsets.shape[0] - 1):
        col = np.empty(3)
        first, last = offsets[r], offsets[r + 1]
        # The distortion's gradient by each sample's weight (the forward pass's), h_i = ∂dist/∂w_i, and
        # Σ h_i w_i (two passes: h_i needs the ray's totals).
        h_total = 0.0
        gd = grad_dist[r]
        if gd != 0.0:
            w_total = s_total = 0.0
            for i in range(first, last):
                w_total += weight[i]
                s_total += weight[i] * s[i]
            w_before = s_before = 0.0
            for i in range(first, last):
                w = weight[i]
                w_after, s_after = w_total - w_before - w, s_total - s_before - w * s[i]
                spread = s[i] * w_before - s_before + s_after - s[i] * w_after  # Σ_j w_j |s_i - s_j|
                grad_weight[i] = gd * (2.0 * spread + 2.0 * w * delta / 3.0)
                h_total += grad_weight[i] * w
                w_before += w
                s_before += w * s[i]
        trans = 1.0
        prefix = np.zeros(3)
        h_prefix = 0.0
        g = grad_rgb[r]
        for i in range(first, last):
            alpha, d_raw = _sample(raw, i, density_shift, step_ratio, alpha_max, col)
            w = trans * alpha
            d_alpha = grad_alpha[r]
            if gd != 0.0:  # ∂w_i/∂alpha_k: T_k for i = k, -w_i / (1 - alpha_k) for i > k
                h_prefix += grad_weight[i] * w
                d_alpha += grad_weight[i] * trans - (h_total - h_prefix) / (1.0 - alpha)
            for ch in range(3):
                prefix[ch] += w * col[ch]
                suffix = rgb[r, ch] - prefix[ch]          # what is behind this sample, background included
                d_alpha += g[ch] * (trans * col[ch] - suffix / (1.0 - alpha))
                grad_raw[i, 1 + ch] = g[ch] * w * col[ch] * (1.0 - col[ch])
            grad_raw[i, 0] = d_alpha * d_raw
            trans *= 1.0 - alpha


@njit(cache=True, parallel=True)
def _corner_backward(grad_raw, inverse, weights, basis, offsets, bounds, grad_sub):
    # Each thread owns the rows bounds[g]..bounds[g + 1] and walks the samples in order, adding into the
    # corners it owns: no two threads write the same row (nor, but at the bounds, the same cache line), and
    # every element gets its additions in sample and corner order whatever the thread count. (Owning columns
    # instead had both threads writing every row's cache lines: 3x slower on the fox, slower than one thread.)
    n_sh = basis.shape[1]
    for g in prange(bounds.shape[0] - 1):
        lo, hi = bounds[g], bounds[g + 1]
        for r in range(offsets.shape[0] - 1):
            for i in range(offsets[r], offsets[r + 1]):
                _scatter_sample(grad_raw, inverse, weights, basis, i, r, n_sh, lo, hi, grad_sub)


@njit(cache=True, inline="always")
def _scatter_sample(grad_raw, inverse, weights, basis, i, r, n_sh, lo, hi, grad_sub):
    """Add sample ``i``'s (on ray ``r``) raw-value gradients into those of its corners' rows in ``lo..hi`` (``lo``
    >= 0: a corner of row -1, not stored, gets none)."""
    for c in range(8):
        row = inverse[i, c]
        if lo <= row < hi:
            w = np.float64(weights[i, c])
            grad_sub[row, 0] += w * grad_raw[i, 0]
            for l in range(n_sh):
                wb = w * basis[r, l]
                grad_sub[row, 1 + l * 3] += wb * grad_raw[i, 1]
                grad_sub[row, 2 + l * 3] += wb * grad_raw[i, 2]
                grad_sub[row, 3 + l * 3] += wb * grad_raw[i, 3]


class Composite(torch.autograd.Function):
    """Interpolate, shade and alpha-composite packed samples per ray, compiled (CPU), with its exact gradient.

    Inputs: the step's rows of the field ``sub (U, F)``, each sample's 8 corners as indices into them
    ``inverse (N, 8)`` (-1: a vertex the field does not store, which counts as zeros and gets no gradient) with
    their trilinear ``weights (N, 8)``, the SH basis of each ray's direction
    ``(B, n_sh)``, ``offsets (B+1)`` (ray ``r``'s samples are ``offsets[r]`` to ``offsets[r + 1]``, the ``N``
    samples all told), each sample's position ``s (N,)`` along its ray and the length ``delta`` a sample
    stands for (both in contracted units), and ``background`` ``(3,)`` or one colour per ray ``(B, 3)``.
    Outputs: ``rgb (B, 3)`` over the background, the per-ray sum of sample opacities ``(B,)``, the per-ray
    distortion ``(B,)`` and, not differentiable, each sample's compositing weight ``(N,)`` (float32; the
    backward pass reuses them in float64). The gradient is ``sub``'s alone.

    Same formulas as :func:`pytest_n2r.field.query.interpolate`, :func:`~pytest_n2r.field.query.shade`,
    :func:`~pytest_n2r.field.query.composite` and :func:`~pytest_n2r.field.query.distortion`, in float64
    inside. A sample's values are never stored whole: each sample keeps its raw density and three colour
    logits (``4`` numbers, not ``1 + 3·n_sh``), and the backward pass spreads their gradients over the corners'
    SH coefficients directly (docs/performance-log.md, "The interpolation fused into the composite").
    """

    @staticmethod
    def forward(ctx, sub, inverse, weights, basis, offsets, s, delta, density_shift, step_ratio, alpha_max,
                background):
        n = offsets.shape[0] - 1
        rgb = torch.empty(n, 3, dtype=torch.float64)
        alpha_sum = torch.empty(n, dtype=torch.float64)
        dist = torch.empty(n, dtype=torch.float64)
        weight = torch.empty(inverse.shape[0], dtype=torch.float64)
        raw = torch.empty(inverse.shape[0], 4, dtype=torch.float64)
        s = s.double().contiguous()
        basis = basis.double().contiguous()
        _composite_forward(sub.detach().numpy(), inverse.numpy(), weights.numpy(), basis.numpy(), offsets.numpy(),
                           s.numpy(), delta, density_shift, step_ratio, alpha_max,
                           background.double().expand(n, 3).contiguous().numpy(), rgb.numpy(), alpha_sum.numpy(),
                           dist.numpy(), weight.numpy(), raw.numpy())
        ctx.save_for_backward(inverse, weights, basis, offsets, s, rgb, weight, raw)
        ctx.params = (delta, density_shift, step_ratio, alpha_max)
        ctx.sub_shape, ctx.sub_dtype = sub.shape, sub.dtype
        sample_weight = weight.float()
        ctx.mark_non_differentiable(sample_weight)
        return rgb.to(sub.dtype), alpha_sum.to(sub.dtype), dist.to(sub.dtype), sample_weight

    @staticmethod
    def backward(ctx, grad_rgb, grad_alpha_sum, grad_dist, _grad_weight):
        inverse, weights, basis, offsets, s, rgb, weight, raw = ctx.saved_tensors
        n = rgb.shape[0]
        grads = [g.double().contiguous() if g is not None else torch.zeros(shape, dtype=torch.float64)
                 for g, shape in ((grad_rgb, (n, 3)), (grad_alpha_sum, (n,)), (grad_dist, (n,)))]
        grad_raw = np.empty((inverse.shape[0], 4))
        grad_weight = np.empty(inverse.shape[0])  # scratch: ∂dist/∂weight per sample
        _composite_backward(raw.numpy(), offsets.numpy(), s.numpy(), *ctx.params, rgb.numpy(), weight.numpy(),
                            *(g.numpy() for g in grads), grad_weight, grad_raw)
        grad_sub = torch.zeros(ctx.sub_shape, dtype=ctx.sub_dtype)
        _corner_backward(grad_raw, inverse.numpy(), weights.numpy(), basis.numpy(), offsets.numpy(),
                         thread_ranges(ctx.sub_shape[0]), grad_sub.numpy())
        return grad_sub, *(None,) * 10
