"""A render leaves the SUT's torch thread count as the SUT set it."""

from __future__ import annotations

import numba
import numpy as np
import pytest
import torch

from pytest_n2r.scene.keep_threads import threads_kept
from pytest_n2r.scene.render_cache import RenderCache
from tests.plugin.fakescene import PlaneScene


@numba.njit(parallel=True, cache=False)
def _parallel_sum(a):
    total = 0.0
    for i in numba.prange(a.shape[0]):
        total += a[i]
    return total


class ParallelKernelScene(PlaneScene):
    """A scene whose render runs a numba parallel kernel, as the scene field's renderer does."""

    def _render(self, c2w, camera, outputs):
        _parallel_sum(np.ones(1000))
        return super()._render(c2w, camera, outputs)


def test_a_render_with_a_parallel_kernel_keeps_torchs_thread_count():
    before = torch.get_num_threads()
    try:
        torch.set_num_threads(1)
        assert torch.get_num_threads() == 1
        scene = ParallelKernelScene()
        view = scene.views[0]
        scene.render(view.c2w, view.camera)  # the kernel alone
        if torch.get_num_threads() == 1:
            pytest.skip(f"numba's {numba.threading_layer()!r} threading layer leaves torch's threads alone here")
        torch.set_num_threads(1)
        RenderCache(None).render(scene, view.c2w, view.camera)
        assert torch.get_num_threads() == 1, "the SUT chose 1 thread; a render through the cache must not change it"
        with threads_kept():
            torch.set_num_threads(2)
        assert torch.get_num_threads() == 1
    finally:
        torch.set_num_threads(before)
