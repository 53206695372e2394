"""Blend masks compiled for the demo renderer: a user's mask function as one loop over a batch of surface
points that LLVM vectorizes.

A :class:`~.materials.Blend` mask is a plain function of ``(a, b)`` written with numpy ufuncs (it serves numpy
arrays in the reference renderer). Compiled as it is, each ``np.sin`` in it is a call into the C library and
every point a call through a function pointer. :func:`compile_mask` compiles a copy whose ``np.sin`` /
``np.cos`` / ``math.sin`` / ``math.cos`` are :mod:`.trig`'s inlined polynomials (within about one unit in the
last place of NumPy's), inlined into a loop over arrays: measured 13× faster per point on the wall's growth
mask (``docs/performance.md``).

Convention
----------
- A compiled mask has the signature :data:`MASK_SIGNATURE`: ``(a, b, out, count)`` writes
  ``mask(a[i], b[i])`` to ``out[i]`` for ``i < count`` (float64, unclipped).
- Helpers the mask calls keep their own globals: a ``np.sin`` inside one is the library's (still correct).
- Compiled masks are kept per function for the process (not on disk: the copy is made at run time).
"""

from __future__ import annotations

import math
import types
from collections.abc import Callable
from typing import Any

import numpy as np
from numba import njit
from numba.core.errors import NumbaError

from ..errors import InvalidArgument
from . import trig

__all__ = ["MASK_SIGNATURE", "compile_mask", "no_mask"]

MASK_SIGNATURE = "void(float64[::1], float64[::1], float64[::1], int64)"
_compiled: dict[Any, Any] = {}


def _module_with_trig(module: types.ModuleType) -> types.ModuleType:
    """A stand-in for ``numpy`` or ``math`` whose ``sin`` and ``cos`` are :mod:`.trig`'s."""
    shim = types.ModuleType(f"n2r_mask_{module.__name__}")
    shim.__dict__.update({k: v for k, v in vars(module).items() if not k.startswith("__")})
    shim.sin, shim.cos = trig.sin, trig.cos
    return shim


_SHIMS = {id(np): _module_with_trig(np), id(math): _module_with_trig(math)}


def _with_inlined_trig(fn: Callable) -> Callable:
    """A copy of ``fn`` that sees :func:`_module_with_trig` where its globals name ``numpy`` or ``math``."""
    scope = {k: _SHIMS.get(id(v), v) for k, v in fn.__globals__.items()}
    copy = types.FunctionType(fn.__code__, scope, fn.__name__, fn.__defaults__, fn.__closure__)
    copy.__qualname__ = fn.__qualname__
    return copy


def compile_mask(fn: Callable) -> Any:
    """``fn`` compiled as a batch loop with the signature :data:`MASK_SIGNATURE` (see the module docstring);
    :class:`InvalidArgument` naming ``fn`` when numba cannot compile it."""
    compiled = _compiled.get(fn)
    if compiled is not None:
        return compiled
    name = getattr(fn, "__name__", fn)
    source = getattr(fn, "py_func", fn)  # a mask already compiled by numba: its Python function
    if not isinstance(source, types.FunctionType):
        raise InvalidArgument(f"Blend mask {name!r} is a {type(fn).__name__}; expected a plain Python function")
    try:
        point = njit(inline="always", error_model="numpy")(_with_inlined_trig(source))

        @njit(MASK_SIGNATURE, nogil=True, error_model="numpy")
        def batch(a, b, out, count):  # pragma: no cover - compiled
            for i in range(count):
                out[i] = point(a[i], b[i])

    except NumbaError as exc:
        raise InvalidArgument(
            f"Blend mask {name!r} cannot be compiled ({type(exc).__name__}); a mask must be a plain function "
            "of two floats written with numpy ufuncs and math") from None
    _compiled[fn] = batch
    return batch


@njit(MASK_SIGNATURE, cache=True)
def no_mask(a, b, out, count):  # pragma: no cover - compiled; only pads an empty tuple of masks (never called)
    pass
