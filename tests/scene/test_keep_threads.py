"""A render leaves the SUT's torch thread count as the SUT set it.

Run in a fresh interpreter: whether numba's OpenMP layer touches torch's count depends on what ran before
in the process (the first parallel launch after torch set its count)."""

from __future__ import annotations

import os
import subprocess
import sys
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[2]

SCRIPT = """
import numba, numpy as np, torch
from pytest_n2r.scene.render_cache import RenderCache
from tests.plugin.fakescene import PlaneScene

@numba.njit(parallel=True)
def parallel_sum(a):
    total = 0.0
    for i in numba.prange(a.shape[0]):
        total += a[i]
    return total

class ParallelKernelScene(PlaneScene):
    # a scene whose render runs a numba parallel kernel, as the scene field's renderer does
    def _render(self, c2w, camera, outputs):
        parallel_sum(np.ones(1000))
        return super()._render(c2w, camera, outputs)

scene = ParallelKernelScene()
view = scene.views[0]
torch.set_num_threads(1)
torch.get_num_threads()
scene.render(view.c2w, view.camera)
bare = torch.get_num_threads()
torch.set_num_threads(1)
RenderCache(None).render(scene, view.c2w, view.camera.scaled(0.5))
print(numba.threading_layer(), bare, torch.get_num_threads())
"""


def test_a_render_with_a_parallel_kernel_keeps_torchs_thread_count():
    done = subprocess.run([sys.executable, "-c", SCRIPT], cwd=ROOT, capture_output=True, text=True, timeout=300,
                          env={**os.environ, "PYTHONPATH": str(ROOT)}, check=False)
    assert done.returncode == 0, done.stderr
    layer, bare, kept = done.stdout.split()
    if bare == "1":
        pytest.skip(f"numba's {layer!r} threading layer leaves torch's thread count alone on this machine")
    assert kept == "1", f"the SUT chose 1 thread; after a render through the cache torch has {kept}"
