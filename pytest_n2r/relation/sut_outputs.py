"""The SUT's outputs on rendered views, kept so that one SUT runs once on one render: relations of a session
that run the same SUT object on the same source view (or the same pose-change follow-up) share its output.

A render is named by its :func:`~pytest_n2r.scene.render_cache.render_key` (scene content, renderer,
camera, exact pose): the same key means the same pixels. The SUT is named by its object identity, so two
tests that build their own detector (``detector("sift")`` in each) do not share, while tests that return
one fixture's object do. A relation assumes its SUT is deterministic (the engine checks it, calling the SUT
again, before the first failure counts); under that assumption a kept output is the one a new call would
give. The determinism check itself always calls the SUT. A SUT object reconfigured between tests (a session
fixture's detector given another threshold by a parametrized test, a module's function whose global a test
patched) keeps its identity but not its outputs: each relation calls its SUT again on the first output another
test left, and where the two differ every output kept for that SUT is dropped
(:meth:`~pytest_n2r.relation.engine.Engine.sut_on_render`). A reconfiguration that changes no output on that image
goes unseen; building the SUT in the test (or a function-scoped fixture) shares nothing and is always safe.

Mutated follow-ups (pixels changed at the source's pose) are not kept: their image is not a render. A
follow-up whose pixels equal its source's byte for byte is no test and runs no SUT (the engine records it
undefined).

The validity verdict on a follow-up render is kept too (:meth:`SUTOutputs.verdict`), by the validity
thresholds and the two render keys: it does not depend on the SUT, so a replayed example (a regression
gate's) is not judged again.

The metric's result on a pair of renders is kept beside the SUT's outputs (:meth:`SUTOutputs.result`): the
same SUT object and the same metric object on the same two renders compare the same two outputs, so a
replay of an example the session already evaluated (a regression gate's baseline) gets its result again
without computing it. The metric is named by its object identity, checked on every lookup.

The outputs kept are bounded in number (:data:`MAX_OUTPUTS`) and in bytes (:data:`MAX_OUTPUT_BYTES`, measured by
:func:`output_bytes`), the least recently used dropped first (an enhancer's image output at 960x540 is 6 MiB: under
the count cap alone a session kept 12 GiB of them); an output over an eighth of the byte budget is not kept at all.
A dropped output costs only time: the deterministic SUT runs again. A torch tensor is kept detached from its
autograd graph (a classifier called without ``torch.no_grad``: its graph holds every activation, 74 MiB an output
for a MobileNetV2), and an output holding a tensor that could not be detached (inside an object of its own
class) is not kept.
"""

from __future__ import annotations

import dataclasses
import sys
import weakref
from collections import OrderedDict
from collections.abc import Callable
from typing import Any

import numpy as np

__all__ = ["MISSING", "SUTOutputs", "output_bytes"]

#: Outputs kept at most (least recently used first out; :data:`MAX_OUTPUT_BYTES` bounds their bytes): a classifier's
#: 1000 probabilities or a detector's 500 keypoints are a few KiB each.
MAX_OUTPUTS = 4096
#: Bytes of outputs kept at most (:func:`output_bytes`; least recently used first out): an image output (an
#: enhancer's, for ``ssim_metric()``) is 1.5 MiB at 480x270 in float32: a session kept 3 GiB of them at the count cap.
MAX_OUTPUT_BYTES = 256 * 2**20
#: The largest share of the byte budget one output may take; a larger one is not kept.
LARGEST_SHARE = 1 / 8
#: How deep :func:`output_bytes` and the detaching of tensors look into containers; how many items of a container
#: are detached at most (a longer one is kept as it is), and how many are measured (a longer container is measured
#: by its first items: a detector's 500 ``cv2.KeyPoint`` measured one by one took 0.6 ms an output).
_DEPTH = 6
_ITEMS = 10_000
_SAMPLE = 32

#: What :meth:`SUTOutputs.get` returns for an output it does not hold (``None`` may be an output).
MISSING = object()


