"""Whether a capture's photos agree on which way is up: the check that catches a photo structure from motion put
half a turn wrong.

A photo read upright (its orientation applied, :mod:`.images`) shows the world's up at its top, within the tilt of
a hand: people hold a phone upright, and the phone records how it was turned. So in a right reconstruction the
photos' up axes, carried into the world by their poses, point nearly the same way, whatever frame and scale
structure from motion chose (the fox's 50 photos: all within 31° of their consensus). On symmetric or repeated
structure (a brick wall, a van's two sides) structure from motion can register a photo half a turn about its
viewing direction; its up axis then points down, against the others (161–180° on the demo wall's phone capture,
``benchmarks/capture_poses.py sfm``). A photo whose up lies more than :data:`UPSIDE_DOWN_DEG` from the consensus
is *upside down against the others*.

What it cannot see: a photo put half a turn wrong about the world's vertical (the object's far side put on its
near side) keeps its up; and which side is right when the photos split evenly.

Convention
----------
Poses are camera-to-world with OpenCV axes (x right, y down, z forward), so a photo's up in the world is
``-c2w[:3, 1]``. The consensus up is the principal axis of the photos' up axes (the eigenvector of ``Σ u uᵀ``
with the largest eigenvalue), signed to agree with most of them.
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass

import numpy as np

from ..errors import InvalidArgument

__all__ = ["UPSIDE_DOWN_DEG", "UPSIDE_DOWN_SHARE", "UprightCheck", "check_upright", "upright_summary"]

#: A photo's up this many degrees or more from the consensus is upside down against the others. Measured
#: (``benchmarks/capture_poses.py sfm --size 320 480 960 --runs 2``, 6 December, and the fox): right photos lie
#: within 31° (the fox, real, orbiting and looking down at its subject) and 36° (the demo captures, even where
#: their reconstruction was poor); a photo looking straight down has its up on the horizon, 90°, whichever way the
#: phone guessed its turn; every photo past the threshold was one the truth puts half a turn wrong (51 of 51).
#: 120° leaves 30° of margin above a nadir photo.
UPSIDE_DOWN_DEG = 120.0
#: More than this share of the photos upside down and the reconstruction as a whole is doubtful, not a few photos
#: in it. Measured on the demo wall's phone capture: 2 of 48 upside down (4 %) beside 44–45 within 1.5–3.8°
#: (median) of the truth; 23 of 48 (48 %) beside a half whose centres were off by 93 % of the camera spread.
UPSIDE_DOWN_SHARE = 0.25


@dataclass(frozen=True)
class UprightCheck:
    """Each photo's up axis against the consensus: ``names``, ``up`` (unit, world frame) and ``angles_deg``."""

    names: tuple[str, ...]
    up: np.ndarray
    angles_deg: np.ndarray

    @property
    def upside_down(self) -> tuple[str, ...]:
        """The photos whose up lies :data:`UPSIDE_DOWN_DEG` or more from the consensus, by name."""
        return tuple(n for n, a in zip(self.names, self.angles_deg) if a >= UPSIDE_DOWN_DEG)

    def as_report(self) -> dict:
        """A JSON-ready record: photos compared, the threshold, the largest angle of the others, the upside-down
        photos with their angles (degrees)."""
        turned = set(self.upside_down)
        rest = [float(a) for n, a in zip(self.names, self.angles_deg) if n not in turned]
        return {"photos": len(self.names), "threshold_deg": UPSIDE_DOWN_DEG,
                "largest_upright_deg": round(max(rest), 1) if rest else None,
                "upside_down": {n: round(float(a), 1) for n, a in zip(self.names, self.angles_deg) if n in turned}}

    def summary(self) -> str:
        """One line: how many photos agree on up, and which do not (:func:`upright_summary`)."""
        return upright_summary(self.as_report())


def upright_summary(record: dict) -> str:
    """One line from a check's record (:meth:`UprightCheck.as_report`, as a report stores it).

    >>> upright_summary({"photos": 4, "largest_upright_deg": 0.0, "upside_down": {"d": 180.0}})
    '1 of 4 photos upside down against the others (d 180°; the others within 0°)'
    """
    if not record["upside_down"]:
        return f"{record['photos']} photos agree on up (all within {record['largest_upright_deg']:.0f}° of it)"
    turned = ", ".join(f"{n} {a:.0f}°" for n, a in record["upside_down"].items())
    return (f"{len(record['upside_down'])} of {record['photos']} photos upside down against the others "
            f"({turned}; the others within {record['largest_upright_deg']:.0f}°)")


def check_upright(names: Sequence[str], c2w: Sequence[np.ndarray]) -> UprightCheck:
    """Compare the photos' up axes (camera-to-world poses ``c2w``, OpenCV axes) with their consensus.

    >>> turned = np.diag([-1.0, -1.0, 1.0, 1.0])  # half a turn about the viewing direction
    >>> check = check_upright(["a", "b", "c", "d"], [np.eye(4), np.eye(4), np.eye(4), turned])
    >>> check.upside_down, check.angles_deg.round(1).tolist()
    (('d',), [0.0, 0.0, 0.0, 180.0])
    """
    if len(names) != len(c2w):
        raise InvalidArgument(f"check_upright: {len(names)} names for {len(c2w)} poses; expected one pose a name")
    if len(names) < 3:
        raise InvalidArgument(f"check_upright: {len(names)} photos; at least 3 are needed to find a consensus")
    poses = np.asarray(c2w, dtype=np.float64)
    if poses.shape[1:] not in ((4, 4), (3, 4)) or not np.all(np.isfinite(poses[:, :3, :3])):
        raise InvalidArgument(f"check_upright: poses of shape {poses.shape[1:]}; expected finite 4x4 or 3x4 matrices")
    ups = -poses[:, :3, 1]
    ups /= np.maximum(np.linalg.norm(ups, axis=1, keepdims=True), 1e-12)
    axis = np.linalg.eigh(ups.T @ ups)[1][:, -1]
    if np.count_nonzero(ups @ axis > 0) * 2 < len(ups):
        axis = -axis
    angles = np.degrees(np.arccos(np.clip(ups @ axis, -1.0, 1.0)))
    return UprightCheck(tuple(names), axis, angles)
