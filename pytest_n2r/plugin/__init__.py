"""The pytest plugin (registered through the ``pytest11`` entry point as ``n2r``; ``-p no:n2r`` disables it).

Thin and lazy: this module imports only pytest; the engine (Hypothesis, NumPy, the scene field) is imported
inside hooks and fixtures, the first time a test uses pytest-n2r. Without an ``--n2r-*`` option, an
``n2r_*`` ini value, an ``n2r_scene`` fixture or a ``@metamorphic`` test, it does nothing.

Every option is a CLI / ini pair; ``@metamorphic(examples=..., size=...)`` and ``@pytest.mark.n2r_scene``
override them per test: marker keyword > command line > ini file > default.
"""

from __future__ import annotations

import inspect
import os
import re
from pathlib import Path
from typing import Any

import pytest

#: Baselines, CI gating and reports live in their own plugin module, loaded (and disabled) with this one.
pytest_plugins = ["pytest_n2r.plugin.report"]

#: (CLI flag, ini name, metavar, help) of every option with an ini twin.
OPTIONS: tuple[tuple[str, str, str, str], ...] = (
    ("--n2r-scene", "n2r_scenes", "PATH",
     ("scene to test on: a .n2r file, 'demo:<name>' or 'module:function' (repeatable; ini: globs allowed, "
      "whitespace-separated). Default: the first built-in demo scene")),
    ("--n2r-examples", "n2r_examples", "N", "Hypothesis examples per relation (default: 50)"),
    ("--n2r-size", "n2r_size", "WxH", "render size: 'WxH' or the longer side in pixels (default: 480)"),
    ("--n2r-render-scale", "n2r_render_scale", "S",
     ("render scene fields at this fraction of the render size and upsample to it: 0.5 is about 4x faster "
      "for a little sharpness (default: 1)")),
    ("--n2r-device", "n2r_device", "DEVICE", "device for scene fields: auto, cpu, cuda, cuda:1 (default: auto)"),
    ("--n2r-cache-dir", "n2r_cache_dir", "DIR",
     "render cache directory, relative to the rootdir; 'none' keeps renders in memory only (default: .n2r-cache)"),
    ("--n2r-cache-size", "n2r_cache_size", "SIZE", "disk cap of the render cache, e.g. 2GiB (default: 2GiB)"),
    ("--n2r-artifacts", "n2r_artifacts", "DIR",
     "where failure pictures go, relative to the rootdir; 'none' saves none (default: n2r-artifacts)"),
    ("--n2r-timeout", "n2r_timeout", "SECONDS",
     "time limit of one render or one SUT call; 0 disables (default: 300)"),
    ("--n2r-derandomize", "n2r_derandomize", "auto|yes|no",
     "draw the same examples every run; 'auto' means yes when the CI environment variable is set (default: auto)"),
)
DEFAULTS = {
    "n2r_examples": "50", "n2r_size": "480", "n2r_render_scale": "1", "n2r_device": "auto",
    "n2r_cache_dir": ".n2r-cache", "n2r_cache_size": "2GiB", "n2r_artifacts": "n2r-artifacts", "n2r_timeout": "300",
    "n2r_derandomize": "auto",
}
SCENE_MARKER = "n2r_scene"
#: Attribute holding the Relation on a ``@metamorphic`` test function (set by pytest_n2r.plugin.marker).
RELATION_ATTR = "__n2r_relation__"
#: Attribute holding the message of an invalid ``@metamorphic(...)`` call (reported at collection).
ERROR_ATTR = "__n2r_error__"
#: The marker ``@metamorphic`` applies (``-m n2r_relation`` selects relation tests).
RELATION_MARKER = "n2r_relation"

_SESSION = pytest.StashKey["Any"]()
_STATS = pytest.StashKey["dict"]()


def pytest_addoption(parser: pytest.Parser) -> None:
    group = parser.getgroup("n2r", "pytest-n2r: metamorphic tests on rendered views")
    for flag, ini, metavar, help_text in OPTIONS:
        dest = ini if ini != "n2r_scenes" else "n2r_scene"
        if flag == "--n2r-scene":
            group.addoption(flag, action="append", dest=dest, metavar=metavar, default=None, help=help_text)
            parser.addini(ini, help_text, type="args", default=[])
        else:
            group.addoption(flag, dest=dest, metavar=metavar, default=None, help=help_text)
            parser.addini(ini, help_text, default=None)
    group.addoption("--n2r-cache-clear", action="store_true", default=False,
                    help="empty the render cache before the run")


