"""Scene ingestion: image folders, videos, COLMAP models and transforms.json into a :class:`Capture`."""

from .capture import Capture, CapturedView, heldout_split
from .colmap import read_colmap_model, write_colmap_text
from .compare import PoseComparison, compare_poses
from .exposure import ExposureSpread, measure_exposure
from .ingest import complete_points, extent, ingest, load_poses, source_kind
from .poses import PoseSet, SourceFrame
from .sfm import run_sfm
from .transforms_json import read_transforms_json, write_transforms_json
from .upright import UprightCheck, check_upright
from .video import extract_frames

__all__ = [
    "Capture", "CapturedView", "heldout_split", "ingest", "load_poses", "complete_points", "extent",
    "source_kind", "PoseSet", "SourceFrame", "read_transforms_json", "write_transforms_json",
    "read_colmap_model", "write_colmap_text", "run_sfm", "extract_frames", "compare_poses", "PoseComparison",
    "measure_exposure", "ExposureSpread", "check_upright", "UprightCheck",
]
