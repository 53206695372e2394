"""The compiled training kernels against torch autograd through the reference formulas of ``query``.

Everything is compared in float64, where the two must agree to rounding (1e-10): the compiled composite
multiplies transmittances while the reference sums ``log(1 - alpha)``, so they are not bit-identical.
"""

from __future__ import annotations

import numpy as np
import pytest
import torch

from pytest_n2r.field.lattice import grid_coords, lattice_position
from pytest_n2r.field.query import ALPHA_MAX, composite, distortion, interpolate, sh_basis, shade, trilinear
from pytest_n2r.fit.optim import RowAdam
from pytest_n2r.fit.train_kernels import (
    Composite,
    RowIndex,
    _corner_backward,
    adam_rows,
    lattice_positions,
    sample_corners,
)

TOL = 1e-10
SHIFT, STEP_RATIO, DELTA = -2.0, 0.5, 0.03


def packed(counts: list[int]) -> tuple[torch.Tensor, torch.Tensor]:
    """``(ray_idx, offsets)`` of rays with ``counts`` samples each."""
    counts_t = torch.tensor(counts, dtype=torch.int64)
    offsets = torch.zeros(len(counts) + 1, dtype=torch.int64)
    offsets[1:] = torch.cumsum(counts_t, 0)
    return torch.repeat_interleave(torch.arange(len(counts)), counts_t), offsets


def samples(counts: list[int], sh_degree: int, seed: int, capped: int | None = None, n_rows: int = 40
            ) -> tuple[torch.Tensor, ...]:
    """A step's random field rows ``sub (U, F)`` (float64, requiring grad), each sample's 8 corners ``inverse
    (N, 8)`` into them and trilinear ``weights (N, 8)`` (summing to 1), unit ray directions' SH basis
    ``(B, n_sh)``, ``ray_idx``, ``offsets`` and increasing sample positions ``s (N,)`` along each ray (gaps
    of at least ``DELTA``, as on the lattice); sample ``capped`` gets a density whose opacity is capped."""
    g = torch.Generator().manual_seed(seed)
    ray_idx, offsets = packed(counts)
    n, n_sh = int(offsets[-1]), (sh_degree + 1) ** 2
    sub = torch.randn(n_rows, 1 + 3 * n_sh, generator=g, dtype=torch.float64) * 2.0
    inverse = torch.randint(0, n_rows - 1, (n, 8), generator=g)
    weights = torch.rand(n, 8, generator=g, dtype=torch.float64)
    weights /= weights.sum(dim=1, keepdim=True)
    if capped is not None:  # its corners all the last row, whose density is high: softplus → 58, alpha = 1 - e⁻²⁹
        inverse[capped] = n_rows - 1
        sub[n_rows - 1, 0] = 60.0
    dirs = torch.randn(len(counts), 3, generator=g, dtype=torch.float64)
    basis = sh_basis(dirs / dirs.norm(dim=-1, keepdim=True), sh_degree)
    gaps = DELTA * (1.0 + 3.0 * torch.rand(n, generator=g, dtype=torch.float64))
    s = torch.cat([torch.cumsum(gaps[a:b], 0) for a, b in zip(offsets[:-1].tolist(), offsets[1:].tolist())])
    return sub.requires_grad_(True), inverse, weights, basis, ray_idx, offsets, s


def reference(sub: torch.Tensor, inverse: torch.Tensor, weights: torch.Tensor, basis: torch.Tensor,
              ray_idx: torch.Tensor, offsets: torch.Tensor, s: torch.Tensor, background: torch.Tensor
              ) -> tuple[torch.Tensor, torch.Tensor, torch.Tensor, torch.Tensor]:
    """rgb, the sum of capped opacities, the distortion and per-sample weights by ``query.interpolate``,
    ``query.shade``, ``query.composite`` and ``query.distortion``."""
    alpha, rgb = shade(interpolate(sub, inverse, weights), basis[ray_idx], SHIFT, STEP_RATIO)
    n_rays = len(offsets) - 1
    out = composite(alpha, rgb, torch.zeros_like(alpha), ray_idx, offsets, n_rays, background)
    alpha_sum = torch.zeros(n_rays, dtype=sub.dtype).index_add(0, ray_idx, alpha.clamp(max=ALPHA_MAX))
    dist = distortion(out["weights"], s, ray_idx, offsets, n_rays, DELTA)
    return out["rgb"], alpha_sum, dist, out["weights"]


