"""A metric's results kept in the render cache across sessions, beside the renders they were computed from.

A warm run (the render cache filled) runs the SUT again on every image, as it must, but a keypoint metric's
result is a function of what it is given alone: the metric's parameters, the SUT's two outputs and the two
renders. When all of those are the same as in an earlier session, so is the result; the engine keeps it as a
*decision* of the render cache (:meth:`~pytest_n2r.scene.render_cache.RenderCache.decision`) under
:func:`result_key` and takes it from there instead of computing it again.

Convention
----------
- Only metrics whose own class declares :attr:`~pytest_n2r.metrics.base.Metric.result_version` are kept (a
  subclass that does not declare it, e.g. a user's, is always computed): the version names the metric's
  arithmetic and is bumped when it changes.
- The key names the metric's class, its ``repr`` (which rebuilds its constructor call: every parameter), its
  ``result_version``, the package's and numpy's versions, both render keys (scene content, renderer, camera,
  exact pose) and a digest of each SUT output; the render cache folds a digest of the package's source into every
  decision's key (:func:`~pytest_n2r.scene.render_cache.source_digest`), so an edited checkout computes again.
  An output the digest cannot name exactly (anything but numbers, strings, numeric arrays and tensors,
  ``cv2.KeyPoint`` objects, and lists, tuples and string-keyed dicts of them) is not kept.
- A result is kept when every detail is a plain ``bool``, ``int``, ``float``, ``str`` or ``None``, which JSON
  gives back as the same value and type (floats to the bit, NaN included).
"""

from __future__ import annotations

import hashlib
import math
from collections.abc import Callable
from typing import Any

import numpy as np

from .. import __version__
from .._validation import is_tensor, tensor_values
from ..metrics.base import Metric, MetricResult
from ..render.view import RenderedView
from ..scene.render_cache import RenderCache

__all__ = ["kept_result", "output_digest", "result_key", "result_to_dict", "result_from_dict", "repainted_key"]

_PLAIN = (bool, int, float, str, type(None))


def output_digest(output: Any) -> str | None:
    """Hex SHA-256 of a SUT output's exact value (types, dtypes, shapes and bytes; a ``cv2.KeyPoint`` by all six of
    its fields, a tensor by its dtype, shape and values wherever it lives), or ``None`` when the output holds
    something this digest does not name exactly (an object array, a dict with other keys than strings, an object
    of one's own).

    >>> output_digest(np.zeros((2, 2), np.float32)) == output_digest(np.zeros((2, 2), np.float32))
    True
    >>> output_digest(np.zeros((2, 2), np.float32)) == output_digest(np.zeros((2, 2), np.float64))
    False
    >>> output_digest([1, 2.0]) == output_digest((1, 2.0)), output_digest(object())
    (False, None)
    """
    digest = hashlib.sha256()
    return digest.hexdigest() if _feed(digest, output) else None


def _feed(digest: Any, value: Any) -> bool:
    """Add ``value`` to ``digest`` with a tag for its type; False when it cannot be named exactly."""
    if isinstance(value, np.ndarray):
        if value.dtype.kind not in "biufc":
            return False
        digest.update(f"a{value.dtype.str}{value.shape}".encode())
        digest.update(np.ascontiguousarray(value).tobytes())
        return True
    if isinstance(value, np.generic):
        return _feed(digest, np.asarray(value)[None])
    if type(value) in _PLAIN:
        digest.update(f"{type(value).__name__}:{value!r};".encode())
        return True
    if type(value) in (list, tuple):
        digest.update(f"{type(value).__name__}{len(value)}[".encode())
        return all(_feed(digest, item) for item in value)
    if _is_keypoint(value):
        fields = (*value.pt, value.size, value.angle, value.response, value.octave, value.class_id)
        digest.update(f"keypoint{fields!r};".encode())  # repr names a float exactly
        return True
    if is_tensor(value):  # its values (bfloat16 as float32, exactly), tagged with its own dtype
        digest.update(f"tensor{value.dtype}".encode())
        return _feed(digest, tensor_values(value))
    if type(value) is dict and all(type(k) is str for k in value):
        digest.update(f"dict{len(value)}{{".encode())
        return all(_feed(digest, k) and _feed(digest, value[k]) for k in sorted(value))
    return False


