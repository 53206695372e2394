"""The pytest plugin (registered through the ``pytest11`` entry point as ``n2r``; ``-p no:n2r`` disables it).

Thin and lazy: this module imports only pytest; the engine (Hypothesis, NumPy, the scene field) is imported
inside hooks and fixtures, the first time a test uses pytest-n2r. Without an ``--n2r-*`` option, an
``n2r_*`` ini value, an ``n2r_scene`` fixture or a ``@metamorphic`` test, it does nothing.

Every option is declared once, in :mod:`pytest_n2r.plugin.options`; ``@metamorphic(examples=..., size=...)``
and ``@pytest.mark.n2r_scene`` override them per test: marker keyword > command line > ini file > default.
"""

from __future__ import annotations

import functools
import inspect
import sys
import time
from pathlib import Path
from typing import Any

import pytest

from . import garbage_collector
from .options import OPTIONS, add_options, is_used, read_options
from .summary import Summary

#: When pytest loaded the plugin (early in its start-up: before conftest files and test modules are imported).
_LOADED = time.perf_counter()

#: Baselines, CI gating and reports, and the order of tests under pytest-xdist, live in their own plugin modules,
#: loaded (and disabled) with this one.
pytest_plugins = ["pytest_n2r.plugin.report", "pytest_n2r.plugin.schedule"]

SCENE_MARKER = "n2r_scene"
#: Attribute holding the Relation on a ``@metamorphic`` test function (set by pytest_n2r.plugin.marker).
RELATION_ATTR = "__n2r_relation__"
#: Attribute holding the message of an invalid ``@metamorphic(...)`` call (reported at collection).
ERROR_ATTR = "__n2r_error__"
#: The marker ``@metamorphic`` applies (``-m n2r_relation`` selects relation tests).
RELATION_MARKER = "n2r_relation"

_SESSION = pytest.StashKey["Any"]()
_RECORD = pytest.StashKey["dict"]()


def pytest_addoption(parser: pytest.Parser) -> None:
    add_options(parser)


def _build_session(config: pytest.Config) -> Any:
    """Parse and check every option (a bad value is a usage error naming the option)."""
    from ..relation import RunSettings
    from .precompile import compile_apart_meanwhile, start_for_session
    from .session import N2RSession

    values = read_options(config)
    settings = RunSettings(examples=values["examples"], size=values["size"], derandomize=values["derandomize"],
                           timeout=values["timeout"] or None, artifacts=values["artifacts"])
    session = N2RSession(settings=settings, scenes=values["scene"] or [], device=values["device"],
                         render_scale=values["render_scale"], cache_dir=values["cache_dir"],
                         cache_bytes=values["cache_size"])
    if values["precompile"]:
        session.on_first_render = functools.partial(start_for_session, session)
        session.while_waiting = functools.partial(compile_apart_meanwhile, session)
    return session


def session_of(config: pytest.Config) -> Any:
    """The session object, built on first use (so an unused plugin imports nothing heavy)."""
    session = config.stash.get(_SESSION, None)
    if session is None:
        session = config.stash[_SESSION] = _build_session(config)
    return session


def pytest_configure(config: pytest.Config) -> None:
    config.addinivalue_line(
        "markers", f"{SCENE_MARKER}(*names): run this test only on the named scenes (configured scene names, "
        "or a .n2r path, 'demo:<name>' or 'module:function')",
    )
    config.addinivalue_line("markers", f"{RELATION_MARKER}: a @metamorphic relation test (set by the decorator)")
    config.add_cleanup(functools.partial(garbage_collector.unfreeze, config))  # the first, so the last to run
    summary = Summary(config, _LOADED, lambda: _describe(session_of(config)))
    config.pluginmanager.register(summary, "n2r-summary")
    if is_used(config):
        garbage_collector.pause(config)  # before the engine's imports
        try:
            session = session_of(config)  # bad options fail now, before collection
        except BaseException:
            garbage_collector.resume(config)
            raise
        if config.getoption("n2r_cache_clear") and not hasattr(config, "workerinput"):
            session.cache.clear()  # the controller clears before xdist workers start


@pytest.hookimpl(tryfirst=True)
def pytest_cmdline_main(config: pytest.Config) -> None:
    """A usage error when a path option's value, written apart (``--n2r-compare PATH``), changed pytest's rootdir
    or config file (:mod:`pytest_n2r.plugin.rootdir`): with any pytest-n2r option given, a report option alone too."""
    if not is_used(config, OPTIONS):
        return
    from .rootdir import check_rootdir

    params = config.invocation_params
    error = check_rootdir(params.args, params.dir, config.rootpath, config.inipath)
    if error is not None:
        raise pytest.UsageError(error)


