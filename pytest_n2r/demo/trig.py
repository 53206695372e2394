"""Sine and cosine as inlinable compiled code (numba) for the demo renderer's inner loops.

``math.sin`` in a numba kernel is a call into the C library: LLVM can neither inline it nor vectorize a loop
that contains it (this numba has no SVML). :func:`sincos` is the same function as a few dozen inlined
floating-point operations: Cody–Waite reduction by ``π/2`` (a 33-bit head of ``π/2`` so that ``n * head`` is
exact for ``|n| < 2**20``) and fdlibm's minimax polynomials on ``[-π/4, π/4]`` by fused multiply-adds.

Convention
----------
- Float64 in and out, radians, for ``|x| <= 1e5`` (the demo scenes' arguments stay below 500): for
  ``|x| <= 500`` within 2 units in the last place of NumPy's ``np.sin`` / ``np.cos`` and 1.2e-16 absolute
  (1e-22 absolute next to the function's zeros, where the result is tiny); a float32 argument gives,
  rounded to float32, NumPy's float32 result to one float32 unit (``tests/demo/test_trig.py``).
- Beyond ``1e5`` the reduction loses digits: callers keep to the stated range.

>>> import math
>>> s, c = sincos(1.0)
>>> abs(s - math.sin(1.0)) <= 2.3e-16, abs(c - math.cos(1.0)) <= 2.3e-16
(True, True)
"""

from __future__ import annotations

import numpy as np
from llvmlite import ir
from numba import njit, types
from numba.extending import intrinsic

__all__ = ["sincos", "sin", "cos"]

_TWO_OVER_PI = 6.36619772367581382433e-01
_PIO2_HEAD = 1.57079632673412561417e00  # the first 33 bits of π/2
_PIO2_TAIL = 6.07710050650619224932e-11  # π/2 - _PIO2_HEAD
# fdlibm's __kernel_sin and __kernel_cos coefficients (|error| < 2**-58 on [-π/4, π/4])
_S1, _S2, _S3 = -1.66666666666666324348e-01, 8.33333333332248946124e-03, -1.98412698298579493134e-04
_S4, _S5, _S6 = 2.75573137070700676789e-06, -2.50507602534068634195e-08, 1.58969099521155010221e-10
_C1, _C2, _C3 = 4.16666666666666019037e-02, -1.38888888888741095749e-03, 2.48015872894767294178e-05
_C4, _C5, _C6 = -2.75573143513906633035e-07, 2.08757232129817482790e-09, -1.13596475577881948265e-11


@intrinsic
def _fma(typingctx, a, b, c):
    """``a * b + c`` rounded once (LLVM's ``fma``: one instruction where the CPU has it, and vectorizable)."""
    def codegen(context, builder, signature, args):
        double = ir.DoubleType()
        fma = builder.module.declare_intrinsic("llvm.fma", [double], ir.FunctionType(double, [double] * 3))
        return builder.call(fma, args)

    return types.float64(types.float64, types.float64, types.float64), codegen


@njit(cache=True, inline="always", error_model="numpy")
def sincos(x):
    """``(sin x, cos x)`` of a float64 ``x`` in radians (see the module *Convention*): branch-free, so loops
    over arrays that call it vectorize."""
    n = np.rint(x * _TWO_OVER_PI)  # the nearest quadrant
    r = (x - n * _PIO2_HEAD) - n * _PIO2_TAIL
    z = r * r
    s = r + (z * r) * _fma(z, _fma(z, _fma(z, _fma(z, _fma(z, _S6, _S5), _S4), _S3), _S2), _S1)
    hz = 0.5 * z
    w = 1.0 - hz
    c = w + (((1.0 - w) - hz) + z * z * _fma(z, _fma(z, _fma(z, _fma(z, _fma(z, _C6, _C5), _C4), _C3), _C2), _C1))
    q = int(n) & 3  # sin(r + q π/2): q = 1 swaps sine and cosine, q = 2 negates both
    sin_, cos_ = (c, s) if q & 1 else (s, c)
    return (-sin_ if q & 2 else sin_), (-cos_ if (q + 1) & 2 else cos_)


@njit(cache=True, inline="always", error_model="numpy")
def sin(x):
    """``sin x`` of a float64 ``x`` in radians, by :func:`sincos`."""
    return sincos(x)[0]


@njit(cache=True, inline="always", error_model="numpy")
def cos(x):
    """``cos x`` of a float64 ``x`` in radians, by :func:`sincos`."""
    return sincos(x)[1]
