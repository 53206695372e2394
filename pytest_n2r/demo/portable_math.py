"""Arithmetic that gives the same bits on every machine, for the numbers a demo scene's content hash covers.

A demo scene's content hash covers its views' poses and its light direction to the bit, and it keys the fitted
twins shipped in ``demo/data/`` (:mod:`.fitted`): a different bit anywhere makes them stale, and the example
project then fits both again on first use (minutes). Computed with NumPy and the C library, those numbers are
not the same everywhere:

- ``np.linalg.norm`` of a vector is a BLAS dot product, and OpenBLAS picks its kernel by CPU. The shipped twins
  were fitted where it summed ``x·x`` as a chain of fused multiply-adds; on an AVX2 AMD EPYC it sums separate
  products, and 13 of the demo poses' 192 normalizations differ in their last bit (12 of the 96 poses with them).
  ``OPENBLAS_CORETYPE=Prescott`` shows such a difference on any x86 machine.
- The C library's ``sin``, ``cos`` and ``tan`` are correctly rounded by glibc on every demo argument, but no C
  standard promises it, and other libraries may round differently.

So the scenes' poses and light use these functions instead, each evaluated exactly (in integers) and rounded once.
(:mod:`.trig` is the other sine here: compiled, within 2 units in the last place, for the renderer's inner loops.)

Convention
----------
- :func:`sin`, :func:`cos`, :func:`tan`: the float64 nearest to the function's true value at the float64
  argument (ties to even), for ``|x| <= 1e6`` radians; glibc's ``math.sin``/``cos``/``tan`` give the same
  on every demo argument (glibc 2.36: ``tests/demo/test_portable_math.py`` builds the scenes with both).
- :func:`fma`: ``a * b + c`` rounded once.
- :func:`norm3`: ``sqrt(fma(v2, v2, fma(v1, v1, v0 * v0)))``, the BLAS kernel's order and roundings that the
  shipped twins were fitted with; not the correctly rounded length, which differs from it in the last bit
  on 33 of the 192 normalizations of the demo poses.

>>> sin(1.0) == 0.8414709848078965, cos(0.5) == 0.8775825618903728
(True, True)
>>> norm3((3.0, 4.0, 12.0))
13.0
"""

from __future__ import annotations

import functools
import math
from collections.abc import Sequence
from typing import TYPE_CHECKING

from ..errors import InvalidArgument

if TYPE_CHECKING:
    import numpy as np

__all__ = ["sin", "cos", "tan", "fma", "norm3"]

#: Arguments of :func:`sin`, :func:`cos` and :func:`tan` stay within this many radians.
MAX_ARGUMENT = 1e6
#: Fixed-point fraction bits of the first attempt; each retry doubles them.
_BITS = 160
#: A bound of the fixed-point error of :func:`_sin_cos_fixed`, in units of ``2**-bits``: the argument's
#: rounding (1/2), ``k`` times ``π/2``'s (``k < 2**20``), then two units a Taylor term (fewer than 64 terms).
_ERROR_UNITS = 1 << 21


@functools.cache
def _pi_fixed(bits: int) -> int:
    """``π * 2**bits`` within 1, from Machin's formula ``π = 16 atan(1/5) - 4 atan(1/239)`` in integers."""
    guard = 16
    one = 1 << (bits + guard)

    def atan_inverse(n: int) -> int:  # atan(1/n) * one, each term truncated: within (terms) units
        total, power, k, n2 = 0, one // n, 0, n * n
        while power:
            total += (-1) ** k * (power // (2 * k + 1))
            power //= n2
            k += 1
        return total

    return (16 * atan_inverse(5) - 4 * atan_inverse(239)) >> guard


def _sin_cos_fixed(x: float, bits: int) -> tuple[int, int]:
    """``(sin x, cos x) * 2**bits``, each within :data:`_ERROR_UNITS` of the true value."""
    num, den = x.as_integer_ratio()
    scaled = ((num << (bits + 1)) + den) // (2 * den)  # x * 2**bits to the nearest integer
    half_pi = _pi_fixed(bits - 1)  # π/2 within 1
    k = (2 * scaled + half_pi) // (2 * half_pi)  # the nearest quarter turn
    r = scaled - k * half_pi  # |r| <= π/4 (plus rounding)
    r2 = (r * r) >> bits
    s = term = r
    n = 1
    while term:
        term = -((term * r2) >> bits) // ((2 * n) * (2 * n + 1))
        s += term
        n += 1
    c = term = 1 << bits
    n = 1
    while term:
        term = -((term * r2) >> bits) // ((2 * n - 1) * (2 * n))
        c += term
        n += 1
    return ((s, c), (c, -s), (-s, -c), (-c, s))[k % 4]


def _check(x: float, name: str) -> None:
    if not isinstance(x, (int, float)) or not math.isfinite(x) or abs(x) > MAX_ARGUMENT:
        raise InvalidArgument(f"{name}(x={x!r}): expected a finite number of radians with |x| <= {MAX_ARGUMENT:g}")


def _evaluate(x: float, name: str) -> float:
    """``name`` (``"sin"``, ``"cos"`` or ``"tan"``) of ``x``, correctly rounded. An integer divided by an integer
    is correctly rounded in Python, and rounding is monotonic: when both ends of the interval that holds the true
    value round to the same float, that float is the true value's."""
    _check(x, name)
    x = float(x)
    if x == 0 and name != "cos":
        return x  # sin and tan of ±0 are ±0; the fixed point would keep no sign
    bits = _BITS
    while True:  # more rounds only where the value lies close to a rounding boundary or to 0
        s, c = _sin_cos_fixed(x, bits)
        e = _ERROR_UNITS
        if name != "tan":
            v, one = (s if name == "sin" else c), 1 << bits
            lo, hi = (v - e) / one, (v + e) / one
        elif abs(c) > e:
            corners = [(s + ds) / (c + dc) for ds in (-e, e) for dc in (-e, e)]
            lo, hi = min(corners), max(corners)
        else:
            lo, hi = -math.inf, math.inf
        if lo == hi:
            return lo
        bits *= 2


def sin(x: float) -> float:
    """The sine of ``x`` radians, correctly rounded (module *Convention*)."""
    return _evaluate(x, "sin")


def cos(x: float) -> float:
    """The cosine of ``x`` radians, correctly rounded (module *Convention*)."""
    return _evaluate(x, "cos")


def tan(x: float) -> float:
    """The tangent of ``x`` radians, correctly rounded (module *Convention*)."""
    return _evaluate(x, "tan")


def fma(a: float, b: float, c: float) -> float:
    """``a * b + c`` with a single rounding (finite floats)."""
    if not all(math.isfinite(t) for t in (a, b, c)):
        raise InvalidArgument(f"fma(a={a!r}, b={b!r}, c={c!r}): expected finite numbers")
    (na, da), (nb, db), (nc, dc) = (float(t).as_integer_ratio() for t in (a, b, c))
    return (na * nb * dc + nc * da * db) / (da * db * dc)  # an integer ratio, rounded once by the division


def norm3(v: Sequence[float] | np.ndarray) -> float:
    """The length of the 3-vector ``v`` as the shipped twins' BLAS summed it (module *Convention*)."""
    if len(v) != 3:
        raise InvalidArgument(f"norm3(v): expected a 3-vector, got {len(v)} components")
    v0, v1, v2 = (float(t) for t in v)
    if not all(map(math.isfinite, (v0, v1, v2))):
        raise InvalidArgument(f"norm3(v={[v0, v1, v2]!r}): expected finite components")
    return math.sqrt(fma(v2, v2, fma(v1, v1, v0 * v0)))