def _raw(config: pytest.Config, ini: str) -> Any:
    """An option's value: the command line if given, else the ini file, else the default."""
    cli = config.getoption(ini if ini != "n2r_scenes" else "n2r_scene")
    if cli is not None:
        return cli
    value = config.getini(ini)
    if value not in (None, "", []):
        return value
    return DEFAULTS.get(ini)


def _used(config: pytest.Config) -> bool:
    """Whether any pytest-n2r option or ini value is set (the header shows only then)."""
    for _, ini, _, _ in OPTIONS:
        if config.getoption(ini if ini != "n2r_scenes" else "n2r_scene") is not None:
            return True
        if config.getini(ini) not in (None, "", []):
            return True
    return bool(config.getoption("n2r_cache_clear"))


def _rooted(config: pytest.Config, value: str) -> Path | None:
    if value.strip().lower() == "none":
        return None
    path = Path(value).expanduser()
    return path if path.is_absolute() else Path(config.rootpath) / path


def _build_session(config: pytest.Config) -> Any:
    """Parse and check every option (a bad value is a usage error naming the option)."""
    from ..data.atomic import unwritable_reason
    from ..errors import N2RError
    from ..relation import RunSettings
    from ..render.size import RenderSize
    from ..scene.render_cache import parse_size
    from .scenes import parse_scene_specs
    from .session import N2RSession

    def fail(ini: str, message: str) -> None:
        flag = next(f for f, i, _, _ in OPTIONS if i == ini)
        raise pytest.UsageError(f"pytest-n2r: {flag} / ini {ini}: {message}")

    try:
        examples = int(_raw(config, "n2r_examples"))
        if examples < 1:
            raise ValueError
    except ValueError:
        fail("n2r_examples", f"{_raw(config, 'n2r_examples')!r} is not a whole number >= 1")
    try:
        size = RenderSize.parse(str(_raw(config, "n2r_size")), "n2r_size")
    except N2RError as exc:
        fail("n2r_size", str(exc))
    try:
        render_scale = float(_raw(config, "n2r_render_scale"))
        if not 0.1 <= render_scale <= 1.0:
            raise ValueError
    except ValueError:
        fail("n2r_render_scale", f"{_raw(config, 'n2r_render_scale')!r} is not a fraction in [0.1, 1]")
    try:
        timeout = float(_raw(config, "n2r_timeout"))
        if not timeout >= 0:
            raise ValueError
    except ValueError:
        fail("n2r_timeout", f"{_raw(config, 'n2r_timeout')!r} is not a number of seconds >= 0")
    derandomize = str(_raw(config, "n2r_derandomize")).strip().lower()
    if derandomize not in ("auto", "yes", "no", "true", "false", "1", "0"):
        fail("n2r_derandomize", f"{derandomize!r}; expected auto, yes or no")
    derandomize_on = derandomize in ("yes", "true", "1") or (derandomize == "auto" and bool(os.environ.get("CI")))
    try:
        cache_bytes = parse_size(str(_raw(config, "n2r_cache_size")), "n2r_cache_size")
    except N2RError as exc:
        fail("n2r_cache_size", str(exc))
    cli_scenes = config.getoption("n2r_scene")
    try:
        if cli_scenes:
            scenes = parse_scene_specs(cli_scenes, Path.cwd(), "--n2r-scene")
        else:
            base = Path(config.inipath).parent if config.inipath else Path(config.rootpath)
            scenes = parse_scene_specs(config.getini("n2r_scenes"), base, "ini n2r_scenes")
    except N2RError as exc:
        raise pytest.UsageError(f"pytest-n2r: {exc}") from None
    device = str(_raw(config, "n2r_device")).strip().lower()
    if not re.fullmatch(r"auto|cpu|cuda(:\d+)?", device):
        fail("n2r_device", f"{device!r}; expected auto, cpu, cuda or cuda:N")
    if device.startswith("cuda"):
        import torch

        if not torch.cuda.is_available():
            fail("n2r_device", f"{device!r}: CUDA is not available on this machine; use auto or cpu")
    for ini in ("n2r_artifacts", "n2r_cache_dir"):
        folder = _rooted(config, str(_raw(config, ini)))
        reason = unwritable_reason(folder) if folder is not None else None
        if reason is not None:
            fail(ini, f"{folder}: {reason}; choose a writable folder, or 'none'")
    for spec in scenes:
        if spec.kind == "file":
            from ..scene.file import check_scene_file  # here: a run without scene files never loads the field

            try:
                check_scene_file(spec.source)
            except N2RError as exc:
                raise pytest.UsageError(f"pytest-n2r: --n2r-scene / ini n2r_scenes {spec.source}: {exc}") from None
    settings = RunSettings(
        examples=examples, size=size, derandomize=derandomize_on, timeout=timeout or None,
        artifacts=_rooted(config, str(_raw(config, "n2r_artifacts"))),
    )
    return N2RSession(settings=settings, scenes=scenes, device=device, render_scale=render_scale,
                      cache_dir=_rooted(config, str(_raw(config, "n2r_cache_dir"))), cache_bytes=cache_bytes)


