"""A grid's first prune drops the rows no occupied cell uses, and carries the others' values and Adam moments."""

from __future__ import annotations

import pytest
import torch

from pytest_n2r.field.config import FieldConfig
from pytest_n2r.fit.field_fit import _Trainer


@pytest.mark.parametrize("compiled", [True, False], ids=["compiled", "torch"])
def test_a_grids_first_prune_keeps_only_the_rows_its_occupied_cells_use(capture48, compiled):
    config = FieldConfig(resolutions=(16, 24), stage_fractions=(0.5,), batch_rays=256, prune_alpha=0.05)
    trainer = _Trainer(capture48, config, torch.device("cpu"))
    trainer.compiled = compiled
    trainer._reset_optimizer()
    trainer.refine()  # a grid upsampled from the last one stores every vertex of its dilated occupancy
    for _ in range(20):
        trainer.step(1.0)
    before = trainer.field
    stored_before = before.values.shape[0]
    moments = (trainer.adam.m.clone(), trainer.adam.v.clone())
    trainer.prune()
    after = trainer.field
    used = after.used_vertex_index()
    assert after.values.shape[0] == used.numel() < stored_before, (
        f"after the grid's first prune the field stores {after.values.shape[0]} rows; its occupied cells use "
        f"{used.numel()} vertices, and {stored_before} were stored before")
    old_rows, new_rows = before.vertex_rows(used), after.vertex_rows(used)
    assert torch.equal(after.values[new_rows], before.values[old_rows]), "compaction changed a used vertex's values"
    for name, old, new in (("m", moments[0], trainer.adam.m), ("v", moments[1], trainer.adam.v)):
        assert torch.equal(new[new_rows], old[old_rows]), f"Adam's {name} did not come along with its rows"
    assert trainer.adam.values is after.values, "Adam updates another tensor than the field's values"
    if compiled:  # the prior's neighbour table indexes rows: a stale one would read past the compacted values
        table, n_values = trainer.tv_rows, after.values.shape[0]
        assert table.shape[0] == n_values and int(table.max()) < n_values, \
            f"the prior's neighbour table has {table.shape[0]} rows up to row {table.max()} for {n_values} values"

    loss, _ = trainer.step(1.0)
    assert torch.isfinite(torch.tensor(loss)), f"a step after compaction gives the loss {loss}"
    rows = after.values.shape[0]
    trainer.prune()
    assert trainer.field.values is after.values and trainer.field.values.shape[0] == rows, \
        "a later prune on the same grid compacted again (only a grid's first prune should)"
