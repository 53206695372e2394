"""Blend masks compiled for the demo renderer: a user's mask function as one loop over a batch of surface
points that LLVM vectorizes.

A :class:`~.materials.Blend` mask is a plain function of ``(a, b)`` written with numpy ufuncs (it serves numpy
arrays in the reference renderer). Compiled as it is, each ``np.sin`` in it is a call into the C library and
every point a call through a function pointer. :func:`compile_mask` compiles a copy whose ``np.sin`` /
``np.cos`` / ``math.sin`` / ``math.cos`` are :mod:`.trig`'s inlined polynomials (within about one unit in the
last place of NumPy's), inlined into a loop over arrays: measured 13× faster per point on the wall's growth
mask (``docs/performance-log.md``).

Convention
----------
- A compiled mask has the signature :data:`MASK_SIGNATURE`: ``(a, b, out, count)`` writes
  ``mask(a[i], b[i])`` to ``out[i]`` for ``i < count`` (float64, unclipped).
- Helpers the mask calls keep their own globals: a ``np.sin`` inside one is the library's (still correct).
- A mask kept on disk compiles under the lock of its kernel piece, named as its files
  (:func:`~pytest_n2r.scene.first_render.claim_piece`).
- Compiled masks are kept per function for the process, and in numba's on-disk cache under a name made from
  :func:`mask_fingerprint`: the mask's code and that of every function it calls (through its globals,
  :mod:`.trig`'s included), each with the bytes of its source file, and the simple values (numbers, strings)
  it reads from its globals. Like numba's own cache, a non-function object another module lends a mask
  (an imported array) is not part of the name. A mask whose source is not a file (typed into a prompt,
  ``exec``) is compiled in every process, as are masks with a closure over anything but simple values.
"""

from __future__ import annotations

import hashlib
import math
import types
from collections.abc import Callable
from contextlib import nullcontext
from functools import cache
from pathlib import Path
from typing import Any

import numpy as np
from numba import njit
from numba.core.errors import NumbaError

from ..errors import InvalidArgument
from ..scene.first_render import claim_piece
from . import trig

__all__ = ["MASK_SIGNATURE", "compile_mask", "mask_fingerprint", "no_mask"]

MASK_SIGNATURE = "void(float64[::1], float64[::1], float64[::1], int64)"
_compiled: dict[Any, Any] = {}
_SIMPLE = (bool, int, float, complex, str, bytes, type(None))


def _module_with_trig(module: types.ModuleType) -> types.ModuleType:
    """A stand-in for ``numpy`` or ``math`` whose ``sin`` and ``cos`` are :mod:`.trig`'s."""
    shim = types.ModuleType(f"n2r_mask_{module.__name__}")
    shim.__dict__.update({k: v for k, v in vars(module).items() if not k.startswith("__")})
    shim.__dict__.update(sin=trig.sin, cos=trig.cos)
    return shim


_SHIMS = {id(np): _module_with_trig(np), id(math): _module_with_trig(math)}


def _with_inlined_trig(fn: Callable) -> Callable:
    """A copy of ``fn`` that sees :func:`_module_with_trig` where its globals name ``numpy`` or ``math``."""
    scope = {k: _SHIMS.get(id(v), v) for k, v in fn.__globals__.items()}
    copy = types.FunctionType(fn.__code__, scope, fn.__name__, fn.__defaults__, fn.__closure__)
    copy.__qualname__ = fn.__qualname__
    return copy


@cache
def _file_digest(path: str) -> str | None:
    """SHA-256 of a source file's bytes; ``None`` when ``path`` is no readable file (``<stdin>``, ``<string>``)."""
    try:
        return hashlib.sha256(Path(path).read_bytes()).hexdigest()
    except OSError:
        return None


def _simple(value: Any) -> bool:
    return isinstance(value, _SIMPLE) or (isinstance(value, tuple) and all(_simple(v) for v in value))


def _code_parts(code: types.CodeType) -> list[Any]:
    """The bytecode, constants (nested code objects recursively) and names of ``code``."""
    parts: list[Any] = [code.co_code, code.co_names]
    for const in code.co_consts:
        parts.append(_code_parts(const) if isinstance(const, types.CodeType) else repr(const))
    return parts


