"""Scene ingestion: images folders, COLMAP models and transforms.json into a :class:`Capture`."""

from .capture import Capture, CapturedView, heldout_split

__all__ = ["Capture", "CapturedView", "heldout_split"]
