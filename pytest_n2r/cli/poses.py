"""``n2r poses SOURCE``: recover or read the camera poses of a capture, summarize, optionally save them."""

from __future__ import annotations

import argparse
import sys
import time
import warnings
from pathlib import Path
from typing import TYPE_CHECKING

from ._output import FORCE_HELP, as_text, printable

if TYPE_CHECKING:
    import numpy as np

    from ..data.poses import PoseSet

__all__ = ["add_parser", "run", "format_summary", "format_skipped", "format_upright", "format_frames",
           "format_warnings", "skipped_records", "add_frames_dir_argument", "check_frames_dir", "ANY_ROLL_HELP"]

#: ``--any-roll``, shared by ``n2r poses`` and ``n2r fit``.
ANY_ROLL_HELP = ("the photos were not all taken upright (looking straight down, or a camera that rolls, on a robot "
                 "arm or a drone): keep the photos structure from motion registers upside down against the others, "
                 "which are otherwise skipped as put half a turn wrong (see docs/ingestion.md)")


def add_parser(subparsers: argparse._SubParsersAction) -> None:
    p = subparsers.add_parser(
        "poses",
        help="camera poses of a capture (SfM on photos, or read a COLMAP model / transforms.json)",
        description=(
            "Read or recover the cameras and poses of SOURCE and print a summary: images, registered, "
            "skipped with reasons, intrinsics, scene bounds, reference length (median z-depth of the "
            "sparse points seen by the training cameras) and time taken. SOURCE is a folder of photos "
            "or a video (structure from motion with pycolmap), a COLMAP sparse model folder, or a "
            "transforms.json."
        ),
    )
    p.add_argument("source", metavar="SOURCE", help="images folder, video, COLMAP model folder or transforms.json")
    p.add_argument("-o", "--output", metavar="PATH", type=Path, default=None,
                   help="write the poses as a nerfstudio transforms.json (image file names kept)")
    p.add_argument("--max-size", metavar="PX", type=int, default=960,
                   help="longer image side for structure from motion, in pixels (default: 960)")
    p.add_argument("--matcher", choices=("auto", "exhaustive", "sequential"), default="auto",
                   help="feature matching for structure from motion: exhaustive up to 100 images with "
                        "'auto', sequential for ordered video frames (default: auto)")
    p.add_argument("--max-frames", metavar="N", type=int, default=120,
                   help="for a video: keep the sharpest frame of each of N equal windows (default: 120)")
    add_frames_dir_argument(p)
    p.add_argument("--any-roll", action="store_true", help=ANY_ROLL_HELP)
    p.add_argument("--compare", metavar="OTHER", default=None,
                   help="also load OTHER (any SOURCE kind) and print the pose errors of SOURCE against it, "
                        "image by image after a similarity alignment")
    p.add_argument("--force", action="store_true", help=FORCE_HELP)
    p.set_defaults(func=run)


def add_frames_dir_argument(parser: argparse.ArgumentParser) -> None:
    """``--frames-dir``, shared by ``n2r poses`` and ``n2r fit`` (checked by :func:`check_frames_dir`)."""
    parser.add_argument("--frames-dir", metavar="DIR", type=Path, default=None,
                        help="for a video: where to write its frames (default: <video stem>_frames beside it); a new "
                             "or empty folder, or one frames were extracted into before (with --force: any folder "
                             "named here)")


def forces_frames_dir(args: argparse.Namespace) -> bool:
    """Whether ``--force`` lets the video's frames be written among other files: only into a folder the user named
    with ``--frames-dir`` (``--force`` given to replace an output must not also write over files in the default
    ``<video stem>_frames`` folder)."""
    return bool(args.force and args.frames_dir is not None)


def check_frames_dir(frames_dir: Path | None, force: bool) -> None:
    """``--frames-dir``, checked before any work: a folder the video's frames may be written into."""
    from ..data.video import is_frames_dir
    from ._output import check_output_dir

    if frames_dir is not None:
        check_output_dir(frames_dir, is_frames_dir, "the video's frames", option="--frames-dir", force=force)


