"""Camera poses and the pose transforms τ of metamorphic relations.

Convention
----------
- A pose is a camera-to-world (``world_from_camera``) 4x4 float64 matrix; the camera frame is OpenCV's
  (x right, y down, z forward).
- A transform τ = (roll, pitch, yaw, x, y, z) acts **in the source camera's own frame**:
  ``c2w_tau = c2w @ T(tau)``.
- ``T(tau)`` rotates by ``R = R_y(yaw) @ R_x(pitch) @ R_z(roll)`` (right-handed rotations about the
  camera's own axes: yaw about y, then pitch about the new x, then roll about the new optical axis) and
  translates by ``(x, y, z) * length`` in the source camera frame.
- In words: +yaw turns the view right, +pitch tilts it up, +roll turns the camera clockwise about its
  optical axis as seen from behind (image content turns counter-clockwise); +x moves right, +y moves
  **down**, +z moves forward.
- Angles are **degrees** in every public function; radians only inside.
- Translations are in *reference lengths* (see :class:`Units`) unless stated otherwise: the public API
  multiplies them by the scene's length scale.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from enum import Enum
from typing import ClassVar

import numpy as np

from .._validation import check_array, check_range, check_real
from ..errors import InvalidArgument, InvalidType

__all__ = [
    "Transform",
    "Units",
    "rotation_from_euler",
    "euler_from_rotation",
    "orthonormalize",
    "compose",
    "invert_pose",
    "check_pose",
    "check_rotation",
    "relative_pose",
]


class Units(str, Enum):
    """What a transform's ``x, y, z`` are measured in.

    ``reference``: fractions of the scene's reference length (the median z-depth of the surface seen
    from the training cameras) -- the default, so one bound means the same on every scene.
    ``scene``: the scene's own (arbitrary, SfM) units. ``metres``: metres, for scenes fitted with a
    known scale.
    """

    REFERENCE = "reference"
    SCENE = "scene"
    METRES = "metres"


def _rx(a: float) -> np.ndarray:
    c, s = math.cos(a), math.sin(a)
    return np.array([[1.0, 0.0, 0.0], [0.0, c, -s], [0.0, s, c]])


def _ry(a: float) -> np.ndarray:
    c, s = math.cos(a), math.sin(a)
    return np.array([[c, 0.0, s], [0.0, 1.0, 0.0], [-s, 0.0, c]])


def _rz(a: float) -> np.ndarray:
    c, s = math.cos(a), math.sin(a)
    return np.array([[c, -s, 0.0], [s, c, 0.0], [0.0, 0.0, 1.0]])


def rotation_from_euler(roll: float, pitch: float, yaw: float) -> np.ndarray:
    """``R = R_y(yaw) @ R_x(pitch) @ R_z(roll)``, angles in **degrees**, camera axes (OpenCV).

    >>> R = rotation_from_euler(0, 0, 90)        # yaw right by 90 degrees
    >>> np.round(R @ [0, 0, 1], 12) + 0.0        # the optical axis now points along old +x
    array([1., 0., 0.])
    """
    roll = check_real("roll", roll)
    pitch = check_real("pitch", pitch)
    yaw = check_real("yaw", yaw)
    return _ry(math.radians(yaw)) @ _rx(math.radians(pitch)) @ _rz(math.radians(roll))


def euler_from_rotation(R: np.ndarray) -> tuple[float, float, float]:
    """Inverse of :func:`rotation_from_euler`: ``(roll, pitch, yaw)`` in **degrees**.

    Ranges: pitch in [-90, 90], roll and yaw in (-180, 180]. At gimbal lock (pitch = ±90°) roll and yaw
    turn about the same axis; the result then puts all of it in yaw and returns roll = 0 (never NaN).
    Roll is solved last from the remaining rotation, so the angles always rebuild ``R`` to round-off.
    """
    R = check_array("R", R, "3 3", dtype=np.float64)
    sin_pitch = -R[1, 2]
    cos_pitch = math.hypot(R[1, 0], R[1, 1])
    pitch = math.atan2(sin_pitch, cos_pitch)
    # (R[0, 2], R[2, 2]) = cos(pitch) * (sin, cos)(yaw): yaw is as accurate as cos(pitch) is large, and
    # an error in yaw moves R only by that error times cos(pitch), which roll (below) cannot absorb.
    # So the gimbal branch starts where that product is below round-off, not at a looser threshold.
    if cos_pitch > 1e-14:
        yaw = math.atan2(R[0, 2], R[2, 2])
    else:  # gimbal lock: R[0, :2] = (cos, sin) of yaw -/+ roll; put it all in yaw (error <= pi * 1e-14)
        yaw = math.atan2(math.copysign(1.0, sin_pitch) * R[0, 1], R[0, 0])
        return 0.0, math.degrees(pitch), _wrap(math.degrees(yaw))
    # Roll from what yaw and pitch leave over, so the three angles rebuild R to round-off even where
    # yaw is poorly conditioned (close to gimbal lock).
    M = (_ry(yaw) @ _rx(pitch)).T @ R
    roll = math.atan2(M[1, 0], M[0, 0])
    return _wrap(math.degrees(roll)), math.degrees(pitch), _wrap(math.degrees(yaw))


def _wrap(deg: float) -> float:
    """Wrap an angle in degrees to (-180, 180]."""
    wrapped = math.fmod(deg, 360.0)
    if wrapped <= -180.0:
        wrapped += 360.0
    elif wrapped > 180.0:
        wrapped -= 360.0
    return wrapped + 0.0


def orthonormalize(R: np.ndarray) -> np.ndarray:
    """The rotation matrix nearest to ``R`` (Frobenius norm), via SVD; fixes accumulated round-off."""
    U, _, Vt = np.linalg.svd(np.asarray(R, dtype=np.float64))
    D = np.diag([1.0, 1.0, np.sign(np.linalg.det(U @ Vt))])
    return U @ D @ Vt


#: A rigid transform's last row, and how far each entry may be from it: ``np.allclose``'s test with
#: ``atol=1e-9`` (``atol + rtol * |b|``, ``rtol=1e-5``), written out (a render cache lookup checks a pose).
_LAST_ROW = np.array([0.0, 0.0, 0.0, 1.0])
_LAST_ROW_TOLERANCE = 1e-9 + 1e-5 * np.abs(_LAST_ROW)
_EYE3 = np.eye(3)


def _det3(R: np.ndarray) -> float:
    """The determinant of a 3x3 matrix, by cofactors (a fifth of ``np.linalg.det``'s time on one matrix).

    >>> _det3(np.diag([1.0, 2.0, -3.0]))
    -6.0
    """
    (a, b, c), (d, e, f), (g, h, i) = R.tolist()
    return a * (e * i - f * h) - b * (d * i - f * g) + c * (d * h - e * g)


def check_rotation(R: np.ndarray, name: str = "R", what: str = "") -> np.ndarray:
    """Return ``R`` as a float64 3x3 rotation (orthonormal within 1e-5, determinant +1), or raise naming
    ``name`` (``what``: how the message names the matrix, default ``name``).

    >>> check_rotation(np.diag([1.0, 1.0, -1.0]))
    Traceback (most recent call last):
    ...
    pytest_n2r.errors.InvalidArgument: R is not a rotation (|R^T R - I| = 0, det = -1)
    """
    R = check_array(name, R, "3 3", dtype=np.float64)
    err = float(np.abs(R.T @ R - _EYE3).max())
    if not err <= 1e-5 or _det3(R) < 0:  # not <=: NaN fails too
        raise InvalidArgument(
            f"{what or name} is not a rotation (|R^T R - I| = {err:.2g}, det = {np.linalg.det(R):.4g})")
    return R


def check_pose(c2w: np.ndarray, name: str = "c2w") -> np.ndarray:
    """Return ``c2w`` as a float64 4x4 rigid transform, or raise naming ``name`` and what is wrong."""
    M = check_array(name, c2w, "4 4", dtype=np.float64)
    if not (np.abs(M[3] - _LAST_ROW) <= _LAST_ROW_TOLERANCE).all():  # False for NaN, as np.allclose
        raise InvalidArgument(f"{name} must have last row [0, 0, 0, 1], got {M[3].tolist()}")
    check_rotation(M[:3, :3], name, f"{name} rotation block")
    return M


def invert_pose(M: np.ndarray) -> np.ndarray:
    """Inverse of a rigid 4x4 transform (``camera_from_world`` from ``world_from_camera`` and back)."""
    M = np.asarray(M, dtype=np.float64)
    out = np.eye(4)
    out[:3, :3] = M[:3, :3].T
    out[:3, 3] = -M[:3, :3].T @ M[:3, 3]
    return out


def compose(*matrices: np.ndarray) -> np.ndarray:
    """Product of rigid 4x4 transforms, left to right, with the rotation re-orthonormalized."""
    out = np.eye(4)
    for M in matrices:
        out = out @ np.asarray(M, dtype=np.float64)
    out[:3, :3] = orthonormalize(out[:3, :3])
    return out


def relative_pose(c2w_from: np.ndarray, c2w_to: np.ndarray) -> np.ndarray:
    """``to_from_from``: maps points in the ``from`` camera frame into the ``to`` camera frame."""
    return invert_pose(c2w_to) @ np.asarray(c2w_from, dtype=np.float64)


@dataclass(frozen=True)
class Transform:
    """A pose transform τ in the source camera's frame (angles in degrees, translation in ``units``).

    >>> tau = Transform(yaw=10, x=0.1)
    >>> tau
    Transform(yaw=10.0, x=0.1)
    >>> Transform.from_matrix(tau.matrix()).yaw
    10.0
    """

    roll: float = 0.0
    pitch: float = 0.0
    yaw: float = 0.0
    x: float = 0.0
    y: float = 0.0
    z: float = 0.0

    #: The six components, in constructor order (a subclass may add fields that are not components).
    COMPONENTS: ClassVar[tuple[str, ...]] = ("roll", "pitch", "yaw", "x", "y", "z")

    def __post_init__(self) -> None:
        for name in self.COMPONENTS:
            value = check_real(name, getattr(self, name))
            if name in ("roll", "pitch", "yaw"):
                value = check_range(name, value, -360.0, 360.0)
            object.__setattr__(self, name, value + 0.0)

    @classmethod
    def identity(cls) -> Transform:
        """The transform that moves nothing: every component 0 (``Transform()``)."""
        return cls()

    @property
    def is_identity(self) -> bool:
        return all(getattr(self, name) == 0.0 for name in self.COMPONENTS)

    @property
    def rotation(self) -> np.ndarray:
        """The 3x3 rotation ``R_y(yaw) @ R_x(pitch) @ R_z(roll)`` (camera frame)."""
        return rotation_from_euler(self.roll, self.pitch, self.yaw)

    @property
    def translation(self) -> np.ndarray:
        """``(x, y, z)`` in this transform's units, camera frame."""
        return np.array([self.x, self.y, self.z])

    def matrix(self, length: float = 1.0) -> np.ndarray:
        """The 4x4 ``T(tau)``; translation multiplied by ``length`` (scene units per translation unit)."""
        length = check_real("length", length)
        T = np.eye(4)
        T[:3, :3] = self.rotation
        with np.errstate(over="ignore"):
            T[:3, 3] = self.translation * length
        if not np.all(np.isfinite(T[:3, 3])):
            raise InvalidArgument(f"{self!r} with length={length!r} moves the camera beyond float64 "
                                  f"({T[:3, 3].tolist()}); expected a translation times length within ±1.8e308")
        return T

    @classmethod
    def from_matrix(cls, T: np.ndarray, length: float = 1.0) -> Transform:
        """Inverse of :meth:`matrix` (see :func:`euler_from_rotation` for angle ranges)."""
        T = check_pose(T, "T")
        length = check_real("length", length)
        if length <= 0:
            raise InvalidArgument(f"length={length!r} must be > 0")
        roll, pitch, yaw = euler_from_rotation(T[:3, :3])
        x, y, z = (T[:3, 3] / length).tolist()
        return cls(roll, pitch, yaw, x, y, z)

    @classmethod
    def parse(cls, text: str, name: str = "transform") -> Transform:
        """A transform from its command-line form: ``name=value`` pairs separated by commas, e.g.
        ``"yaw=10,x=0.1"`` (angles in degrees, translations in the caller's units); ``""`` or
        ``"identity"`` is the identity. Errors name ``name`` (the option or argument being parsed).

        >>> Transform.parse("yaw=10, x=0.1")
        Transform(yaw=10.0, x=0.1)
        >>> Transform.parse("identity").is_identity
        True
        """
        if not isinstance(text, str):
            raise InvalidType(f"{name}={text!r} must be a string such as 'yaw=10,x=0.1'")
        known = list(cls.COMPONENTS)
        values: dict[str, float] = {}
        stripped = text.strip()
        if stripped in ("", "identity"):
            return cls()
        for part in stripped.split(","):
            key, sep, value = (s.strip() for s in part.partition("="))
            if not sep or not key or not value:
                raise InvalidArgument(f"{name}={text!r}: {part.strip()!r} is not 'name=value'; expected e.g. "
                                      f"'yaw=10,x=0.1' with names from {known}")
            if key not in known:
                raise InvalidArgument(f"{name}={text!r}: unknown component {key!r}; expected one of {known}")
            if key in values:
                raise InvalidArgument(f"{name}={text!r}: {key!r} is given twice")
            try:
                values[key] = float(value)
            except ValueError:
                raise InvalidArgument(f"{name}={text!r}: {key}={value!r} is not a number") from None
        try:
            return cls(**values)
        except InvalidArgument as exc:
            raise InvalidArgument(f"{name}={text!r}: {exc}") from None

    def apply(self, c2w: np.ndarray, length: float = 1.0) -> np.ndarray:
        """The follow-up pose ``c2w @ T(tau)`` (translation scaled by ``length``)."""
        return compose(check_pose(c2w), self.matrix(length))

    def then(self, other: Transform) -> Transform:
        """The single transform equal to applying ``self`` and then ``other`` (in the moved frame)."""
        return Transform.from_matrix(compose(self.matrix(), other.matrix()))

    def inverse(self) -> Transform:
        """The transform that undoes this one: ``tau.then(tau.inverse())`` is the identity."""
        return Transform.from_matrix(invert_pose(self.matrix()))

    def as_dict(self) -> dict[str, float]:
        """The six components by name (degrees; translations in the caller's units)."""
        return {name: getattr(self, name) for name in self.COMPONENTS}

    def __repr__(self) -> str:
        parts = [f"{name}={getattr(self, name)!r}" for name in self.COMPONENTS if getattr(self, name) != 0.0]
        return f"Transform({', '.join(parts)})"

    def describe(self, units: str = "ref") -> str:
        """Human-readable form for failure messages, e.g. ``yaw=+5.120°, x=+0.1 ref``; an angle under 0.01° shows
        3 significant digits, one under 1e-12° (float noise) is left out.

        >>> Transform(yaw=5.12, pitch=0.0001, roll=1e-15, x=0.1).describe()
        'pitch=+0.0001°, yaw=+5.120°, x=+0.1 ref'
        """
        parts = [f"{n}={v:+.3f}°" if abs(v) >= 0.01 else f"{n}={v:+.3g}°"
                 for n, v in ((n, getattr(self, n)) for n in ("roll", "pitch", "yaw")) if abs(v) >= 1e-12]
        parts += [f"{n}={getattr(self, n):+.4g} {units}" for n in ("x", "y", "z") if getattr(self, n)]
        return ", ".join(parts) or "identity"
