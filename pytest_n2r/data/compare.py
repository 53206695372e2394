"""Compare two pose sets of the same photos, image by image, after a similarity alignment.

Two reconstructions of one scene differ by an arbitrary similarity (SfM fixes no origin, orientation
or scale). The camera centres of the images both sets hold are aligned with Umeyama's least-squares
similarity (set *a* onto set *b*); then, per image, the rotation error is the angle between the
aligned camera orientation of *a* and that of *b* (degrees), and the centre error is the distance
between the aligned centre of *a* and the centre of *b*, as a fraction of the **camera spread** of *b*
(the RMS distance of its centres from their mean).
"""

from __future__ import annotations

from dataclasses import dataclass
from pathlib import PurePosixPath

import numpy as np

from ..errors import IngestError
from ..geometry import apply_similarity_to_pose, rotation_angle_deg, umeyama
from .poses import PoseSet

__all__ = ["PoseComparison", "compare_poses"]


@dataclass(frozen=True, eq=False)
class PoseComparison:
    """Per-image errors of pose set *a* against *b* (see the module docstring).

    ``names`` are the images both hold (names of *b*); ``rotation_deg`` and ``centre_error`` (a
    fraction of the camera spread) follow their order; ``scale`` is the similarity's scale (units of *b*
    per unit of *a*); ``only_a`` and ``only_b`` list the images one set holds and the other does not.
    """

    names: list[str]
    rotation_deg: np.ndarray
    centre_error: np.ndarray
    scale: float
    spread: float
    only_a: list[str]
    only_b: list[str]

    def summary(self) -> str:
        """One line: counts, max and median rotation error (degrees) and centre error (% of spread)."""
        r, c = self.rotation_deg, self.centre_error * 100
        return (
            f"{len(self.names)} common images: rotation error max {r.max():.3f} deg, median {np.median(r):.3f} deg; "
            f"centre error max {c.max():.3f} %, median {np.median(c):.3f} % of the camera spread "
            f"(scale {self.scale:.4g}; {len(self.only_a)} only in a, {len(self.only_b)} only in b)"
        )


def _key(name: str) -> str:
    return PurePosixPath(name.replace("\\", "/")).name


def compare_poses(a: PoseSet, b: PoseSet) -> PoseComparison:
    """Align ``a`` onto ``b`` by their common images' centres and measure per-image pose errors.

    Images are matched by file name (``images/0001.jpg`` in a transforms.json matches ``0001.jpg`` in a
    COLMAP model or an SfM run). Raises :class:`IngestError` when fewer than 3 images are common or the
    common centres are collinear.
    """
    frames_a = {_key(f.name): f for f in a.frames}
    frames_b = {_key(f.name): f for f in b.frames}
    common = [k for k in frames_b if k in frames_a]
    if len(common) < 3:
        raise IngestError(
            f"only {len(common)} images are in both pose sets ({a.source!r} and {b.source!r}); "
            "at least 3 are needed to align them"
        )
    src = np.array([frames_a[k].c2w[:3, 3] for k in common])
    dst = np.array([frames_b[k].c2w[:3, 3] for k in common])
    try:
        s, R, t = umeyama(src, dst)
    except ValueError as exc:
        raise IngestError(f"cannot align the pose sets: {exc}") from None
    aligned = [apply_similarity_to_pose(frames_a[k].c2w, s, R, t) for k in common]
    rot = np.array([rotation_angle_deg(m[:3, :3], frames_b[k].c2w[:3, :3]) for m, k in zip(aligned, common)])
    spread = float(np.sqrt(np.mean(np.sum((dst - dst.mean(0)) ** 2, axis=1))))
    centre = np.array([np.linalg.norm(m[:3, 3] - frames_b[k].c2w[:3, 3]) for m, k in zip(aligned, common)]) / spread
    return PoseComparison(
        names=[frames_b[k].name for k in common], rotation_deg=rot, centre_error=centre, scale=s, spread=spread,
        only_a=sorted(frames_a[k].name for k in frames_a if k not in frames_b),
        only_b=sorted(frames_b[k].name for k in frames_b if k not in frames_a),
    )
