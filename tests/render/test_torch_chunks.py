"""The torch backend's chunks are sized so that its dense march stays within a memory budget.

``march_dense`` lists every lattice slot of every ray of a chunk before it keeps the occupied ones
(:data:`~pytest_n2r.field.march.DENSE_MARCH_BYTES` a slot), so the default 65 536 rays took up to 5 GiB at 224³: a
4–8 GB GPU ran out of memory with ``device="auto"``. The torch backend now traces at most
:func:`~pytest_n2r.field.march.dense_rays` rays within :data:`~pytest_n2r.render.field_render.DENSE_MARCH_BUDGET` at a
time, and chunking does not change the picture (on the CPU, torch rounds a float32 ``softplus`` differently in its
vector loop and its scalar tail, so two chunkings agree to float32 rounding, not to the bit: 0.2 ppm in depth).
"""

from __future__ import annotations

import weakref

import numpy as np
import pytest
import torch
from torch.utils._python_dispatch import TorchDispatchMode
from torch.utils._pytree import tree_map

from pytest_n2r.field.march import DENSE_MARCH_BYTES, MarchGrid, march_dense
from pytest_n2r.geometry import Camera
from pytest_n2r.render import field_render
from pytest_n2r.render.field_render import DENSE_MARCH_BUDGET, FieldRenderer, RenderSettings

from ..field.fields import POSES, named_pose, random_field

OUTPUTS = ("rgb", "depth", "opacity")
CAMERA = Camera(64, 48, 40.0, 40.0, 31.5, 23.5)


def assert_same_picture(got: dict, expected: dict, what: str) -> None:
    """The same picture to float32 rounding: every colour byte, opacity within 1e-6, depth within 1 ppm."""
    assert np.array_equal(got["rgb"], expected["rgb"]), \
        f"{what}: {int((got['rgb'] != expected['rgb']).sum())} colour bytes differ"
    np.testing.assert_allclose(got["opacity"], expected["opacity"], rtol=0, atol=1e-6,
                               err_msg=f"{what}: the opacity differs")
    np.testing.assert_allclose(got["depth"], expected["depth"], rtol=1e-6, atol=0, err_msg=f"{what}: the depth differs")


def test_the_torch_backend_sizes_its_chunks_from_the_lattice_to_the_budget():
    """At 224³ a ray crosses up to 662 lattice slots: 6 335 rays a chunk, not the 65 536 asked for, fit 512 MiB."""
    field = random_field(resolution=224, sh_degree=0, occupied=0.0)
    field.occupancy[100:104, 100:104, 100:104] = True
    field = field.compact()
    torch_chunk = FieldRenderer(field, RenderSettings(backend="torch")).chunk_rays
    compiled_chunk = FieldRenderer(field, RenderSettings(backend="compiled")).chunk_rays
    slots = MarchGrid(field.occupancy, field.space.shell, 0.5, None, 100.0).lattice_slots()
    assert slots == 662, f"a ray crosses up to {slots} lattice slots at 224³, not 662"
    assert torch_chunk == 6335 and torch_chunk * slots * DENSE_MARCH_BYTES <= DENSE_MARCH_BUDGET, (
        f"the torch backend marches {torch_chunk} rays a chunk at 224³: "
        f"{torch_chunk * slots * DENSE_MARCH_BYTES / 2 ** 20:.0f} MiB against a budget of "
        f"{DENSE_MARCH_BUDGET / 2 ** 20:.0f} MiB")
    assert compiled_chunk == RenderSettings().chunk_rays, \
        f"the compiled backend (which marches sparsely) traces {compiled_chunk} rays a chunk, not chunk_rays"


