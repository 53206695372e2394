"""Look-at compensation: the turn that keeps a point ahead of the source camera in view after it moves.

Convention
----------
- Everything is in the **source camera's frame** (OpenCV: x right, y down, z forward), as the transforms
  τ of :mod:`pytest_n2r.geometry.pose`: the camera moves by ``(x, y, z)`` and the look-at point is
  ``(0, 0, depth)``, both in the same length units (reference lengths in the plugin).
- Angles are **degrees**; the compensation is the ``(pitch, yaw)`` of ``R = R_y(yaw) @ R_x(pitch)``, which
  turns the moved camera's optical axis onto the look-at point (moving up, ``y < 0``, pitches down;
  moving right, ``x > 0``, yaws left), as in the N2R-Tester paper.
"""

from __future__ import annotations

import math

from ..errors import InvalidArgument
from .pose import Transform

__all__ = ["look_at_compensation", "look_at_transform", "MAX_LOOK_AT_PITCH"]

#: The pitch of a look-at transform is clamped to ±this many degrees (straight down / up).
MAX_LOOK_AT_PITCH = 90.0


def look_at_compensation(x: float, y: float, z: float, depth: float = 1.0) -> tuple[float, float]:
    """``(pitch, yaw)`` in degrees that keep the point ``(0, 0, depth)`` of the source camera frame on the
    optical axis after the camera moves by ``(x, y, z)`` (camera frame, same units as ``depth``).

    Moving the camera up (``y < 0``) gives a downward pitch (< 0), as in the N2R-Tester paper; moving it
    right (``x > 0``) turns it left (yaw < 0).

    >>> pitch, yaw = look_at_compensation(0.0, -0.1, 0.0)
    >>> round(pitch, 3), yaw
    (-5.711, 0.0)
    """
    dx, dy, dz = -x, -y, depth - z  # from the moved camera centre to the look-at point
    if dz <= 0:
        raise InvalidArgument(f"z={z!r} moves the camera past the look-at point at depth {depth!r}")
    # R e_z = (cos p sin y, -sin p, cos p cos y) for R = Ry(yaw) Rx(pitch) Rz(roll)
    yaw = math.degrees(math.atan2(dx, dz))
    pitch = math.degrees(math.atan2(-dy, math.hypot(dx, dz)))
    return pitch + 0.0, yaw + 0.0


def look_at_transform(roll: float = 0.0, pitch: float = 0.0, yaw: float = 0.0,
                      x: float = 0.0, y: float = 0.0, z: float = 0.0) -> Transform:
    """The transform that moves the camera by ``(x, y, z)`` and turns it by the
    :func:`look_at_compensation` toward the point one length unit ahead (``depth=1``), with ``roll``,
    ``pitch`` and ``yaw`` (degrees) added on top of the compensation; the pitch is clamped to
    ±:data:`MAX_LOOK_AT_PITCH`.

    >>> look_at_transform(y=-0.1)
    Transform(pitch=-5.710593137499643, y=-0.1)
    >>> look_at_transform(x=0.1, yaw=2.0).yaw
    -3.710593137499643
    """
    Transform(roll=roll, pitch=pitch, yaw=yaw, x=x, y=y, z=z)  # the arguments' own checks, naming what was passed
    comp_pitch, comp_yaw = look_at_compensation(x, y, z)
    pitch = max(-MAX_LOOK_AT_PITCH, min(MAX_LOOK_AT_PITCH, pitch + comp_pitch))
    yaw = yaw + comp_yaw
    if abs(yaw) > 360.0:  # a turn more than once around: the same rotation one turn back
        yaw -= math.copysign(360.0, yaw)
    return Transform(roll=roll, pitch=pitch, yaw=yaw, x=x, y=y, z=z)
