"""When is a rendered follow-up view a fair test input? (Invalid ones are rejected, not failed.)

A scene field only knows what its training cameras saw. A follow-up view that looks past the captured
region shows empty space (low opacity) or surfaces no training camera saw (rendered from guesswork); a SUT
that disagrees there is not inconsistent, the input is. Two checks, both on the follow-up render:

- **empty**: the share of *empty* pixels (opacity below 0.5) may exceed the source view's by at most
  ``max_empty_increase``: a view that turns from the captured content to nothing is rejected, while a
  scene whose views always show some empty sky (an object in the open) is not;
- **coverage**: of the surface points the view sees (a grid of ``grid x grid`` pixels with opacity >= 0.5,
  back-projected with the rendered z-depth), at least ``min_coverage`` must project inside the image of
  at least one training camera, in front of it.
"""

from __future__ import annotations

import functools
import hashlib
import json
import weakref
from collections.abc import Sequence
from dataclasses import asdict, dataclass

import numpy as np

from .._validation import check_int, check_range
from ..geometry import CameraStack, backproject
from ..render.view import RenderedView
from ..scene.base import Scene, SceneView

__all__ = ["Validity", "Verdict", "too_many_invalid_so_far"]

#: Give up on a relation once this many draws were invalid and, with 99 % confidence, more than ``max_rejected``
#: of all draws will be (:func:`too_many_invalid_so_far`, :meth:`~pytest_n2r.relation.engine.Engine.count`).
_MIN_REJECTED_TO_GIVE_UP = 40
_GIVE_UP_CONFIDENCE = 0.99

#: A verdict's reason when the view passed.
VALID = "valid"
#: Part of every :meth:`Validity.verdict_key`: bump it when the checks' arithmetic changes, so that verdicts a
#: render cache kept from the old checks are not served.
CHECKS_VERSION = "1"


@dataclass(frozen=True)
class Verdict:
    """Whether a view is valid; if not, ``reason`` is ``"empty view"`` or ``"outside the captured
    region"`` and ``detail`` gives the numbers."""

    valid: bool
    reason: str = VALID
    detail: str = ""

    def to_dict(self) -> dict:
        return asdict(self)

    @classmethod
    def from_dict(cls, data: dict) -> Verdict:
        return cls(bool(data["valid"]), str(data["reason"]), str(data["detail"]))


