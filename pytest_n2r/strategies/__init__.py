"""Hypothesis strategies for metamorphic tests: pose transforms τ, the paper's presets τ1–τ6, image
mutations m1–m3 and source views.

Convention
----------
- Transforms are :class:`~pytest_n2r.geometry.Transform` values applied in the **source camera's frame**
  (``c2w_tau = c2w @ T(tau)``, design.md §2): angles in **degrees**, translations in ``units``
  (reference lengths by default, so one bound means the same on every scene).
- Mutations (:mod:`.mutation`) change the source render's pixels at the same pose.
- Every strategy shrinks toward the identity (no motion, no change): a failing example is reported as
  the smallest follow-up that still breaks the system under test.

Modules: :mod:`.grid` (bounded numbers on a decimal grid), :mod:`.pose_strategies` (``transforms``),
:mod:`.presets` (τ1–τ6), :mod:`.mutation` (the mutations), :mod:`.mutation_strategies` (their
strategies), :mod:`.view_strategies` (``views``).
"""

from __future__ import annotations

from ..geometry.look_at import look_at_compensation
from .mutation import BlackPatches, Brightness, Mutation, NoisePatch, mutation_from_dict
from .mutation_strategies import any_mutation, black_patches, brightness, noise_patch
from .pose_strategies import transform_units, transforms
from .presets import PRESETS, tau1, tau2, tau3, tau4, tau5, tau6
from .view_strategies import ViewPick, views

__all__ = [
    "transforms", "views", "ViewPick", "look_at_compensation", "PRESETS",
    "tau1", "tau2", "tau3", "tau4", "tau5", "tau6", "transform_units",
    "Mutation", "Brightness", "NoisePatch", "BlackPatches", "mutation_from_dict",
    "brightness", "noise_patch", "black_patches", "any_mutation",
]