def run(args: argparse.Namespace) -> int:
    from ..data.ingest import complete_points, extent, load_poses
    from ..data.transforms_json import RATIONAL_MODEL_NOTE, camera_model_of, write_transforms_json
    from ..data.transforms_pixels import tagged_count
    from ._interrupt import sigterm_kept_from_pycolmap

    check_arguments(args)
    sigterm_kept_from_pycolmap()  # SIGTERM as Ctrl-C, also while structure from motion runs
    start = time.perf_counter()
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")  # every skipped file is listed in the summary below
        poses = load_poses(args.source, sfm_max_size=args.max_size, matcher=args.matcher,
                           max_frames=args.max_frames, frames_dir=args.frames_dir, upright=not args.any_roll,
                           force_frames_dir=forces_frames_dir(args))
        complete_points(poses)
    bounds, ref = extent(poses)
    total = time.perf_counter() - start
    print(printable(format_summary(poses, bounds, ref, total)))
    for line in format_warnings(poses.report, "poses"):
        print(printable(line), file=sys.stderr)
    if args.compare is not None:
        from ..data.compare import compare_poses

        with warnings.catch_warnings():
            warnings.simplefilter("ignore")
            other = load_poses(args.compare, sfm_max_size=args.max_size, matcher=args.matcher,
                               max_frames=args.max_frames, upright=not args.any_roll)
        print(printable(f"compare     against {other.source} ({other.kind}): {compare_poses(poses, other).summary()}"))
    if args.output is not None:
        # the photos not used ride in the n2r block, which nerfstudio and instant-ngp do not read (they read the keys
        # they know), so the file stays a plain transforms.json and the list cannot be separated from its poses
        extra = {"n2r": {"source": str(args.source), "reference_length": ref, "bounds": bounds.tolist(),
                         "note": "camera-to-world in OpenGL axes like every transforms.json",
                         "images": _listed(poses), "skipped": skipped_records(poses.skipped),
                         "warnings": list(poses.report.get("warnings", []))}}
        path = write_transforms_json(args.output, poses, extra=extra)
        print(f"wrote       {printable(path)} ({len(poses.frames)} frames)")
        if camera_model_of(poses) != "OPENCV":  # a lens only n2r reads back: say so where the file is named
            print(printable(f"n2r poses: warning: {path} has {RATIONAL_MODEL_NOTE}"), file=sys.stderr)
        turned = tagged_count([f.path for f in poses.frames if f.path is not None]) if poses.pixels == "upright" else 0
        if turned:  # upright cameras of photos another tool reads as stored
            print(printable(f"n2r poses: warning: {path} describes its photos upright ({turned} of them turned by an "
                            "EXIF tag or a HEIF rotation), as n2r reads them back; nerfstudio and instant-ngp read "
                            "the pixels as stored, so for them save the photos turned, the tag removed"),
                  file=sys.stderr)
    return 0


def check_arguments(args: argparse.Namespace) -> None:
    """The sources, numbers and output paths, checked before any structure from motion runs."""
    from ..errors import InvalidArgument
    from ._output import POSES_JSON, check_output

    for option, source in (("SOURCE", args.source), ("--compare", args.compare)):
        if source is not None and not Path(source).exists():
            raise InvalidArgument(f"{option} {source}: does not exist; expected a folder of photos, a video, "
                                  "a COLMAP model folder or a transforms.json")
    for option, value in (("--max-size", args.max_size), ("--max-frames", args.max_frames)):
        if value < 1:
            raise InvalidArgument(f"{option} {value}: expected an integer >= 1")
    if args.max_size < 64:
        raise InvalidArgument(f"--max-size {args.max_size}: structure from motion needs images of at least 64 "
                              "pixels on the longer side (default: 960)")
    sources = [Path(s) for s in (args.source, args.compare) if s is not None]
    sources += [p / "transforms.json" for p in sources if p.is_dir()]
    if args.output is not None:
        check_output(args.output, POSES_JSON, inputs=sources, force=args.force)
    check_frames_dir(args.frames_dir, args.force)


