"""The size a relation renders at: ``"480x270"`` (a box: the view's aspect ratio is kept) or ``"480"`` (longer
side)."""

from __future__ import annotations

import math
import re
from dataclasses import dataclass

from .._validation import check_int
from ..errors import InvalidArgument, InvalidType
from ..geometry import Camera

__all__ = ["MAX_SIDE", "MIN_SIDE", "RenderSize"]

#: The largest image side (pixels) a render is asked for, and a scene file's camera may have.
MAX_SIDE = 16384
#: The smallest side (pixels) a render size may give: below it no SUT sees anything (OpenCV's ORB, SIFT and AKAZE
#: fail inside OpenCV on a 2 x 1 render, reported as the SUT's error), and such a number is a slip (``2`` for ``2x``).
MIN_SIDE = 16


@dataclass(frozen=True)
class RenderSize:
    """A render size: ``width`` and ``height`` in pixels, or only ``longer`` (the longer side). The camera's aspect
    ratio is always kept: ``width`` x ``height`` is exact for a view of that aspect (to a pixel), and a view of
    another (a portrait photo at ``320x180``, a 4:3 one) renders at the largest size of its own aspect that fits
    in the box: stretching it would hand the SUT a picture no camera took. Intrinsics are rescaled with the
    pixel-centre rule of docs/conventions.md ("Pixels: centres at integer coordinates", resizing). Each side given is
    an int in [:data:`MIN_SIDE`, :data:`MAX_SIDE`]; a width alone (``RenderSize(480)``) is refused: the longer side
    is ``RenderSize(longer=480)``."""

    width: int | None = None
    height: int | None = None
    longer: int | None = None

    def __post_init__(self) -> None:
        given = tuple(getattr(self, label) is not None for label in ("width", "height", "longer"))
        if given not in ((True, True, False), (False, False, True)):
            raise InvalidArgument(f"{self!r} is not a render size; expected a width and a height (a box), or only "
                                  "longer (the longer side): e.g. RenderSize(480, 270), RenderSize(longer=480) or "
                                  "RenderSize.parse('480')")
        for label in ("width", "height", "longer"):
            if getattr(self, label) is not None:
                check_int(f"RenderSize {label}", getattr(self, label), MIN_SIDE, MAX_SIDE)

    @classmethod
    def parse(cls, value: RenderSize | str | int | tuple[int, int], name: str = "size") -> RenderSize:
        """``"480x270"``, ``(480, 270)``, ``"480"`` or ``480`` → a size; anything else names ``name``."""
        if isinstance(value, RenderSize):
            return value
        if isinstance(value, bool):
            raise InvalidType(f"{name}={value!r} must be 'WxH', a pair (W, H) or an int (longer side)")
        if isinstance(value, int):
            width = height = None
            longer = value
        elif isinstance(value, tuple) and len(value) == 2 and all(isinstance(v, int) for v in value):
            (width, height), longer = value, None
        elif isinstance(value, str) and (m := re.fullmatch(r"\s*(\d+)\s*(?:[xX×]\s*(\d+))?\s*", value)):
            if m.group(2) is None:
                width, height, longer = None, None, int(m.group(1))
            else:
                width, height, longer = int(m.group(1)), int(m.group(2)), None
        else:
            raise InvalidArgument(
                f"{name}={value!r} is not a render size; expected 'WxH' (e.g. '480x270'), a pair (W, H) "
                "or an int for the longer side"
            )
        for label, v in (("width", width), ("height", height), ("longer side", longer)):
            if v is not None and not MIN_SIDE <= v <= MAX_SIDE:
                raise InvalidArgument(f"{name}={value!r}: {label} {v} must be in [{MIN_SIDE}, {MAX_SIDE}] pixels")
        return cls(width, height, longer)

    def apply(self, camera: Camera) -> Camera:
        """``camera`` resized to this size, its aspect ratio kept (see the class).

        >>> RenderSize.parse("320x180").apply(Camera(1920, 1080, 1500.0, 1500.0, 959.5, 539.5)).size
        (320, 180)
        >>> RenderSize.parse("320x180").apply(Camera(1080, 1920, 1500.0, 1500.0, 539.5, 959.5)).size
        (101, 180)

        A view so elongated that its shorter side would fall below :data:`MIN_SIDE` at this size is refused:

        >>> RenderSize.parse("16").apply(Camera(4000, 300, 3000.0, 3000.0, 1999.5, 149.5))
        Traceback (most recent call last):
        ...
        pytest_n2r.errors.InvalidArgument: a 4000x300 view at render size 16 is 16x1 pixels; a side below 16 \
pixels is no picture (OpenCV's detectors fail inside OpenCV on it); expected a larger render size (at least 207 \
for this view)
        """
        if self.longer is not None:
            fitted = camera.scaled(self.longer / max(camera.width, camera.height))
        else:
            width, height = self._box()
            fitted = camera.scaled(min(width / camera.width, height / camera.height))
            if abs(fitted.width - width) <= 1 and abs(fitted.height - height) <= 1:
                fitted = camera.resized(width, height)  # the same aspect, to a pixel: exactly the box
        if min(fitted.width, fitted.height) < MIN_SIDE:
            raise InvalidArgument(
                f"a {camera.width}x{camera.height} view at render size {self} is {fitted.width}x{fitted.height} "
                f"pixels; a side below {MIN_SIDE} pixels is no picture (OpenCV's detectors fail inside OpenCV on it); "
                f"expected a larger render size ({self._larger_for(camera)} for this view)")
        return fitted

    def _larger_for(self, camera: Camera) -> str:
        """A size of this form whose render of ``camera`` has no side below :data:`MIN_SIDE`, as text: the smallest
        longer side, or a box of this one's aspect grown until its fit reaches :data:`MIN_SIDE`."""
        need = MIN_SIDE / min(camera.width, camera.height)  # the scale that gives the shorter side MIN_SIDE
        if self.longer is not None:
            longer = max(camera.width, camera.height)
            side = max(1, math.floor((MIN_SIDE - 0.5) / min(camera.width, camera.height) * longer) - 1)
            while side < MAX_SIDE and min(camera.scaled(side / longer).size) < MIN_SIDE:  # Camera.scaled rounds
                side += 1
            return f"at least {side}"
        # the box scales the view by min(W / width, H / height): both ratios must reach ``need``
        width, height = self._box()
        grow = max(need * camera.width / width, need * camera.height / height, 1.0)
        return f"e.g. {math.ceil(width * grow)}x{math.ceil(height * grow)}"

    def _box(self) -> tuple[int, int]:
        """``(width, height)`` of a box size (one without ``longer``: :meth:`__post_init__` holds both set)."""
        assert self.width is not None and self.height is not None, "a box size has a width and a height"
        return self.width, self.height

    def __str__(self) -> str:
        return f"{self.width}x{self.height}" if self.longer is None else f"{self.longer}"
