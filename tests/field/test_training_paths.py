"""The two training paths — compiled kernels (CPU) and plain torch (the CUDA path) — take the same steps."""

from __future__ import annotations

import torch

from pytest_n2r.demo.rendered_capture import capture_scene
from pytest_n2r.demo.scenes import build_scene
from pytest_n2r.field.config import FieldConfig
from pytest_n2r.field.fit import _Trainer


def _train(capture, compiled: bool, steps: int = 30) -> _Trainer:
    trainer = _Trainer(capture, FieldConfig(resolutions=(24,), stage_fractions=(), batch_rays=256), torch.device("cpu"))
    trainer.compiled = compiled
    trainer._reset_optimizer()
    for _ in range(steps):
        trainer.step(1.0)
    trainer.prune()
    return trainer


def test_compiled_and_torch_training_paths_agree():
    capture = capture_scene(build_scene("object"), (48, 27))
    compiled, reference = _train(capture, True), _train(capture, False)
    diff = (compiled.field.values - reference.field.values).abs().max().item()
    assert diff < 1e-4, f"after 30 steps the compiled and torch paths' grid values differ by {diff}"
    assert torch.equal(compiled.field.occupancy, reference.field.occupancy), \
        "the two paths pruned different cells (visibility bookkeeping differs)"
    assert (compiled.field.values != 0).any(), "the fit did not move any value: the test would pass vacuously"
