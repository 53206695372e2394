"""The compiled occupancy refresh keeps the same cells as the dense torch formulation, on dense and sparse
fields, whatever the opacities, the visibility record and the threshold; and a hand-checked case of what
the refresh keeps."""

from __future__ import annotations

import numpy as np
import torch
from hypothesis import given, settings
from hypothesis import strategies as st

from pytest_n2r.field.grid import SceneField, used_vertex_index
from pytest_n2r.field.space import SceneSpace
from pytest_n2r.fit.prune import pruned_occupancy, pruned_occupancy_dense


def _field(resolution: int, occupied: float, extra: float, seed: int, sparse: bool) -> SceneField:
    """A random field of ``resolution``³ with a fraction ``occupied`` of its cells occupied; a sparse one stores
    the vertices of its occupied cells and each other vertex with probability ``extra`` (a fit's refreshes
    leave such rows behind)."""
    rng = np.random.default_rng(seed)
    n = resolution - 1
    occupancy = torch.from_numpy(rng.random((n, n, n)) < occupied)
    rows = None
    stored = np.arange(resolution ** 3)
    if sparse:
        used = np.zeros(resolution ** 3, dtype=bool)
        used[used_vertex_index(occupancy).numpy()] = True
        stored = np.flatnonzero(used | (rng.random(resolution ** 3) < extra))
        rows = torch.full((resolution ** 3,), -1, dtype=torch.int32)
        rows[torch.from_numpy(stored)] = torch.arange(len(stored), dtype=torch.int32)
    values = torch.from_numpy(rng.normal(0.0, 3.0, size=(max(len(stored), 1), 4)).astype(np.float32))
    return SceneField(SceneSpace((0.0, 0.0, 0.0), 1.0), values, occupancy, -2.0, 0, rows=rows)


def _compiled(field: SceneField, cell_weight: torch.Tensor, threshold: float, weight: float) -> torch.Tensor:
    occ = np.ascontiguousarray(field.occupancy.numpy().astype(np.uint8))
    return pruned_occupancy(field, occ, field.kernel_rows(), cell_weight, threshold, weight, 0.5)


@settings(max_examples=60, deadline=None)
@given(resolution=st.integers(4, 14), occupied=st.sampled_from([0.0, 0.03, 0.3, 1.0]),
       extra=st.sampled_from([0.0, 0.2]), sparse=st.booleans(), seed=st.integers(0, 2**16),
       threshold=st.sampled_from([0.0, 1e-3, 0.08, 0.5, 0.99]), seen=st.floats(0.0, 1.0))
def test_the_compiled_refresh_keeps_the_cells_the_dense_one_keeps(resolution, occupied, extra, sparse, seed,
                                                                  threshold, seen):
    field = _field(resolution, occupied, extra, seed, sparse)
    generator = torch.Generator().manual_seed(seed)
    n = field.occupancy.numel()
    cell_weight = torch.where(torch.rand(n, generator=generator) < seen, torch.rand(n, generator=generator) * 2e-3,
                              torch.tensor(-1.0))
    got = _compiled(field, cell_weight, threshold, 1e-3)
    expected = pruned_occupancy_dense(field, cell_weight, threshold, 1e-3, 0.5)
    assert got.dtype == torch.bool and got.shape == expected.shape, f"got {got.dtype} {tuple(got.shape)}"
    differ = (got != expected).nonzero().tolist()
    assert not differ, (f"{resolution}³, {'sparse' if sparse else 'dense'}, threshold {threshold}: the compiled "
                        f"refresh differs from the dense one at cells {differ[:5]} ({len(differ)} in all)")


def test_a_kept_cell_keeps_its_neighbours_and_an_unseen_empty_cell_does_not_count_as_kept():
    """10³ vertices, every cell occupied, every density empty except at the corners of cell (2, 2, 2): the
    27 cells sharing one of those corners are kept, they and their neighbours stay (cells 0..4 on each axis),
    nothing farther; once rays sampled every cell without any weight, nothing stays."""
    res = 10
    values = torch.full((res ** 3, 4), -50.0)
    corners = [((2 + a) * res + 2 + b) * res + 2 + c for a in (0, 1) for b in (0, 1) for c in (0, 1)]
    values[corners, 0] = 50.0
    occupancy = torch.ones((res - 1,) * 3, dtype=torch.bool)
    field = SceneField(SceneSpace((0.0, 0.0, 0.0), 1.0), values, occupancy, 0.0, 0)
    unseen = torch.full((occupancy.numel(),), -1.0)
    kept = _compiled(field, unseen, 0.08, 1e-3)
    expected = torch.zeros_like(occupancy)
    expected[0:5, 0:5, 0:5] = True
    assert torch.equal(kept, expected), f"kept {int(kept.sum())} cells, expected {int(expected.sum())}"
    dark = torch.full((occupancy.numel(),), 0.0)
    assert not _compiled(field, dark, 0.08, 1e-3).any(), "cells sampled without weight were kept"