CASES = {
    "mixed": [3, 0, 1, 7, 2, 0],
    "capped_sample": [4, 5, 1],
    "one_sample_each": [1, 1, 1, 1],
    "all_empty": [0, 0, 0],
    "long_ray": [300],
}
CAPPED = {"capped_sample": 5, "one_sample_each": 2, "long_ray": 150}


@pytest.mark.parametrize("per_ray_background", [False, True], ids=["one_background", "background_per_ray"])
@pytest.mark.parametrize("sh_degree", [0, 1, 2])
@pytest.mark.parametrize("case", list(CASES))
def test_composite_forward_and_gradient_equal_autograd_through_the_reference(case, sh_degree, per_ray_background):
    sub, inverse, weights, basis, ray_idx, offsets, s = samples(CASES[case], sh_degree, seed=len(case),
                                                                capped=CAPPED.get(case))
    g = torch.Generator().manual_seed(1)
    if per_ray_background:  # training composites each ray over its own random colour
        background = torch.rand(len(offsets) - 1, 3, generator=g, dtype=torch.float64)
    else:
        background = torch.tensor([0.3, 0.6, 0.1], dtype=torch.float64)
    d_rgb = torch.randn(len(offsets) - 1, 3, generator=g, dtype=torch.float64)
    d_alpha = torch.randn(len(offsets) - 1, generator=g, dtype=torch.float64)
    d_dist = torch.randn(len(offsets) - 1, generator=g, dtype=torch.float64)

    def value_and_grad(fn):
        sub.grad = None
        rgb, alpha_sum, dist, sample_weights = fn()
        ((rgb * d_rgb).sum() + (alpha_sum * d_alpha).sum() + (dist * d_dist).sum()).backward()
        return rgb.detach(), alpha_sum.detach(), dist.detach(), sample_weights.detach(), sub.grad

    rgb, alpha_sum, dist, sample_weights, grad = value_and_grad(
        lambda: Composite.apply(sub, inverse, weights, basis, offsets, s, DELTA, SHIFT, STEP_RATIO, ALPHA_MAX,
                                background))
    rgb_ref, alpha_sum_ref, dist_ref, weights_ref, grad_ref = value_and_grad(
        lambda: reference(sub, inverse, weights, basis, ray_idx, offsets, s, background))

    what = f"case {case!r} (samples per ray {CASES[case]}), sh_degree={sh_degree}, background {tuple(background.shape)}"
    torch.testing.assert_close(rgb, rgb_ref, rtol=0, atol=TOL, msg=lambda m: f"{what}: Composite rgb: {m}")
    torch.testing.assert_close(alpha_sum, alpha_sum_ref, rtol=0, atol=TOL,
                               msg=lambda m: f"{what}: Composite opacity sum: {m}")
    torch.testing.assert_close(dist, dist_ref, rtol=0, atol=TOL, msg=lambda m: f"{what}: Composite distortion: {m}")
    torch.testing.assert_close(sample_weights.double(), weights_ref, rtol=1e-6, atol=1e-7,
                               msg=lambda m: f"{what}: Composite sample weights (float32): {m}")
    torch.testing.assert_close(grad, grad_ref, rtol=0, atol=TOL, msg=lambda m: f"{what}: Composite gradient: {m}")
    if case in CAPPED:  # the capped sample alone uses the last row
        last = sub.shape[0] - 1
        assert grad[last, 0] == 0.0, (
            f"{what}: the capped sample's density has gradient {float(grad[last, 0])}; expected 0")
        assert grad[last, 1:].abs().max() > 0, f"{what}: the capped sample's colour got no gradient"
    if case == "all_empty":
        torch.testing.assert_close(rgb, background.expand(len(offsets) - 1, 3), rtol=0, atol=0,
                                   msg=lambda m: f"{what}: empty rays must show the background: {m}")


