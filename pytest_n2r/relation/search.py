"""The search: Hypothesis draws source views and follow-ups for the :class:`~pytest_n2r.relation.engine.Engine`.

No pytest here: the plugin (and anyone else) calls :func:`check_relation` with a scene, a SUT and a
:class:`~pytest_n2r.relation.spec.Relation`, and gets the run's
:class:`~pytest_n2r.relation.record.RelationRecord` back or a
:class:`~pytest_n2r.relation.failure.RelationFailure` (an ``AssertionError``) that carries it.

Hypothesis drives the search: it draws a source view and a transform, shrinks a failure to the smallest
transform that still fails, replays the last failure first from its example database, seeds from the
relation's identity when ``derandomize`` is on, and with ``search="targeted"`` steers toward larger
deviations with :func:`hypothesis.target`. Deadlines are off and the "too slow" / "filters too much"
health checks are suppressed, because renders are slow and invalid views are expected; a real hang is
caught by the per-call time limit instead (:mod:`pytest_n2r.relation.timeout`).
"""

from __future__ import annotations

import hashlib
import random
import re
import time
from collections.abc import Callable, Iterator
from contextlib import contextmanager
from typing import Any

import numpy as np
from hypothesis import HealthCheck, Phase, given
from hypothesis import seed as hypothesis_seed
from hypothesis import settings as hsettings
from hypothesis.database import ExampleDatabase
from hypothesis.errors import Flaky, Unsatisfiable

from ..errors import InvalidArgument, InvalidType, SUTOutputError
from ..scene.base import Scene, SceneView
from ..scene.render_cache import RenderCache
from ..strategies.view_strategies import views as source_views
from .artifacts import remove_pictures
from .determinism import NotDeterministic, SUTNotDeterministic
from .engine import Engine, forced_seed, recorded_view
from .failure import MAX_UNDEFINED, RelationFailure, nothing_to_test, too_many_invalid
from .outputs import SUTError
from .record import MORE_TIMINGS, TIMINGS, ExampleRecord, RelationRecord
from .settings import RunSettings
from .spec import Relation
from .sut_outputs import SUTOutputs
from .timeout import TimeLimitReached

__all__ = ["check_relation", "replay_relation"]