def pytest_report_header(config: pytest.Config) -> list[str] | None:
    return [_describe(session_of(config))] if is_used(config) else None


def _describe(session: Any) -> str:
    from .scenes import default_scene_specs

    names = ", ".join(s.name for s in session.scenes or default_scene_specs()) or "none configured"
    torch = sys.modules.get("torch")  # not imported for the header
    threads = f"torch threads {torch.get_num_threads()}" if torch is not None else "torch not loaded"
    device = session.device
    if device == "auto" and torch is not None:  # loaded (by a scene, a SUT, the caller): say which it chose
        from ..field.device import resolve_device

        device = f"auto ({resolve_device(device)})"
    cache = session.cache_dir if session.cache_dir is not None else "memory only"
    return f"n2r: scenes {names}; device {device}; {threads}; cache {cache}"


# -- collection --------------------------------------------------------------------------------------------


@pytest.hookimpl(tryfirst=True)
def pytest_pycollect_makeitem(collector: pytest.Collector, name: str, obj: Any) -> None:
    """Report an invalid ``@metamorphic(...)`` as a collection error naming the test."""
    if isinstance(obj, (staticmethod, classmethod)):  # the function inside carries what @metamorphic set
        obj = obj.__func__
    if inspect.isfunction(obj):
        error = obj.__dict__.get(ERROR_ATTR)
        if error:
            raise collector.CollectError(f"{collector.nodeid}::{name}: {error}")
        hypothesis = [f"@{deco}" for deco, attr in (("settings", "_hypothesis_internal_settings_applied"),
                                                     ("example", "hypothesis_explicit_examples"),
                                                     ("seed", "_hypothesis_internal_use_seed"))
                      if obj.__dict__.get(attr) is not None]
        if hypothesis and RELATION_ATTR in obj.__dict__:  # Hypothesis would say only that they are "pointless"
            raise collector.CollectError(
                f"{collector.nodeid}::{name}: {' and '.join(hypothesis)} "
                f"{'does' if len(hypothesis) == 1 else 'do'} not apply to a @metamorphic test (the "
                "plugin runs its search): give @metamorphic(examples=...) or --n2r-examples, --n2r-derandomize or "
                "--hypothesis-seed, and replay recorded examples through a baseline")


def pytest_generate_tests(metafunc: pytest.Metafunc) -> None:
    if "n2r_scene" not in metafunc.fixturenames:
        return
    from ..errors import N2RError

    for mark in metafunc.definition.iter_markers("parametrize"):
        names = mark.args[0] if mark.args else mark.kwargs.get("argnames", "")
        if "n2r_scene" in ([n.strip() for n in names.split(",")] if isinstance(names, str) else list(names)):
            raise pytest.Collector.CollectError(
                f"{metafunc.definition.nodeid}: n2r_scene is parametrized by pytest-n2r over the configured scenes; "
                f"choose this test's scenes with @pytest.mark.{SCENE_MARKER}(...), not @pytest.mark.parametrize")
    definitions = getattr(metafunc, "_arg2fixturedefs", {}).get("n2r_scene") or ()
    ours = n2r_scene.__wrapped__  # type: ignore[attr-defined]  # set by pytest's fixture wrapper, not in its types
    if definitions and definitions[-1].func is not ours and "n2r_scene" not in definitions[-1].argnames:
        return  # a conftest's own n2r_scene fixture replaces pytest-n2r's: its scene, not the configured ones
    session = session_of(metafunc.config)
    # the closest level's pins decide (a function's over its class's over its module's), as for a fixture, every
    # pin of that level counted (two stacked marks, a pytestmark list); no pins: every configured scene
    marks = list(metafunc.definition.iter_markers_with_node(SCENE_MARKER))
    pins = [str(a) for node, mark in marks if node is marks[0][0] for a in mark.args]
    try:
        specs = session.scene_specs(pins, base=Path(metafunc.definition.path).parent)
    except N2RError as exc:  # a collection error of this test's module, with just the message
        raise pytest.Collector.CollectError(f"{metafunc.definition.nodeid}: {exc}") from None
    if specs:
        metafunc.parametrize("n2r_scene", specs, ids=[s.name for s in specs], indirect=True, scope="session")
    else:
        metafunc.parametrize("n2r_scene", [None], ids=["no-scene"], indirect=True, scope="session")


def pytest_collection_finish(session: pytest.Session) -> None:
    """Tell the n2r session the scene of every collected test, in the final order (:meth:`.session.N2RSession.plan`)."""
    tests = [(item, getattr(getattr(item, "callspec", None), "params", {}).get("n2r_scene")) for item in session.items]
    if any(spec is not None for _, spec in tests):  # else an unused plugin stays unbuilt; an xdist worker's own
        # --dist is "no": the controller's comes in its workerinput (pytest_configure_node)
        session_of(session.config).plan(tests, getattr(session.config, "workerinput", {}).get("n2r_dist", "no"))


