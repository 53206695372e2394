"""The sample lattice's positions along a ray (the distortion loss's ``s``)."""

from __future__ import annotations

import numpy as np
import torch
from hypothesis import given, settings

from pytest_n2r.field.lattice import lattice_position
from pytest_n2r.field.march import MarchGrid, march_dense
from pytest_n2r.geometry import camera_rays

from ..field.fields import CAMERA, SPACE, pose
from ..render.strategies import poses


@settings(max_examples=40, deadline=None)
@given(poses(max_distance=5.0))
def test_every_lattice_sample_stands_for_one_step_inner_and_shell_alike(eye_target):
    """With every cell occupied, consecutive samples of a ray are one ``step`` apart in lattice position,
    across the cube, the shell, and the border between them."""
    grid = MarchGrid(torch.ones(15, 15, 15, dtype=torch.bool), SPACE.shell, 0.5, None, 100.0)
    o, d = SPACE.normalize_rays(*camera_rays(CAMERA, pose(*eye_target)))
    o, d = torch.from_numpy(o.reshape(-1, 3)[::37]), torch.from_numpy(d.reshape(-1, 3)[::37])
    ray_idx, t, offsets = march_dense(o, d, grid)
    s = lattice_position(o, d, t, ray_idx, grid.step, grid.shell_samples, grid.far).numpy()
    for r in range(o.shape[0]):
        gaps = np.diff(s[offsets[r]:offsets[r + 1]])
        np.testing.assert_allclose(gaps, grid.step, rtol=1e-3, err_msg=(
            f"ray {r} from eye {eye_target[0]}: lattice positions are not one step ({grid.step}) apart"))
        assert s[offsets[r]] >= 0.0, f"ray {r}: the first sample's position {s[offsets[r]]} is negative"