def test_composite_gradient_in_float32_tracks_float64():
    """Training runs in float32: the kernel computes in float64 inside and rounds only where it adds a sample's
    share into a row's float32 gradient, so the float32 gradient tracks the float64 one."""
    sub, inverse, weights, basis, _, offsets, s = samples([5, 2, 9], 1, seed=3)
    background = torch.zeros(3, dtype=torch.float64)
    grads = []
    for dtype in (torch.float64, torch.float32):
        x = sub.detach().to(dtype).requires_grad_(True)
        rgb, alpha_sum, dist, _ = Composite.apply(x, inverse, weights.to(dtype), basis.to(dtype), offsets,
                                                  s.to(dtype), DELTA, SHIFT, STEP_RATIO, ALPHA_MAX,
                                                  background.to(dtype))
        assert rgb.dtype == dtype, f"Composite returned {rgb.dtype} rgb for {dtype} values"
        (rgb.sum() + alpha_sum.sum() + dist.sum()).backward()
        grads.append(x.grad.double())
    torch.testing.assert_close(grads[1], grads[0], rtol=1e-6, atol=1e-7,
                               msg=lambda m: f"float32 Composite gradient drifts from float64: {m}")


@pytest.mark.parametrize("n_samples", [0, 1, 257])
def test_row_index_gives_each_distinct_row_once_ascending(n_samples):
    g = torch.Generator().manual_seed(n_samples)
    rows = torch.randint(0, 40, (n_samples, 8), generator=g).numpy()
    unique, inverse = RowIndex(40).unique(rows)
    assert len(set(unique.tolist())) == len(unique), f"RowIndex.unique returned repeated rows {unique.tolist()}"
    assert np.all(np.diff(unique) > 0), f"RowIndex.unique rows are not ascending: {unique.tolist()}"
    np.testing.assert_array_equal(unique[inverse], rows, err_msg="RowIndex.unique: unique[inverse] is not rows")
    assert sorted(unique.tolist()) == sorted(set(rows.ravel().tolist())), "RowIndex.unique lost or invented rows"


@pytest.mark.parametrize("groups", [2, 3, 8])
def test_corner_gradient_is_the_same_bits_however_its_rows_are_shared_out(groups):
    # the backward pass gives each thread a range of rows; every element must still get its additions in
    # sample and corner order, so a fit is the same on any thread count
    rng = np.random.default_rng(groups)
    rows = rng.integers(0, 300, size=(2000, 8))
    unique, inverse = RowIndex(300).unique(rows)
    grad_raw = rng.normal(size=(2000, 4))
    weights = rng.random((2000, 8)).astype(np.float32)
    offsets = np.arange(0, 2001, 10)  # 200 rays of 10 samples
    basis = rng.normal(size=(200, 4))
    one = np.zeros((len(unique), 13), dtype=np.float32)
    _corner_backward(grad_raw, inverse, weights, basis, offsets, np.array([0, len(unique)]), one)
    shared = np.zeros_like(one)
    _corner_backward(grad_raw, inverse, weights, basis, offsets,
                     np.linspace(0, len(unique), groups + 1).round().astype(np.int64), shared)
    differ = np.flatnonzero((one != shared).any(axis=1))
    assert not len(differ), f"rows {differ[:10].tolist()} differ when {groups} ranges share the rows out"


