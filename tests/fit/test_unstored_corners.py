"""A training sample whose position lies in an unoccupied cell reads and updates only the rows of its stored corners.

The march tests a sample's cell at its float64 ``t`` but stores ``t`` as float32, so the position a step recomputes
can round into an unoccupied neighbour cell, whose corners a sparse field may not store (row -1: measured 1 sample in
1.4 M on a sparse 24³ field). Both training paths used to read such a corner from the last stored row (-1 wraps) and
take an Adam step on it; now it counts as zeros, as :meth:`~pytest_n2r.field.grid.SceneField.upsampled` counts a
vertex it does not store. The sample here is placed in such a cell on purpose, in a batch of its own.
"""

from __future__ import annotations

import pytest
import torch

from pytest_n2r.errors import FitError
from pytest_n2r.field.config import FieldConfig
from pytest_n2r.field.lattice import grid_coords
from pytest_n2r.field.query import trilinear
from pytest_n2r.fit.field_fit import _Trainer

#: One grid, no prior (the TV prior reads each touched row's stored neighbours: rows the samples do not own).
CONFIG = FieldConfig(resolutions=(16,), stage_fractions=(), batch_rays=64, tv=0.0, tv_density=0.0)


def _sparse_trainer(capture48, compiled: bool) -> _Trainer:
    """A trainer whose field is sparse: a sixth of the cells of the first grid occupied, only their vertices stored."""
    trainer = _Trainer(capture48, CONFIG, torch.device("cpu"))
    keep = torch.rand(trainer.field.occupancy.shape, generator=torch.Generator().manual_seed(0)) < 0.15
    trainer.field.occupancy = keep
    trainer.field = trainer.field.compact()
    trainer.compiled = compiled
    trainer._reset_optimizer()
    return trainer


def _stray_sample(trainer: _Trainer, o: torch.Tensor, d: torch.Tensor) -> tuple[int, float, torch.Tensor]:
    """``(ray, t, corner rows)`` of a point on one of the rays ``o, d`` in the middle of a run of points in unoccupied
    cells with both stored and unstored corners (as a float32 ``t`` rounds a sample into such a cell, but away from
    its faces: both training paths place it in the same cell)."""
    f = trainer.field
    t = torch.linspace(0.0, 3.0, 6001, dtype=torch.float64)
    for ray in range(o.shape[0]):
        p = o[ray].double() + t[:, None] * d[ray].double()
        coords = grid_coords(p, f.space.shell, f.resolution)
        corners, _ = trilinear(coords, f.resolution)
        rows = f.vertex_rows(corners)
        cell = coords.floor().long().clamp(0, f.resolution - 2)
        stray = ~f.occupancy[cell[:, 0], cell[:, 1], cell[:, 2]] & (rows < 0).any(1) & (rows >= 0).any(1)
        runs = torch.nonzero(stray[:-8] & stray[8:]).reshape(-1)  # eight points on: well inside the cell
        if runs.numel():
            k = int(runs[0]) + 4
            return ray, float(t[k]), rows[k]
    raise AssertionError("no training ray of the batch crosses an unoccupied cell next to the field: the test would "
                         "pass vacuously")


@pytest.mark.parametrize("compiled", [True, False], ids=["compiled", "torch"])
def test_a_sample_in_an_unoccupied_cell_reads_and_updates_only_its_stored_corners(capture48, compiled, monkeypatch):
    """Every row but the sample's stored corners holds NaN: a step that read one would diverge, one that took an
    Adam step on one would give it moments."""
    trainer = _sparse_trainer(capture48, compiled)
    state = trainer.generator.get_state()  # the batch the step will draw
    pick = torch.randint(trainer.rays.n, (CONFIG.batch_rays,), generator=trainer.generator)
    trainer.generator.set_state(state)
    o, d = trainer.rays.o(pick), trainer.rays.d[pick]
    ray, t, rows = _stray_sample(trainer, o, d)

    def march(o_step: torch.Tensor, d_step: torch.Tensor) -> tuple[torch.Tensor, torch.Tensor, torch.Tensor]:
        assert torch.equal(o_step, o) and torch.equal(d_step, d), "the step drew another batch than the test's"
        offsets = torch.zeros(o.shape[0] + 1, dtype=torch.int64)
        offsets[ray + 1:] = 1
        return torch.tensor([ray]), torch.tensor([t], dtype=torch.float32), offsets

    monkeypatch.setattr(trainer, "march", march)
    values = trainer.field.values
    mine = rows[rows >= 0].unique()
    others = torch.ones(values.shape[0], dtype=torch.bool)
    others[mine] = False
    last = values.shape[0] - 1
    assert others[last], "the sample owns the last row: the test cannot tell a wrapped -1 from it"
    with torch.no_grad():
        values[:, 0] += 4.0  # opaque: the sample's density and colour reach the loss
        values[others] = float("nan")
    before = values[mine].clone()
    try:
        trainer.step(1.0)
    except FitError as error:
        pytest.fail(f"a sample in an unoccupied cell read a row none of its corners stores (the last, {last}, "
                    f"where -1 wraps?): {error}")
    moved = torch.nonzero(others & (trainer.adam.m != 0).any(1)).reshape(-1).tolist()
    assert not moved, (f"the step took an Adam step on rows {moved} (of {values.shape[0]}; the last is {last}) that "
                       f"no corner of its one sample stores (its rows: {mine.tolist()})")
    assert torch.isfinite(values[mine]).all() and not torch.equal(values[mine], before), \
        "the step did not move the sample's own rows: the test would pass vacuously"
