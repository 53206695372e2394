"""Reproducible draws of the study's transforms τ1–τ6 and mutations m1–m3.

The study characterizes SUTs, so it samples each family **uniformly** within its bounds from a seeded
``numpy.random.Generator`` (Hypothesis's draws, made to find and shrink failures, favour boundaries).
The τ families are the presets of :mod:`pytest_n2r.strategies.presets`, drawn by the same
:class:`~pytest_n2r.strategies.pose_strategies.PoseChangeFamily` as the plugin's strategies (same bounds,
same look-at compensation), uniformly.

Mutation families (the paper gives no parameters; these are ours, stated here):

- m1 brightness: ±13 to ±77 grey levels (5 % to 30 % of full scale), sign drawn at random;
- m2 one noise patch: 20 % to 50 % of the width and height, anywhere in the image;
- m3 six black patches: 3 % to 8 % of the width and height each.
"""

from __future__ import annotations

import numpy as np

from ..strategies.mutation import BlackPatches, Brightness, Mutation, NoisePatch
from ..strategies.pose_change import PoseChange
from ..strategies.presets import PRESET_FAMILIES

__all__ = ["TRANSFORM_FAMILIES", "MUTATION_FAMILIES", "sample_transform", "sample_mutation"]

TRANSFORM_FAMILIES = ("tau1", "tau2", "tau3", "tau4", "tau5", "tau6")
MUTATION_FAMILIES = ("m1", "m2", "m3")


def sample_transform(family: str, rng: np.random.Generator) -> PoseChange:
    """A pose change drawn uniformly within the bounds of preset ``family`` (``"tau1"`` … ``"tau6"``)."""
    return PRESET_FAMILIES[family].sample(rng)


def sample_mutation(family: str, rng: np.random.Generator) -> Mutation:
    """A mutation of family ``family`` (``"m1"``, ``"m2"``, ``"m3"``) with parameters drawn from ``rng``."""
    seed = int(rng.integers(0, 2**32 - 1))
    if family == "m1":
        return Brightness(int(rng.choice([-1, 1]) * rng.integers(13, 78)))
    if family == "m2":
        return NoisePatch(float(rng.uniform(0.2, 0.5)), float(rng.random()), float(rng.random()), seed)
    if family == "m3":
        return BlackPatches(float(rng.uniform(0.03, 0.08)), 6, seed)
    raise KeyError(f"unknown mutation family {family!r}; expected one of {MUTATION_FAMILIES}")
