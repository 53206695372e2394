"""Shared argument checks, so every error message has the same shape: ``name=value``, what was expected."""

from __future__ import annotations

import math
import re
from collections.abc import Iterable
from enum import Enum
from numbers import Real
from typing import Any, TypeVar

import numpy as np

from .errors import InvalidArgument, InvalidType

_E = TypeVar("_E", bound=Enum)


def is_tensor(value: Any) -> bool:
    """Whether ``value`` is a tensor (torch, any device and dtype; by its methods: torch is not imported here).

    >>> is_tensor(np.zeros(2)), is_tensor([1.0])
    (False, False)
    """
    return hasattr(value, "detach") and hasattr(value, "cpu") and hasattr(value, "double")


def tensor_values(tensor: Any) -> np.ndarray:
    """A tensor's values as a numpy array on the host: detached, conjugate and negated views resolved, and a dtype
    numpy has no name for (bfloat16, the float8 types, complex32) as float32 (complex64), which holds each of its
    values exactly."""
    import torch

    host = tensor.detach().cpu().resolve_conj().resolve_neg()
    try:
        return host.numpy()
    except (TypeError, RuntimeError):
        return host.to(torch.complex64 if host.is_complex() else torch.float32).numpy()


def is_finite(value: Any) -> bool:
    """Whether the real number ``value`` is finite as a float: an int too large for one (JSON's integers have no
    limit; ``float(10**400)`` overflows) is not.

    >>> is_finite(1.5), is_finite(float("nan")), is_finite(10**400)
    (True, False, False)
    """
    try:
        return math.isfinite(value)
    except OverflowError:
        return False


def check_real(name: str, value: Any) -> float:
    """Return ``value`` as a finite float, or raise naming ``name``."""
    if isinstance(value, bool) or not isinstance(value, (Real, np.floating, np.integer)):
        raise InvalidType(f"{name}={value!r} must be a real number, not {type(value).__name__}")
    if not is_finite(value):
        raise InvalidArgument(f"{name}={value!r} must be finite")
    return float(value)


def repeated_name(names: Iterable[str]) -> tuple[int, int, str] | None:
    """``(first, second, name)``: the positions of the first name that ``names`` hold twice; ``None`` when all differ.

    >>> repeated_name(["a.png", "b.png", "a.png"]), repeated_name(["a.png", "b.png"])
    ((0, 2, 'a.png'), None)
    """
    seen: dict[str, int] = {}
    for i, name in enumerate(names):
        if name in seen:
            return seen[name], i, name
        seen[name] = i
    return None


def check_range(name: str, value: Any, lo: float | None = None, hi: float | None = None) -> float:
    """Return ``value`` as a finite float in ``[lo, hi]`` (either bound may be ``None``), or raise."""
    value = check_real(name, value)
    if (lo is not None and value < lo) or (hi is not None and value > hi):
        lo_s = "-inf" if lo is None else f"{lo:g}"
        hi_s = "inf" if hi is None else f"{hi:g}"
        raise InvalidArgument(f"{name}={value!r} is out of range; expected a value in [{lo_s}, {hi_s}]")
    return value


def check_int(name: str, value: Any, lo: int, hi: int) -> int:
    """``value`` as an int in ``[lo, hi]``, or raise naming ``name`` (a bool is not an int here)."""
    if isinstance(value, bool) or not isinstance(value, (int, np.integer)):
        raise InvalidType(f"{name}={value!r} must be an int, not {type(value).__name__}")
    if not lo <= value <= hi:
        raise InvalidArgument(f"{name}={value!r} is out of range; expected an int in [{lo}, {hi}]")
    return int(value)


def check_choice(name: str, value: Any, choices: type[_E], what: str) -> _E:
    """``value`` as a member of the enum ``choices`` (a member or its value), or an :class:`InvalidArgument` naming
    ``name``, saying it is not ``what`` and listing the values.

    >>> from pytest_n2r.geometry import Units
    >>> check_choice("units", "scene", Units, "a unit").name
    'SCENE'
    >>> check_choice("units", "meters", Units, "a unit")
    Traceback (most recent call last):
    ...
    pytest_n2r.errors.InvalidArgument: units='meters' is not a unit; expected one of ['reference', 'scene', 'metres']
    """
    try:
        return choices(value)
    except ValueError:
        raise InvalidArgument(f"{name}={value!r} is not {what}; expected one of {[c.value for c in choices]}") from None