def format_skipped(skipped: list[tuple[str, str]]) -> list[str]:
    """Summary lines for the input images that were not used, ``(file, reason)`` each: every one of them (an
    unrelated photo among them is what the list is read for)."""
    return [f"  skipped   {r['file']}: {r['reason']}" for r in skipped_records(skipped)]


def skipped_records(skipped: list[tuple[str, str]]) -> list[dict[str, str]]:
    """The photos not used as JSON-ready records, ``{"file": ..., "reason": ...}`` each (what ``n2r poses -o`` and
    ``n2r fit``'s report keep). A file name that is not text (bytes no encoding decodes, which Python keeps as lone
    surrogates) is written with those bytes escaped (``\\xff``), so any terminal can print it back."""
    return [{"file": as_text(name), "reason": as_text(reason)} for name, reason in skipped]


def format_frames(report: dict) -> list[str]:
    """The line saying where a video's frames were written (none for other sources)."""
    if "frames_dir" not in report:
        return []
    count, video = report.get("video_frames", "?"), report.get("video", "the video")
    return [f"frames      {count} frames of {video} extracted to {report['frames_dir']}"]


def format_warnings(report: dict, command: str) -> list[str]:
    """``n2r COMMAND: warning: ...`` for each warning of the ingestion (``report["warnings"]``: structure from motion
    keeping only part of the photos, photos in subfolders not read)."""
    return [f"n2r {command}: warning: {text}" for text in report.get("warnings", [])]


def _listed(poses: PoseSet) -> int:
    """How many images the source listed or its folder held."""
    return poses.report.get("listed", poses.report.get("images", len(poses.frames) + len(poses.skipped)))


def format_upright(report: dict) -> list[str]:
    """The line saying whether structure from motion's photos agree on which way is up (none for given poses)."""
    from ..data.upright import upright_summary

    record = report.get("upright")
    return [f"upright     {upright_summary(record)}"] if record else []


def format_summary(poses: PoseSet, bounds: np.ndarray, ref: float, total_s: float) -> str:
    """The plain-text summary ``n2r poses`` prints (``bounds`` and ``ref`` in scene units, time in seconds)."""
    frames = poses.frames
    lines = [
        f"source      {poses.source} ({poses.kind})",
        *format_frames(poses.report),
        f"images      {_listed(poses)} found, {len(frames)} registered, {len(poses.skipped)} skipped",
    ]
    lines += format_skipped(poses.skipped) + format_upright(poses.report)
    cameras = list(dict.fromkeys(f.camera for f in frames))
    lines.append(f"cameras     {len(cameras)} (OpenCV pixel centres; COLMAP/nerfstudio cx = cx + 0.5)")
    for cam in cameras[:3]:
        dist = " ".join(f"{k}={v:.4g}"
                        for k, v in zip(("k1", "k2", "p1", "p2", "k3", "k4", "k5", "k6"), cam.distortion))
        lines.append(f"  {cam.width}x{cam.height} fx={cam.fx:.2f} fy={cam.fy:.2f} cx={cam.cx:.2f} cy={cam.cy:.2f}"
                     + (f" {dist}" if dist else " no distortion"))
    if len(cameras) > 3:
        lines.append(f"  ... and {len(cameras) - 3} more")
    lines.append(f"points      {len(poses.points)} ({poses.report.get('points_method', '')})")
    lo, hi = bounds
    lines.append("bounds      min (" + ", ".join(f"{v:.3f}" for v in lo) + ")  max ("
                 + ", ".join(f"{v:.3f}" for v in hi) + ") scene units")
    lines.append(f"reference   {ref:.4g} scene units (median z-depth of the points seen by the training cameras)")
    stages = ", ".join(f"{k} {v:.1f} s" for k, v in poses.report.get("time_s", {}).items())
    lines.append(f"time        {total_s:.1f} s ({stages})")
    return "\n".join(lines)
