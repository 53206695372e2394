"""What a fit holds in memory, and the finest grid it can move to: the bytes a grid stage takes at its peak
(:func:`stage_bytes`) and the finest grid that fits in the memory free (:func:`choose_grid`, with
:func:`~pytest_n2r.fit.free_memory.free_bytes`).

A fit stores only the vertices of its occupied cells (a sparse field, :mod:`pytest_n2r.field.grid`), so its
memory follows the surfaces the field has formed, not the cube. A field that has not formed yet has no such
bound: a 30-step fit of the fox with the 40-minute config (nothing pruned yet) moved a field that still
occupied every cell to 384³ and was killed by the kernel at 24 GB (docs/scene-field-log.md, "A fit killed for
memory"). So each move to a finer grid is sized by the vertices that grid will actually store, against the
memory free at that moment; where the wanted grid does not fit in :data:`HEADROOM` of it, the fit trains the
finest coarser one that does, or stays on its grid, and says so (``report["grid_limits"]``, ``n2r info``).

Convention
----------
Bytes; grid sizes in vertices per axis (``R``: ``R³`` vertices, ``(R - 1)³`` cells); ``width``: float32 values
a stored vertex holds (``1 + 3·(sh_degree + 1)²``: 4, 13 or 28).
"""

from __future__ import annotations

import math
from dataclasses import dataclass

from ..errors import InvalidArgument
from ..field.config import FieldConfig
from ..field.grid import SceneField, used_vertex_mask

__all__ = ["GRID_STEP", "HEADROOM", "GridChoice", "GridMemoryLimit", "byte_count", "choose_grid", "fit_memory_bytes",
           "memory_resolution", "stage_bytes"]

#: The share of the free memory a new grid may take: the rest is for what :func:`stage_bytes` leaves out (the
#: upsampling's chunk, about 150 MB at SH degree 2, and its 3 bytes a fine cell; a step's samples; the end's
#: renderer, about 40 bytes a stored vertex) and for other processes.
HEADROOM = 0.8
#: A grid that does not fit is replaced by the finest multiple of this below it that does.
GRID_STEP = 16


def byte_count(n: float) -> str:
    """``n`` bytes for a message: in GiB from 1 GiB, MiB from 1 MiB, KiB from 1 KiB, bytes below.

    >>> byte_count(30743256953), byte_count(1552437657), byte_count(100_000), byte_count(512)
    ('28.6 GiB', '1.4 GiB', '97.7 KiB', '512 bytes')
    """
    for unit, size in (("GiB", 2**30), ("MiB", 2**20), ("KiB", 2**10)):
        if n >= size:
            return f"{n / size:.1f} {unit}"
    return f"{int(n)} bytes"


class GridMemoryLimit(UserWarning):
    """A fit trained a coarser grid than its ladder's, or stayed on its grid, because the finer one would not
    fit in the memory free (the fit report's ``grid_limits`` says which, at which step)."""


def stage_bytes(resolution: int, stored: int, *, width: int = 13) -> int:
    """The bytes a fit holds at its peak on a grid of ``resolution``³ that stores ``stored`` vertices.

    Held throughout: the row map (int32 a vertex); the occupancy, the training visibility and the march grid's
    copy of the cells (a byte, a float32 and a byte a cell); and for each stored vertex its ``width`` float32
    values with Adam's two moments, its flat index and its step's row index (int64 each) and its six neighbours
    for the prior (int32 each, :func:`~pytest_n2r.fit.prior.tv_neighbours`). On top, at its moments: a
    checkpoint's copy of the field (:meth:`~pytest_n2r.field.grid.SceneField.quantized`: values, flat index,
    row map, occupancy) or the compaction after the first prune (the kept rows' values and indices built while
    the old ones live), each at most ``4·width + 40`` bytes a stored vertex and a row map.

    >>> round(stage_bytes(384, 384 ** 3, width=28) / 2**30, 1)  # every vertex of a 384³ grid at SH degree 2
    28.6
    """
    if isinstance(resolution, bool) or not isinstance(resolution, int) or resolution < 2:
        raise InvalidArgument(f"resolution={resolution!r}: expected vertices per axis >= 2")
    if isinstance(stored, bool) or not isinstance(stored, int) or not 0 <= stored <= resolution ** 3:
        raise InvalidArgument(f"stored={stored!r}: expected a vertex count in 0..{resolution ** 3}")
    if isinstance(width, bool) or not isinstance(width, int) or width < 1:
        raise InvalidArgument(f"width={width!r}: expected float32 values a vertex >= 1")
    held = 4 * resolution ** 3 + 6 * (resolution - 1) ** 3 + stored * (3 * 4 * width + 8 + 8 + 6 * 4)
    transient = 4 * resolution ** 3 + (resolution - 1) ** 3 + stored * (4 * width + 40)
    return int(held + transient)


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
    800
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
        free = "free memory unknown" if self.free is None else f"{byte_count(self.free)} free"
        trained = f"trained {self.resolution}³ instead" if self.limited else f"trained {self.resolution}³"
        return (f"a {self.wanted}³ grid would need {byte_count(self.needed)}, {free} (at most {HEADROOM:.0%} of it "
                f"is taken): {trained}")

    def describe(self) -> dict:
        """Plain JSON values for the fit report."""
        return {"wanted": self.wanted, "trained": self.resolution, "needed_bytes": self.needed,
                "free_bytes": self.free}


def choose_grid(field: SceneField, wanted: int, free: int | None) -> GridChoice:
    """The finest grid up to ``wanted`` that ``field`` can move to within :data:`HEADROOM` of ``free`` bytes:
    ``wanted`` itself where it fits (or ``free`` is ``None``), else the finest multiple of :data:`GRID_STEP`
    above the field's own grid that does, else the field's own. A candidate is sized by the vertices
    :meth:`~pytest_n2r.field.grid.SceneField.upsampled` would store for it, counted only where storing them all
    would not fit (counting takes 3 bytes a fine cell)."""
    if wanted < field.resolution:
        raise InvalidArgument(f"wanted={wanted!r}: expected a grid no coarser than the field's {field.resolution}³")
    width = field.values.shape[1]
    room = None if free is None else HEADROOM * free

    def needed(resolution: int) -> int:
        everything = stage_bytes(resolution, resolution ** 3, width=width)
        if room is None or everything <= room:
            return everything  # unchecked, or fits even with every vertex stored: not worth counting them
        stored = int(used_vertex_mask(field.upsampled_occupancy(resolution)).sum())
        return stage_bytes(resolution, stored, width=width)

    wanted_bytes = needed(wanted)
    if room is None or wanted_bytes <= room:
        return GridChoice(wanted, wanted, wanted_bytes, free)
    for resolution in range(GRID_STEP * ((wanted - 1) // GRID_STEP), field.resolution, -GRID_STEP):
        if needed(resolution) <= room:
            return GridChoice(wanted, resolution, wanted_bytes, free)
    return GridChoice(wanted, field.resolution, wanted_bytes, free)