def check_relation(scene: Scene, sut: Callable[[np.ndarray], Any], relation: Relation, *,
                   settings: RunSettings | None = None, cache: RenderCache | None = None,
                   test_id: str = "relation", replay: list[ExampleRecord] | None = None,
                   on_start: Callable[[RelationRecord], None] | None = None,
                   sut_outputs: SUTOutputs | None = None) -> RelationRecord:
    """Search for a source view and transform where ``sut`` breaks ``relation`` on ``scene``.

    Returns the run's :class:`~pytest_n2r.relation.record.RelationRecord` (one
    :class:`~pytest_n2r.relation.record.ExampleRecord` per drawn example: accepted, rejected and undefined)
    when the relation held on every valid example; raises :class:`RelationFailure` (with the record as
    ``.record``) naming the minimal failing transform, or saying that the SUT produced nothing to test (more
    than :data:`MAX_UNDEFINED` of the evaluated draws undefined); :class:`~pytest_n2r.errors.InvalidArgument`
    when almost every drawn follow-up view was invalid. ``replay``: recorded examples (e.g. a baseline's)
    evaluated exactly, before the search, into the record's ``replayed`` (their verdicts do not fail the run:
    a baseline comparison judges them). ``test_id`` names the run in reports and keys its Hypothesis database
    entries and seed; ``on_start`` receives the (still empty) record before anything runs, so a caller keeps
    it even when the run raises. ``sut_outputs``: the SUT's outputs on renders kept across relations (a
    session's :class:`~pytest_n2r.relation.sut_outputs.SUTOutputs`); without it, the run keeps its own.
    A run that ends without failure pictures removes those an earlier run left for ``test_id`` in
    ``settings.artifacts`` (:func:`~pytest_n2r.relation.artifacts.remove_pictures`).
    """
    __tracebackhide__ = True
    if not isinstance(scene, Scene):
        raise InvalidType(f"scene={scene!r} must be a pytest_n2r.Scene, not {type(scene).__name__}")
    if not callable(sut):
        raise InvalidType(f"sut={sut!r} must be a callable taking an H×W×3 uint8 RGB image, "
                          f"not {type(sut).__name__}")
    if not isinstance(relation, Relation):
        raise InvalidType(f"relation={relation!r} must be a Relation (build one with Relation.build)")
    settings = settings or RunSettings()
    cache = cache if cache is not None else RenderCache(None)
    started = time.perf_counter()
    record = _new_record(scene, relation, test_id)
    if on_start is not None:
        on_start(record)
    engine = Engine(scene, sut, relation, settings, cache, record, sut_outputs)
    interrupted = False  # by a KeyboardInterrupt, pytest.exit, ...: not a finished run
    try:
        if replay is not None:
            record.replayed = engine.replay(replay)
        _search(engine, scene, relation, settings, test_id)
    except RelationFailure as exc:
        record.outcome, record.message = "failed", str(exc)
        exc.record = record
        raise
    except (TimeLimitReached, NotDeterministic) as exc:  # escaped Hypothesis: the example ran once
        record.outcome, record.message = "error", str(exc)
        raise exc.error() from None
    except Flaky as exc:
        record.outcome = "error"
        outcome = _not_an_error(exc)
        if outcome is not None:  # pytest-timeout's Failed, a KeyboardInterrupt: raised once, as itself
            record.message, interrupted = f"{type(outcome).__name__}: {outcome}", True
            raise outcome from None
        sut_error = _sut_error(exc)
        if sut_error is not None:  # the SUT raised (or returned garbage) once, then not on the same example
            record.message = _intermittent(sut_error)
            raise type(sut_error)(record.message) from sut_error
        other = _other_error(exc)
        if other is not None:  # e.g. an OSError of the disk or the render cache's folder: said as itself
            record.message = f"{type(other).__name__}: {other}"
            _add_note(other, "pytest-n2r: raised on an example and not when Hypothesis replayed it, so neither the "
                             "SUT nor the relation's verdict; its traceback is the first run's")
            raise other from None
        # a failure that passed on replay without the SUT changing its outputs: the scene's render
        record.message = ("the relation failed on an example and passed when Hypothesis replayed it: something "
                         "is not deterministic. The system under test gave the same outputs twice on the first "
                         "failure, but may still vary from call to call; else the scene's renders (a custom Scene "
                         "with randomness?) or the metric vary")
        raise SUTNotDeterministic(record.message) from exc  # Hypothesis's own account beside ours
    except BaseException as exc:
        record.outcome, record.message = "error", f"{type(exc).__name__}: {exc}"
        interrupted = not isinstance(exc, Exception)
        raise
    finally:
        record.timings["total"] = time.perf_counter() - started
        # a run that ended (not interrupted) without failure pictures: an earlier run's are stale
        if settings.artifacts is not None and not interrupted and not (record.minimal and record.minimal.images):
            remove_pictures(settings.artifacts, test_id)
    return record


def replay_relation(scene: Scene, sut: Callable[[np.ndarray], Any], relation: Relation, examples: list[Any], *,
                    settings: RunSettings | None = None, cache: RenderCache | None = None,
                    test_id: str = "relation", sut_outputs: SUTOutputs | None = None) -> RelationRecord:
    """Evaluate exactly the recorded ``examples`` (e.g. a baseline's, see
    :func:`pytest_n2r.report.replay_candidates`) for ``sut`` on ``scene``, without a search: their records
    are the returned record's ``replayed``, in order. A verdict never raises; only the SUT's own errors do.
    Pair them with :func:`pytest_n2r.report.compare_paired`. ``sut_outputs``: outputs of SUT objects on
    renders to share (the plugin session's, so a replay does not run a SUT again on a render a relation of
    the session already ran it on)."""
    if not isinstance(scene, Scene):
        raise InvalidType(f"scene={scene!r} must be a pytest_n2r.Scene, not {type(scene).__name__}")
    if not isinstance(relation, Relation):
        raise InvalidType(f"relation={relation!r} must be a Relation (build one with Relation.build)")
    record = _new_record(scene, relation, test_id)
    engine = Engine(scene, sut, relation, settings or RunSettings(), cache if cache is not None else RenderCache(None),
                    record, sut_outputs)
    record.replayed = engine.replay(examples)
    return record


def _sut_error(exc: BaseException) -> SUTError | SUTOutputError | None:
    """The SUT's own error inside Hypothesis's ``FlakyFailure`` (an exception group, perhaps nested), if any."""
    for inner in getattr(exc, "exceptions", ()):
        found = inner if isinstance(inner, (SUTError, SUTOutputError)) else _sut_error(inner)
        if found is not None:
            return found
    return None


def _add_note(exc: BaseException, note: str) -> None:
    """``exc.add_note(note)``, which Python 3.10 lacks: there the note is kept in ``__notes__`` as 3.11 keeps it."""
    if hasattr(exc, "add_note"):
        exc.add_note(note)
    else:  # 3.10 types no BaseException.__notes__: set as the dynamic attribute it is there
        setattr(exc, "__notes__", [*getattr(exc, "__notes__", ()), note])  # noqa: B010