def test_sample_corners_are_the_reference_trilinear_corners():
    rng = np.random.default_rng(0)
    n_rays, per_ray, res, shell = 50, 6, 17, 0.25
    o = rng.uniform(-1.5, 1.5, (n_rays, 3)).astype(np.float32)
    d = rng.normal(size=(n_rays, 3)).astype(np.float32)
    ray_idx = np.repeat(np.arange(n_rays), per_ray)
    t = rng.uniform(0.0, 4.0, n_rays * per_ray).astype(np.float32)  # also far into the contracted shell
    rows, weights, cells = sample_corners(o, d, t, ray_idx, shell, res, np.zeros(0, dtype=np.int32))
    p = torch.from_numpy(o.astype(np.float64))[ray_idx] + torch.from_numpy(t.astype(np.float64))[:, None] \
        * torch.from_numpy(d.astype(np.float64))[ray_idx]
    rows_ref, weights_ref = trilinear(grid_coords(p, shell, res), res)
    np.testing.assert_array_equal(rows, rows_ref.numpy(), err_msg="sample_corners rows differ from query.trilinear")
    np.testing.assert_allclose(weights, weights_ref.numpy(), atol=1e-6, err_msg="sample_corners weights differ")
    np.testing.assert_allclose(weights.sum(1), 1.0, atol=1e-5, err_msg="trilinear weights do not sum to 1")
    base = rows[:, 0]
    expected_cells = ((base // (res * res)) * (res - 1) + (base // res) % res) * (res - 1) + base % res
    np.testing.assert_array_equal(cells, expected_cells, err_msg="sample_corners cell index is not corner 0's cell")


def test_lattice_positions_are_the_reference_positions_to_the_bit():
    from pytest_n2r.field.march import MarchGrid, march_dense

    rng = np.random.default_rng(1)
    o = torch.from_numpy(rng.uniform(-0.9, 0.9, (40, 3)).astype(np.float32))
    d = torch.from_numpy(rng.normal(size=(40, 3)).astype(np.float32))
    grid = MarchGrid(torch.ones(16, 16, 16, dtype=torch.bool), 0.25, 0.5, None, 100.0)
    ray_idx, t, _ = march_dense(o, d, grid)  # every lattice sample: the unit cube and the contracted shell
    want = lattice_position(o, d, t, ray_idx, grid.step, grid.shell_samples, grid.far)
    got = lattice_positions(o, d, t, ray_idx, grid.step, grid.shell_samples, grid.far)
    assert (t > 10.0).any() and (t < 1.0).any(), "the samples should reach from the cube far into the shell"
    assert torch.equal(got, want), f"{int((got != want).sum())} of {len(t)} positions differ from lattice_position"


def reference_adam(values: np.ndarray, m: np.ndarray, v: np.ndarray, rows: np.ndarray, grad: np.ndarray,
                   lrs: np.ndarray, t: int, b1: float = 0.9, b2: float = 0.99, eps: float = 1e-8) -> None:
    """Textbook Adam (Kingma & Ba, bias-corrected) on ``values[rows]`` in float64, in place."""
    m[rows] = b1 * m[rows] + (1 - b1) * grad
    v[rows] = b2 * v[rows] + (1 - b2) * grad ** 2
    m_hat, v_hat = m[rows] / (1 - b1 ** t), v[rows] / (1 - b2 ** t)
    values[rows] -= lrs * m_hat / (np.sqrt(v_hat) + eps)


def test_row_adam_on_cpu_is_adam_on_the_touched_rows_only():
    rng = np.random.default_rng(0)
    start = rng.normal(size=(30, 5)).astype(np.float32)
    values = torch.from_numpy(start.copy())
    lrs = torch.tensor([0.2, 0.1, 0.1, 0.05, 0.05])
    adam = RowAdam(values, lrs)
    ref_values, ref_m, ref_v = start.astype(np.float64), np.zeros((30, 5)), np.zeros((30, 5))
    touched = np.zeros(30, dtype=bool)
    for step, lr_scale in enumerate([1.0, 0.5, 1.0, 0.25], start=1):
        rows = np.sort(rng.choice(24, size=9, replace=False))  # rows 24..29 are never touched
        grad = rng.normal(size=(9, 5)).astype(np.float32) * 10.0 ** rng.uniform(-4, 2)
        adam.step(torch.from_numpy(rows), torch.from_numpy(grad), lr_scale)
        reference_adam(ref_values, ref_m, ref_v, rows, grad.astype(np.float64), lrs.numpy() * lr_scale, step)
        touched[rows] = True
        np.testing.assert_allclose(values.numpy(), ref_values, rtol=0, atol=1e-6,
                                   err_msg=f"RowAdam values differ from textbook Adam after step {step}")
        np.testing.assert_allclose(adam.m.numpy(), ref_m, rtol=1e-6, atol=1e-9,
                                   err_msg=f"RowAdam first moments differ after step {step}")
    assert 0 < touched.sum() < 30
    np.testing.assert_array_equal(values.numpy()[~touched], start[~touched],
                                  err_msg="RowAdam changed rows that no step touched")
    assert not adam.m.numpy()[~touched].any() and not adam.v.numpy()[~touched].any(), \
        "RowAdam moments of untouched rows are not zero"
    assert np.abs(values.numpy()[touched] - start[touched]).min() > 0, "a touched row did not move"


def test_adam_rows_with_a_zero_gradient_still_applies_momentum():
    values = np.ones((3, 2), dtype=np.float32)
    m = np.full((3, 2), 0.5, dtype=np.float32)
    v = np.full((3, 2), 0.25, dtype=np.float32)
    adam_rows(values, m, v, np.array([1]), np.zeros((1, 2), np.float32), np.array([0.1, 0.1], np.float32),
              0.9, 0.99, 1e-8, 1.0, 1.0)
    expected = 1.0 - 0.1 * 0.45 / (np.sqrt(0.2475) + 1e-8)
    np.testing.assert_allclose(values[1], expected, rtol=1e-6, err_msg="adam_rows: momentum step with zero gradient")
    np.testing.assert_array_equal(values[[0, 2]], 1.0, err_msg="adam_rows changed rows it was not given")


class _OffTheCPU(torch.Tensor):
    """A CPU tensor that says it lives elsewhere: RowAdam then takes its torch path, the one CUDA fits run."""

    @property
    def device(self) -> torch.device:
        return torch.device("meta")


def test_row_adam_on_cuda_is_adam_on_the_touched_rows_only():
    """The torch path of RowAdam (every CUDA fit's optimizer) held to textbook Adam as the compiled one is, on the
    CPU: no CPU fit ever runs it."""
    rng = np.random.default_rng(1)
    start = rng.normal(size=(30, 5)).astype(np.float32)
    values = torch.from_numpy(start.copy())
    lrs = torch.tensor([0.2, 0.1, 0.1, 0.05, 0.05])
    adam = RowAdam(values, lrs)
    adam.values = values.as_subclass(_OffTheCPU)  # the same storage
    assert adam.values.device.type != "cpu"
    ref_values, ref_m, ref_v = start.astype(np.float64), np.zeros((30, 5)), np.zeros((30, 5))
    for step, lr_scale in enumerate([1.0, 0.5, 1.0, 0.25], start=1):
        rows = np.sort(rng.choice(24, size=9, replace=False))  # rows 24..29 are never touched
        grad = rng.normal(size=(9, 5)).astype(np.float32) * 10.0 ** rng.uniform(-4, 2)
        adam.step(torch.from_numpy(rows), torch.from_numpy(grad), lr_scale)
        reference_adam(ref_values, ref_m, ref_v, rows, grad.astype(np.float64), lrs.numpy() * lr_scale, step)
        np.testing.assert_allclose(values.numpy(), ref_values, rtol=0, atol=1e-6,
                                   err_msg=f"RowAdam's torch path differs from textbook Adam after step {step}")
        np.testing.assert_allclose(adam.m.numpy(), ref_m, rtol=1e-6, atol=1e-9,
                                   err_msg=f"RowAdam's torch path: first moments differ after step {step}")
        np.testing.assert_allclose(adam.v.numpy(), ref_v, rtol=1e-5, atol=1e-12,
                                   err_msg=f"RowAdam's torch path: second moments differ after step {step}")
    np.testing.assert_array_equal(values.numpy()[24:], start[24:], err_msg="RowAdam changed rows no step touched")
