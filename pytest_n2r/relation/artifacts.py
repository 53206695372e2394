"""Failure pictures: the source and follow-up renders with the SUT's output drawn on them, as PNGs.

What is drawn depends on the output: keypoints (an ``(N, 2+)`` array or ``cv2.KeyPoint`` list) as
circles, a class (an int, a string, or a 1-D score vector whose argmax is the top-1 class) as text.
Anything else is saved undecorated. Files are written atomically (temporary name, then rename).

A run of a test id that ends without failure pictures (it passed, or failed without saving any) removes
those an earlier run left for that id (:func:`remove_pictures`), so the folder shows only current failures.
"""

from __future__ import annotations

import hashlib
import re
from contextlib import suppress
from pathlib import Path
from typing import Any

import numpy as np

from ..data.atomic import atomic_write_bytes

__all__ = ["draw_output", "save_png", "save_pair", "artifact_dir", "remove_pictures", "PICTURE_NAMES"]

_GREEN, _RED = (40, 220, 40), (235, 50, 50)  # RGB

#: The files :func:`save_pair` writes in a test's folder, by role.
PICTURE_NAMES = {"source": "source.png", "follow": "follow.png", "source_raw": "source-raw.png",
                 "follow_raw": "follow-raw.png"}


def artifact_dir(root: str | Path, test_id: str) -> Path:
    """``root/<test id made filename-safe, at most 150 characters>-<8 hex digits of its SHA-256>``
    (``test_a.py::test_b[fox]`` → ``test_a.py-test_b-fox-b2d5e930``): readable, and one folder per test id,
    also for ids that differ only in punctuation or after 150 characters.

    >>> artifact_dir("n2r-artifacts", "test_a.py::test_b[fox]").as_posix()
    'n2r-artifacts/test_a.py-test_b-fox-b2d5e930'
    """
    safe = re.sub(r"[^A-Za-z0-9_.-]+", "-", test_id).strip("-")[:150].rstrip("-") or "relation"
    return Path(root) / f"{safe}-{hashlib.sha256(test_id.encode()).hexdigest()[:8]}"


def _keypoints(output: Any) -> np.ndarray | None:
    if isinstance(output, (list, tuple)) and output and all(hasattr(k, "pt") for k in output):
        return np.array([k.pt for k in output], dtype=np.float64)
    if isinstance(output, np.ndarray) and output.ndim == 2 and output.shape[1] >= 2 and output.dtype.kind in "fiu":
        return output[:, :2].astype(np.float64)
    return None


def _label(output: Any) -> str | None:
    if isinstance(output, (str, int, np.integer)) and not isinstance(output, bool):
        return f"class {output}"
    if isinstance(output, np.ndarray) and output.ndim == 1 and output.size > 1 and output.dtype.kind in "fiu":
        top = int(np.argmax(output))
        return f"top-1: {top} ({float(output[top]):.3g})"
    return None


def draw_output(rgb: np.ndarray, output: Any, color: tuple[int, int, int] = _GREEN) -> np.ndarray:
    """A copy of ``rgb`` (H×W×3 uint8 RGB) with ``output`` drawn on it (see the module docstring)."""
    import cv2

    canvas = np.ascontiguousarray(rgb, dtype=np.uint8).copy()
    radius = max(2, round(max(canvas.shape[:2]) / 160))
    points = _keypoints(output)
    text: str | None
    if points is not None:
        for u, v in points[np.isfinite(points).all(axis=1)]:
            cv2.circle(canvas, (int(round(u)), int(round(v))), radius, color, 1, cv2.LINE_AA)
        text = f"{len(points)} keypoints"
    else:
        text = _label(output)
    if text:
        scale = max(0.35, canvas.shape[1] / 900)
        org = (4, int(18 * scale / 0.5))
        cv2.putText(canvas, text, org, cv2.FONT_HERSHEY_SIMPLEX, scale, (0, 0, 0), 3, cv2.LINE_AA)
        cv2.putText(canvas, text, org, cv2.FONT_HERSHEY_SIMPLEX, scale, color, 1, cv2.LINE_AA)
    return canvas


def save_png(path: str | Path, rgb: np.ndarray) -> Path:
    """Write an H×W×3 uint8 RGB image as PNG, atomically."""
    import cv2

    ok, data = cv2.imencode(".png", cv2.cvtColor(np.ascontiguousarray(rgb), cv2.COLOR_RGB2BGR))
    if not ok:  # pragma: no cover - OpenCV fails to encode only on impossible shapes
        raise ValueError(f"could not encode an image of shape {np.shape(rgb)} as PNG")
    return atomic_write_bytes(path, data.tobytes())


def save_pair(directory: str | Path, source_rgb: np.ndarray, follow_rgb: np.ndarray,
              out_source: Any, out_follow: Any) -> dict[str, str]:
    """Save the renders the SUT saw and the same with its outputs drawn; returns ``{role: path}``."""
    directory, names = Path(directory), PICTURE_NAMES
    return {
        "source": str(save_png(directory / names["source"], draw_output(source_rgb, out_source, _GREEN))),
        "follow": str(save_png(directory / names["follow"], draw_output(follow_rgb, out_follow, _RED))),
        "source_raw": str(save_png(directory / names["source_raw"], source_rgb)),
        "follow_raw": str(save_png(directory / names["follow_raw"], follow_rgb)),
    }


def remove_pictures(root: str | Path, test_id: str) -> list[Path]:
    """Remove the failure pictures an earlier run left for ``test_id`` in the artifacts folder ``root``;
    returns the files removed.

    Only what :func:`save_pair` writes goes: the regular files named in :data:`PICTURE_NAMES` in
    :func:`artifact_dir` of ``test_id``, then that folder itself if it is empty. Any other
    file (the user's notes, a symbolic link), a folder that is a symbolic link (it may lead out of
    ``root``), and ``root`` itself stay. Best effort: a file that cannot be removed (a read-only folder)
    stays without an error, since a passing test must not fail over a stale picture.
    """
    folder = artifact_dir(root, test_id)
    removed: list[Path] = []
    with suppress(OSError):  # is_dir and is_file raise on a folder the user may not read
        if folder.is_symlink() or not folder.is_dir():
            return removed
        for path in (folder / name for name in PICTURE_NAMES.values()):
            if path.is_file() and not path.is_symlink():
                with suppress(OSError):
                    path.unlink()
                    removed.append(path)
        folder.rmdir()  # only when empty: else an OSError, and the folder stays
    return removed
