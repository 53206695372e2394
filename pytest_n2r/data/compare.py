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


def _parts(name: str) -> tuple[str, ...]:
    """A frame name's path components (``./`` aside, either slash)."""
    return PurePosixPath(name.replace("\\", "/")).parts


def _by_tail(names: dict[str, tuple[str, ...]], depth: int) -> dict[tuple[str, ...], list[str]]:
    """The names whose path has at least ``depth`` components, by their last ``depth`` components."""
    found: dict[tuple[str, ...], list[str]] = {}
    for name, parts in names.items():
        if len(parts) >= depth:
            found.setdefault(parts[-depth:], []).append(name)
    return found


def _pair_names(a: list[str], b: list[str]) -> list[tuple[str, str]]:
    """``(name in a, name in b)`` of the images both sets hold: matched on their whole path first, then on ever
    shorter trailing paths down to the file name, each only where it names one image on both sides
    (``images/cam0/0000.jpg`` matches ``cam0/0000.jpg``). A file name left on both sides that several images share
    is an :class:`IngestError` naming them."""
    left, right = {n: _parts(n) for n in a}, {n: _parts(n) for n in b}
    pairs = []
    for depth in range(max(map(len, [*left.values(), *right.values()]), default=0), 0, -1):
        tails_a, tails_b = _by_tail(left, depth), _by_tail(right, depth)
        for tail in tails_a.keys() & tails_b.keys():
            if len(tails_a[tail]) == len(tails_b[tail]) == 1:
                pairs.append((tails_a[tail][0], tails_b[tail][0]))
                del left[tails_a[tail][0]], right[tails_b[tail][0]]
    tails_a, tails_b = _by_tail(left, 1), _by_tail(right, 1)
    ambiguous = sorted(n for tail in tails_a.keys() & tails_b.keys() for n in tails_a[tail] + tails_b[tail])
    if ambiguous:
        more = f" and {len(ambiguous) - 6} more" if len(ambiguous) > 6 else ""
        raise IngestError(f"cannot tell which image is which: {', '.join(ambiguous[:6])}{more} share file names, and "
                          "their folders do not tell them apart between the two pose sets; expected names that match "
                          "on their path below each source's folder (cam0/0000.jpg and cam1/0000.jpg on both sides)")
    return pairs


def compare_poses(a: PoseSet, b: PoseSet) -> PoseComparison:
    """Align ``a`` onto ``b`` by their common images' centres and measure per-image pose errors.

    Images are matched by their path, then by as much of its end as tells them apart (``images/0001.jpg`` in a
    transforms.json matches ``0001.jpg`` in a COLMAP model or an SfM run; ``images/cam0/0000.jpg`` matches
    ``cam0/0000.jpg``, never ``cam1/0000.jpg``). Raises :class:`IngestError` when fewer than 3 images are common, a
    file name several images share cannot be told apart, or the common centres are collinear.
    """
    frames_a = {f.name: f for f in a.frames}
    frames_b = {f.name: f for f in b.frames}
    order = {name: k for k, name in enumerate(frames_b)}
    pairs = sorted(_pair_names(list(frames_a), list(frames_b)), key=lambda pair: order[pair[1]])
    if len(pairs) < 3:
        raise IngestError(
            f"only {len(pairs)} images are in both pose sets ({a.source!r} and {b.source!r}); "
            "at least 3 are needed to align them"
        )
    src = np.array([frames_a[ka].c2w[:3, 3] for ka, _ in pairs])
    dst = np.array([frames_b[kb].c2w[:3, 3] for _, kb in pairs])
    try:
        s, R, t = umeyama(src, dst)
    except ValueError as exc:
        raise IngestError(f"cannot align the pose sets: {exc}") from None
    aligned = [apply_similarity_to_pose(frames_a[ka].c2w, s, R, t) for ka, _ in pairs]
    truth = [frames_b[kb].c2w for _, kb in pairs]
    rot = np.array([rotation_angle_deg(m[:3, :3], c[:3, :3]) for m, c in zip(aligned, truth)])
    spread = float(np.sqrt(np.mean(np.sum((dst - dst.mean(0)) ** 2, axis=1))))
    centre = np.array([np.linalg.norm(m[:3, 3] - c[:3, 3]) for m, c in zip(aligned, truth)]) / spread
    paired_a, paired_b = {ka for ka, _ in pairs}, {kb for _, kb in pairs}
    return PoseComparison(
        names=[kb for _, kb in pairs], rotation_deg=rot, centre_error=centre, scale=s, spread=spread,
        only_a=sorted(set(frames_a) - paired_a), only_b=sorted(set(frames_b) - paired_b),
    )