def test_no_chunk_of_the_torch_backend_marches_more_rays_than_the_budget_holds(monkeypatch):
    """With a budget of 1 MiB a 16³ lattice (44 slots a ray) holds 186 rays: a 64×48 render marches in 17 chunks of
    at most that, and gives the picture one chunk gives."""
    field = random_field(resolution=16).compact()
    c2w = named_pose("inside")
    settings = RenderSettings(backend="torch", adaptive=0.0)
    whole = FieldRenderer(field, settings).render(c2w, CAMERA, OUTPUTS)
    marched: list[int] = []

    def march(o, d, grid):
        marched.append(o.shape[0])
        return march_dense(o, d, grid)

    monkeypatch.setattr(field_render, "DENSE_MARCH_BUDGET", 1 << 20)
    monkeypatch.setattr(field_render, "march_dense", march)
    chunked = FieldRenderer(field, settings).render(c2w, CAMERA, OUTPUTS)
    assert marched and max(marched) <= 186 and len(marched) == 17, (
        f"with a 1 MiB budget the torch backend marched chunks of {sorted(set(marched))} rays ({len(marched)} "
        "chunks); expected 17 of at most 186")
    assert_same_picture(chunked, whole, "a render in chunks of 186 rays against one chunk")


@pytest.mark.parametrize("chunk_rays", [7, 100])
@pytest.mark.parametrize("sh_degree, sparse", [(0, False), (1, True), (2, True)])
def test_chunking_does_not_change_a_torch_render(chunk_rays, sh_degree, sparse):
    field = random_field(resolution=16, sh_degree=sh_degree, seed=sh_degree)
    field = field.compact() if sparse else field
    camera = Camera(24, 18, 15.0, 15.0, 11.5, 8.5)
    for pose in POSES:
        c2w = named_pose(pose)
        whole = FieldRenderer(field, RenderSettings(backend="torch")).render(c2w, camera, OUTPUTS)
        small = FieldRenderer(field, RenderSettings(backend="torch", chunk_rays=chunk_rays)).render(c2w, camera,
                                                                                                     OUTPUTS)
        assert_same_picture(small, whole, f"pose {pose!r}, SH degree {sh_degree}: chunks of {chunk_rays} rays")


class _PeakBytes(TorchDispatchMode):
    """The most bytes of torch tensors alive at once while it is active (each new storage, until it is freed)."""

    def __init__(self):
        super().__init__()
        self.live = self.peak = 0
        self.held: set[int] = set()

    def __torch_dispatch__(self, func, types, args=(), kwargs=None):
        out = func(*args, **(kwargs or {}))
        tree_map(self._count, out)
        return out

    def _count(self, value):
        if isinstance(value, torch.Tensor):
            storage = value.untyped_storage()
            key, size = storage.data_ptr(), storage.nbytes()
            if key and key not in self.held:
                self.held.add(key)
                self.live += size
                self.peak = max(self.peak, self.live)
                weakref.finalize(storage, self._free, key, size)
        return value

    def _free(self, key: int, size: int) -> None:
        self.live -= size
        self.held.discard(key)


@pytest.mark.parametrize("resolution", [32, 96])
def test_the_dense_march_takes_no_more_than_its_price_a_lattice_slot(resolution):
    """Rays along the cube's diagonal through an occupied grid use every slot of the lattice: the worst case the
    chunks are sized for."""
    grid = MarchGrid(torch.ones((resolution - 1,) * 3, dtype=torch.bool), 0.25, 0.5, None, 100.0)
    generator = torch.Generator().manual_seed(0)
    n = 500
    o = torch.full((n, 3), -0.999) + 1e-3 * torch.rand(n, 3, generator=generator)
    d = torch.ones(n, 3) + 1e-3 * torch.rand(n, 3, generator=generator)
    with _PeakBytes() as peak:
        _, t, _ = march_dense(o, d, grid)
    assert t.numel() >= 0.95 * n * grid.lattice_slots(), "the rays leave lattice slots unused: not the worst case"
    price = DENSE_MARCH_BYTES * n * grid.lattice_slots()
    assert peak.peak <= price, (f"the dense march of {n} rays at {resolution}³ held {peak.peak} bytes at its peak, "
                                f"{peak.peak / (n * grid.lattice_slots()):.1f} a lattice slot: more than the "
                                f"{DENSE_MARCH_BYTES} its chunks are sized for")