def _names(code: types.CodeType) -> set[str]:
    """Every name ``code`` and its nested code objects load (globals and attributes alike)."""
    out = set(code.co_names)
    for const in code.co_consts:
        if isinstance(const, types.CodeType):
            out |= _names(const)
    return out


def _function_parts(fn: types.FunctionType, seen: set[int]) -> list[Any] | None:
    """What :func:`mask_fingerprint` hashes for ``fn`` and the functions it calls; ``None`` when some part
    cannot be named stably (no source file, a closure or default that is not a simple value)."""
    seen.add(id(fn))
    source = _file_digest(fn.__code__.co_filename)
    cells = tuple(c.cell_contents for c in fn.__closure__ or ())
    if source is None or not _simple(cells) or not _simple(fn.__defaults__):
        return None
    parts: list[Any] = [fn.__module__, fn.__qualname__, source, _code_parts(fn.__code__), repr(cells),
                        repr(fn.__defaults__)]
    for name in sorted(_names(fn.__code__)):
        if name not in fn.__globals__:
            continue
        value = _SHIMS.get(id(fn.__globals__[name]), fn.__globals__[name])
        called = [value.sin, value.cos] if any(value is shim for shim in _SHIMS.values()) else [value]
        for item in called:
            item = getattr(item, "py_func", item)  # a numba dispatcher: its Python function
            if isinstance(item, types.FunctionType):
                if id(item) not in seen:
                    inner = _function_parts(item, seen)
                    if inner is None:
                        return None
                    parts.append((name, inner))
            elif _simple(item):
                parts.append((name, repr(item)))
            elif isinstance(item, types.ModuleType):
                parts.append((name, item.__name__))
    return parts


def mask_fingerprint(fn: types.FunctionType) -> str | None:
    """A name for the compiled form of mask ``fn`` (a plain Python function) that changes when the mask's code,
    a function it calls, their source files or a simple global it reads changes (see the module's
    *Convention*); ``None`` when the mask cannot be kept on disk.

    >>> from pytest_n2r.demo.scenes import _growth_mask, _road_mask
    >>> len(mask_fingerprint(_growth_mask)), mask_fingerprint(_growth_mask) != mask_fingerprint(_road_mask)
    (16, True)
    """
    parts = _function_parts(fn, set())
    return None if parts is None else hashlib.sha256(repr(parts).encode()).hexdigest()[:16]


def _batch(a, b, out, count):  # pragma: no cover - compiled; copied by compile_mask with `point` in its globals
    for i in range(count):
        out[i] = point(a[i], b[i])  # noqa: F821 - the copy's own global


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
    fingerprint = mask_fingerprint(source)
    try:
        point = njit(inline="always", error_model="numpy")(_with_inlined_trig(source))
        # numba names a cached function's files by its qualified name and keys them by its bytecode: each mask's
        # loop is a copy of _batch with its own name, and reaches the mask as a global (a closure would put the
        # dispatcher, whose pickled form differs in every process, into numba's key)
        batch = types.FunctionType(_batch.__code__, {**globals(), "point": point}, "batch")
        batch.__qualname__ = f"mask_{fingerprint or 'uncached'}"
        # a kernel piece: a process that finds another compiling it waits and loads it from numba's cache
        with claim_piece(batch.__qualname__) if fingerprint is not None else nullcontext():
            kernel = njit(MASK_SIGNATURE, nogil=True, error_model="numpy", cache=fingerprint is not None)(batch)
    except NumbaError as exc:
        raise InvalidArgument(
            f"Blend mask {name!r} cannot be compiled ({type(exc).__name__}); a mask must be a plain function "
            "of two floats written with numpy ufuncs and math") from None
    _compiled[fn] = kernel
    return kernel


@njit(MASK_SIGNATURE, cache=True)
def no_mask(a, b, out, count):  # pragma: no cover - compiled; only pads an empty tuple of masks (never called)
    pass