class SUTOutputs:
    """Outputs of SUT calls keyed by ``(SUT object, render key)``; a SUT's outputs are forgotten when the SUT
    object is garbage-collected (objects that take no weak reference, e.g. built-in functions, are held)."""

    def __init__(self, max_outputs: int = MAX_OUTPUTS, max_bytes: int = MAX_OUTPUT_BYTES):
        self.max_outputs = max_outputs
        self.max_bytes = max_bytes
        #: Bytes of the outputs kept now (:func:`output_bytes`), at most ``max_bytes``.
        self.bytes = 0
        self._outputs: OrderedDict[tuple[int, str], tuple[Any, int]] = OrderedDict()  # (output, its bytes)
        self._suts: dict[int, Any] = {}  # id -> weak reference (or the object), so an id is never reused
        self._verdicts: OrderedDict[tuple[Any, str, str], Any] = OrderedDict()
        self.hits = 0

    def __len__(self) -> int:
        return len(self._outputs)

    def get(self, sut: Callable[..., Any], key: str) -> Any:
        """The kept output of ``sut`` on the render ``key``, or :data:`MISSING`."""
        if not self._knows(sut):
            return MISSING
        kept = self._outputs.get((id(sut), key))
        if kept is None:
            return MISSING
        self._outputs.move_to_end((id(sut), key))
        self.hits += 1
        return kept[0]

    def put(self, sut: Callable[..., Any], key: str, output: Any) -> None:
        """Keep ``sut``'s ``output`` on the render ``key`` (a tensor detached from its autograd graph), unless it
        takes over :data:`LARGEST_SHARE` of the byte budget."""
        found = [False]
        size = _bytes(output, set(), 0, found)
        if found[0]:  # a tensor in what was measured (a container is measured by its first items): detached all
            output = _detached(output)
            size = output_bytes(output)
        self._keep(sut, key, output, size)

    def _keep(self, sut: Callable[..., Any], key: str, value: Any, size: float) -> None:
        ident = id(sut)
        if not self._knows(sut):
            try:
                self._suts[ident] = weakref.ref(sut, lambda _: self._forget(ident))
            except TypeError:  # no weak reference to it: hold the object itself
                self._suts[ident] = sut
        self._drop((ident, key))  # an output kept before under this key: its bytes leave the total
        if size > self.max_bytes * LARGEST_SHARE:
            return
        self._outputs[(ident, key)] = (value, int(size))
        self.bytes += int(size)
        while self._outputs and (len(self._outputs) > self.max_outputs or self.bytes > self.max_bytes):
            self._drop(next(iter(self._outputs)))

    def _drop(self, key: tuple[int, str]) -> None:
        kept = self._outputs.pop(key, None)
        if kept is not None:
            self.bytes -= kept[1]

    def result(self, sut: Callable[..., Any], metric: Any, source_key: str, follow_key: str) -> Any:
        """The kept result of ``metric`` on ``sut``'s outputs on the renders ``source_key`` and ``follow_key``,
        or :data:`MISSING`."""
        kept = self.get(sut, _pair_key(source_key, follow_key))
        if kept is MISSING or kept[0] is not metric:
            return MISSING
        return kept[1]

    def put_result(self, sut: Callable[..., Any], metric: Any, source_key: str, follow_key: str,
                   result: Any) -> None:
        """Keep ``metric``'s ``result`` on ``sut``'s outputs on the two renders (held with the metric object,
        so a result is never returned for another metric that reused its id; its bytes are the result's alone)."""
        self._keep(sut, _pair_key(source_key, follow_key), (metric, result), output_bytes(result))

    def verdict(self, validity: Any, source_key: str, follow_key: str) -> Any:
        """The kept verdict of ``validity`` (a frozen, hashable set of thresholds) on the follow-up render
        ``follow_key`` of the source render ``source_key``, or :data:`MISSING`."""
        key = (validity, source_key, follow_key)
        verdict = self._verdicts.get(key, MISSING)
        if verdict is not MISSING:
            self._verdicts.move_to_end(key)
        return verdict

    def put_verdict(self, validity: Any, source_key: str, follow_key: str, verdict: Any) -> None:
        key = (validity, source_key, follow_key)
        self._verdicts[key] = verdict
        self._verdicts.move_to_end(key)
        while len(self._verdicts) > self.max_outputs:
            self._verdicts.popitem(last=False)

    def forget(self, sut: Callable[..., Any]) -> None:
        """Drop every output and metric result kept for ``sut`` (it no longer gives them: reconfigured)."""
        if self._knows(sut):
            self._forget(id(sut))

    def _knows(self, sut: Any) -> bool:
        held = self._suts.get(id(sut))
        if held is None:
            return False
        return (held() if isinstance(held, weakref.ref) else held) is sut

    def _forget(self, ident: int) -> None:
        self._suts.pop(ident, None)
        for k in [k for k in self._outputs if k[0] == ident]:
            self._drop(k)