@dataclass(frozen=True)
class Validity:
    """Thresholds of the validity checks: fractions in [0, 1] and the ``grid`` size (an int in [2, 256]).

    ``max_empty_increase=1`` disables the empty-view check and ``min_coverage=0`` the coverage check."""

    max_empty_increase: float = 0.1
    min_coverage: float = 0.8
    grid: int = 16
    #: Fail the relation (a usage error, not an inconsistency) when more than this fraction of the draws
    #: were invalid: the transform bounds leave the captured region. 0 is the strictest (no invalid draw
    #: allowed); 1 allows any share, but a relation with no valid example at all still fails: it compared
    #: nothing.
    max_rejected: float = 0.9

    def __post_init__(self) -> None:
        for name in ("max_empty_increase", "min_coverage", "max_rejected"):
            check_range(name, getattr(self, name), 0.0, 1.0)
        check_int("grid", self.grid, 2, 256)

    @property
    def outputs(self) -> tuple[str, ...]:
        """The render outputs the checks need (of the follow-up view; the source needs ``opacity``)."""
        if self.min_coverage > 0:
            return ("depth", "opacity")
        return ("opacity",) if self.max_empty_increase < 1 else ()

    def check(self, view: RenderedView, scene: Scene, source: RenderedView | None = None,
              cameras: Sequence[SceneView] | None = None) -> Verdict:
        """Judge a rendered follow-up ``view`` of ``scene`` (rendered with :attr:`outputs`) against its
        ``source`` view (rendered with ``opacity``; without it, the source counts as full). ``cameras`` are
        the views the field was fitted on (default: the scene's training views, or all of them)."""
        if not self.outputs:
            return Verdict(True)
        view.require(*self.outputs)
        assert view.opacity is not None, "every check needs opacity: require raised without it"
        empty = float((view.opacity < 0.5).mean())
        before = float((source.opacity < 0.5).mean()) if source is not None and source.opacity is not None else 0.0
        if empty - before > self.max_empty_increase:
            return Verdict(False, "empty view",
                           f"{empty:.0%} of the pixels are empty (opacity < 0.5), {before:.0%} in the source view "
                           f"(at most {self.max_empty_increase:.0%} more allowed)")
        if self.min_coverage <= 0:
            return Verdict(True)
        coverage = self.coverage(view, scene, cameras)
        if coverage < self.min_coverage:
            return Verdict(False, "outside the captured region",
                           f"{coverage:.0%} of the visible surface was seen by a training camera "
                           f"(min {self.min_coverage:.0%})")
        return Verdict(True)

    def verdict_key(self, scene: Scene, source_key: str, follow_key: str) -> str | None:
        """Hex SHA-256 naming the verdict of :meth:`check` on the follow-up render ``follow_key`` of the source
        render ``source_key`` (render keys: scene content, renderer, camera, pose) against ``scene``'s training
        cameras (not part of a scene's content hash), with these thresholds and :data:`CHECKS_VERSION`: a
        render cache keeps the verdict under it (:meth:`~pytest_n2r.scene.render_cache.RenderCache.decision`).
        ``None`` for a subclass: its own checks are code no key names (an edited check kept passing on a warm
        cache what it rejects on an empty one), so its verdicts are not kept between runs."""
        if type(self) is not Validity:
            return None
        spec = f"{self._checks}|{_training_digest(scene)}|{source_key}|{follow_key}"
        return hashlib.sha256(spec.encode()).hexdigest()

    @functools.cached_property
    def _checks(self) -> str:
        """:data:`CHECKS_VERSION` and the thresholds, as they name a verdict (:meth:`verdict_key`)."""
        return json.dumps({"checks": CHECKS_VERSION, "thresholds": asdict(self)}, sort_keys=True)

    def coverage(self, view: RenderedView, scene: Scene, cameras: Sequence[SceneView] | None = None) -> float:
        """Fraction of the view's sampled surface points inside some training camera's image (``cameras``,
        default: the scene's :func:`training_views`), all cameras projected in one array operation."""
        view.require("depth", "opacity")
        assert view.depth is not None and view.opacity is not None, "require raised without them"
        cam = view.camera
        us = np.linspace(0, cam.width - 1, self.grid)
        vs = np.linspace(0, cam.height - 1, self.grid)
        uv = np.stack(np.meshgrid(us, vs), axis=-1).reshape(-1, 2)
        iu, iv = np.round(uv[:, 0]).astype(int), np.round(uv[:, 1]).astype(int)
        solid = view.opacity[iv, iu] >= 0.5
        if not solid.any():
            return 0.0
        points = backproject(uv[solid], view.depth[iv, iu][solid].astype(np.float64), cam, view.c2w)
        stack = training_stack(scene) if cameras is None else _stack_of(cameras)
        return float(stack.sees(points).any(axis=0).mean())


_STACKS: weakref.WeakKeyDictionary[Scene, tuple[object, CameraStack, str]] = weakref.WeakKeyDictionary()


def training_stack(scene: Scene) -> CameraStack:
    """The :class:`CameraStack` of a scene's :func:`training_views`, built once per scene (and again when
    its ``views`` are replaced)."""
    return _training(scene)[1]


def _training_digest(scene: Scene) -> str:
    """Hex SHA-256 of the bytes of :func:`training_stack` (poses, intrinsics, sizes)."""
    return _training(scene)[2]


def _training(scene: Scene) -> tuple[object, CameraStack, str]:
    known = _STACKS.get(scene)
    if known is None or known[0] is not scene.views:
        stack = _stack_of(training_views(scene))
        digest = hashlib.sha256()
        for array in (stack.w2c, stack.intrinsics, stack.size):
            digest.update(np.ascontiguousarray(array, dtype="<f8").tobytes())
        known = _STACKS[scene] = (scene.views, stack, digest.hexdigest())
    return known


def _stack_of(views: Sequence[SceneView]) -> CameraStack:
    return CameraStack.of([v.camera for v in views], [v.c2w for v in views])


def training_views(scene: Scene) -> list[SceneView]:
    """The views a scene was fitted on (every view when it has no train split, as exact scenes)."""
    train = [v for v in scene.views if v.split == "train"]
    return train or list(scene.views)


def too_many_invalid_so_far(rejected: int, drawn: int, limit: float) -> bool:
    """Whether ``rejected`` invalid draws of ``drawn`` show, with 99 % confidence (a one-sided Clopper-Pearson
    bound), that more than ``limit`` of all draws will be invalid; never before 40 rejections.

    >>> too_many_invalid_so_far(44, 44, 0.9), too_many_invalid_so_far(43, 44, 0.9)
    (True, False)
    """
    if rejected < _MIN_REJECTED_TO_GIVE_UP or limit >= 1.0:
        return False
    from scipy.stats import beta

    return float(beta.ppf(1.0 - _GIVE_UP_CONFIDENCE, rejected, drawn - rejected + 1)) > limit
