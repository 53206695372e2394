"""The compiled total-variation prior adds the torch formulation's gradient (which the training-path tests
hold to autograd's), on dense and sparse fields, whatever rows a step touches and whichever columns are
weighted."""

from __future__ import annotations

import numpy as np
import torch
from hypothesis import given, settings
from hypothesis import strategies as st

from pytest_n2r.field.grid import SceneField
from pytest_n2r.field.space import SceneSpace
from pytest_n2r.fit.prior import add_tv_gradient, tv_gradient, tv_neighbours


def _field(resolution: int, stored: float, seed: int) -> tuple[SceneField, torch.Tensor]:
    """A random SH-degree-1 field of ``resolution``³ storing each vertex with probability ``stored`` (1: dense),
    and each row's flat vertex index."""
    rng = np.random.default_rng(seed)
    n = resolution ** 3
    keep = np.flatnonzero(rng.random(n) < stored) if stored < 1.0 else np.arange(n)
    keep = keep if len(keep) else np.array([0])
    values = torch.from_numpy(rng.normal(size=(len(keep), 13)).astype(np.float32))
    rows = None
    if stored < 1.0:
        rows = torch.full((n,), -1, dtype=torch.int32)
        rows[torch.from_numpy(keep)] = torch.arange(len(keep), dtype=torch.int32)
    occupancy = torch.ones((resolution - 1,) * 3, dtype=torch.bool)
    field = SceneField(SceneSpace((0.0, 0.0, 0.0), 1.0), values, occupancy, 0.0, 1, rows=rows)
    return field, torch.from_numpy(keep.astype(np.int64))


@settings(max_examples=40, deadline=None)
@given(resolution=st.integers(4, 12), stored=st.sampled_from([1.0, 0.9, 0.5, 0.15]), seed=st.integers(0, 2**16),
       touched=st.floats(0.05, 1.0), tv=st.sampled_from([0.0, 1e-4, 0.3]), tv_density=st.sampled_from([0.0, 2e-5, 1.0]))
def test_the_compiled_tv_gradient_adds_the_torch_one(resolution, stored, seed, touched, tv, tv_density):
    field, flat_of_row = _field(resolution, stored, seed)
    n_rows = field.values.shape[0]
    generator = torch.Generator().manual_seed(seed)
    unique = torch.randperm(n_rows, generator=generator)[:max(1, int(touched * n_rows))].sort().values
    weights = torch.tensor([tv_density] + [tv] * 12)
    start = torch.randn(unique.numel(), 13, generator=generator)
    expected = start + weights * tv_gradient(field, flat_of_row, unique)
    got = start.clone()
    neighbours = tv_neighbours(flat_of_row, field.kernel_rows(), field.resolution)
    add_tv_gradient(field.values, unique, neighbours, weights, got)
    torch.testing.assert_close(got, expected, rtol=1e-5, atol=1e-6,
                               msg=lambda m: f"compiled TV gradient != torch's ({resolution}³, {stored:.0%} "
                                             f"stored, tv={tv}, tv_density={tv_density}): {m}")


def test_the_compiled_tv_gradient_pulls_towards_stored_neighbours_only():
    """A hand-checked case: on a 4³ sparse field, a vertex with one stored neighbour is pulled by 2/|U| times
    its difference to it (one row touched), and an unstored neighbour pulls nothing."""
    field, _ = _field(4, 1.0, 0)
    rows = torch.full((64,), -1, dtype=torch.int32)
    corner, right = 0, 1  # flat (0, 0, 0) and its +z neighbour (0, 0, 1); (0, 1, 0) and (1, 0, 0) unstored
    rows[corner], rows[right] = 0, 1
    values = torch.zeros(2, 13)
    values[0] = 3.0
    values[1, 0], values[1, 1:] = 1.0, 2.0
    sparse = SceneField(field.space, values, field.occupancy, 0.0, 1, rows=rows)
    grad = torch.zeros(1, 13)
    weights = torch.tensor([0.5] + [0.0] * 12)
    neighbours = tv_neighbours(torch.tensor([corner, right]), sparse.kernel_rows(), 4)
    assert neighbours.tolist() == [[-1, -1, -1, -1, -1, 1], [-1, -1, -1, -1, 0, -1]], \
        f"expected (0, 0, 0) and (0, 0, 1) each other's only neighbours along z, got {neighbours.tolist()}"
    add_tv_gradient(sparse.values, torch.tensor([0]), neighbours, weights, grad)
    expected = torch.zeros(1, 13)
    expected[0, 0] = 0.5 * 2.0 * (3.0 - 1.0)
    assert torch.equal(grad, expected), f"expected only the density pulled by 2.0, got {grad.tolist()}"


@settings(max_examples=30, deadline=None)
@given(resolution=st.integers(4, 9), stored=st.sampled_from([1.0, 0.6, 0.2]), seed=st.integers(0, 2**16))
def test_the_neighbour_table_holds_each_rows_stored_neighbours_along_each_axis(resolution, stored, seed):
    """Each row's entry ``2·axis + (0 for −, 1 for +)`` is the row of the vertex one step along that axis, or
    -1 where that vertex is outside the grid or not stored, checked vertex by vertex in Python."""
    field, flat_of_row = _field(resolution, stored, seed)
    table = tv_neighbours(flat_of_row, field.kernel_rows(), resolution)
    assert table.shape == (field.values.shape[0], 6) and table.dtype == np.int32, \
        f"expected an int32 ({field.values.shape[0]}, 6) table, got {table.dtype} {table.shape}"
    row_of = {int(flat): row for row, flat in enumerate(flat_of_row.tolist())}
    for row, flat in enumerate(flat_of_row.tolist()):
        ijk = (flat // resolution ** 2, flat // resolution % resolution, flat % resolution)
        for axis in range(3):
            for side, sign in enumerate((-1, 1)):
                moved = list(ijk)
                moved[axis] += sign
                inside = 0 <= moved[axis] < resolution
                expected = row_of.get((moved[0] * resolution + moved[1]) * resolution + moved[2], -1) if inside else -1
                got = table[row, 2 * axis + side]
                assert got == expected, \
                    f"row {row} (vertex {ijk}): neighbour along axis {axis}, sign {sign}, is {got}; expected {expected}"
