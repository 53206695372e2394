"""Hypothesis strategies for metamorphic tests: pose transforms τ, the paper's presets, source views.

Convention
----------
- Transforms are :class:`~pytest_n2r.geometry.Transform` values applied in the **source camera's frame**
  (``c2w_tau = c2w @ T(tau)``, design.md §2): angles in **degrees**, translations in ``units``
  (reference lengths by default, so one bound means the same on every scene).
- Every strategy shrinks toward the identity (no motion): a failing example is reported as the smallest
  motion that still breaks the system under test.

Values are drawn on a decimal grid (for example 0.01° for a ±20° bound and 0.0001 for a ±0.1 bound, at
least 2000 steps across each bound), so shrinking is a binary search for the smallest failing step: a
SUT that breaks beyond 5° of yaw is reported at ``yaw=5.01``, not at the nearest "simple" float.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Any

import numpy as np
from hypothesis import strategies as st

from ._validation import check_real
from .errors import InvalidArgument, InvalidType
from .geometry import Transform, Units
from .scene.base import Scene, SceneView

__all__ = [
    "transforms", "views", "ViewPick", "look_at_compensation", "PRESETS",
    "tau1", "tau2", "tau3", "tau4", "tau5", "tau6", "transform_units",
]

AXES = ("roll", "pitch", "yaw", "x", "y", "z")
ANGLES = ("roll", "pitch", "yaw")
#: Largest accepted angle bound (degrees); |yaw| > 180 describes the same views twice.
MAX_ANGLE = 180.0
#: At least this many grid steps across a bound (see the module docstring).
MIN_STEPS = 2000
#: Wide step ranges are drawn as one of about this many buckets plus an offset (see _draw_steps).
_BUCKETS = 64
_BUCKET = 255

Bound = tuple[float, float]


def _check_bound(name: str, value: Any) -> Bound:
    """Normalise a bound: ``b`` means ``(-|b|, |b|)``; ``(lo, hi)`` must be finite with ``lo <= hi``."""
    if isinstance(value, (tuple, list)):
        if len(value) != 2:
            raise InvalidArgument(f"{name}={value!r} must be a number b (meaning -b..b) or a pair (lo, hi)")
        lo = check_real(f"{name}[0]", value[0])
        hi = check_real(f"{name}[1]", value[1])
        if lo > hi:
            raise InvalidArgument(f"{name}={tuple(value)!r} has lo > hi; write {name}=({value[1]!r}, {value[0]!r})")
    else:
        try:
            b = check_real(name, value)
        except InvalidType:
            raise InvalidType(
                f"{name}={value!r} must be a number b (meaning -b..b) or a pair (lo, hi), "
                f"not {type(value).__name__}"
            ) from None
        lo, hi = -abs(b), abs(b)
    if name in ANGLES and max(abs(lo), abs(hi)) > MAX_ANGLE:
        raise InvalidArgument(f"{name}={value!r} is out of range; angles are degrees in [-180, 180]")
    return lo + 0.0, hi + 0.0


def _grid_step(lo: float, hi: float) -> float:
    """The decimal step (a power of ten) that puts at least :data:`MIN_STEPS` steps across ``[lo, hi]``."""
    span = hi - lo
    return 10.0 ** math.floor(math.log10(span / MIN_STEPS)) if span > 0 else 1.0


def _draw_steps(draw: Any, n: int) -> int:
    """An integer in ``[0, n]``, spread over the whole range, that shrinks to the smallest failing value.

    Hypothesis draws a wide integer range with a strong bias toward small values (the median draw of
    ``integers(0, 8000)`` is about 800), so a wide range first draws a bucket start (a near-uniform small
    range), then the smaller of two values between that start and ``n`` (which offsets the upward skew
    of starting inside a bucket). Shrinking lowers the bucket to 0 while the values stay valid in the
    widened range, then binary-searches the smaller value: the result is the smallest failing integer.
    """
    if n <= _BUCKET:
        return draw(st.integers(0, n))
    start = draw(st.integers(0, _BUCKETS - 1)) * n // _BUCKETS
    return min(draw(st.integers(start, n)), draw(st.integers(start, n)))


def _draw_axis(draw: Any, lo: float, hi: float) -> float:
    """A value in ``[lo, hi]`` that shrinks toward the point of the interval nearest 0, step by step."""
    if lo == hi:
        return lo
    origin = min(max(0.0, lo), hi)
    step = _grid_step(lo, hi)
    digits = max(0, -int(round(math.log10(step))))
    sides = []  # (sign, steps on the grid, the exact end of the bound)
    for sign, end in ((1, hi), (-1, lo)):
        n = math.floor(abs(end - origin) / step + 1e-9)
        if abs(end - origin) > 0:
            sides.append((sign, n + (abs(origin + sign * n * step - end) > 1e-12), end))
    sign, n, end = sides[draw(st.integers(0, len(sides) - 1))] if len(sides) > 1 else sides[0]
    k = _draw_steps(draw, n)
    value = origin + sign * k * step
    if sign * (value - end) >= 0 or k == n:
        return end
    return min(max(round(value, digits), lo), hi) + 0.0  # rounding may cross a bound that is off the grid


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


def _transforms_impl(draw: Any, *, look_at: bool = False, units: str = "reference", **bounds: Bound) -> Transform:
    values = {a: _draw_axis(draw, *bounds[a]) if a in bounds else 0.0 for a in AXES}
    if look_at:
        pitch, yaw = look_at_compensation(values["x"], values["y"], values["z"])
        values["pitch"] = max(-90.0, min(90.0, values["pitch"] + pitch))
        values["yaw"] += yaw
    return Transform(**values)


_transforms_impl.__name__ = _transforms_impl.__qualname__ = "transforms"  # so the repr reads transforms(...)
_transforms = st.composite(_transforms_impl)


def transforms(
    roll: float | Bound = 0.0, pitch: float | Bound = 0.0, yaw: float | Bound = 0.0,
    x: float | Bound = 0.0, y: float | Bound = 0.0, z: float | Bound = 0.0,
    *, units: Units | str = Units.REFERENCE, look_at: bool = False,
) -> st.SearchStrategy[Transform]:
    """Pose transforms τ with each component within its bound; shrinks toward the identity.

    Each bound is a number ``b`` (meaning ``-|b|..|b|``) or a pair ``(lo, hi)``. Angles are **degrees**
    (yaw about the camera's y axis, pitch about x, roll about the optical axis; +yaw turns right, +pitch
    tilts up), translations ``x, y, z`` are in ``units``: ``"reference"`` (fractions of the scene's
    reference length, the default), ``"scene"`` or ``"metres"``. +x moves right, +y **down**, +z forward.

    ``look_at=True`` adds the yaw and pitch that keep the scene point one reference length ahead on the
    optical axis at the image centre (the paper's design: moving the camera up tilts it down); the
    ``yaw`` / ``pitch`` bounds are then extra rotation on top of that compensation.

    Shrinking: each component moves toward the point of its bound nearest 0 (0 itself when the bound
    contains it) on a decimal grid, so a reported counterexample is within one grid step of the
    smallest failing motion.

    >>> transforms(yaw=10, x=(-0.1, 0.2))
    transforms(x=(-0.1, 0.2), yaw=(-10.0, 10.0))
    """
    bounds = {}
    for name, value in zip(AXES, (roll, pitch, yaw, x, y, z)):
        lo, hi = _check_bound(name, value)
        if (lo, hi) != (0.0, 0.0):
            bounds[name] = (lo, hi)
    try:
        units = Units(units)
    except ValueError:
        raise InvalidArgument(f"units={units!r} is not a unit; expected one of {[u.value for u in Units]}") from None
    if not isinstance(look_at, bool):
        raise InvalidType(f"look_at={look_at!r} must be True or False")
    if look_at and units is not Units.REFERENCE:
        raise InvalidArgument(
            f"look_at=True needs units='reference' (the look-at point is one reference length ahead); "
            f"got units={units.value!r}"
        )
    if look_at and "z" in bounds and bounds["z"][1] >= 0.9:
        raise InvalidArgument(
            f"z={bounds['z']!r} with look_at=True moves the camera up to the look-at point one reference "
            "length ahead; keep z below 0.9"
        )
    extra: dict[str, Any] = {}
    if look_at:
        extra["look_at"] = True
    if units is not Units.REFERENCE:
        extra["units"] = units.value
    strategy = _transforms(**bounds, **extra)
    strategy.n2r_units = units  # read by the relation engine through transform_units()
    strategy.n2r_bounds = dict(bounds)
    strategy.n2r_look_at = look_at
    return strategy


def transform_units(strategy: Any) -> Units:
    """The translation units of a :func:`transforms` strategy (reference lengths for anything else)."""
    return getattr(strategy, "n2r_units", Units.REFERENCE)


#: The N2R-Tester paper's transforms τ1–τ6, scale-normalized: translations in reference lengths (the
#: median viewing distance), look-at compensated so the subject stays in view, plus extra rotation.
tau1 = transforms(x=0.05, yaw=3.0, look_at=True)  #: small x translation + small yaw
tau2 = transforms(y=0.05, pitch=3.0, look_at=True)  #: small y translation + small pitch
tau3 = transforms(x=0.25, yaw=10.0, look_at=True)  #: large x translation + large yaw
tau4 = transforms(y=0.25, pitch=10.0, look_at=True)  #: large y translation + large pitch
tau5 = transforms(x=0.05, yaw=3.0, roll=5.0, look_at=True)  #: τ1 + small roll
tau6 = transforms(y=0.05, pitch=3.0, roll=5.0, look_at=True)  #: τ2 + small roll

#: Presets by name, for ``@metamorphic(..., transform="tau3")``.
PRESETS: dict[str, st.SearchStrategy[Transform]] = {
    "tau1": tau1, "tau2": tau2, "tau3": tau3, "tau4": tau4, "tau5": tau5, "tau6": tau6,
}


SPLITS = ("heldout", "train", "all")


def scene_views(scene: Scene, split: str = "heldout") -> list[SceneView]:
    """The captured views of ``scene`` in ``split``: ``"heldout"`` (views the field was not fitted on;
    every view when the scene has none, as exact procedural scenes do), ``"train"`` or ``"all"``."""
    if split not in SPLITS:
        raise InvalidArgument(f"split={split!r} is not a split; expected one of {SPLITS}")
    views = list(scene.views)
    if not views:
        reason = getattr(scene, "no_views_reason", None)
        raise InvalidArgument(
            f"scene {scene.name!r} has no views to use as sources" + (f": {reason}" if reason else ""))
    if split == "all":
        return views
    chosen = [v for v in views if v.split == split]
    if split == "heldout" and not chosen:
        return views
    if not chosen:
        raise InvalidArgument(f"scene {scene.name!r} has no {split!r} views; use split='all'")
    return chosen


def interpolate_view(a: SceneView, b: SceneView, t: float) -> SceneView:
    """The view a fraction ``t`` in [0, 1] of the way from ``a`` to ``b``: rotation by slerp (constant
    angular speed about one axis), camera centre by linear interpolation, ``a``'s camera."""
    import cv2

    t = check_real("t", t)
    if t == 0.0:
        return a
    Ra, Rb = a.c2w[:3, :3], b.c2w[:3, :3]
    rvec, _ = cv2.Rodrigues(np.ascontiguousarray(Ra.T @ Rb))
    step, _ = cv2.Rodrigues(rvec * t)
    c2w = np.eye(4)
    c2w[:3, :3] = Ra @ step
    c2w[:3, 3] = (1.0 - t) * a.c2w[:3, 3] + t * b.c2w[:3, 3]
    return SceneView(index=a.index, name=f"{a.name}~{b.name}@{t:.2f}", camera=a.camera, c2w=c2w,
                     split="interpolated")


@dataclass(frozen=True)
class ViewPick:
    """A source view drawn without the scene at hand (``views()`` with no scene); a scene turns it into
    a :class:`~pytest_n2r.scene.SceneView` with :meth:`resolve` (``scene.pair`` does this for you)."""

    split: str
    index: int
    t: float = 0.0

    def resolve(self, scene: Scene) -> SceneView:
        if self.t:
            trajectory = list(scene.views)
            if len(trajectory) < 2:
                return trajectory[0]
            i = self.index % (len(trajectory) - 1)
            return interpolate_view(trajectory[i], trajectory[i + 1], self.t)
        candidates = scene_views(scene, self.split)
        return candidates[self.index % len(candidates)]


def views(
    scene: Scene | None = None, *, split: str = "heldout", interpolate: bool = False
) -> st.SearchStrategy[Any]:
    """Source views: captured views of ``split`` (``"heldout"``, ``"train"`` or ``"all"``), or with
    ``interpolate=True`` poses interpolated along the capture trajectory (consecutive views in capture
    order: slerp of rotations, linear centres), which the field has not seen either.

    With a ``scene`` it draws :class:`~pytest_n2r.scene.SceneView` objects; without one it draws
    :class:`ViewPick` values that ``scene.pair(view, tau)`` resolves. Shrinks toward the first view
    (and toward the captured pose itself when interpolating).
    """
    if split not in SPLITS:
        raise InvalidArgument(f"split={split!r} is not a split; expected one of {SPLITS}")
    if not isinstance(interpolate, bool):
        raise InvalidType(f"interpolate={interpolate!r} must be True or False")
    if scene is None:
        t = st.integers(0, 100).map(lambda k: k / 100) if interpolate else st.just(0.0)
        return st.builds(ViewPick, st.just(split), st.integers(0, 4095), t)
    if not isinstance(scene, Scene):
        raise InvalidType(f"scene={scene!r} must be a pytest_n2r.Scene, not {type(scene).__name__}")
    if not interpolate:
        return st.sampled_from(scene_views(scene, split))
    trajectory = list(scene.views)
    if len(trajectory) < 2:
        return st.sampled_from(trajectory)
    return st.builds(
        lambda i, k: interpolate_view(trajectory[i], trajectory[i + 1], k / 100),
        st.integers(0, len(trajectory) - 2), st.integers(0, 100),
    )