def _not_an_error(exc: BaseException) -> BaseException | None:
    """A ``BaseException`` that is no ``Exception`` inside Hypothesis's ``FlakyFailure``, if any: a test runner's
    outcome (pytest's ``Failed`` of pytest-timeout, ``Skipped``, ``Exit``), ``KeyboardInterrupt``, ``SystemExit``.
    Hypothesis wraps each in an ``Exception`` whose ``__cause__`` it is (an exception group holds only
    exceptions); it stops the run as itself, not as an error of the example it interrupted."""
    for inner in getattr(exc, "exceptions", ()):
        for found in (inner, inner.__cause__):
            if isinstance(found, BaseException) and not isinstance(found, Exception) \
                    and not hasattr(found, "exceptions"):  # a group's own members are looked at below
                return found
        found = _not_an_error(inner)
        if found is not None:
            return found
    return None


def _other_error(exc: BaseException) -> Exception | None:
    """An error inside Hypothesis's ``FlakyFailure`` that is neither a verdict (:class:`RelationFailure`) nor the
    engine's rejection of a draw (Hypothesis's ``UnsatisfiedAssumption``), if any."""
    from hypothesis.errors import UnsatisfiedAssumption

    for inner in getattr(exc, "exceptions", ()):
        if isinstance(inner, (RelationFailure, UnsatisfiedAssumption)):
            continue
        found = _other_error(inner) if hasattr(inner, "exceptions") else inner
        if isinstance(found, Exception):
            return found
    return None


def _intermittent(error: SUTError | SUTOutputError) -> str:
    """Why a run stopped on a SUT error that did not happen again when Hypothesis replayed its example."""
    cause = error.__cause__ if isinstance(error, SUTError) else None
    what = f"raised {type(cause).__name__}: {cause}" if cause is not None else "gave an output it cannot use"
    told = "its traceback and the example it broke on are above" if cause is not None else f"the first time: {error}"
    return (f"the system under test {what} on an example and not when it was replayed: it fails intermittently "
            f"(its state, a race, a resource running out?); {told}")


def _new_record(scene: Scene, relation: Relation, test_id: str) -> RelationRecord:
    """The still empty record of a run of ``relation`` on ``scene``, its clock at zero."""
    return RelationRecord(nodeid=test_id, metric=repr(relation.metric), eps=relation.eps, scene=scene.name,
                          scene_hash=scene.content_hash, timings=dict.fromkeys((*TIMINGS, *MORE_TIMINGS), 0.0))


def _search(engine: Engine, scene: Scene, relation: Relation, settings: RunSettings, test_id: str) -> None:
    """The survey pass, then (after a failure) the shrink pass; raise the relation's verdict."""
    __tracebackhide__ = True
    run = engine.run_record

    def example(view: SceneView, tau: Any) -> None:
        __tracebackhide__ = True
        engine.example(view, tau)

    # key this run's database entries and (with derandomize or --hypothesis-seed) its seed to the test, scene and
    # relation
    identity = run_identity(test_id, scene, relation)
    setattr(example, "_hypothesis_internal_add_digest", identity)  # noqa: B010 -- read by Hypothesis; no function type has it
    run.asked = relation.examples or settings.examples
    options: dict[str, Any] = {
        "max_examples": run.asked, "deadline": None,
        "derandomize": settings.derandomize,
        "suppress_health_check": [HealthCheck.too_slow, HealthCheck.filter_too_much, HealthCheck.data_too_large],
        # no "explain" phase: it re-runs variations of the failure (renders) to annotate source lines
        "phases": [Phase.explicit, Phase.reuse, Phase.generate, Phase.target, Phase.shrink],
    }
    database = None if settings.derandomize else (
        hsettings().database if settings.database == "default" else settings.database)
    seed = None if settings.derandomize else _seed(identity)  # both passes draw the same examples

    def search(db: Any) -> None:
        __tracebackhide__ = True
        test = given(view=source_views(scene, split=relation.views, interpolate=relation.interpolate),
                     tau=relation.transform)(example)
        if seed is not None:
            test = hypothesis_seed(seed)(test)
        hsettings(**options, database=db)(test)()

    survey_database = None if database is None else _HeldBackWrites(database)
    try:  # the survey: records every draw, never fails (its writes to the example database held back)
        with _without_local_constants():
            search(survey_database)
    except Unsatisfiable:
        pass
    drawn, undefined = len(run.examples), run.undefined
    if undefined and undefined / (len(run.valid_examples) + undefined) > MAX_UNDEFINED:
        raise RelationFailure(nothing_to_test(run, relation), run)
    # no valid example (every draw rejected) compared nothing: never a pass, even with max_rejected=1
    if engine.gave_up == "invalid" or not run.valid_examples or run.rejected / drawn > relation.validity.max_rejected:
        raise InvalidArgument(too_many_invalid(run, relation))
    if not run.inconsistencies:
        if survey_database is not None:  # nothing failed: the saved failures replayed and passed, so they go
            survey_database.write()
        return
    if not settings.shrink:
        _report_as_drawn(engine, "not shrunk: shrinking is off (the test is expected to fail)")
    engine.start_shrink_pass()
    try:
        with _without_local_constants():
            search(database)
    except Unsatisfiable:
        pass
    # the shrink pass did not reproduce the survey's failure (a SUT that is not deterministic)
    _report_as_drawn(engine, "not shrunk: the shrink pass did not reproduce it; is the SUT deterministic?")


