"""Bounded numbers drawn on a decimal grid, so shrinking finds the smallest failing value.

Values are drawn on a decimal grid (for example 0.01° for a ±20° bound and 0.0001 for a ±0.1 bound, at
least :data:`MIN_STEPS` steps across each bound), so shrinking is a binary search for the smallest failing
step: a SUT that breaks beyond 5° of yaw is reported at ``yaw=5.01``, not at the nearest "simple" float.
"""

from __future__ import annotations

import functools
import math
import sys
from collections.abc import Mapping
from typing import Any

from hypothesis import strategies as st

from .._validation import check_real
from ..errors import InvalidArgument, InvalidType

__all__ = ["AXES", "ANGLES", "MAX_ANGLE", "MIN_STEPS", "Bound", "check_bound", "grid_step", "draw_axis", "draw_moved",
           "draw_motion"]

#: The components of a pose transform, in :class:`~pytest_n2r.geometry.Transform` order.
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


def check_bound(name: str, value: Any) -> Bound:
    """Normalise a bound: ``b`` means ``(-|b|, |b|)``; ``(lo, hi)`` must be finite with ``lo <= hi``.
    Angle bounds (``name`` in :data:`ANGLES`, degrees) must lie within ±:data:`MAX_ANGLE`."""
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
    if not math.isfinite(hi - lo):
        raise InvalidArgument(f"{name}={value!r} spans {hi - lo} (hi - lo overflows a float); expected a bound "
                              f"at most {sys.float_info.max:.4g} wide")
    return lo + 0.0, hi + 0.0


#: The exponent of the smallest power of ten a float holds (a subnormal; 10.0 ** -324 is 0).
_MIN_EXPONENT = -323


def grid_step(lo: float, hi: float) -> float:
    """The decimal step (a power of ten) that puts at least :data:`MIN_STEPS` steps across ``[lo, hi]``.

    A span of a few subnormal floats gets the smallest power of ten a float holds (``1e-323``), not a step
    that underflows to 0.

    >>> grid_step(-20.0, 20.0), grid_step(-0.1, 0.1), grid_step(0.0, 5e-324)
    (0.01, 0.0001, 1e-323)
    """
    span = hi - lo
    if not span > 0:
        return 1.0
    per_step = span / MIN_STEPS
    exponent = math.floor(math.log10(per_step)) if per_step > 0 else _MIN_EXPONENT
    return 10.0 ** max(exponent, _MIN_EXPONENT)


@functools.lru_cache(maxsize=4096)
def _integers(lo: int, hi: int) -> st.SearchStrategy[int]:
    """``st.integers(lo, hi)``, built once and unwrapped: Hypothesis's cache of built strategies (a heap it
    rebalances on every look-up) and its unwrapping of a lazy strategy on every draw cost more than the draw."""
    strategy = st.integers(lo, hi)
    return getattr(strategy, "wrapped_strategy", strategy)


def _draw_steps(draw: Any, n: int) -> int:
    """An integer in ``[0, n]``, spread over the whole range, that shrinks to the smallest failing value.

    Hypothesis draws a wide integer range with a strong bias toward small values (the median draw of
    ``integers(0, 8000)`` is about 800), so a wide range first draws a bucket (a near-uniform small range), then a
    value between the bucket's start and ``n``. Starting inside the range skews values upward, so the starts crowd
    toward 0 (the bucket's share of ``n`` grows as ``b (b + B) / 2 B²``): about half of the draws of a ±80° bound lie
    beyond 40°. Shrinking lowers the bucket to 0 (the value stays valid in the widened range), then binary-searches
    the value: the result is the smallest failing integer. Every choice is used: with two values of which only
    the smaller counted, the shrinker traded between the unused one and the next unused draw, each trade a
    "successful" shrink, and stopped at its cap of 500 short of the smallest failing value.
    """
    if n <= _BUCKET:
        return draw(_integers(0, n))
    bucket = draw(_integers(0, _BUCKETS - 1))
    start = bucket * (bucket + _BUCKETS) * n // (2 * _BUCKETS**2)
    return draw(_integers(start, n))


def draw_axis(draw: Any, lo: float, hi: float) -> float:
    """A value in ``[lo, hi]`` that shrinks toward the point of the interval nearest 0 (its origin), step by
    step (``draw`` is a Hypothesis composite's draw function)."""
    return _draw_axis(draw, lo, hi, None)


def draw_moved(draw: Any, lo: float, hi: float) -> float:
    """:func:`draw_axis`, but never the origin (the point of ``[lo, hi]`` nearest 0) while the interval holds
    another value: shrinking ends one grid step from it."""
    return _draw_axis(draw, lo, hi, True)


def _draw_axis(draw: Any, lo: float, hi: float, moved: bool | None) -> float:
    """:func:`draw_axis`; with ``moved`` True or False a second step count is drawn (one choice, which the shrinker
    takes to 0 at once when unused): ``True`` takes it when the first is 0 (one step when it is 0 too), so the
    origin is never drawn, one step only rarely, and shrinking ends at one step; ``False`` leaves it unused. Both
    draw the same, so the shrinker goes from one to the other."""
    if lo == hi:
        return lo
    origin = min(max(0.0, lo), hi)
    step = grid_step(lo, hi)
    digits = max(0, -int(round(math.log10(step))))
    sides = []  # (sign, steps on the grid, the exact end of the bound)
    for sign, end in ((1, hi), (-1, lo)):
        n = math.floor(abs(end - origin) / step + 1e-9)
        if abs(end - origin) > 0:
            sides.append((sign, n + (abs(origin + sign * n * step - end) > 1e-12), end))
    sign, n, end = sides[draw(_integers(0, len(sides) - 1))] if len(sides) > 1 else sides[0]
    k = _draw_steps(draw, n)
    if moved is not None:
        spare = draw(_integers(0, n))
        k = max(spare, 1) if moved and k == 0 else k
    if k == 0:
        return origin  # exactly the bound's end nearest 0 when it is off the grid (rounding would move it)
    value = origin + sign * k * step
    if sign * (value - end) >= 0 or k >= n:
        return end
    return min(max(round(value, digits), lo), hi) + 0.0  # rounding may cross a bound that is off the grid


def draw_motion(draw: Any, bounds: Mapping[str, Bound]) -> dict[str, float]:
    """One value of each component of :data:`AXES` in its bound (:func:`draw_axis`; a component not in ``bounds``
    is 0), never all 0 while a bound allows anything else: when every component before the last one whose bound
    holds 0 drew 0, that one is drawn off 0. So no draw is the identity, and the smallest draw (where shrinking
    ends when any motion fails) is one grid step along that last component."""
    forced = None  # the component drawn off 0 when all before it are 0; none when the identity cannot be drawn
    if all(lo <= 0.0 <= hi for lo, hi in bounds.values()):
        forced = next((a for a in reversed(AXES) if a in bounds and bounds[a][0] < bounds[a][1]), None)
    values: dict[str, float] = {}
    for axis in AXES:
        if axis not in bounds:
            values[axis] = 0.0
        elif axis == forced:
            values[axis] = _draw_axis(draw, *bounds[axis], not any(values.values()))
        else:
            values[axis] = draw_axis(draw, *bounds[axis])
    return values