def _session(config: pytest.Config) -> Any:
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
    config.pluginmanager.register(_Summary(config), "n2r-summary")
    if _used(config):
        session = _session(config)  # bad options fail now, before collection
        if config.getoption("n2r_cache_clear") and not hasattr(config, "workerinput"):
            session.cache.clear()  # the controller clears before xdist workers start


def pytest_report_header(config: pytest.Config) -> list[str] | None:
    if not _used(config):
        return None
    return [_describe(config, _session(config))]


def _describe(config: pytest.Config, session: Any) -> str:
    import sys

    from .scenes import default_scene_specs

    scenes = session.scenes or default_scene_specs()
    names = ", ".join(s.name for s in scenes) or "none configured"
    torch = sys.modules.get("torch")
    threads = str(torch.get_num_threads()) if torch is not None else "torch not loaded"
    cache = session.cache_dir if session.cache_dir is not None else "memory only"
    return f"n2r: scenes {names}; device {session.device}; torch threads {threads}; cache {cache}"


# -- collection --------------------------------------------------------------------------------------------


@pytest.hookimpl(tryfirst=True)
def pytest_pycollect_makeitem(collector: pytest.Collector, name: str, obj: Any) -> None:
    """Report an invalid ``@metamorphic(...)`` as a collection error naming the test."""
    if inspect.isfunction(obj):
        error = obj.__dict__.get(ERROR_ATTR)
        if error:
            raise collector.CollectError(f"{collector.nodeid}::{name}: {error}")


def pytest_generate_tests(metafunc: pytest.Metafunc) -> None:
    if "n2r_scene" not in metafunc.fixturenames:
        return
    from ..errors import N2RError

    session = _session(metafunc.config)
    pins = [str(a) for m in metafunc.definition.iter_markers(SCENE_MARKER) for a in m.args]
    try:
        specs = session.scene_specs(pins, base=Path(metafunc.definition.path).parent)
    except N2RError as exc:  # a collection error of this test's module, with just the message
        raise pytest.Collector.CollectError(f"{metafunc.definition.nodeid}: {exc}") from None
    if specs:
        metafunc.parametrize("n2r_scene", specs, ids=[s.name for s in specs], indirect=True, scope="session")
    else:
        metafunc.parametrize("n2r_scene", [None], ids=["no-scene"], indirect=True, scope="session")


@pytest.fixture(scope="session")
def n2r_scene(request: pytest.FixtureRequest) -> Any:
    """The scene under test (a :class:`pytest_n2r.Scene`), loaded once per session; tests that use it
    are parametrized over every configured scene, with the scene name in the test id."""
    from ..errors import N2RError
    from .scenes import NO_SCENE_MESSAGE

    spec = getattr(request, "param", None)
    if spec is None:
        pytest.skip(NO_SCENE_MESSAGE)
    try:
        return _session(request.config).load(spec)
    except N2RError as exc:  # the scene's own message, not a traceback through the loader
        pytest.fail(f"pytest-n2r: scene {spec.source}: {exc}", pytrace=False)


# -- running -----------------------------------------------------------------------------------------------


@pytest.hookimpl(tryfirst=True)
def pytest_pyfunc_call(pyfuncitem: pytest.Function) -> bool | None:
    """Run a ``@metamorphic`` test: call it for the SUT, then check the relation on ``n2r_scene``."""
    relation = getattr(pyfuncitem.obj, RELATION_ATTR, None)
    if relation is None:
        return None
    __tracebackhide__ = True
    from .._timeout import CallTimeout
    from ..relation import RelationFailure
    from ..relation.determinism import SUTNotDeterministic

    funcargs = pyfuncitem.funcargs
    sut = pyfuncitem.obj(**{arg: funcargs[arg] for arg in pyfuncitem._fixtureinfo.argnames})
    if not callable(sut):
        pytest.fail(
            f"{pyfuncitem.nodeid}: a @metamorphic test must return the system under test, a callable taking "
            f"an H×W×3 uint8 RGB image; it returned {sut!r}", pytrace=False,
        )
    session = _session(pyfuncitem.config)
    from .report import baseline_examples

    replay = baseline_examples(pyfuncitem.config, pyfuncitem.nodeid, funcargs["n2r_scene"], relation)
    failure = None
    try:
        session.run(funcargs["n2r_scene"], sut, relation, test_id=pyfuncitem.nodeid, replay=replay)
    except (RelationFailure, CallTimeout, SUTNotDeterministic) as exc:
        failure = str(exc)
    finally:
        if session.stats and session.stats[-1].test_id == pyfuncitem.nodeid:  # kept whatever happened
            plain = pyfuncitem.stash[_STATS] = _plain(session.stats[-1])
            plain["floor"] = plain["record"]["floor"] = _floor(session, funcargs["n2r_scene"], sut, relation,
                                                                session.stats[-1].records)
    if failure is not None:  # outside the except block, so the report shows the message once
        floor = pyfuncitem.stash.get(_STATS, {}).get("floor") or {}
        pytest.fail(failure + (f"\n  floor:      {floor['line']}" if floor.get("below_floor") else ""),
                    pytrace=False)
    return True


