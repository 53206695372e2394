"""Whether a capture's photos agree on which way is up: the check that catches a photo structure from motion put
half a turn wrong.

A photo read upright (its orientation applied, :mod:`.images`) shows the world's up at its top, within the tilt of
a hand: people hold a phone upright, and the phone records how it was turned. So in a right reconstruction the
photos' up axes, carried into the world by their poses, point nearly the same way, whatever frame and scale
structure from motion chose (the fox's 50 photos: all within 31.3° of their consensus). On symmetric or repeated
structure (a brick wall, a van's two sides) structure from motion can register a photo half a turn about its
viewing direction; its up axis then points down, against the others (on the demo wall's phone capture,
``benchmarks/capture_poses.py sfm``). A photo whose up lies more than :data:`UPSIDE_DOWN_DEG` from the consensus
is *upside down against the others*.

What it cannot see: a photo put half a turn wrong about the world's vertical (the object's far side put on its
near side) keeps its up; a photo turned in a capture that looks down steeply (more than 60°) can stay within
:data:`UPSIDE_DOWN_DEG` of the others, and where the other photos' up axes fan out past :data:`JUDGED_SPREAD_DEG`
none is judged; and which side is right when many photos disagree. Photos looking straight
down can disagree rightly, the phone guessing its turn: a walk to and fro over a floor splits into two opposite
groups, which the check cannot tell from a half-turn error: the smaller group is skipped when it is a quarter of the
photos or less, and the reconstruction refused when more (``upright=False`` where the check reads such photos).

Convention
----------
Poses are camera-to-world with OpenCV axes (x right, y down, z forward), so a photo's up in the world is
``-c2w[:3, 1]``. The consensus up is the direction most photos' up axes lie within 90° of: from the mean of all the
up axes, and from a photo's up (up to 64 photos spread over the capture), the mean of the up axes within 90° of the
current direction, repeated eight times (the mean of a
hemisphere, so a capture looking steeply down, whose up axes fan out in a wide cone, keeps its consensus on the
cone's axis); the start whose consensus has the most photos within 90° wins.
"""

from __future__ import annotations

from collections import Counter
from collections.abc import Sequence
from dataclasses import dataclass

import numpy as np

from .._validation import check_array
from ..errors import InvalidArgument

__all__ = ["UPSIDE_DOWN_DEG", "UPSIDE_DOWN_SHARE", "JUDGED_SPREAD_DEG", "UprightCheck", "check_upright",
           "upright_summary"]

#: A photo's up this many degrees or more from the consensus is upside down against the others. Measured
#: (``benchmarks/capture_poses.py sfm --scenes wall object --size 320 480 960 --runs 2`` and
#: ``benchmarks/sfm_fox.py``, 6 December 18:27–18:30 UTC): right photos lie within 31.3° (the fox, real, orbiting and
#: looking down at its subject) and 36.3° (the demo captures, even where their reconstruction was poor); a photo
#: looking straight down has its up on the horizon, 90°, whichever way the phone guessed its turn; every photo past
#: the threshold was one the truth puts half a turn wrong (68 of 68, in 12 reconstructions). 120° leaves 30° of
#: margin above a nadir photo.
UPSIDE_DOWN_DEG = 120.0
#: More than this share of the photos upside down and the reconstruction as a whole is doubtful, not a few photos
#: in it. Measured on the demo wall's phone capture (same runs): 2 of 48 upside down (4 %) beside 44 within 3.6°
#: (median) of the truth; 21–23 of 48 (44–48 %) beside halves whose centres were off by 65–94 % of the camera spread.
UPSIDE_DOWN_SHARE = 0.25
#: A turned photo is told from a steep view only while the other photos' up axes lie within this many degrees of
#: the consensus; where they fan out wider (a capture looking down steeply, from few photos), none is judged upside
#: down. Measured (``python benchmarks/upright_rings.py``: rings of 3-48 photos, 3 900 draws each way, 6 December
#: 19:03 UTC): turned photos found, all and only them, with the others within 25.0°; right photos of rings looking
#: down 65-85° read as upside down 51 times before this gate, each time with the others spread 50.0° or more; real
#: captures' right photos within 31.3° (the fox) and 36.3° (the demo captures).
JUDGED_SPREAD_DEG = 45.0
#: Rounds of the hemisphere mean from each start, and the most starts from photos' ups (spread over the capture),
#: beside the one from the mean of all: the check's cost grows with the photos, not with their square.
_SETTLE_STEPS = 8
_MAX_STARTS = 64


