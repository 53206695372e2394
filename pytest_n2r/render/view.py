"""The result of rendering a scene at one pose."""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from ..geometry import Camera

__all__ = ["RenderedView", "OUTPUTS"]

#: Every output a scene can render; ask only for what you need (each costs time and memory).
OUTPUTS = ("rgb", "depth", "opacity")


@dataclass(frozen=True, eq=False)
class RenderedView:
    """A rendered view: only the outputs asked for are set, the others are ``None``.

    - ``rgb``: H×W×3 ``uint8``, **RGB** order (convert before handing to OpenCV functions that expect BGR).
    - ``depth``: H×W ``float32`` **z-depth** (along the optical axis) in scene units: of a field, the depth
      of the ray's compositing weight (its weighted mean). Where ``opacity`` is ~0 the scene has nothing and
      depth is not to be trusted: read it only with ``opacity``. Where ``opacity`` is 0 depth is a placeholder
      that differs by kind of scene: a field's ray's far bound, an exact demo scene's ``far`` (30 or 60, nearer
      than its surfaces to a camera further away), a splat scene's 0.
    - ``opacity``: H×W ``float32`` in [0, 1], the accumulated weight along the ray.
    - ``camera`` and ``c2w`` (camera-to-world 4x4, OpenCV axes): the view's geometry, so metrics can
      map pixels between two views.
    """

    camera: Camera
    c2w: np.ndarray
    rgb: np.ndarray | None = None
    depth: np.ndarray | None = None
    opacity: np.ndarray | None = None

    def __post_init__(self) -> None:
        c2w = np.asarray(self.c2w)
        if c2w.shape != (4, 4) or not np.issubdtype(c2w.dtype, np.number) or not np.all(np.isfinite(c2w)):
            from ..errors import InvalidArgument

            what = f"of shape {c2w.shape}" if c2w.shape != (4, 4) else "with values that are not finite numbers"
            raise InvalidArgument(f"RenderedView c2w {what}; expected the view's 4x4 camera-to-world pose of finite "
                                  "numbers (OpenCV axes)")

    def require(self, *outputs: str, name: str = "this view") -> None:
        """Raise a clear error, naming the view ``name``, if an output a metric needs was not rendered."""
        missing = [o for o in outputs if getattr(self, o) is None]
        if missing:
            from ..errors import InvalidArgument

            raise InvalidArgument(
                f"{name} was rendered without {', '.join(missing)}; expected a view rendered with outputs including "
                f"{tuple(outputs)!r}"
            )

    def output(self, output: str, name: str = "this view") -> np.ndarray:
        """The rendered ``output`` (``"rgb"``, ``"depth"`` or ``"opacity"``); the error of :meth:`require`, naming the
        view ``name``, if it was not rendered."""
        self.require(output, name=name)
        return getattr(self, output)
