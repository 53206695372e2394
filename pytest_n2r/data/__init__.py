"""Scene ingestion: images folders, COLMAP models and transforms.json into a :class:`Capture`."""

from .capture import Capture, CapturedView, heldout_split
from .ingest import ingest, load_poses, source_kind
from .poses import PoseSet, SourceFrame
from .transforms_json import read_transforms_json, write_transforms_json

__all__ = [
    "Capture", "CapturedView", "heldout_split", "ingest", "load_poses", "source_kind", "PoseSet", "SourceFrame",
    "read_transforms_json", "write_transforms_json",
]
