"""What ingestion produces: a captured scene as views with cameras, poses and images."""

from __future__ import annotations

from collections.abc import Collection, Sequence
from dataclasses import dataclass, field
from typing import Literal

import numpy as np

from ..errors import InvalidArgument
from ..geometry import Camera

__all__ = ["CapturedView", "Capture", "HELDOUT_EVERY", "heldout_split", "split_frames"]

Split = Literal["train", "heldout"]


@dataclass(frozen=True, eq=False)
class CapturedView:
    """One captured image with its camera and pose.

    ``camera`` is the ideal pinhole camera of ``image`` (distortion already removed, at the loaded
    resolution); ``c2w`` is camera-to-world 4x4 float64 with OpenCV axes; ``image`` is H×W×3 uint8 RGB
    or ``None`` when images were not loaded.
    """

    name: str
    camera: Camera
    c2w: np.ndarray
    split: Split = "train"
    image: np.ndarray | None = None


@dataclass(eq=False)
class Capture:
    """A captured scene ready for fitting.

    Attributes
    ----------
    views:
        The registered views, in capture order (sorted by file name for image folders).
    points:
        ``(N, 3)`` float64 sparse surface points in world (scene) units: SfM points, or points
        triangulated from the given poses. May be empty.
    bounds:
        ``(2, 3)`` float64 axis-aligned box ``[min, max]`` of the region the cameras observe (scene units).
    reference_length:
        The median z-depth of ``points`` seen from the training cameras (scene units): the unit of transform
        translations in the public API.
    source:
        Where the capture came from (path, as given).
    skipped:
        ``(file, reason)`` for every input image that was not used (missing, unreadable, not registered).
    report:
        Timings and counts for ``n2r poses`` (plain JSON-ready values).
    """

    views: list[CapturedView]
    points: np.ndarray
    bounds: np.ndarray
    reference_length: float
    source: str = ""
    skipped: list[tuple[str, str]] = field(default_factory=list)
    report: dict = field(default_factory=dict)

    @property
    def train_views(self) -> list[CapturedView]:
        return [v for v in self.views if v.split == "train"]

    @property
    def heldout_views(self) -> list[CapturedView]:
        return [v for v in self.views if v.split == "heldout"]


#: The NeRF custom's default: every 8th image (0, 8, 16, ...) is held out.
HELDOUT_EVERY = 8


def heldout_split(n: int, every: int = HELDOUT_EVERY, first: int = 0) -> list[Split]:
    """The NeRF custom: every ``every``-th image from ``first`` (0, 8, 16, ... by default) is held out, the
    rest train.

    >>> heldout_split(10)
    ['heldout', 'train', 'train', 'train', 'train', 'train', 'train', 'train', 'heldout', 'train']
    >>> heldout_split(10, first=4)
    ['train', 'train', 'train', 'train', 'heldout', 'train', 'train', 'train', 'train', 'train']
    """
    if not 0 <= first < max(every, 1):
        raise InvalidArgument(f"first={first!r}: expected an index in [0, every={every})")
    return ["heldout" if every > 0 and i % every == first else "train" for i in range(n)]


def split_frames(names: Sequence[str], heldout: Collection[str] | None, heldout_every: int | None) -> list[Split]:
    """The split of frames named ``names`` (in order): the source's own split (``heldout``: the names it holds
    out) when ``heldout_every`` is ``None`` and the source has one, else every ``heldout_every``-th frame held out
    (:func:`heldout_split`; :data:`HELDOUT_EVERY` when ``None``, 0 holds none).

    >>> split_frames(["a", "b", "c"], {"b"}, None), split_frames(["a", "b", "c"], {"b"}, 2)
    (['train', 'heldout', 'train'], ['heldout', 'train', 'heldout'])
    """
    if heldout_every is None and heldout is not None:
        return ["heldout" if name in heldout else "train" for name in names]
    return heldout_split(len(names), HELDOUT_EVERY if heldout_every is None else heldout_every)
