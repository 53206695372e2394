"""Hypothesis strategies of the image mutations m1–m3 (:mod:`.mutation`).

Public functions validate their arguments eagerly and hand them to private composites whose ``repr`` is
the public call (``brightness(max_levels=30)``). The composites' float arguments have no defaults, so the
``repr`` always shows them (``noise_patch(max_size=0.5, min_size=0.0)``): a relation's description, which
keys its Hypothesis database entries and derandomized seed, must not change with how a caller spelled
the defaults. No draw is "no change" (it would compare a view with itself, a test that cannot fail):
Hypothesis shrinks toward the smallest change, so a failing example is reported as the smallest mutation
that still breaks the SUT. Patch sizes are drawn on a decimal grid (:func:`~.grid.draw_moved`, as pose
changes are), so a size shrinks step by step to within one grid step of the smallest failing size.
"""

from __future__ import annotations

from collections.abc import Callable
from typing import Any

from hypothesis import strategies as st

from .._validation import check_int, check_positive, check_range
from .grid import draw_axis, draw_moved
from .mutation import MAX_COUNT, MAX_SEED, BlackPatches, Brightness, Mutation, NoisePatch

__all__ = ["brightness", "noise_patch", "black_patches", "any_mutation"]

_seeds = st.integers(0, MAX_SEED)


def _composite(name: str) -> Callable[[Callable[..., Any]], Callable[..., st.SearchStrategy]]:
    """``st.composite`` under the public ``name``, so the strategy's ``repr`` reads as the public call."""

    def wrap(impl: Callable[..., Any]) -> Callable[..., st.SearchStrategy]:
        impl.__name__ = impl.__qualname__ = name
        return st.composite(impl)

    return wrap


@_composite("brightness")
def _brightness(draw: st.DrawFn, max_levels: int = 128) -> Brightness:
    levels = draw(st.integers(1, max_levels))  # never 0: shrinks to ±1 grey level
    return Brightness(-levels if draw(st.booleans()) else levels)


@_composite("noise_patch")
def _noise_patch(draw: st.DrawFn, *, max_size: float, min_size: float) -> NoisePatch:
    size = (draw_moved if min_size == 0 else draw_axis)(draw, min_size, max_size)  # a patch of size 0 changes nothing
    return NoisePatch(size, draw(st.floats(0.0, 1.0)), draw(st.floats(0.0, 1.0)), draw(_seeds))


@_composite("black_patches")
def _black_patches(draw: st.DrawFn, *, max_size: float, count: int = 6) -> BlackPatches:
    return BlackPatches(draw_moved(draw, 0.0, max_size), count, draw(_seeds))


@_composite("any_mutation")
def _any_mutation(
    draw: st.DrawFn, max_levels: int = 128, *, max_noise_size: float, max_patch_size: float,
) -> Mutation:
    return draw(st.one_of(
        _brightness(max_levels=max_levels), _noise_patch(max_size=max_noise_size, min_size=0.0),
        _black_patches(max_size=max_patch_size),
    ))


def brightness(max_levels: int = 128) -> st.SearchStrategy[Brightness]:
    """:class:`Brightness` with ``levels`` in ``[-max_levels, max_levels]``, never 0; shrinks toward ``levels=1``
    (integers shrink exactly: a failure is reported at the smallest offset that breaks the SUT)."""
    return _brightness(max_levels=check_int("max_levels", max_levels, 1, 255))


def noise_patch(max_size: float = 0.5, min_size: float = 0.0) -> st.SearchStrategy[NoisePatch]:
    """:class:`NoisePatch` with ``size`` in ``[min_size, max_size]`` (never 0), any position and seed; shrinks
    toward ``size=min_size`` (one grid step above it when it is 0) on a grid of at least 2000 steps, the top-left
    position and seed 0."""
    max_size = check_range("max_size", check_positive("max_size", max_size), 0.0, 1.0)
    return _noise_patch(max_size=max_size, min_size=check_range("min_size", min_size, 0.0, max_size))


def black_patches(max_size: float = 0.08, count: int = 6) -> st.SearchStrategy[BlackPatches]:
    """:class:`BlackPatches` of ``count`` patches with ``size`` in ``(0, max_size]`` and any seed; shrinks
    toward one grid step (of at least 2000 across the bound) and seed 0."""
    return _black_patches(max_size=check_range("max_size", check_positive("max_size", max_size), 0.0, 1.0),
                          count=check_int("count", count, 1, MAX_COUNT))


def any_mutation(
    max_levels: int = 128, max_noise_size: float = 0.5, max_patch_size: float = 0.08,
) -> st.SearchStrategy[Mutation]:
    """One of m1, m2, m3 with the given bounds, never a mutation that changes nothing; shrinks toward
    ``Brightness(levels=1)``."""
    return _any_mutation(
        max_levels=check_int("max_levels", max_levels, 1, 255),
        max_noise_size=check_range("max_noise_size", check_positive("max_noise_size", max_noise_size), 0.0, 1.0),
        max_patch_size=check_range("max_patch_size", check_positive("max_patch_size", max_patch_size), 0.0, 1.0),
    )