@dataclass(frozen=True)
class UprightCheck:
    """The photos' ``names``, their consensus ``up`` (a unit vector, world frame) and each photo's angle from it,
    ``angles_deg``."""

    names: tuple[str, ...]
    up: np.ndarray
    angles_deg: np.ndarray

    @property
    def judged(self) -> bool:
        """Whether the photos not past :data:`UPSIDE_DOWN_DEG` lie within :data:`JUDGED_SPREAD_DEG` of the consensus,
        so that a photo past it can be told from a steep view."""
        rest = self.angles_deg[self.angles_deg < UPSIDE_DOWN_DEG]
        return rest.size == 0 or float(rest.max()) <= JUDGED_SPREAD_DEG

    @property
    def upside_down(self) -> tuple[str, ...]:
        """The photos whose up lies :data:`UPSIDE_DOWN_DEG` or more from the consensus, by name; none where the
        check cannot judge (:attr:`judged`)."""
        if not self.judged:
            return ()
        return tuple(n for n, a in zip(self.names, self.angles_deg) if a >= UPSIDE_DOWN_DEG)

    @property
    def doubtful(self) -> bool:
        """Whether more than :data:`UPSIDE_DOWN_SHARE` of the photos are upside down: then the reconstruction as a
        whole is in doubt, not a few of its photos.

        >>> turned = np.diag([-1.0, -1.0, 1.0, 1.0])
        >>> [check_upright("abcd", [np.eye(4)] * (4 - k) + [turned] * k).doubtful for k in (1, 2)]
        [False, True]
        """
        return len(self.upside_down) > UPSIDE_DOWN_SHARE * len(self.names)

    def as_report(self) -> dict:
        """A JSON-ready record: photos compared, the threshold, the largest angle of the others, the upside-down
        photos with their angles (degrees), and whether that makes the reconstruction doubtful."""
        turned = set(self.upside_down)
        rest = [float(a) for n, a in zip(self.names, self.angles_deg) if n not in turned]
        return {"photos": len(self.names), "threshold_deg": UPSIDE_DOWN_DEG, "judged": self.judged,
                "largest_upright_deg": round(max(rest), 1) if rest else None,
                "upside_down": {n: round(float(a), 1) for n, a in zip(self.names, self.angles_deg) if n in turned},
                "doubtful": self.doubtful}

    def summary(self) -> str:
        """One line: how many photos agree on up, and which do not (:func:`upright_summary`)."""
        return upright_summary(self.as_report())


def upright_summary(record: dict) -> str:
    """One line from a check's record (:meth:`UprightCheck.as_report`, as a report stores it; with ``dropped``, as
    :func:`~pytest_n2r.data.sfm.run_sfm` adds it, what was done with the photos).

    >>> upright_summary({"photos": 5, "largest_upright_deg": 0.0, "upside_down": {"e": 180.0}, "doubtful": False})
    '1 of 5 photos upside down against the others (e 180°; the others within 0°)'
    """
    if not record.get("judged", True):
        return (f"{record['photos']} photos' up axes fan out too widely to tell a photo turned half a turn from one "
                f"looking steeply down: none judged")
    if not record["upside_down"]:
        return f"{record['photos']} photos agree on up (all within {record['largest_upright_deg']:.0f}° of it)"
    turned = ", ".join(f"{n} {a:.0f}°" for n, a in list(record["upside_down"].items())[:5])
    more = f" and {len(record['upside_down']) - 5} more" if len(record["upside_down"]) > 5 else ""
    if record.get("dropped") is True:
        after = ": skipped (--any-roll keeps them)"
    elif record.get("dropped") is False:
        after = ": kept, as --any-roll asks"
    else:
        after = ": too many for a few wrong poses" if record.get("doubtful") else ""
    return (f"{len(record['upside_down'])} of {record['photos']} photos upside down against the others "
            f"({turned}{more}; the others within {record['largest_upright_deg']:.0f}°){after}")


def check_upright(names: Sequence[str], c2w: Sequence[np.ndarray] | np.ndarray) -> UprightCheck:
    """Compare the photos' up axes (camera-to-world poses ``c2w``, OpenCV axes) with their consensus.

    >>> turned = np.diag([-1.0, -1.0, 1.0, 1.0])  # half a turn about the viewing direction
    >>> check = check_upright(["a", "b", "c", "d"], [np.eye(4), np.eye(4), np.eye(4), turned])
    >>> check.upside_down, check.angles_deg.round(1).tolist()
    (('d',), [0.0, 0.0, 0.0, 180.0])
    """
    poses = check_array("c2w", c2w, "N 4 4", dtype=np.float64)
    if len(names) != len(poses):
        raise InvalidArgument(f"check_upright: {len(names)} names for {len(poses)} poses; expected one pose a name")
    if len(names) < 3:
        raise InvalidArgument(f"check_upright: {len(names)} photos; at least 3 are needed to find a consensus")
    if len(set(names)) != len(names):
        twice = sorted(n for n, count in Counter(names).items() if count > 1)
        raise InvalidArgument(f"check_upright: names {twice} given more than once; expected one name a photo")
    ups = -poses[:, :3, 1]
    ups /= np.maximum(np.linalg.norm(ups, axis=1, keepdims=True), 1e-12)
    starts = [ups.sum(axis=0), *ups[:: max(1, -(-len(ups) // _MAX_STARTS))]]  # the mean first, then photos' ups
    directions = np.array(starts)
    for _ in range(_SETTLE_STEPS):
        within = (directions @ ups.T) > 0.0  # start x photo: within 90°
        sums = within.astype(np.float64) @ ups
        directions = sums / np.maximum(np.linalg.norm(sums, axis=1, keepdims=True), 1e-12)
    support = np.count_nonzero((directions @ ups.T) > 0.0, axis=1)
    up = directions[int(np.argmax(support))]
    angles = np.degrees(np.arccos(np.clip(ups @ up, -1.0, 1.0)))
    return UprightCheck(tuple(names), up, angles)
