"""Hypothesis strategies behind :mod:`pytest_n2r.mutations` (arguments already validated there).

They are composites so that a strategy's ``repr`` is its public call (``brightness(max_levels=30)``).
Every draw starts from "no change" so Hypothesis shrinks toward the identity mutation.
"""

from __future__ import annotations

import hypothesis.strategies as st

from .mutations import _MAX_SEED, BlackPatches, Brightness, Mutation, NoisePatch

_seeds = st.integers(0, _MAX_SEED)


@st.composite
def brightness(draw: st.DrawFn, max_levels: int = 128) -> Brightness:
    return Brightness(draw(st.integers(-max_levels, max_levels)))


@st.composite
def noise_patch(draw: st.DrawFn, max_size: float = 0.5, min_size: float = 0.0) -> NoisePatch:
    size = draw(st.floats(min_size, max_size))
    return NoisePatch(size, draw(st.floats(0.0, 1.0)), draw(st.floats(0.0, 1.0)), draw(_seeds))


@st.composite
def black_patches(draw: st.DrawFn, max_size: float = 0.08, count: int = 6) -> BlackPatches:
    return BlackPatches(draw(st.floats(0.0, max_size)), count, draw(_seeds))


@st.composite
def any_mutation(
    draw: st.DrawFn, max_levels: int = 128, max_noise_size: float = 0.5, max_patch_size: float = 0.08,
) -> Mutation:
    return draw(st.one_of(
        brightness(max_levels=max_levels), noise_patch(max_size=max_noise_size),
        black_patches(max_size=max_patch_size),
    ))