def _floor(session: Any, scene: Any, sut: Any, relation: Any, records: list) -> dict | None:
    """The field floor beside a relation's result (:func:`pytest_n2r.relation.floor.annotate_relation`)."""
    from ..relation.floor import annotate_relation

    return annotate_relation(scene, sut, relation, records, size=relation.size or session.settings.size,
                             cache=session.cache, cache_dir=session.cache_dir)


def _plain(stats: Any) -> dict:
    """The JSON-ready summary of a relation run (travels from xdist workers on the test report)."""
    return {
        "test_id": stats.test_id, "scene": stats.scene, "metric": stats.metric, "eps": stats.eps,
        "outcome": stats.outcome, "examples": stats.examples, "rejected": dict(stats.rejected),
        "undefined": dict(stats.undefined), "inconsistencies": stats.inconsistencies,
        "shrink_examples": stats.shrink_examples,
        "worst_deviation": stats.worst_deviation, "render_s": stats.render_s, "sut_s": stats.sut_s,
        "metric_s": stats.metric_s, "renders": stats.renders, "summary": stats.summary_line(),
        "images": (stats.minimal or {}).get("images", {}),
        "record": stats.to_record().to_dict(),
    }


@pytest.hookimpl(hookwrapper=True)  # old-style wrapper: works from pytest 7.4 on
def pytest_runtest_makereport(item: pytest.Item, call: pytest.CallInfo) -> Any:
    outcome = yield
    if call.when == "call":
        stats = item.stash.get(_STATS, None)
        if stats is not None:
            outcome.get_result().n2r_stats = stats  # a plain dict: pytest-xdist ships it to the controller


def relation_records(config: pytest.Config) -> list[Any]:
    """The :class:`pytest_n2r.report.RelationRecord` of every relation run so far in this session
    (including those of pytest-xdist workers), for reports and baselines."""
    from ..report.records import RelationRecord

    summary = config.pluginmanager.get_plugin("n2r-summary")
    return [RelationRecord.from_dict(run["record"]) for run in (summary.runs if summary else [])]


class _Summary:
    """Collects the relation stats of every test report (from xdist workers too) for the summary."""

    def __init__(self, config: pytest.Config):
        self.config = config
        self.runs: list[dict] = []

    def pytest_runtest_logreport(self, report: pytest.TestReport) -> None:
        stats = getattr(report, "n2r_stats", None)
        if stats is not None and report.when == "call":
            self.runs.append(stats)

    def pytest_terminal_summary(self, terminalreporter: Any) -> None:
        runs = self.runs
        if not runs:
            return
        terminalreporter.section("pytest-n2r")
        from ..relation.floor import annotation_lines

        for stats in runs:
            terminalreporter.write_line(stats["summary"])
            for line, warn in annotation_lines(stats.get("floor")):
                terminalreporter.write_line(f"       {line}", yellow=warn, bold=warn)
        total = {k: sum(s[k] for s in runs)
                 for k in ("examples", "inconsistencies", "render_s", "sut_s", "metric_s", "renders")}
        rejected = sum(sum(s["rejected"].values()) for s in runs)
        undefined = sum(sum(s.get("undefined", {}).values()) for s in runs)
        terminalreporter.write_line(
            f"{len(runs)} relation{'s' if len(runs) != 1 else ''}: {total['examples']} example"
            f"{'s' if total['examples'] != 1 else ''}, {rejected} rejected as invalid, {undefined} undefined, "
            f"{total['inconsistencies']} inconsistent; {total['renders']} renders (the rest from the cache); "
            f"time render {total['render_s']:.2f} s / SUT {total['sut_s']:.2f} s / metric "
            f"{total['metric_s']:.2f} s"
        )
        terminalreporter.write_line(_describe(self.config, _session(self.config)))