@pytest.hookimpl(optionalhook=True)  # pytest-xdist's, in its controller
def pytest_configure_node(node: Any) -> None:
    node.workerinput["n2r_dist"] = node.config.option.dist


@pytest.hookimpl(hookwrapper=True)  # after pytest's own teardown, even one whose fixture finalizer raised
def pytest_runtest_teardown(item: pytest.Item, nextitem: pytest.Item | None) -> Any:
    """Release the scenes no later test of this process uses (:meth:`~.session.N2RSession.release_done`)."""
    yield
    if (session := item.config.stash.get(_SESSION, None)) is not None and session.release_done(item, nextitem):
        garbage_collector.rescan_scenes(item.config)


def pytest_unconfigure(config: pytest.Config) -> None:
    garbage_collector.resume(config)
    if (session := config.stash.get(_SESSION, None)) is not None:
        session.close()


@pytest.fixture(scope="session")
def n2r_scene(request: pytest.FixtureRequest) -> Any:
    """The scene under test (a :class:`pytest_n2r.Scene`), parametrized over the configured scenes (its name in the
    test id); a process keeps a scene from its first test to its last (:func:`pytest_runtest_teardown`)."""
    from ..errors import N2RError
    from .scenes import NO_SCENE_MESSAGE

    if not hasattr(request, "param"):  # pytest_generate_tests did not see this test take n2r_scene
        pytest.fail("pytest-n2r: n2r_scene was requested where pytest-n2r cannot parametrize it over the configured "
                    "scenes (a unittest.TestCase method, or request.getfixturevalue('n2r_scene')); take n2r_scene "
                    "as an argument of a test function or of a method of a plain test class", pytrace=False)
    if (spec := request.param) is None:
        pytest.skip(NO_SCENE_MESSAGE)
    try:
        return session_of(request.config).load(spec)
    except N2RError as exc:  # the scene's own message, not a traceback through the loader
        message = f"pytest-n2r: scene {spec.source}: {exc}"
    pytest.fail(message, pytrace=False)  # outside the except block, so the report shows the message once


@pytest.fixture(scope="session")
def n2r_session(request: pytest.FixtureRequest) -> Any:
    """The session's :class:`~pytest_n2r.plugin.session.N2RSession`, for tests that evaluate examples
    themselves (a regression gate replaying a baseline): its ``cache`` is the render cache the relations use
    (renders they read are in memory), its ``sut_outputs`` the outputs of SUT objects on renders, shared
    with them (``replay_relation(..., sut_outputs=...)``)."""
    return session_of(request.config)


# -- running -----------------------------------------------------------------------------------------------


@pytest.hookimpl(hookwrapper=True)  # old-style wrapper: works from pytest 7.4 on
def pytest_runtest_setup(item: pytest.Item) -> Any:
    """Freeze the heap after the first setup on each scene (:func:`.garbage_collector.freeze_after_setup`)."""
    yield
    garbage_collector.freeze_after_setup(item)


@pytest.hookimpl(tryfirst=True)
def pytest_pyfunc_call(pyfuncitem: pytest.Function) -> bool | None:
    """Run a ``@metamorphic`` test: call it for the SUT, then check the relation on ``n2r_scene``."""
    relation = getattr(pyfuncitem.obj, RELATION_ATTR, None)
    if relation is None:
        return None
    __tracebackhide__ = True
    from ..errors import SUTOutputError
    from ..relation import RelationFailure
    from ..relation.determinism import SUTNotDeterministic
    from ..relation.timeout import CallTimeout

    funcargs = pyfuncitem.funcargs
    sut = pyfuncitem.obj(**{arg: funcargs[arg] for arg in pyfuncitem._fixtureinfo.argnames})
    if not callable(sut):
        pytest.fail(f"{pyfuncitem.nodeid}: a @metamorphic test must return the system under test, a callable "
                    f"taking an H×W×3 uint8 RGB image; it returned {sut!r}", pytrace=False)
    session = session_of(pyfuncitem.config)
    from .report import baseline_examples

    replay = baseline_examples(pyfuncitem.config, pyfuncitem.nodeid, funcargs["n2r_scene"], relation)
    failure, verdict = None, False
    try:
        session.run(funcargs["n2r_scene"], sut, relation, test_id=pyfuncitem.nodeid, replay=replay,
                    shrink=not _expected_to_fail(pyfuncitem))
        verdict = True
    except RelationFailure as exc:
        failure, verdict = str(exc), True
    except (CallTimeout, SUTNotDeterministic) as exc:
        failure = str(exc)
    except SUTOutputError as exc:  # the SUT's output breaks the metric's contract: the message and the example
        notes = [note for note in getattr(exc, "__notes__", ()) if "@reproduce_failure" not in note]  # not ours
        failure = "\n".join((f"{type(exc).__name__}: {exc}", *notes))
    finally:
        record = session.records[-1] if session.records else None
        if record is not None and record.nodeid == pyfuncitem.nodeid:  # kept whatever happened
            if verdict:  # not after an error, a time-out or an interrupt: the floor runs the SUT again
                start = time.perf_counter()
                record.floor = _floor(session, funcargs["n2r_scene"], sut, relation, record.examples)
                record.timings["floor"] = time.perf_counter() - start
            pyfuncitem.stash[_RECORD] = record.to_dict()
    if failure is not None:  # outside the except block, so the report shows the message once
        floor = pyfuncitem.stash.get(_RECORD, {}).get("floor") or {}
        pytest.fail(failure + (f"\n  floor:      {floor['line']}" if floor.get("below_floor") else ""),
                    pytrace=False)
    return True


