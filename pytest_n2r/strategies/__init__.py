"""Follow-ups and the Hypothesis strategies that draw them: pose changes τ (and the paper's presets
τ1–τ6), image mutations m1–m3, and source views.

Convention
----------
- A follow-up (:class:`FollowUp`, :mod:`.follow_up`) turns a source view into the follow-up view: a
  :class:`PoseChange` moves the camera (a :class:`~pytest_n2r.geometry.Transform` applied in the **source
  camera's frame**, ``c2w_tau = c2w @ T(tau)``, angles in **degrees**, carrying the ``units`` of its
  translation: reference lengths by default, so one bound means the same on every scene); a
  :class:`Mutation` changes the source render's pixels at the same pose.
- Every strategy shrinks toward the smallest follow-up (the smallest motion: a drawn pose change is never
  the identity; no change for a mutation): a failing example is reported as the smallest follow-up that
  still breaks the system under test.

Modules: :mod:`.follow_up` (the protocol), :mod:`.pose_change`, :mod:`.mutation` (the follow-ups),
:mod:`.grid` (bounded numbers on a decimal grid), :mod:`.pose_strategies` (``transforms``, pose-change
families), :mod:`.presets` (τ1–τ6), :mod:`.mutation_strategies`, :mod:`.view_strategies` (``views``).
"""

from __future__ import annotations

from ..geometry.look_at import look_at_compensation
from .follow_up import FollowUp
from .mutation import BlackPatches, Brightness, Mutation, NoisePatch, mutation_from_dict
from .mutation_strategies import any_mutation, black_patches, brightness, noise_patch
from .pose_change import PoseChange, as_follow_up
from .pose_strategies import PoseChangeFamily, transforms
from .presets import PRESET_FAMILIES, PRESETS, tau1, tau2, tau3, tau4, tau5, tau6
from .view_strategies import ViewPick, views

__all__ = [
    "FollowUp", "PoseChange", "as_follow_up", "PoseChangeFamily",
    "transforms", "views", "ViewPick", "look_at_compensation", "PRESETS", "PRESET_FAMILIES",
    "tau1", "tau2", "tau3", "tau4", "tau5", "tau6",
    "Mutation", "Brightness", "NoisePatch", "BlackPatches", "mutation_from_dict",
    "brightness", "noise_patch", "black_patches", "any_mutation",
]
