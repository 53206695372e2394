"""What a fit holds in memory, and the finest grid it can move to: the bytes a grid stage takes, the memory the
fitting device has free, and the finest grid between the two.

A fit stores only the vertices of its occupied cells (a sparse field, :mod:`pytest_n2r.field.grid`), so its
memory follows the surfaces the field has formed, not the cube. A field that has not formed yet has no such
bound: a 30-step fit of the fox with the 40-minute config (nothing pruned yet) moved a field that still
occupied every cell to 384³ and was killed by the kernel at 24 GB (5 December; docs/scene-field-log.md). So each
move to a finer grid is sized by the vertices that grid will actually store, against the memory free at that
moment (:func:`choose_grid`); where the wanted grid does not fit in :data:`HEADROOM` of it, the fit trains the
finest coarser one that does, or stays on its grid, and says so (``report["grid_limits"]``, ``n2r info``).

Convention
----------
Bytes; grid sizes in vertices per axis (``R``: ``R³`` vertices, ``(R - 1)³`` cells); ``width``: float32 values
a stored vertex holds (``1 + 3·(sh_degree + 1)²``: 4, 13 or 28).
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from pathlib import Path

import torch

from ..errors import InvalidArgument
from ..field.config import FieldConfig
from ..field.grid import SceneField, used_vertex_mask

__all__ = ["GRID_STEP", "HEADROOM", "GridChoice", "GridMemoryLimit", "choose_grid", "fit_memory_bytes", "free_bytes",
           "memory_resolution", "stage_bytes"]

#: The share of the free memory a new grid may take: the rest is for what the estimate leaves out (the
#: upsampling's own tensors, about 20 bytes a stored vertex at its peak; a step's samples; the evaluation's
#: renderer) and for other processes.
HEADROOM = 0.8
#: A grid that does not fit is replaced by the finest multiple of this below it that does.
GRID_STEP = 16
#: Where the kernel lists this process's cgroups, and where their files are (module constants for the tests).
_PROC_CGROUP = Path("/proc/self/cgroup")
_CGROUP_ROOT = Path("/sys/fs/cgroup")


class GridMemoryLimit(UserWarning):
    """A fit trained a coarser grid than its ladder's, or stayed on its grid, because the finer one would not
    fit in the memory free (the fit report's ``grid_limits`` says which, at which step)."""


def stage_bytes(resolution: int, stored: int, *, width: int = 13) -> int:
    """The bytes a fit holds on a grid of ``resolution``³ that stores ``stored`` vertices: the row map (int32 a
    vertex), the occupancy and the training visibility (a byte and a float32 a cell), and for each stored
    vertex its ``width`` float32 values with Adam's two moments, its flat index (int64) and its six neighbours
    for the prior (int32 each, :func:`~pytest_n2r.fit.prior.tv_neighbours`).

    >>> stage_bytes(384, 384 ** 3, width=28) / 2**30  # every vertex of a 384³ grid at SH degree 2
    19.9
    """
    if isinstance(resolution, bool) or not isinstance(resolution, int) or resolution < 2:
        raise InvalidArgument(f"resolution={resolution!r}: expected vertices per axis >= 2")
    if not 0 <= stored <= resolution ** 3:
        raise InvalidArgument(f"stored={stored!r}: expected a vertex count in 0..{resolution ** 3}")
    return int(4 * resolution ** 3 + 5 * (resolution - 1) ** 3 + stored * (3 * 4 * width + 8 + 6 * 4))


def fit_memory_bytes(resolution: int, *, occupied: float = 0.1, width: int = 13) -> int:
    """An upper estimate of the bytes a fit holds on its finest grid of ``resolution``³ once the field has
    formed: :func:`stage_bytes` with the vertices of ``occupied`` of the cells stored (about 1.2 vertices an
    occupied cell at the fractions fits reach)."""
    if not 0.0 < occupied <= 1.0:
        raise InvalidArgument(f"occupied={occupied!r}: expected a fraction of the cells in (0, 1]")
    if isinstance(resolution, bool) or not isinstance(resolution, int) or resolution < 2:
        raise InvalidArgument(f"resolution={resolution!r}: expected vertices per axis >= 2")
    stored = min(resolution ** 3, int(1.2 * occupied * (resolution - 1) ** 3))
    return stage_bytes(resolution, stored, width=width)


def memory_resolution(memory_bytes: float, *, occupied: float = 0.1, width: int = 13, multiple: int = 16) -> int:
    """The largest grid size (a multiple of ``multiple``, at most 1024) whose fit fits in ``memory_bytes``
    by :func:`fit_memory_bytes`.

    >>> memory_resolution(24 * 2**30)
    928
    """
    if not (math.isfinite(memory_bytes) and memory_bytes > 0):
        raise InvalidArgument(f"memory_bytes={memory_bytes!r}: expected a number of bytes > 0")
    best = 0
    for r in range(multiple, 1024 + 1, multiple):
        if fit_memory_bytes(r, occupied=occupied, width=width) <= memory_bytes:
            best = r
    if best == 0:
        raise InvalidArgument(f"memory_bytes={memory_bytes!r}: not even a {multiple}³ grid fits")
    return best


def free_bytes(device: torch.device) -> int | None:
    """The bytes a fit on ``device`` may still allocate: on CUDA the device's free memory plus what torch's
    cache holds unused; on the CPU the kernel's ``MemAvailable``, or less where this process's cgroup (v1 or
    v2, a container's limit) leaves less. ``None`` where the system does not say (no guard is then applied)."""
    if device.type == "cuda":
        free, _ = torch.cuda.mem_get_info(device)
        return int(free + torch.cuda.memory_reserved(device) - torch.cuda.memory_allocated(device))
    known = [b for b in (_meminfo_available(), _cgroup_free()) if b is not None]
    return min(known) if known else None


@dataclass(frozen=True)
class GridChoice:
    """The grid a fit moves to: ``wanted``, the ladder's; ``resolution``, the finest that fits (the field's own
    where none finer does); ``needed``, the bytes the wanted one would take (:func:`stage_bytes`, with the
    vertices it would store); ``free``, the bytes free when it was chosen (``None``: unknown)."""

    wanted: int
    resolution: int
    needed: int
    free: int | None

    @property
    def limited(self) -> bool:
        """Whether memory stopped the fit short of the wanted grid."""
        return self.resolution != self.wanted

    def applied_to(self, config: FieldConfig, stage: int) -> FieldConfig:
        """``config`` with its ``stage``-th grid replaced by the one chosen, or dropped (with its start) where
        the chosen one is the grid before it."""
        res, fractions = list(config.resolutions), list(config.stage_fractions)
        if self.resolution > res[stage - 1]:
            res[stage] = self.resolution
        else:
            del res[stage], fractions[stage - 1]
        return config.replace(resolutions=tuple(res), stage_fractions=tuple(fractions))

    def message(self) -> str:
        """One line for the user: what was wanted, what it needed, what was free, what was trained instead."""
        gib = 2 ** 30
        trained = f"trained {self.resolution}³ instead" if self.limited else f"trained {self.resolution}³"
        return (f"a {self.wanted}³ grid would need {self.needed / gib:.1f} GiB, {self.free / gib:.1f} GiB free "
                f"(at most {HEADROOM:.0%} of it is taken): {trained}")

    def describe(self) -> dict:
        """Plain JSON values for the fit report."""
        return {"wanted": self.wanted, "trained": self.resolution, "needed_bytes": self.needed,
                "free_bytes": self.free}


def choose_grid(field: SceneField, wanted: int, free: int | None) -> GridChoice:
    """The finest grid up to ``wanted`` that ``field`` can move to within :data:`HEADROOM` of ``free`` bytes:
    ``wanted`` itself where it fits (or ``free`` is ``None``), else the finest multiple of :data:`GRID_STEP`
    above the field's own grid that does, else the field's own. Each candidate is sized by the vertices
    :meth:`~pytest_n2r.field.grid.SceneField.upsampled` would store for it."""
    if wanted <= field.resolution:
        raise InvalidArgument(f"wanted={wanted!r}: expected a grid finer than the field's {field.resolution}³")
    width = field.values.shape[1]

    def needed(resolution: int) -> int:
        stored = int(used_vertex_mask(field.upsampled_occupancy(resolution)).sum())
        return stage_bytes(resolution, stored, width=width)

    wanted_bytes = needed(wanted)
    if free is None or wanted_bytes <= HEADROOM * free:
        return GridChoice(wanted, wanted, wanted_bytes, free)
    for resolution in range(GRID_STEP * ((wanted - 1) // GRID_STEP), field.resolution, -GRID_STEP):
        if needed(resolution) <= HEADROOM * free:
            return GridChoice(wanted, resolution, wanted_bytes, free)
    return GridChoice(wanted, field.resolution, wanted_bytes, free)


def _meminfo_available() -> int | None:
    try:
        for line in Path("/proc/meminfo").read_text().splitlines():
            if line.startswith("MemAvailable:"):
                return int(line.split()[1]) * 1024
    except (OSError, ValueError, IndexError):
        return None
    return None


def _cgroup_free() -> int | None:
    """The least headroom under this process's cgroup memory limits and their ancestors' (usage counted
    without the inactive file cache the kernel reclaims first, as ``docker stats`` does)."""
    try:
        lines = _PROC_CGROUP.read_text().splitlines()
    except OSError:
        return None
    free = []
    for line in lines:
        parts = line.split(":", 2)
        if len(parts) != 3:
            continue
        _, controllers, path = parts
        if controllers == "":
            base, limit_file, usage_file, cache_key = _CGROUP_ROOT, "memory.max", "memory.current", "inactive_file"
        elif "memory" in controllers.split(","):
            base, limit_file, usage_file, cache_key = (_CGROUP_ROOT / "memory", "memory.limit_in_bytes",
                                                       "memory.usage_in_bytes", "total_inactive_file")
        else:
            continue
        folder = base / path.lstrip("/")
        while folder != base.parent:
            limit, usage = _read_int(folder / limit_file), _read_int(folder / usage_file)
            if limit is not None and usage is not None:
                free.append(limit - usage + _stat_value(folder / "memory.stat", cache_key))
            folder = folder.parent
    return min(free) if free else None


def _read_int(path: Path) -> int | None:
    try:
        return int(path.read_text().strip())
    except (OSError, ValueError):
        return None  # absent, or "max": no limit


def _stat_value(path: Path, key: str) -> int:
    try:
        for line in path.read_text().splitlines():
            name, _, value = line.partition(" ")
            if name == key:
                return int(value)
    except (OSError, ValueError):
        pass
    return 0