def output_bytes(value: Any) -> float:
    """The bytes ``value`` holds, roughly and cheaply: an array or tensor by its buffer (a view by the whole array
    it views), a list, tuple, set or dict, a dataclass or another object with a ``__dict__`` by its items (each object
    once; a long container by its first items), anything else by :func:`sys.getsizeof`. Infinite for a tensor that
    requires grad (its autograd graph holds what cannot be measured)."""
    return _bytes(value, set(), 0, [False])


def _bytes(value: Any, seen: set[int], depth: int, tensors: list[bool]) -> float:
    """:func:`output_bytes`; ``tensors[0]`` set when a torch tensor was met."""
    if id(value) in seen:
        return 0
    seen.add(id(value))
    torch = sys.modules.get("torch")  # no tensor exists before torch is imported; never imported here
    if torch is not None and isinstance(value, torch.Tensor):
        tensors[0] = True
        if value.requires_grad:
            return float("inf")
        try:
            return max(value.element_size() * value.nelement(), value.untyped_storage().nbytes())
        except (RuntimeError, NotImplementedError, AttributeError):  # a tensor without storage (sparse, meta)
            return value.element_size() * value.nelement()
    nbytes = getattr(value, "nbytes", None)
    if isinstance(nbytes, int):  # numpy arrays and scalars, memoryviews
        base = value
        while isinstance(getattr(base, "base", None), type(value)):  # a view keeps the array it views
            base = base.base
        return max(nbytes, getattr(base, "nbytes", 0))
    if type(value).__module__.startswith("PIL.") and hasattr(value, "getbands"):  # a PIL image: its pixels' bytes
        from PIL import ImageMode

        mode = ImageMode.getmode(value.mode)
        return value.width * value.height * len(mode.bands) * np.dtype(mode.typestr).itemsize
    size = sys.getsizeof(value, 64)
    if isinstance(value, (str, bytes, bytearray, int, float, complex, bool)) or value is None or depth >= _DEPTH:
        return size
    if isinstance(value, dict):
        items, count = [x for pair, _ in zip(value.items(), range(_SAMPLE // 2)) for x in pair], 2 * len(value)
    elif isinstance(value, (list, tuple, set, frozenset)):
        items, count = [v for v, _ in zip(value, range(_SAMPLE))], len(value)
    elif dataclasses.is_dataclass(value) and not isinstance(value, type):
        items = [getattr(value, f.name, None) for f in dataclasses.fields(value)]
        count = len(items)
    elif isinstance(getattr(value, "__dict__", None), dict) and not isinstance(value, type):
        items = list(vars(value).values())
        count = len(items)
    else:
        return size
    measured = items[:_SAMPLE]
    if not measured:
        return size
    return size + sum(_bytes(v, seen, depth + 1, tensors) for v in measured) * count / len(measured)


def _detached(value: Any) -> Any:
    """``value`` with every torch tensor that requires grad (in it, or in its lists, tuples and dicts) detached from
    its autograd graph; ``value`` itself when there is none. Torch is never imported here."""
    torch = sys.modules.get("torch")
    return value if torch is None else _detach(value, torch.Tensor, 0)


def _detach(value: Any, tensor: type[Any], depth: int) -> Any:
    if isinstance(value, tensor):
        return value.detach() if value.requires_grad else value
    if depth >= _DEPTH or not isinstance(value, (list, tuple, dict)) or len(value) > _ITEMS:
        return value
    if isinstance(value, dict):
        if type(value) is not dict:
            return value
        items = {k: _detach(v, tensor, depth + 1) for k, v in value.items()}
        return value if all(items[k] is v for k, v in value.items()) else items
    new = [_detach(v, tensor, depth + 1) for v in value]
    if all(a is b for a, b in zip(new, value)):
        return value
    if type(value) in (list, tuple):
        return type(value)(new)
    return type(value)._make(new) if hasattr(value, "_make") else value  # a named tuple; another class as it is


def _pair_key(source_key: str, follow_key: str) -> str:
    """A metric result's key: two render keys (hex digests) cannot collide with one."""
    return f"metric:{source_key}:{follow_key}"