def _is_keypoint(value: Any) -> bool:
    """Whether ``value`` is a ``cv2.KeyPoint`` (by its type's module and name: OpenCV is not imported here; a class
    of one's own named so may hold more than the six fields the digest names)."""
    return type(value).__module__ == "cv2" and type(value).__name__ == "KeyPoint"



def kept_result(cache: RenderCache, metric: Metric, source_key: str, follow_key: str, out_source: Any,
                out_follow: Any, compute: Callable[[], MetricResult]) -> MetricResult:
    """``metric``'s result on the two outputs and renders as ``cache`` keeps it from an earlier session, else
    ``compute()``'s, kept in ``cache`` when it can be (see the module's Convention); an exception of ``compute``
    goes to the caller and nothing is kept."""
    key = None if cache.directory is None else result_key(metric, source_key, follow_key, out_source, out_follow)
    stored = cache.decision(key) if key is not None else None
    try:
        result = result_from_dict(stored) if stored is not None else None
    except (KeyError, TypeError, ValueError):  # another shape of decision under the key: computed again
        result = None
    if result is None:
        result = compute()
        kept = result_to_dict(result) if key is not None else None
        if key is not None and kept is not None:
            cache.put_decision(key, kept)
    return result


def repainted_key(source: RenderedView, source_key: str, follow: RenderedView) -> str | None:
    """A key naming ``follow`` when it is the render ``source_key`` with other pixels (a mutation's follow-up:
    the same camera, pose, depth and opacity arrays, its own ``rgb``), from the source's key and a digest of its
    pixels; ``None`` for any other view.

    >>> from pytest_n2r.geometry import Camera
    >>> view = RenderedView(Camera(2, 1, 1, 1, 0.5, 0), np.eye(4), rgb=np.zeros((1, 2, 3), np.uint8))
    >>> brighter = RenderedView(view.camera, view.c2w, rgb=view.rgb + 1)
    >>> repainted_key(view, "k", brighter) != repainted_key(view, "k", view), repainted_key(view, "k", view)[:7]
    (True, 'painted')
    """
    if not (follow.depth is source.depth and follow.opacity is source.opacity and follow.camera == source.camera
            and np.array_equal(follow.c2w, source.c2w)) or follow.rgb is None:
        return None
    pixels = output_digest(follow.rgb)
    return None if pixels is None else f"painted {source_key} {pixels}"


def result_key(metric: Metric, source_key: str, follow_key: str, out_source: Any, out_follow: Any) -> str | None:
    """Hex SHA-256 naming ``metric``'s result on the two outputs and the two renders (see the module's
    Convention), or ``None`` when it is not kept: the metric's class declares no ``result_version`` or an
    output has no :func:`output_digest`."""
    version = vars(type(metric)).get("result_version")
    if version is None:
        return None
    digests = output_digest(out_source), output_digest(out_follow)
    if None in digests:
        return None
    cls = type(metric)
    spec = (f"metric result|{cls.__module__}.{cls.__qualname__}|{metric!r}|{version}|{__version__}|"
            f"numpy {np.__version__}|{source_key}|{follow_key}|{digests[0]}|{digests[1]}")
    return hashlib.sha256(spec.encode()).hexdigest()


def result_to_dict(result: MetricResult) -> dict | None:
    """The JSON object of ``result``, or ``None`` when a detail is not a plain value JSON gives back exactly."""
    if type(result) is not MetricResult or not all(type(v) in _PLAIN and type(k) is str
                                                   for k, v in result.details.items()):
        return None
    if not all(type(v) is float for v in (result.score, result.deviation)):
        return None
    return {"metric": result.metric, "score": result.score, "deviation": result.deviation,
            "details": result.details, "valid": result.valid}


def result_from_dict(data: dict) -> MetricResult:
    """The result :func:`result_to_dict` wrote; :class:`KeyError`, :class:`TypeError` or :class:`ValueError` for
    another shape of object."""
    score, deviation, details = data["score"], data["deviation"], data["details"]
    if not (type(score) is float and type(deviation) is float and type(details) is dict
            and type(data["valid"]) is bool and type(data["metric"]) is str):
        raise TypeError(f"not a kept metric result: {data!r}")
    if not all(type(v) in _PLAIN for v in details.values()):
        raise TypeError(f"not a kept metric result's details: {details!r}")
    if data["valid"] and not math.isfinite(deviation):
        raise ValueError(f"a valid kept metric result with deviation {deviation}")
    return MetricResult(data["metric"], score, deviation, details, valid=data["valid"])
