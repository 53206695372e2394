"""Video files → a folder of still frames for structure from motion.

The video is cut into ``max_frames`` windows of equal length (in frames) and the **sharpest** frame of
each window is kept (variance of the Laplacian of a grey copy at most 480 px wide), so motion blur
is avoided without losing coverage. Frames are written losslessly as ``frame_<index>.png`` (index
in the video, zero-padded, so names sort in time order), each to a temporary name then renamed,
together with ``frames.json``, a manifest that lets a second call with the same video and settings
reuse them.

A frames folder is ours only when it holds that manifest: frames go into a missing or empty folder or
one of ours (unless ``force``), and of a folder of ours only the files its manifest lists are ever
deleted; the manifest is written before the first frame and lists each frame as it is written, so an
interrupted extraction leaves a folder that is still ours.

Convention
----------
Frames are written exactly as OpenCV decodes them (its container orientation handling applied);
read them back with :func:`pytest_n2r.data.images.read_image` to get RGB.
"""

from __future__ import annotations

import json
import os
import re
from pathlib import Path

import numpy as np

from ..errors import IngestError
from .atomic import atomic_write_bytes, atomic_write_text

__all__ = ["VIDEO_SUFFIXES", "is_video", "extract_frames", "default_frames_dir", "is_frames_dir"]

#: File suffixes treated as videos (compared lower-case).
VIDEO_SUFFIXES: tuple[str, ...] = (".mp4", ".mov", ".avi", ".mkv", ".webm", ".m4v")
_MANIFEST = "frames.json"
_FRAME_NAME = re.compile(r"frame_[0-9]+\.png")


def is_video(path: str | os.PathLike) -> bool:
    """Whether ``path`` is a file with a video suffix."""
    path = Path(path)
    return path.is_file() and path.suffix.lower() in VIDEO_SUFFIXES


def default_frames_dir(video: str | os.PathLike) -> Path:
    """Where frames of ``video`` go unless told otherwise: ``<stem>_frames`` beside the video."""
    video = Path(video)
    return video.with_name(f"{video.stem}_frames")


def _read_manifest(folder: Path) -> dict | None:
    """The manifest of an earlier extraction into ``folder``, or ``None`` when it holds none of ours."""
    try:
        saved = json.loads((folder / _MANIFEST).read_text(encoding="utf-8"))
    except (OSError, UnicodeDecodeError, ValueError, RecursionError):
        return None
    if not isinstance(saved, dict) or "video" not in saved or not isinstance(saved.get("frames"), list) \
            or not all(isinstance(n, str) and _FRAME_NAME.fullmatch(n) for n in saved["frames"]):
        return None
    return saved


def is_frames_dir(folder: str | os.PathLike) -> bool:
    """Whether ``folder`` holds the manifest of an earlier :func:`extract_frames`, so frames may be replaced there."""
    return _read_manifest(Path(folder)) is not None


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
    force: bool = False,
) -> list[Path]:
    """Write the sharpest frame of each of ``max_frames`` equal windows of ``video`` into ``frames_dir``.

    ``frames_dir`` defaults to :func:`default_frames_dir`. Frames already extracted there from the
    same video (same size and modification time) with the same ``max_frames`` are reused; other frames an
    earlier extraction left there are deleted first. Returns the frame files in time order. Raises
    :class:`IngestError` naming the video when it cannot be decoded or has fewer than 3 frames, and naming
    ``frames_dir`` when it cannot be written or holds other files and no manifest of ours (``force``: write
    among them, replacing files of the frames' names).
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
    saved = _read_manifest(out)
    if saved is not None and saved.get("complete") is True and {k: saved.get(k) for k in key} == key \
            and all((out / n).is_file() for n in saved["frames"]):
        return [out / n for n in saved["frames"]]

    cap = cv2.VideoCapture(str(video))
    if not cap.isOpened():
        raise IngestError(f"video file {str(video)!r} cannot be opened (unknown container or codec)")
    cap.release()
    total = _count_frames(video)
    if total < 3:
        raise IngestError(f"video file {str(video)!r} has {total} decodable frames; at least 3 are needed")
    if saved is None and not force and out.is_dir() and any(out.iterdir()):
        raise IngestError(
            f"frames folder {str(out)!r} holds other files and no {_MANIFEST} of an earlier extraction, so the "
            "video's frames would be written among them; expected a new or empty folder (or one frames were "
            "extracted into before): choose another with --frames-dir DIR (n2r poses, n2r fit; frames_dir= in "
            "Python), or write among them by naming this folder with --frames-dir and adding --force "
            "(force_frames_dir=True)")
    try:
        out.mkdir(parents=True, exist_ok=True)
        probe = out / ".n2r-write-test"
        probe.write_bytes(b"")
        probe.unlink()
    except OSError as exc:
        raise IngestError(
            f"cannot write video frames to {str(out)!r} ({exc.strerror}); pass a writable frames folder"
        ) from None
    for name in saved["frames"] if saved is not None else ():  # only what an earlier extraction wrote
        (out / name).unlink(missing_ok=True)

    windows = min(max_frames, total)
    edges = np.linspace(0, total, windows + 1).round().astype(int)
    width = len(str(total))
    names: list[str] = []

    def record(complete: bool) -> None:
        atomic_write_text(out / _MANIFEST, json.dumps({**key, "frames": names, "complete": complete}, indent=1) + "\n")

    record(False)  # the folder is ours from here on, whatever happens
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
            encoded, png = cv2.imencode(".png", best)
            if not encoded:
                raise IngestError(f"cannot encode frame {best_index} of {str(video)!r} as a PNG")
            atomic_write_bytes(out / name, png.tobytes())
            names.append(name)
            record(False)
    finally:
        cap.release()
    if len(names) < 3:
        raise IngestError(
            f"video file {str(video)!r}: only {len(names)} frames could be decoded; at least 3 are needed")
    record(True)
    return [out / n for n in names]
