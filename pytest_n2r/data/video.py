"""Video files → a folder of still frames for structure from motion.

The video is cut into ``max_frames`` windows of equal length (in frames) and the **sharpest** frame of
each window is kept (variance of the Laplacian of a grey copy at most 480 px wide), so motion blur
is avoided without losing coverage. Frames are written losslessly as ``frame_<index>.png`` (index
in the video, zero-padded, so names sort in time order) together with ``frames.json``, a manifest
that lets a second call with the same video and settings reuse them.

Convention
----------
Frames are written exactly as OpenCV decodes them (its container orientation handling applied);
read them back with :func:`pytest_n2r.data.images.read_image` to get RGB.
"""

from __future__ import annotations

import json
import os
from pathlib import Path

import numpy as np

from ..errors import IngestError
from .atomic import atomic_write_text

__all__ = ["VIDEO_SUFFIXES", "is_video", "extract_frames", "default_frames_dir"]

#: File suffixes treated as videos (compared lower-case).
VIDEO_SUFFIXES: tuple[str, ...] = (".mp4", ".mov", ".avi", ".mkv", ".webm", ".m4v")
_MANIFEST = "frames.json"


def is_video(path: str | os.PathLike) -> bool:
    """Whether ``path`` is a file with a video suffix."""
    path = Path(path)
    return path.is_file() and path.suffix.lower() in VIDEO_SUFFIXES


def default_frames_dir(video: str | os.PathLike) -> Path:
    """Where frames of ``video`` go unless told otherwise: ``<stem>_frames`` beside the video."""
    video = Path(video)
    return video.with_name(f"{video.stem}_frames")


def _sharpness(frame: np.ndarray) -> float:
    import cv2

    gray = cv2.cvtColor(frame, cv2.COLOR_BGR2GRAY) if frame.ndim == 3 else frame
    if gray.shape[1] > 480:
        scale = 480 / gray.shape[1]
        gray = cv2.resize(gray, (480, max(1, round(gray.shape[0] * scale))), interpolation=cv2.INTER_AREA)
    return float(cv2.Laplacian(gray, cv2.CV_64F).var())


def _count_frames(video: Path) -> int:
    import cv2

    cap = cv2.VideoCapture(str(video))
    count = 0
    try:
        while cap.grab():
            count += 1
    finally:
        cap.release()
    return count


def extract_frames(
    video: str | os.PathLike, frames_dir: str | os.PathLike | None = None, *, max_frames: int = 120,
) -> list[Path]:
    """Write the sharpest frame of each of ``max_frames`` equal windows of ``video`` into ``frames_dir``.

    ``frames_dir`` defaults to :func:`default_frames_dir`. Frames already extracted there from the
    same video (same size and modification time) with the same ``max_frames`` are reused. Returns
    the frame files in time order. Raises :class:`IngestError` naming the video when it cannot be
    decoded or has fewer than 3 frames, and naming ``frames_dir`` when it cannot be written.
    """
    import cv2

    video = Path(video)
    if isinstance(max_frames, bool) or not isinstance(max_frames, int) or max_frames < 3:
        raise IngestError(f"max_frames={max_frames!r} must be an int >= 3")
    if not video.is_file():
        raise IngestError(f"video file {str(video)!r} does not exist")
    out = Path(frames_dir) if frames_dir is not None else default_frames_dir(video)
    stat = video.stat()
    key = {"video": video.name, "bytes": stat.st_size, "mtime_ns": stat.st_mtime_ns, "max_frames": max_frames}
    manifest = out / _MANIFEST
    if manifest.is_file():
        try:
            saved = json.loads(manifest.read_text())
        except (OSError, json.JSONDecodeError):
            saved = {}
        if {k: saved.get(k) for k in key} == key and all((out / n).is_file() for n in saved.get("frames", [])):
            return [out / n for n in saved["frames"]]

    cap = cv2.VideoCapture(str(video))
    if not cap.isOpened():
        raise IngestError(f"video file {str(video)!r} cannot be opened (unknown container or codec)")
    cap.release()
    total = _count_frames(video)
    if total < 3:
        raise IngestError(f"video file {str(video)!r} has {total} decodable frames; at least 3 are needed")
    try:
        out.mkdir(parents=True, exist_ok=True)
        probe = out / ".n2r-write-test"
        probe.write_bytes(b"")
        probe.unlink()
    except OSError as exc:
        raise IngestError(
            f"cannot write video frames to {str(out)!r} ({exc.strerror}); pass a writable frames folder"
        ) from None
    for old in out.glob("frame_*.png"):
        old.unlink()

    windows = min(max_frames, total)
    edges = np.linspace(0, total, windows + 1).round().astype(int)
    width = len(str(total))
    names: list[str] = []
    cap = cv2.VideoCapture(str(video))
    try:
        for w in range(windows):
            best, best_score, best_index = None, -1.0, -1
            for index in range(edges[w], edges[w + 1]):
                ok, frame = cap.read()
                if not ok:
                    break
                score = _sharpness(frame)
                if score > best_score:
                    best, best_score, best_index = frame, score, index
            if best is None:
                break
            name = f"frame_{best_index:0{width}d}.png"
            if not cv2.imwrite(str(out / name), best):
                raise IngestError(f"cannot write frame {str(out / name)!r}")
            names.append(name)
    finally:
        cap.release()
    if len(names) < 3:
        raise IngestError(
            f"video file {str(video)!r}: only {len(names)} frames could be decoded; at least 3 are needed")
    atomic_write_text(manifest, json.dumps({**key, "frames": names}, indent=1) + "\n")
    return [out / n for n in names]
