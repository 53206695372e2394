"""Hypothesis strategies of the image mutations m1–m3 (:mod:`.mutation`).

Public functions validate their arguments eagerly and hand them to private composites whose ``repr`` is
the public call (``brightness(max_levels=30)``). The composites' float arguments have no defaults, so the
``repr`` always shows them (``noise_patch(max_size=0.5, min_size=0.0)``): a relation's description, which
keys its Hypothesis database entries and derandomized seed, must not change with how a caller spelled
the defaults. Every draw starts from "no change", so Hypothesis shrinks
toward the identity mutation: a failing example is reported as the smallest mutation that still breaks
the SUT.
"""

from __future__ import annotations

from collections.abc import Callable
from typing import Any

from hypothesis import strategies as st

from .._validation import check_int, check_range
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
    return Brightness(draw(st.integers(-max_levels, max_levels)))


@_composite("noise_patch")
def _noise_patch(draw: st.DrawFn, *, max_size: float, min_size: float) -> NoisePatch:
    size = draw(st.floats(min_size, max_size))
    return NoisePatch(size, draw(st.floats(0.0, 1.0)), draw(st.floats(0.0, 1.0)), draw(_seeds))


@_composite("black_patches")
def _black_patches(draw: st.DrawFn, *, max_size: float, count: int = 6) -> BlackPatches:
    return BlackPatches(draw(st.floats(0.0, max_size)), count, draw(_seeds))


@_composite("any_mutation")
def _any_mutation(
    draw: st.DrawFn, max_levels: int = 128, *, max_noise_size: float, max_patch_size: float,
) -> Mutation:
    return draw(st.one_of(
        _brightness(max_levels=max_levels), _noise_patch(max_size=max_noise_size, min_size=0.0),
        _black_patches(max_size=max_patch_size),
    ))


def brightness(max_levels: int = 128) -> st.SearchStrategy[Brightness]:
    """:class:`Brightness` with ``levels`` in ``[-max_levels, max_levels]``; shrinks toward ``levels=0``
    (integers shrink exactly: a failure is reported at the smallest offset that breaks the SUT)."""
    return _brightness(max_levels=check_int("max_levels", max_levels, 0, 255))


def noise_patch(max_size: float = 0.5, min_size: float = 0.0) -> st.SearchStrategy[NoisePatch]:
    """:class:`NoisePatch` with ``size`` in ``[min_size, max_size]``, any position and seed; shrinks toward
    ``size=min_size`` (no change when 0), the top-left position and seed 0."""
    max_size = check_range("max_size", max_size, 0.0, 1.0)
    return _noise_patch(max_size=max_size, min_size=check_range("min_size", min_size, 0.0, max_size))


def black_patches(max_size: float = 0.08, count: int = 6) -> st.SearchStrategy[BlackPatches]:
    """:class:`BlackPatches` of ``count`` patches with ``size`` in ``[0, max_size]`` and any seed; shrinks
    toward ``size=0`` (no change) and seed 0."""
    return _black_patches(max_size=check_range("max_size", max_size, 0.0, 1.0),
                          count=check_int("count", count, 0, MAX_COUNT))


def any_mutation(
    max_levels: int = 128, max_noise_size: float = 0.5, max_patch_size: float = 0.08,
) -> st.SearchStrategy[Mutation]:
    """One of m1, m2, m3 with the given bounds; shrinks toward ``Brightness(levels=0)`` (no change)."""
    return _any_mutation(
        max_levels=check_int("max_levels", max_levels, 0, 255),
        max_noise_size=check_range("max_noise_size", max_noise_size, 0.0, 1.0),
        max_patch_size=check_range("max_patch_size", max_patch_size, 0.0, 1.0),
    )