def _expected_to_fail(item: pytest.Item) -> bool:
    """Whether ``item`` carries an ``xfail`` mark whose condition holds (or that has none): its failure is not
    shrunk, which would only cost time (a strict xfail still fails the run if the relation holds)."""
    if item.config.getoption("runxfail", False):  # pytest --runxfail: xfail marks count for nothing
        return False
    try:  # pytest's own reading of every xfail mark (condition= as a keyword, string conditions, several marks)
        from _pytest.skipping import evaluate_xfail_marks, xfailed_key
    except ImportError:  # a pytest that moved them: the closest mark, its positional conditions
        mark = item.get_closest_marker("xfail")
        conditions = mark.args if mark is not None else ()
        return mark is not None and (not conditions or any(c for c in conditions if not isinstance(c, str)))
    xfailed = item.stash.get(xfailed_key, None)
    xfailed = xfailed if xfailed is not None else evaluate_xfail_marks(item)
    if xfailed is None:
        return False
    # xfail(raises=ValueError) expects that error, not a relation's failure: pytest reports the relation's failure
    # as FAILED, so it is shrunk (a raises= matcher object other than exception types is pytest's to judge)
    from ..relation import RelationFailure

    raises = xfailed.raises
    return raises is None or not isinstance(raises, (type, tuple)) or issubclass(RelationFailure, raises)


def _floor(session: Any, scene: Any, sut: Any, relation: Any, records: list) -> dict | None:
    """The field floor beside a relation's result (:func:`pytest_n2r.relation.floor.annotate_relation`)."""
    from ..relation.floor import annotate_relation

    return annotate_relation(scene, sut, relation, records, size=relation.size or session.settings.size,
                             cache=session.cache, cache_dir=session.cache_dir, timeout=session.settings.timeout)


@pytest.hookimpl(hookwrapper=True)  # old-style wrapper: works from pytest 7.4 on
def pytest_runtest_makereport(item: pytest.Item, call: pytest.CallInfo) -> Any:
    outcome = yield
    if call.when == "call":
        record = item.stash.get(_RECORD, None)
        if record is not None:  # the RelationRecord as a plain dict: pytest-xdist ships it to the controller
            outcome.get_result().n2r_record = record
            _locate_at_the_test(item, outcome.get_result())


def _locate_at_the_test(item: pytest.Item, report: pytest.TestReport) -> None:
    """A relation's failure, raised from this plugin's hook (every frame hidden), located at the test function
    (``--tb=line``, IDEs and CI annotations read it) rather than in pluggy, without pytest's note that every
    traceback entry is hidden: the message is the whole failure."""
    longrepr: Any = report.longrepr  # read by what it has: pytest's ExceptionChainRepr is private (_pytest._code)
    crash = getattr(longrepr, "reprcrash", None)
    if not report.failed or crash is None or not hasattr(longrepr, "reprtraceback"):
        return
    path, line, _ = item.reportinfo()
    at_test = longrepr.reprcrash = type(crash)(str(path), (line or 0) + 1, crash.message)
    chain = getattr(longrepr, "chain", [])
    chain[-1:] = [(traceback, at_test, descr) for traceback, _, descr in chain[-1:]]  # what pytest-xdist ships
    for traceback in [longrepr.reprtraceback, *(entry[0] for entry in chain)]:
        if traceback.style == "value":
            traceback.extraline = None


def relation_records(config: pytest.Config) -> list[Any]:
    """The :class:`pytest_n2r.report.RelationRecord` of every relation run so far in this session
    (including those of pytest-xdist workers), for reports and baselines."""
    summary = config.pluginmanager.get_plugin("n2r-summary")
    return list(summary.records) if summary else []