def _report_as_drawn(engine: Engine, note: str) -> None:
    """Raise the failure of the survey's worst failing example as it was drawn, with ``note`` on why."""
    __tracebackhide__ = True
    worst = engine.run_record.worst
    assert worst is not None, "reported after the survey found an inconsistent (so valid) example"
    view, tau = recorded_view(worst, "drawn"), worst.follow_up()
    engine.fail(view, tau, engine.evaluate(view, tau, camera=view.camera), note=note)


class _HeldBackWrites(ExampleDatabase):
    """An example database read as it is, whose writes are held back until :meth:`write`.

    The survey never raises a failure, so to Hypothesis every example it replays from the database passes, and it
    deletes each as fixed. Held back, those deletions happen only when the survey found no failure (the failure was
    fixed: the saved examples go, as plain Hypothesis drops them); after a failure the writes are dropped and the
    shrink pass replays the saved examples first, against the database itself.
    """

    def __init__(self, database: ExampleDatabase) -> None:
        super().__init__()
        self.database = database
        self.writes: list[tuple[str, bytes, bytes]] = []  # (method, key, value), in Hypothesis's order

    def __repr__(self) -> str:
        return f"_HeldBackWrites({self.database!r})"

    def fetch(self, key: bytes) -> Iterator[bytes]:
        yield from self.database.fetch(key)

    def save(self, key: bytes, value: bytes) -> None:
        self.writes.append(("save", key, value))

    def delete(self, key: bytes, value: bytes) -> None:
        self.writes.append(("delete", key, value))

    def write(self) -> None:
        """Make the held-back writes, in the order Hypothesis asked for them."""
        for method, key, value in self.writes:
            getattr(self.database, method)(key, value)
        self.writes.clear()


#: A memory address in a repr (``<Obj object at 0x7f3a...>``): it differs between processes.
_ADDRESS = re.compile(r" at 0x[0-9a-fA-F]+")


def run_identity(test_id: str, scene: Scene, relation: Relation) -> bytes:
    """The run's identity (test, scene, relation), which keys its database entries and seeds its draws; memory
    addresses are left out of it, so a rerun in another process draws and replays the same examples."""
    return _ADDRESS.sub("", f"{test_id}|{scene.name}|{relation.describe()}").encode()


def _seed(identity: bytes) -> int:
    """The seed of a search that is not derandomized: drawn at random, or with pytest's ``--hypothesis-seed``
    (Hypothesis's ``global_force_seed``) derived from it and the run's ``identity``, so that the same seed draws
    the same examples again and each relation draws its own."""
    forced = forced_seed()
    if forced is None:
        return random.getrandbits(64)
    return int.from_bytes(hashlib.sha256(f"{forced!r}|".encode() + identity).digest()[:8], "big")


@contextmanager
def _without_local_constants() -> Iterator[None]:
    """Hypothesis mixes numbers it finds in the source of the loaded local modules into its draws, so which
    modules happen to be imported changed the examples of a derandomized search (a rerun in one process, a
    pytest-xdist worker, a run that loads the report modules earlier). The engine's draws (views,
    transforms) gain nothing from them, so they are off while it searches. This patches Hypothesis's
    internal ``providers`` module; if that moves, nothing is patched."""
    try:
        from hypothesis.internal.conjecture import providers

        empty, original, cache = providers.Constants(), providers._get_local_constants, providers.CONSTANTS_CACHE
        cache.cache.clear()
    except (ImportError, AttributeError):
        yield
        return
    providers._get_local_constants = lambda: empty
    try:
        yield
    finally:
        providers._get_local_constants = original
