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
"""

from __future__ import annotations

import weakref
from collections import OrderedDict
from collections.abc import Callable
from typing import Any

__all__ = ["MISSING", "SUTOutputs"]

#: Outputs kept at most (least recently used first out): a classifier's 1000 probabilities or a detector's
#: 500 keypoints are a few KiB each.
MAX_OUTPUTS = 4096

#: What :meth:`SUTOutputs.get` returns for an output it does not hold (``None`` may be an output).
MISSING = object()


class SUTOutputs:
    """Outputs of SUT calls keyed by ``(SUT object, render key)``; a SUT's outputs are forgotten when the SUT
    object is garbage-collected (objects that take no weak reference, e.g. built-in functions, are held)."""

    def __init__(self, max_outputs: int = MAX_OUTPUTS):
        self.max_outputs = max_outputs
        self._outputs: OrderedDict[tuple[int, str], Any] = OrderedDict()
        self._suts: dict[int, Any] = {}  # id -> weak reference (or the object), so an id is never reused
        self._verdicts: OrderedDict[tuple[Any, str, str], Any] = OrderedDict()
        self.hits = 0

    def __len__(self) -> int:
        return len(self._outputs)

    def get(self, sut: Callable[..., Any], key: str) -> Any:
        """The kept output of ``sut`` on the render ``key``, or :data:`MISSING`."""
        if not self._knows(sut):
            return MISSING
        output = self._outputs.get((id(sut), key), MISSING)
        if output is not MISSING:
            self._outputs.move_to_end((id(sut), key))
            self.hits += 1
        return output

    def put(self, sut: Callable[..., Any], key: str, output: Any) -> None:
        ident = id(sut)
        if not self._knows(sut):
            try:
                self._suts[ident] = weakref.ref(sut, lambda _: self._forget(ident))
            except TypeError:  # no weak reference to it: hold the object itself
                self._suts[ident] = sut
        self._outputs[(id(sut), key)] = output
        self._outputs.move_to_end((id(sut), key))
        while len(self._outputs) > self.max_outputs:
            self._outputs.popitem(last=False)

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
        so a result is never returned for another metric that reused its id)."""
        self.put(sut, _pair_key(source_key, follow_key), (metric, result))

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
            del self._outputs[k]


def _pair_key(source_key: str, follow_key: str) -> str:
    """A metric result's key: two render keys (hex digests) cannot collide with one."""
    return f"metric:{source_key}:{follow_key}"