def check_positive(name: str, value: Any) -> float:
    """Return ``value`` as a finite float > 0, or raise."""
    value = check_real(name, value)
    if value <= 0:
        raise InvalidArgument(f"{name}={value!r} must be > 0")
    return value


def as_unit_rgb(value: Any) -> tuple[float, float, float] | None:
    """``value`` as an RGB triple of floats in [0, 1], or ``None`` when it is not one (callers name it): a list,
    tuple or 1-D array of three real numbers (a bool is not a number, a string not three of them, and a set or a
    dict has no channel order).

    >>> as_unit_rgb([0.25, 1, 0]), as_unit_rgb("101"), as_unit_rgb((True, False, True)), as_unit_rgb(["1", "0", "1"])
    ((0.25, 1.0, 0.0), None, None, None)
    """
    if not (isinstance(value, (list, tuple)) or (isinstance(value, np.ndarray) and value.ndim == 1)) or len(value) != 3:
        return None  # np.ndim of a ragged list ([1, [2, 3], 4]) would raise, not answer
    if any(isinstance(c, (bool, np.bool_)) or not isinstance(c, (Real, np.integer, np.floating)) for c in value):
        return None
    rgb = tuple(float(c) for c in value)
    if not all(0.0 <= c <= 1.0 for c in rgb):
        return None
    return rgb[0], rgb[1], rgb[2]


def check_array(
    name: str, value: Any, shape: str, *, dtype: type | None = None, finite: bool = True
) -> np.ndarray:
    """Return ``value`` as an array whose shape matches the spec ``shape``, or raise naming ``name``.

    ``shape`` is a space-separated spec: integers must match exactly, a letter matches any length, and
    a leading ``*`` matches any number of leading axes (``"* 3"``, ``"N 2"``, ``"4 4"``, ``"H W 3"``).
    """
    try:
        arr = np.asarray(value) if dtype is None else np.asarray(value, dtype=dtype)
    except (TypeError, ValueError) as exc:
        raise InvalidType(f"{name} must be an array of shape ({shape}), got {type(value).__name__}") from exc
    if arr.dtype == object:
        raise InvalidType(f"{name} must be a numeric array of shape ({shape}), got an object array")
    dims = shape.split()
    batch = bool(dims) and dims[0] == "*"
    dims = dims[1:] if batch else dims
    ok = arr.ndim >= len(dims) if batch else arr.ndim == len(dims)
    if ok:
        tail = arr.shape[arr.ndim - len(dims):]
        ok = all(not d.isdigit() or int(d) == n for d, n in zip(dims, tail))
    if not ok:
        raise InvalidType(f"{name} must have shape ({shape}), got {arr.shape}")
    if finite and arr.dtype.kind in "fc" and not np.all(np.isfinite(arr)):
        bad = int(np.size(arr) - np.count_nonzero(np.isfinite(arr)))
        raise InvalidArgument(f"{name} contains {bad} non-finite value(s) (NaN or Inf)")
    return arr


#: A size's units (:func:`parse_size`), binary whatever their spelling.
_UNITS = {"": 1, "b": 1, "k": 2**10, "kb": 2**10, "kib": 2**10, "m": 2**20, "mb": 2**20, "mib": 2**20,
          "g": 2**30, "gb": 2**30, "gib": 2**30}


def parse_size(text: str | int, name: str = "size") -> int:
    """``"512MiB"``, ``"2G"``, ``"300kb"`` or a plain number of bytes → bytes (binary units).

    >>> parse_size("512MiB"), parse_size("2G"), parse_size(300)
    (536870912, 2147483648, 300)
    """
    if isinstance(text, int) and not isinstance(text, bool):
        value = text
    else:
        match = re.fullmatch(r"\s*(\d+(?:\.\d+)?)\s*([a-zA-Z]*)\s*", str(text))
        if not match or match.group(2).lower() not in _UNITS:
            raise InvalidArgument(f"{name}={text!r} is not a size; expected e.g. '2GiB', '512MB' or a byte count")
        value = int(float(match.group(1)) * _UNITS[match.group(2).lower()])
    if value < 0:
        raise InvalidArgument(f"{name}={text!r} must not be negative")
    return value
